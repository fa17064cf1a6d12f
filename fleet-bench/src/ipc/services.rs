//! The bench's own iceoryx2 services, beside the run's real ones.

use iceoryx2::prelude::*;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use protocol::frame::CvsFrame;
use protocol::ipc::{self as pipc, Ipc, IpcOpenError, RunNode};

use super::FLEET;
use super::message::{Ack, Stamp, WINDOW};

/// The benchmark's own services of a run, named here and nowhere else: `{run}/bench/{what}`.
pub struct BenchServices<'a> {
    node: &'a RunNode,
}

/// The frame service: the frame with a [`Stamp`].
pub type FrameService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, CvsFrame, Stamp>;
/// The ack service.
pub type AckService = pipc::PubSubService<Ack>;
/// A variable-size message service with a [`Stamp`].
pub type StampedService =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, [u8], Stamp>;

impl<'a> BenchServices<'a> {
    /// The services of `node`'s run.
    pub fn new(node: &'a RunNode) -> Self {
        Self { node }
    }

    fn name(&self, what: &str) -> anyhow::Result<ServiceName> {
        let s = format!("{}/bench/{what}", self.node.run());
        ServiceName::new(&s).map_err(|e| anyhow::anyhow!("invalid service name {s:?}: {e:?}"))
    }

    /// `{run}/bench/frame`: one publisher, up to `FLEET` subscribers.
    pub fn frames(&self) -> anyhow::Result<FrameService> {
        let name = self.name("frame")?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .publish_subscribe::<CvsFrame>()
            .user_header::<Stamp>()
            .max_publishers(1)
            .max_subscribers(FLEET as usize)
            .max_nodes(pipc::MAX_NODES)
            .subscriber_max_buffer_size(2 * WINDOW as usize)
            .subscriber_max_borrowed_samples(pipc::MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(pub_sub_error(&name))?)
    }

    /// `{run}/bench/frame-ack`: every subscriber's acks to the frame publisher.
    pub fn acks(&self) -> anyhow::Result<AckService> {
        let name = self.name("frame-ack")?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .publish_subscribe::<Ack>()
            .max_publishers(FLEET as usize)
            .max_subscribers(1)
            .max_nodes(pipc::MAX_NODES)
            // Every subscriber may have a window of acks outstanding.
            .subscriber_max_buffer_size(4 * FLEET as usize * WINDOW as usize)
            .subscriber_max_borrowed_samples(pipc::MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(pub_sub_error(&name))?)
    }

    /// `{run}/bench/estimate/{i}`: process `i`'s estimates, with the QoS of the run's estimate
    /// services.
    pub fn estimates(&self, i: u32) -> anyhow::Result<StampedService> {
        let name = self.name(&format!("estimate/{i}"))?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .publish_subscribe::<[u8]>()
            .user_header::<Stamp>()
            .max_publishers(1)
            .max_subscribers(FLEET as usize)
            .max_nodes(pipc::MAX_NODES)
            .subscriber_max_buffer_size(pipc::MESSAGE_BUFFER)
            .subscriber_max_borrowed_samples(pipc::MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(pub_sub_error(&name))?)
    }

    /// `{run}/bench/{what}`: an event service (`frame-wake`, `ack-wake`).
    pub fn event(&self, what: &str) -> anyhow::Result<pipc::EventService> {
        let name = self.name(what)?;
        Ok(self
            .node
            .node()
            .service_builder(&name)
            .event()
            .max_notifiers(FLEET as usize)
            .max_listeners(FLEET as usize)
            .max_nodes(pipc::MAX_NODES)
            .open_or_create()
            .map_err(|source| IpcOpenError::Event {
                service: name.as_str().to_owned(),
                source,
            })?)
    }
}

/// How the run's services report a publish-subscribe service iceoryx2 would not open.
fn pub_sub_error(
    name: &ServiceName,
) -> impl FnOnce(PublishSubscribeOpenOrCreateError) -> IpcOpenError {
    let service = name.as_str().to_owned();
    move |source| IpcOpenError::PubSub { service, source }
}
