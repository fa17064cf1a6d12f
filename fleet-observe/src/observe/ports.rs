//! The observer's iceoryx2 ports on the run's services: what it subscribes to (the truth,
//! every agent's estimates, the guidance token, the shown UAV's camera frames), what it
//! publishes (its acks) and the events that wake it and the world.
//!
//! The ports are opened once on the observer's thread (iceoryx2 ports are not `Send`) and
//! only read or written by the loop; what a message means is for the part that gets it
//! ([`reception`](super::reception) for estimates, [`showing`](super::showing) for frames and
//! plans). Each port keeps its service open ([`Services`]) for as long as it lives.

use anyhow::Context as _;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use protocol::frame::CvsFrame;
use protocol::ipc::{
    EventService, Ipc, PubSubService, RunNode, WakeEvent, WireService, WireSubscriber,
};
use protocol::wire::{ObserverAck, TruthState, UavMask};

/// The observer's ports, opened by [`Ports::open`].
pub(super) struct Ports {
    /// The world's truth of each step.
    pub(super) truth: Subscriber<Ipc, TruthState, ()>,
    /// Each agent's estimates, by UAV.
    pub(super) estimates: Vec<(u32, WireSubscriber)>,
    /// The guidance token, whoever sends it.
    pub(super) tokens: WireSubscriber,
    /// The shown UAV's camera frames, when a viewer is on.
    pub(super) frames: Option<Subscriber<Ipc, CvsFrame, ()>>,
    /// The observer's acks (and hellos) to the world.
    ack: Publisher<Ipc, ObserverAck, ()>,
    /// Wakes the world once an ack is sent.
    world_wake: Notifier<Ipc>,
    /// Wakes the observer (new messages, the end of the run).
    pub(super) wake: Listener<Ipc>,
    _services: Services,
}

/// The services the ports belong to, kept open as long as the ports.
struct Services {
    _truth: PubSubService<TruthState>,
    _estimates: Vec<WireService>,
    _guidance: WireService,
    _ack: PubSubService<ObserverAck>,
    _events: Vec<EventService>,
    _frames: Option<PubSubService<CvsFrame>>,
}

impl Ports {
    /// The observer's ports; with `camera`, also a subscriber to that UAV's frames.
    pub(super) fn open(node: &RunNode, uavs: u32, camera: Option<u32>) -> anyhow::Result<Ports> {
        let truth_service = node.open_truth()?;
        let truth = truth_service.subscriber_builder().create()?;
        let mut estimate_services = Vec::new();
        let mut estimates = Vec::new();
        for uav in 0..uavs {
            let s = node.open_estimate(uav)?;
            estimates.push((uav, s.subscriber_builder().create()?));
            estimate_services.push(s);
        }
        let guidance = node.open_guidance()?;
        let tokens = guidance.subscriber_builder().create()?;
        let ack_service = node.open_observer_ack()?;
        let ack = ack_service.publisher_builder().create()?;
        let world = node.open_world_wake()?;
        let world_wake = world.notifier_builder().create()?;
        let own = node.open_observer_wake()?;
        let wake = own.listener_builder().create()?;
        let frame_service = camera.map(|uav| node.open_cvs(uav)).transpose()?;
        let frames = frame_service
            .as_ref()
            .map(|s| s.subscriber_builder().create())
            .transpose()?;
        Ok(Ports {
            truth,
            estimates,
            tokens,
            frames,
            ack,
            world_wake,
            wake,
            _services: Services {
                _truth: truth_service,
                _estimates: estimate_services,
                _guidance: guidance,
                _ack: ack_service,
                _events: vec![world, own],
                _frames: frame_service,
            },
        })
    }

    /// Acknowledges `step` of the run tagged `run_tag` to the world (a hello with
    /// [`HELLO_STEP`](protocol::wire::HELLO_STEP)), announcing the agents `restarted`, and
    /// wakes it.
    pub(super) fn send_ack(
        &self,
        run_tag: u64,
        step: u64,
        restarted: UavMask,
    ) -> anyhow::Result<()> {
        self.ack
            .send_copy(ObserverAck {
                run_tag,
                step,
                restarted,
            })
            .context("cannot send the observer's ack")?;
        if let Err(e) = self
            .world_wake
            .notify_with_custom_event_id(WakeEvent::ObserverAck.id())
        {
            tracing::debug!(error = ?e, "cannot wake the world");
        }
        Ok(())
    }
}
