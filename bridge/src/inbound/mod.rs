//! Zenoh -> iceoryx2: what other hosts publish for this one, put into the local services as
//! their own processes would, with the same wake-up events.
//!
//! Zenoh calls the subscribers' callbacks on its own threads, and iceoryx2 ports may not
//! leave the thread that made them, so the callbacks only queue what arrived; one thread
//! owns every local port and handles the queue in arrival order. Liveliness and data share
//! that queue: a remote process's proxy node exists before its first message is published
//! here (its host declares it alive before forwarding anything of it, see
//! [`crate::outbound`], and this thread holds what comes before the declaration, see
//! `inbound/unannounced.rs`), so a local process that lists the run's nodes on receipt of a
//! hello or an estimate finds the sender alive, as it would on one host.

mod unannounced;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::SignalHandlingMode;
use protocol::frame::CvsFrame;
use protocol::ipc::{Ipc, IpcOpenError, PubSubService, RunNode, WakeEvent, WirePublisher};
use protocol::wire::{UavCommand, WireKind};

use crate::envelope::{self, EnvelopeError};
use crate::keys::Topic;
use crate::placement::HostPlan;
use crate::report::Counters;
use unannounced::{Message, Unannounced};

/// What the Zenoh callbacks queue for the inbound thread.
#[derive(Debug)]
pub enum Arrival {
    /// A message on a data key.
    Data {
        /// What it is.
        topic: Topic,
        /// Its bytes.
        bytes: Vec<u8>,
    },
    /// A remote process was announced alive (`true`) or gone (`false`).
    Alive {
        /// The announcing host.
        host: String,
        /// The process's node name.
        node: String,
        /// Alive or gone.
        up: bool,
    },
}

/// Initial sample size of the estimate and token publishers (they grow as needed).
const WIRE_INITIAL_BYTES: usize = 64 * 1024;
/// Longest wait on the queue before the shutdown flag is looked at again.
const POLL: Duration = Duration::from_millis(100);

/// The local ports the inbound thread publishes on.
struct Ports {
    frames: BTreeMap<u32, Publisher<Ipc, CvsFrame, ()>>,
    commands: BTreeMap<u32, Publisher<Ipc, UavCommand, ()>>,
    estimates: BTreeMap<u32, WirePublisher>,
    token: WirePublisher,
    agent_wakes: Vec<Notifier<Ipc>>,
    world_wake: Option<Notifier<Ipc>>,
    observer_wake: Option<Notifier<Ipc>>,
    _frame_services: Vec<PubSubService<CvsFrame>>,
    _command_services: Vec<PubSubService<UavCommand>>,
}

impl Ports {
    fn open(node: &RunNode, plan: &HostPlan) -> Result<Ports, IpcOpenError> {
        let mut frames = BTreeMap::new();
        let mut frame_services = Vec::new();
        let mut commands = BTreeMap::new();
        let mut command_services = Vec::new();
        if !plan.world {
            for &uav in &plan.agents {
                let service = node.open_cvs(uav)?;
                frames.insert(uav, service.publisher_builder().create()?);
                frame_services.push(service);
            }
        }
        let mut estimates = BTreeMap::new();
        for uav in plan.remote_agents() {
            if plan.world {
                let service = node.open_cmd(uav)?;
                commands.insert(uav, service.publisher_builder().create()?);
                command_services.push(service);
            }
            let service = node.open_estimate(uav)?;
            estimates.insert(uav, RunNode::wire_publisher(&service, WIRE_INITIAL_BYTES)?);
        }
        let token = RunNode::wire_publisher(&node.open_guidance()?, WIRE_INITIAL_BYTES)?;
        let agent_wakes = plan
            .agents
            .iter()
            .map(|&u| Ok(node.open_agent_wake(u)?.notifier_builder().create()?))
            .collect::<Result<_, IpcOpenError>>()?;
        let (world_wake, observer_wake) = if plan.world {
            (
                Some(node.open_world_wake()?.notifier_builder().create()?),
                Some(node.open_observer_wake()?.notifier_builder().create()?),
            )
        } else {
            (None, None)
        };
        Ok(Ports {
            frames,
            commands,
            estimates,
            token,
            agent_wakes,
            world_wake,
            observer_wake,
            _frame_services: frame_services,
            _command_services: command_services,
        })
    }

    fn wake_agents(&self, event: WakeEvent) {
        for n in &self.agent_wakes {
            notify(n, event);
        }
    }
}

/// Why a received message was not published.
#[derive(Debug, thiserror::Error)]
enum Refusal {
    #[error("not for this host")]
    NotForThisHost,
    #[error(transparent)]
    Envelope(#[from] EnvelopeError),
    #[error("its key names UAV {key} but the message UAV {inside}")]
    Sender { key: u32, inside: u32 },
    #[error("its header is not of a {0:?}")]
    Kind(&'static [WireKind]),
    #[error("cannot publish it: {0}")]
    Publish(String),
}

impl Refusal {
    fn label(&self) -> &'static str {
        match self {
            Refusal::NotForThisHost => "not_for_this_host",
            Refusal::Envelope(_) => "malformed",
            Refusal::Sender { .. } => "sender_mismatch",
            Refusal::Kind(_) => "kind",
            Refusal::Publish(_) => "publish_failed",
        }
    }
}

/// The inbound thread's body: publishes what `arrivals` brings until the queue closes or
/// `shutdown` is raised.
pub fn run(
    plan: &HostPlan,
    arrivals: Receiver<Arrival>,
    ready: impl FnOnce(Result<(), IpcOpenError>),
    shutdown: &AtomicBool,
) -> Counters {
    let mut counters = Counters::default();
    let opened = RunNode::new(&plan.run, "bridge-in", SignalHandlingMode::Disabled)
        .and_then(|node| Ok((Ports::open(&node, plan)?, node)));
    let (ports, _node) = match opened {
        Ok(p) => {
            ready(Ok(()));
            p
        }
        Err(e) => {
            ready(Err(e));
            return counters;
        }
    };
    let mut proxies = Proxies::default();
    let mut unannounced = Unannounced::default();
    while !shutdown.load(Ordering::Relaxed) {
        let wait = unannounced.next_deadline().map_or(POLL, |d| {
            d.saturating_duration_since(Instant::now()).min(POLL)
        });
        match arrivals.recv_timeout(wait) {
            Ok(Arrival::Data { topic, bytes }) => {
                let node = sender(topic);
                if unannounced.holds(&node)
                    || (plan.is_remote_node(&node) && !proxies.exists(&node))
                {
                    counters.held += 1;
                    let over = unannounced.hold(&node, (topic, bytes), Instant::now());
                    deliver_unannounced(plan, &ports, over, &mut counters);
                } else {
                    deliver(plan, &ports, topic, &bytes, &mut counters);
                }
            }
            Ok(Arrival::Alive { host, node, up }) => {
                proxies.update(plan, &host, &node, up, &mut counters);
                if proxies.exists(&node) {
                    for (topic, bytes) in unannounced.release(&node) {
                        deliver(plan, &ports, topic, &bytes, &mut counters);
                    }
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        let expired = unannounced.expired(Instant::now());
        deliver_unannounced(plan, &ports, expired, &mut counters);
    }
    let left = unannounced.release_all();
    deliver_unannounced(plan, &ports, left, &mut counters);
    counters
}

/// The node that publishes `topic`'s messages.
fn sender(topic: Topic) -> String {
    match topic {
        Topic::Frame(_) | Topic::EndOfRun => RunNode::WORLD.to_owned(),
        Topic::Command(uav) | Topic::Estimate(uav) | Topic::State(uav) | Topic::Token(uav) => {
            RunNode::agent_name(uav)
        }
    }
}

/// Publishes a message here, or counts it refused.
fn deliver(plan: &HostPlan, ports: &Ports, topic: Topic, bytes: &[u8], counters: &mut Counters) {
    match publish(plan, ports, topic, bytes) {
        Ok(()) => counters.received(topic_label(topic), bytes.len() as u64),
        Err(e) => {
            tracing::warn!(?topic, error = %e, "message from another host refused");
            counters.refused(topic_label(topic), e.label());
        }
    }
}

/// Publishes held messages whose sender's announcement did not come in time.
fn deliver_unannounced(
    plan: &HostPlan,
    ports: &Ports,
    messages: Vec<Message>,
    counters: &mut Counters,
) {
    for (topic, bytes) in messages {
        tracing::warn!(
            ?topic,
            "published before its sender was announced alive: no announcement within the hold, \
             or the sender's held messages outgrew it"
        );
        counters.unannounced += 1;
        deliver(plan, ports, topic, &bytes, counters);
    }
}

/// Name of a topic in the counters.
pub fn topic_label(topic: Topic) -> &'static str {
    match topic {
        Topic::Frame(_) => "frame",
        Topic::Command(_) => "command",
        Topic::Estimate(_) => "estimate",
        Topic::State(_) => "state",
        Topic::Token(_) => "token",
        Topic::EndOfRun => "end_of_run",
    }
}

fn publish(plan: &HostPlan, ports: &Ports, topic: Topic, bytes: &[u8]) -> Result<(), Refusal> {
    match topic {
        Topic::Frame(uav) => {
            let publisher = ports.frames.get(&uav).ok_or(Refusal::NotForThisHost)?;
            let mut sample = publisher
                .loan_uninit()
                .map_err(|e| Refusal::Publish(e.to_string()))?;
            let frame = CvsFrame::init_in_place(sample.payload_mut());
            envelope::decode_frame_into(bytes, frame)?;
            if frame.header.uav != uav {
                return Err(Refusal::Sender {
                    key: uav,
                    inside: frame.header.uav,
                });
            }
            // SAFETY: init_in_place initialised the whole payload.
            unsafe { sample.assume_init() }
                .send()
                .map_err(|e| Refusal::Publish(e.to_string()))?;
            notify_agent(plan, ports, uav, WakeEvent::Frame);
        }
        Topic::Command(uav) => {
            let publisher = ports.commands.get(&uav).ok_or(Refusal::NotForThisHost)?;
            let cmd = envelope::decode_command(bytes)?;
            if cmd.uav != uav {
                return Err(Refusal::Sender {
                    key: uav,
                    inside: cmd.uav,
                });
            }
            publisher
                .send_copy(cmd)
                .map_err(|e| Refusal::Publish(e.to_string()))?;
            if let Some(n) = &ports.world_wake {
                notify(n, WakeEvent::Command);
            }
        }
        Topic::Estimate(uav) => {
            let publisher = ports.estimates.get(&uav).ok_or(Refusal::NotForThisHost)?;
            publish_wire(publisher, &[WireKind::Estimate], uav, bytes)?;
            ports.wake_agents(WakeEvent::Estimate);
            if let Some(n) = &ports.observer_wake {
                notify(n, WakeEvent::Estimate);
            }
        }
        Topic::State(uav) => {
            // The sender's sets for the observers, on its estimate service as on one host
            // (peers skip them unread): only the observer's host takes them.
            if !plan.world {
                return Err(Refusal::NotForThisHost);
            }
            let publisher = ports.estimates.get(&uav).ok_or(Refusal::NotForThisHost)?;
            publish_wire(publisher, &[WireKind::State], uav, bytes)?;
            if let Some(n) = &ports.observer_wake {
                notify(n, WakeEvent::Estimate);
            }
        }
        Topic::Token(uav) => {
            if plan.is_local(uav) {
                return Err(Refusal::NotForThisHost);
            }
            publish_wire(&ports.token, &[WireKind::Token], uav, bytes)?;
            ports.wake_agents(WakeEvent::Token);
        }
        Topic::EndOfRun => {
            if plan.world {
                return Err(Refusal::NotForThisHost);
            }
            ports.wake_agents(WakeEvent::EndOfRun);
        }
    }
    Ok(())
}

/// Publishes a variable-size message whose key names `uav` as its sender and whose header
/// names one of `kinds`.
fn publish_wire(
    publisher: &WirePublisher,
    kinds: &'static [WireKind],
    uav: u32,
    bytes: &[u8],
) -> Result<(), Refusal> {
    let (header, payload) = envelope::decode_wire(bytes)?;
    if header.sender != uav {
        return Err(Refusal::Sender {
            key: uav,
            inside: header.sender,
        });
    }
    if !kinds.iter().any(|&kind| header.kind == kind as u32) {
        return Err(Refusal::Kind(kinds));
    }
    let mut sample = publisher
        .loan_slice_uninit(payload.len())
        .map_err(|e| Refusal::Publish(e.to_string()))?;
    *sample.user_header_mut() = header;
    sample
        .write_from_slice(payload)
        .send()
        .map_err(|e| Refusal::Publish(e.to_string()))?;
    Ok(())
}

fn notify_agent(plan: &HostPlan, ports: &Ports, uav: u32, event: WakeEvent) {
    if let Some(i) = plan.agents.iter().position(|&u| u == uav) {
        notify(&ports.agent_wakes[i], event);
    }
}

/// Notifies, logging (not failing) when the event cannot be sent: a wake-up is a hint.
pub fn notify(notifier: &Notifier<Ipc>, event: WakeEvent) {
    if let Err(e) = notifier.notify_with_custom_event_id(event.id()) {
        tracing::debug!(error = ?e, ?event, "notify failed");
    }
}

/// The local stand-ins of remote processes: an iceoryx2 node of the same name for each
/// process another host announces alive, so that the local processes, which tell who is
/// alive by listing the run's nodes, see the remote ones as they would on one host.
#[derive(Default)]
struct Proxies {
    /// Node name -> the node and the hosts that announce it (one, unless a process moved).
    nodes: BTreeMap<String, (RunNode, BTreeSet<String>)>,
}

impl Proxies {
    /// Whether a proxy of `node` exists.
    fn exists(&self, node: &str) -> bool {
        self.nodes.contains_key(node)
    }

    fn update(
        &mut self,
        plan: &HostPlan,
        host: &str,
        node: &str,
        up: bool,
        counters: &mut Counters,
    ) {
        if host == plan.host {
            return;
        }
        if !plan.is_remote_node(node) {
            tracing::warn!(
                host,
                node,
                "liveliness of an unknown or local process ignored"
            );
            counters.refused("alive", "unknown_node");
            return;
        }
        if up {
            if let Some((_, hosts)) = self.nodes.get_mut(node) {
                hosts.insert(host.to_owned());
                return;
            }
            match RunNode::new(&plan.run, node, SignalHandlingMode::Disabled) {
                Ok(proxy) => {
                    tracing::info!(host, node, "remote process alive: proxy created");
                    counters.proxies_created += 1;
                    self.nodes
                        .insert(node.to_owned(), (proxy, BTreeSet::from([host.to_owned()])));
                }
                Err(e) => {
                    tracing::warn!(host, node, error = %e, "cannot create a proxy node");
                    counters.refused("alive", "proxy_failed");
                }
            }
        } else if let Some((_, hosts)) = self.nodes.get_mut(node) {
            hosts.remove(host);
            if hosts.is_empty() {
                tracing::info!(host, node, "remote process gone: proxy removed");
                self.nodes.remove(node);
            }
        }
    }
}
