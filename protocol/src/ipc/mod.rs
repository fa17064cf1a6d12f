//! The one place that knows how setfleet uses iceoryx2: node configuration, the quality of
//! service of every service, the wake-up event ids, and cleaning up after dead processes.
//!
//! Every process opens every service through [`RunNode`], so all of them ask for identical
//! settings and none can open a service with limits another process did not expect.
//!
//! # Choices and why
//!
//! - **One prefix per run.** Each run's files carry [`RunId::file_prefix`] (iceoryx2's
//!   `global.prefix`), so runs and tests never see each other and a run's leftovers can be
//!   removed by prefix ([`remove_run_files`]; [`run_of_file`] reads a file's run back, and
//!   [`runs_with_files`] lists the runs that left some). The configuration starts from
//!   iceoryx2's built-in defaults, not from a config file on the machine, so every process
//!   agrees.
//! - **Nobody ever blocks on a dead peer.** Every publish-subscribe service uses safe overflow:
//!   a full subscriber buffer drops its oldest sample instead of stalling the publisher. Every
//!   message carries its run tag and step, so a receiver tells what it missed.
//! - **Room for a whole fleet.** Limits allow [`MAX_UAVS`] agents all-to-all, plus the world,
//!   [`MAX_OBSERVERS`] observers and [`RESTART_OVERLAP`] restarted agents whose dead predecessor
//!   was not cleaned up yet.
//! - **Waiting.** Ports of `ipc::Service` are not `Send`; a process waits on its wake-up
//!   [`Listener`](iceoryx2::port::listener::Listener) with a [`WaitSet`] built by
//!   [`RunNode::waitset`]. Senders notify with a [`WakeEvent`] id so a woken process knows
//!   what to look at.
//! - **Signals.** The world-server and agents use
//!   [`SignalHandlingMode::HandleTerminationRequests`]: SIGTERM and SIGINT end their wait loop
//!   cleanly (after the first wait; before it, the default action applies). Test harnesses and
//!   tokio processes use [`SignalHandlingMode::Disabled`] and handle signals themselves.
//!
//! # Handshake
//!
//! An agent opens its subscribers, then sends a [`UavCommand`] with `step ==`
//! [`crate::wire::HELLO_STEP`] and notifies [`world_wake`](crate::service::world_wake); it
//! repeats the hello every few hundred milliseconds until its first frame arrives (a message
//! sent before the world subscribed is lost). The observer does the same with an
//! [`ObserverAck`]. Each frame, truth and end of run is announced with a [`WakeEvent`].
//!
//! # Example
//!
//! **World-server (process 1)**
//!
//! ```no_run
//! use iceoryx2::prelude::SignalHandlingMode;
//! use protocol::frame::CvsFrame;
//! use protocol::ipc::{RunNode, WakeEvent};
//! use protocol::service::RunId;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let run = RunId::new("demo")?;
//! let node = RunNode::new(&run, "world", SignalHandlingMode::HandleTerminationRequests)?;
//! let cvs = node.open_cvs(0)?;
//! let publisher = cvs.publisher_builder().max_loaned_samples(2).create()?;
//! let wake = node.open_agent_wake(0)?.notifier_builder().create()?;
//! let mut sample = publisher.loan_uninit()?;
//! let frame = CvsFrame::init_in_place(sample.payload_mut());
//! frame.header.step = 0; // ... render in place ...
//! // SAFETY: init_in_place initialised the whole payload.
//! unsafe { sample.assume_init() }.send()?;
//! wake.notify_with_custom_event_id(WakeEvent::Frame.id())?;
//! # Ok(())
//! # }
//! ```
//!
//! **Agent 0 (process 2)**
//!
//! ```no_run
//! use std::time::Duration;
//! use iceoryx2::prelude::SignalHandlingMode;
//! use protocol::ipc::RunNode;
//! use protocol::service::RunId;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let run = RunId::new("demo")?;
//! let node = RunNode::new(&run, &RunNode::agent_name(0), SignalHandlingMode::HandleTerminationRequests)?;
//! let frames = node.open_cvs(0)?.subscriber_builder().create()?;
//! let listener = node.open_agent_wake(0)?.listener_builder().create()?;
//! let waitset = node.waitset()?;
//! let _guard = waitset.attach_notification(&listener)?;
//! let wake = protocol::ipc::wait_for_wake(&waitset, &listener, Duration::from_secs(1))?;
//! if wake.end_of_run {
//!     println!("the run ended");
//! }
//! while let Some(frame) = frames.receive()? {
//!     println!("frame {}", frame.payload().header.step);
//! }
//! # Ok(())
//! # }
//! ```

mod run_files;

use std::time::Duration;

use iceoryx2::node::{NodeCreationFailure, NodeListFailure, NodeView};
use iceoryx2::port::listener::ListenerCreateError;
use iceoryx2::port::notifier::NotifierCreateError;
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::SubscriberCreateError;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::builder::request_response::RequestResponseOpenOrCreateError;
use iceoryx2::service::port_factory::client::ClientCreateError;
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};
use iceoryx2::waitset::{
    WaitSetAttachmentError, WaitSetCreateError, WaitSetRunError, WaitSetRunResult,
};

use crate::frame::CvsFrame;
use crate::service::{self, RunId};
use crate::wire::{MAX_UAVS, ObserverAck, TruthState, UavCommand, WireHeader};

pub use run_files::{
    belongs_to_run, is_global_segment, remove_run_files, run_files, run_of_file, runs_with_files,
};

/// The iceoryx2 service flavour every setfleet process uses (inter-process, single-threaded
/// ports).
pub type Ipc = ipc::Service;
/// A publish-subscribe service of fixed-size messages.
pub type PubSubService<T> = publish_subscribe::PortFactory<Ipc, T, ()>;
/// A publish-subscribe service of variable-size messages behind a [`WireHeader`].
pub type WireService = publish_subscribe::PortFactory<Ipc, [u8], WireHeader>;
/// A publisher of variable-size messages.
pub type WirePublisher = Publisher<Ipc, [u8], WireHeader>;
/// A subscriber to variable-size messages (estimates, tokens).
pub type WireSubscriber = iceoryx2::port::subscriber::Subscriber<Ipc, [u8], WireHeader>;
/// An event service (wake-ups).
pub type EventService = event::PortFactory<Ipc>;
/// The request-response service of an agent and its external planner: bytes both ways.
pub type PlanService = request_response::PortFactory<Ipc, [u8], (), [u8], ()>;

/// Observers (the orchestrator's observer, a debugging tool) a run allows at once.
pub const MAX_OBSERVERS: usize = 2;
/// Restarted processes that may overlap their dead predecessor until it is cleaned up.
pub const RESTART_OVERLAP: usize = 2;
/// Nodes that may open one service at once: the whole fleet twice over (restarts), the world
/// and the observers.
pub const MAX_NODES: usize = 2 * MAX_UAVS + MAX_OBSERVERS + 4;
/// Buffer of a frame subscriber: the world waits for acks, so one frame in flight is normal.
pub const CVS_BUFFER: usize = 2;
/// Buffer of the other subscribers (commands, estimates, token, truth, acks).
pub const MESSAGE_BUFFER: usize = 16;
/// Samples a subscriber may hold at once.
pub const MAX_BORROWED: usize = 2;
/// Connections to publishers that went away a subscriber keeps while it still has their
/// samples to read or holds one (iceoryx2's `subscriber_expired_connection_buffer`, 128 by
/// default). Each subscriber allocates room for this many connections beside those to live
/// publishers, about 3.7 kB each: at iceoryx2's default, 0.48 MB per subscriber, 30 MB for an
/// agent of a 64-UAV fleet with its 63 peers' estimate subscribers (heaptrack). Past it, the
/// oldest expired connection without a held sample is dropped, and with it the dead
/// publisher's unread messages, which lossy delivery already allows; a held sample is never
/// dropped, since a subscriber holds at most [`MAX_BORROWED`], fewer than this.
pub const EXPIRED_CONNECTIONS: usize = MAX_BORROWED + RESTART_OVERLAP;
// A subscriber never has to drop a connection whose sample it holds.
const _: () = assert!(EXPIRED_CONNECTIONS >= MAX_BORROWED);

/// What a wake-up notification announces; its value is the iceoryx2 event id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(usize)]
pub enum WakeEvent {
    /// A frame was published for the woken agent.
    Frame = 1,
    /// A peer published an estimate.
    Estimate = 2,
    /// The guidance token was passed.
    Token = 3,
    /// Truth of a step was published.
    Truth = 4,
    /// An agent sent a command (ack or hello).
    Command = 5,
    /// The run ended: stop after handling what already arrived.
    EndOfRun = 6,
    /// The observer acknowledged a step (or said hello).
    ObserverAck = 7,
    /// An external planner answered the woken agent ([`crate::plan`]).
    PlanAnswer = 8,
}

impl WakeEvent {
    /// Every event, in id order.
    pub const ALL: [WakeEvent; 8] = [
        WakeEvent::Frame,
        WakeEvent::Estimate,
        WakeEvent::Token,
        WakeEvent::Truth,
        WakeEvent::Command,
        WakeEvent::EndOfRun,
        WakeEvent::ObserverAck,
        WakeEvent::PlanAnswer,
    ];
    /// Largest id, the event services' `event_id_max_value`.
    pub const MAX_ID: usize = WakeEvent::PlanAnswer as usize;

    /// The iceoryx2 event id.
    pub fn id(self) -> EventId {
        EventId::new(self as usize)
    }

    /// Decodes an event id; `None` for an id no setfleet process sends.
    pub fn from_id(id: EventId) -> Option<WakeEvent> {
        WakeEvent::ALL
            .into_iter()
            .find(|e| *e as usize == id.as_value())
    }
}

/// Why a node, a service, a port or a wait set could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum IpcOpenError {
    /// The node name is not a valid iceoryx2 node name.
    #[error("invalid node name {0:?}")]
    NodeName(String),
    /// The run's file prefix is not a valid iceoryx2 file name.
    #[error("invalid iceoryx2 prefix {0:?}")]
    Prefix(String),
    /// iceoryx2 refused to create the node.
    #[error("cannot create the iceoryx2 node: {0}")]
    Node(#[from] NodeCreationFailure),
    /// A publish-subscribe service could not be opened or created (e.g. another version's
    /// payload type, or limits that do not match).
    #[error("cannot open service {service}: {source}")]
    PubSub {
        /// The service name.
        service: String,
        /// iceoryx2's reason.
        source: PublishSubscribeOpenOrCreateError,
    },
    /// A request-response service could not be opened or created.
    #[error("cannot open request-response service {service}: {source}")]
    RequestResponse {
        /// The service name.
        service: String,
        /// iceoryx2's reason.
        source: RequestResponseOpenOrCreateError,
    },
    /// A client could not be created.
    #[error("cannot create a client: {0}")]
    Client(#[from] ClientCreateError),
    /// An event service could not be opened or created.
    #[error("cannot open event service {service}: {source}")]
    Event {
        /// The service name.
        service: String,
        /// iceoryx2's reason.
        source: EventOpenOrCreateError,
    },
    /// A publisher could not be created (e.g. the service's publisher limit is reached).
    #[error("cannot create a publisher: {0}")]
    Publisher(#[from] PublisherCreateError),
    /// A subscriber could not be created.
    #[error("cannot create a subscriber: {0}")]
    Subscriber(#[from] SubscriberCreateError),
    /// A notifier could not be created.
    #[error("cannot create a notifier: {0}")]
    Notifier(#[from] NotifierCreateError),
    /// A listener could not be created.
    #[error("cannot create a listener: {0}")]
    Listener(#[from] ListenerCreateError),
    /// A wait set could not be created.
    #[error("cannot create a wait set: {0}")]
    WaitSet(#[from] WaitSetCreateError),
    /// A listener could not be attached to a wait set.
    #[error("cannot wait on a wake-up event: {0}")]
    Attach(#[from] WaitSetAttachmentError),
}

/// Why the nodes of a run could not be listed.
#[derive(Debug, thiserror::Error)]
pub enum NodeScanError {
    /// The run's file prefix is not a valid iceoryx2 file name.
    #[error("invalid iceoryx2 prefix {0:?}")]
    Prefix(String),
    /// iceoryx2 could not list the nodes.
    #[error("cannot list iceoryx2 nodes: {0}")]
    List(#[from] NodeListFailure),
}

/// The iceoryx2 configuration of a run: built-in defaults with the run's file prefix, and
/// [`EXPIRED_CONNECTIONS`] expired connections per subscriber.
pub fn run_config(run: &RunId) -> Result<Config, IpcOpenError> {
    let prefix = run.file_prefix();
    let mut config = Config::default();
    config.global.prefix =
        FileName::new(prefix.as_bytes()).map_err(|_| IpcOpenError::Prefix(prefix.clone()))?;
    config
        .defaults
        .publish_subscribe
        .subscriber_expired_connection_buffer = EXPIRED_CONNECTIONS;
    Ok(config)
}

/// Installs iceoryx2's SIGTERM and SIGINT handler now. iceoryx2 installs it at the first
/// check for a termination request, i.e. at a process's first wait; until then either signal
/// kills the process. An empty wait set's zero wait makes that check (and then fails for want
/// of attachments, which is ignored); a request already made is seen by the next wait.
fn install_termination_handler() {
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Ipc>();
    if let Ok(waitset) = waitset {
        let _ = waitset
            .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, Duration::ZERO);
    }
}

/// One process's iceoryx2 node in a run, and the typed way to open the run's services.
pub struct RunNode {
    node: Node<Ipc>,
    run: RunId,
    signals: SignalHandlingMode,
}

impl RunNode {
    /// Node name of the world-server.
    pub const WORLD: &'static str = "world";
    /// Node name of an observer.
    pub const OBSERVER: &'static str = "observer";

    /// Node name of agent `uav`: `agent-{uav}`.
    pub fn agent_name(uav: u32) -> String {
        format!("agent-{uav}")
    }

    /// Creates the node `name` of `run` with the given signal handling. With
    /// [`SignalHandlingMode::HandleTerminationRequests`], the process handles SIGTERM and
    /// SIGINT from before its node exists: whoever sees the node may signal it.
    pub fn new(
        run: &RunId,
        name: &str,
        signals: SignalHandlingMode,
    ) -> Result<RunNode, IpcOpenError> {
        if signals == SignalHandlingMode::HandleTerminationRequests {
            install_termination_handler();
        }
        let config = run_config(run)?;
        let node_name = NodeName::new(name).map_err(|_| IpcOpenError::NodeName(name.to_owned()))?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&config)
            .signal_handling_mode(signals)
            .create::<Ipc>()?;
        Ok(RunNode {
            node,
            run: run.clone(),
            signals,
        })
    }

    /// The iceoryx2 node.
    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }

    /// The run.
    pub fn run(&self) -> &RunId {
        &self.run
    }

    /// A wait set with the node's signal handling.
    pub fn waitset(&self) -> Result<WaitSet<Ipc>, IpcOpenError> {
        Ok(WaitSetBuilder::new()
            .signal_handling_mode(self.signals)
            .create::<Ipc>()?)
    }

    /// `{run}/uav/{i}/cvs`: frames, one publisher (the world), lossy, small buffer.
    pub fn open_cvs(&self, uav: u32) -> Result<PubSubService<CvsFrame>, IpcOpenError> {
        let name = service::cvs(&self.run, uav);
        self.node
            .service_builder(&name)
            .publish_subscribe::<CvsFrame>()
            .max_publishers(1)
            .max_subscribers(1 + RESTART_OVERLAP + MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(CVS_BUFFER)
            .subscriber_max_borrowed_samples(MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|source| pub_sub_error(&name, source))
    }

    /// `{run}/uav/{i}/cmd`: agent `i`'s commands and acks; two publishers (a restarted agent
    /// may overlap its dead predecessor).
    pub fn open_cmd(&self, uav: u32) -> Result<PubSubService<UavCommand>, IpcOpenError> {
        let name = service::cmd(&self.run, uav);
        self.fixed_message_service(&name, 1 + RESTART_OVERLAP, 1 + MAX_OBSERVERS)
    }

    /// `{run}/truth`: ground truth for observers, one publisher (the world).
    pub fn open_truth(&self) -> Result<PubSubService<TruthState>, IpcOpenError> {
        let name = service::truth(&self.run);
        self.fixed_message_service(&name, 1, MAX_OBSERVERS + RESTART_OVERLAP)
    }

    /// `{run}/observer/ack`: observers' lockstep acks, read by the world.
    pub fn open_observer_ack(&self) -> Result<PubSubService<ObserverAck>, IpcOpenError> {
        let name = service::observer_ack(&self.run);
        self.fixed_message_service(&name, MAX_OBSERVERS + RESTART_OVERLAP, 1)
    }

    /// `{run}/uav/{i}/estimate`: agent `i`'s estimates for every peer and observer.
    pub fn open_estimate(&self, uav: u32) -> Result<WireService, IpcOpenError> {
        let name = service::estimate(&self.run, uav);
        self.wire_service(&name, 1 + RESTART_OVERLAP)
    }

    /// `{run}/guidance`: the token, sent by any agent (and an observer).
    pub fn open_guidance(&self) -> Result<WireService, IpcOpenError> {
        let name = service::guidance(&self.run);
        self.wire_service(&name, MAX_UAVS + 1 + RESTART_OVERLAP)
    }

    /// A publisher of variable-size messages whose samples grow as needed (power-of-two
    /// reallocation), starting at `initial_len` bytes.
    pub fn wire_publisher(
        service: &WireService,
        initial_len: usize,
    ) -> Result<WirePublisher, IpcOpenError> {
        Ok(service
            .publisher_builder()
            .initial_max_slice_len(initial_len.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .max_loaned_samples(2)
            .create()?)
    }

    /// `{run}/uav/{i}/wake`: wakes agent `i`; notified by the world, every peer and observers.
    pub fn open_agent_wake(&self, uav: u32) -> Result<EventService, IpcOpenError> {
        let name = service::agent_wake(&self.run, uav);
        self.event_service(&name, fleet_senders() + 1, 1 + RESTART_OVERLAP)
    }

    /// `{run}/world/wake`: wakes the world-server (commands, observer acks).
    pub fn open_world_wake(&self) -> Result<EventService, IpcOpenError> {
        let name = service::world_wake(&self.run);
        self.event_service(&name, fleet_senders(), 2)
    }

    /// `{run}/observer/wake`: wakes observers (truth, estimates, end of run).
    pub fn open_observer_wake(&self) -> Result<EventService, IpcOpenError> {
        let name = service::observer_wake(&self.run);
        self.event_service(&name, fleet_senders() + 1, MAX_OBSERVERS + RESTART_OVERLAP)
    }

    /// `{run}/uav/{i}/plan`: agent `i`'s requests to an external planner and its answers
    /// (payloads of bytes, [`crate::plan`]); the agent and a restarted one, and a planner
    /// with a restarted one.
    pub fn open_plan(&self, uav: u32) -> Result<PlanService, IpcOpenError> {
        let name = service::plan(&self.run, uav);
        self.node
            .service_builder(&name)
            .request_response::<[u8], [u8]>()
            .max_clients(1 + RESTART_OVERLAP)
            .max_servers(1 + RESTART_OVERLAP)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|source| IpcOpenError::RequestResponse {
                service: name.as_str().to_owned(),
                source,
            })
    }

    /// `{run}/planner/wake`: wakes external planners; the event id is the asking UAV.
    pub fn open_planner_wake(&self) -> Result<EventService, IpcOpenError> {
        let name = service::planner_wake(&self.run);
        self.node
            .service_builder(&name)
            .event()
            .max_notifiers(fleet_senders())
            .max_listeners(MAX_OBSERVERS + RESTART_OVERLAP)
            .max_nodes(MAX_NODES)
            .event_id_max_value(MAX_UAVS - 1)
            .open_or_create()
            .map_err(|source| IpcOpenError::Event {
                service: name.as_str().to_owned(),
                source,
            })
    }

    fn fixed_message_service<T: std::fmt::Debug + ZeroCopySend>(
        &self,
        name: &ServiceName,
        publishers: usize,
        subscribers: usize,
    ) -> Result<PubSubService<T>, IpcOpenError> {
        self.node
            .service_builder(name)
            .publish_subscribe::<T>()
            .max_publishers(publishers)
            .max_subscribers(subscribers)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(MESSAGE_BUFFER)
            .subscriber_max_borrowed_samples(MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|source| pub_sub_error(name, source))
    }

    fn wire_service(
        &self,
        name: &ServiceName,
        publishers: usize,
    ) -> Result<WireService, IpcOpenError> {
        self.node
            .service_builder(name)
            .publish_subscribe::<[u8]>()
            .user_header::<WireHeader>()
            .max_publishers(publishers)
            .max_subscribers(MAX_UAVS + RESTART_OVERLAP + MAX_OBSERVERS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(MESSAGE_BUFFER)
            .subscriber_max_borrowed_samples(MAX_BORROWED)
            .history_size(0)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|source| pub_sub_error(name, source))
    }

    fn event_service(
        &self,
        name: &ServiceName,
        notifiers: usize,
        listeners: usize,
    ) -> Result<EventService, IpcOpenError> {
        self.node
            .service_builder(name)
            .event()
            .max_notifiers(notifiers)
            .max_listeners(listeners)
            .max_nodes(MAX_NODES)
            .event_id_max_value(WakeEvent::MAX_ID)
            .open_or_create()
            .map_err(|source| IpcOpenError::Event {
                service: name.as_str().to_owned(),
                source,
            })
    }
}

/// Processes that may send to one receiver: every agent, restarts, observers.
fn fleet_senders() -> usize {
    MAX_UAVS + RESTART_OVERLAP + MAX_OBSERVERS
}

fn pub_sub_error(name: &ServiceName, source: PublishSubscribeOpenOrCreateError) -> IpcOpenError {
    IpcOpenError::PubSub {
        service: name.as_str().to_owned(),
        source,
    }
}

/// The nodes of a run by name, as iceoryx2 sees them now.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct NodeScan {
    /// Names of nodes whose process is alive.
    pub alive: Vec<String>,
    /// Names of nodes whose process died without cleaning up (their resources were removed
    /// when the scan was made with `cleanup`).
    pub dead: Vec<String>,
    /// Dead nodes whose resources could not be removed (permissions, another cleaner).
    pub cleanup_failures: usize,
}

impl NodeScan {
    /// Whether a node of that name is alive.
    pub fn is_alive(&self, name: &str) -> bool {
        self.alive.iter().any(|n| n == name)
    }
}

/// What one [`wait_for_wake`] saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Wake {
    /// At least one notification arrived.
    pub woken: bool,
    /// One of them was [`WakeEvent::EndOfRun`].
    pub end_of_run: bool,
    /// The wait set reported SIGINT or SIGTERM (only under
    /// [`SignalHandlingMode::HandleTerminationRequests`]). Other signals that cut a wait short
    /// (SIGCONT after SIGSTOP, SIGCHLD) are not interrupts: the wait returns without a wake.
    pub interrupted: bool,
}

/// Waits at most `timeout` for a notification on `listener` (attached to `waitset`), and
/// drains every pending one so that the next wait blocks until something new arrives. The
/// waiting loop of every setfleet process.
pub fn wait_for_wake(
    waitset: &WaitSet<Ipc>,
    listener: &iceoryx2::port::listener::Listener<Ipc>,
    timeout: Duration,
) -> Result<Wake, WaitSetRunError> {
    let mut wake = Wake::default();
    let result = waitset.wait_and_process_once_with_timeout(
        |_| {
            wake.woken = true;
            let _ = listener.try_wait(|activation| {
                if WakeEvent::from_id(activation.id) == Some(WakeEvent::EndOfRun) {
                    wake.end_of_run = true;
                }
            });
            CallbackProgression::Continue
        },
        timeout,
    )?;
    // Only a termination request stops a process. `Interrupt` is any other signal that cut
    // the wait short: SIGCONT after a SIGSTOP, SIGCHLD, a profiler's. SIGINT and SIGTERM
    // first show up as one too (under `HandleTerminationRequests` the next wait reports
    // them), so an interrupted wait is a spurious wake-up and the caller simply waits again.
    wake.interrupted = result == WaitSetRunResult::TerminationRequest;
    Ok(wake)
}

/// Lists the nodes of `run`; with `cleanup`, removes the resources of dead ones (a SIGKILLed
/// process shows up as dead at once).
pub fn scan_nodes(run: &RunId, cleanup: bool) -> Result<NodeScan, NodeScanError> {
    let prefix = run.file_prefix();
    let config = run_config(run).map_err(|_| NodeScanError::Prefix(prefix))?;
    let mut scan = NodeScan::default();
    let name_of = |details: &Option<iceoryx2::node::NodeDetails>| {
        details
            .as_ref()
            .map(|d| d.name().as_str().to_owned())
            .unwrap_or_default()
    };
    Node::<Ipc>::list(&config, |state| {
        match state {
            NodeState::Alive(view) => scan.alive.push(name_of(view.details())),
            NodeState::Dead(view) => {
                scan.dead.push(name_of(view.details()));
                if cleanup && view.try_remove_stale_resources().is_err() {
                    scan.cleanup_failures += 1;
                }
            }
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => {}
        }
        CallbackProgression::Continue
    })?;
    Ok(scan)
}

/// Removes the resources of every dead node of `run`; returns their names.
pub fn cleanup_stale(run: &RunId) -> Result<Vec<String>, NodeScanError> {
    Ok(scan_nodes(run, true)?.dead)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wake_events_round_trip_through_their_ids() {
        for e in WakeEvent::ALL {
            assert_eq!(WakeEvent::from_id(e.id()), Some(e));
            assert!(e as usize <= WakeEvent::MAX_ID);
        }
        assert_eq!(WakeEvent::from_id(EventId::new(0)), None);
    }

    #[test]
    fn every_service_opens_and_the_run_leaves_no_file_behind() {
        let run = RunId::new(&format!("ipc-unit-{}", std::process::id())).unwrap();
        {
            let node = RunNode::new(&run, RunNode::WORLD, SignalHandlingMode::Disabled).unwrap();
            let cvs = node.open_cvs(0).unwrap();
            let _frames = cvs.publisher_builder().create().unwrap();
            let _sub = cvs.subscriber_builder().create().unwrap();
            node.open_cmd(0).unwrap();
            node.open_truth().unwrap();
            node.open_observer_ack().unwrap();
            let est = node.open_estimate(0).unwrap();
            let _est_pub = RunNode::wire_publisher(&est, 64).unwrap();
            node.open_guidance().unwrap();
            node.open_agent_wake(0).unwrap();
            node.open_world_wake().unwrap();
            node.open_observer_wake().unwrap();
            let scan = scan_nodes(&run, false).unwrap();
            assert!(scan.is_alive(RunNode::WORLD), "{scan:?}");
            assert!(!run_files(&run).unwrap().is_empty());
        }
        remove_run_files(&run).unwrap();
        assert_eq!(run_files(&run).unwrap(), Vec::<std::path::PathBuf>::new());
    }

    /// What the largest fleet needs of each service on one host at worst: all its agents
    /// and the world there, both observers, [`RESTART_OVERLAP`] restarted agents whose dead
    /// predecessors are not cleaned up yet, and the host's bridge (one node that publishes
    /// what comes from other hosts, one that subscribes to what goes to them) when some agent
    /// is elsewhere.
    #[test]
    fn the_largest_fleet_fits_every_services_limits() {
        assert_eq!(MAX_UAVS, 64);
        let run = RunId::new(&format!("ipc-fleet-{}", std::process::id())).unwrap();
        {
            let node = RunNode::new(&run, "agent-0", SignalHandlingMode::Disabled).unwrap();
            // Every process of the run, the restarted ones and both bridge nodes.
            let nodes = MAX_UAVS + RESTART_OVERLAP + 1 + MAX_OBSERVERS + 2;
            // UAV 0's estimates: the other 63 agents, the observers, the restarted agents and
            // the bridge (one agent less when the bridge is there: 63 + 2 + 2 + 1 at most).
            let est = node.open_estimate(0).unwrap();
            let readers = (MAX_UAVS - 1) + MAX_OBSERVERS + RESTART_OVERLAP + 1;
            assert!(est.static_config().max_subscribers() >= readers);
            assert!(est.static_config().max_nodes() >= nodes);
            let subscribers: Vec<_> = (0..readers)
                .map(|_| est.subscriber_builder().create().unwrap())
                .collect();
            // The token: sent by every agent, the restarted ones and the bridge (which
            // publishes the tokens of remote agents, so 63 local ones at most), read by as
            // many and the observers.
            let guidance = node.open_guidance().unwrap();
            let senders = (MAX_UAVS - 1) + RESTART_OVERLAP + 1;
            assert!(guidance.static_config().max_publishers() >= senders.max(MAX_UAVS));
            assert!(guidance.static_config().max_subscribers() >= readers);
            let publishers: Vec<_> = (0..senders)
                .map(|_| RunNode::wire_publisher(&guidance, 64).unwrap())
                .collect();
            // Agent 0's wake-ups: the world, the 63 other agents, the observers, the
            // restarted agents and the bridge.
            let wake = node.open_agent_wake(0).unwrap();
            let wakers = 1 + (MAX_UAVS - 1) + MAX_OBSERVERS + RESTART_OVERLAP + 1;
            assert!(wake.static_config().max_notifiers() >= wakers);
            let notifiers: Vec<_> = (0..wakers)
                .map(|_| wake.notifier_builder().create().unwrap())
                .collect();
            // The world's and the observers' wake-ups: every agent, the observers, the
            // restarted agents (and the bridge instead of one agent).
            for service in [
                node.open_world_wake().unwrap(),
                node.open_observer_wake().unwrap(),
            ] {
                assert!(service.static_config().max_notifiers() >= fleet_senders());
                assert!(service.static_config().max_nodes() >= nodes);
            }
            assert_eq!(
                (subscribers.len(), publishers.len(), notifiers.len()),
                (readers, senders, wakers)
            );
        }
        remove_run_files(&run).unwrap();
    }

    #[test]
    fn config_carries_the_run_prefix() {
        let run = RunId::new("cfg-test").unwrap();
        let config = run_config(&run).unwrap();
        assert_eq!(config.global.prefix.to_string(), run.file_prefix());
        let pub_sub = &config.defaults.publish_subscribe;
        assert_eq!(
            pub_sub.subscriber_expired_connection_buffer,
            EXPIRED_CONNECTIONS
        );
        let host = run.in_domain(2);
        let config = run_config(&host).unwrap();
        assert_eq!(config.global.prefix.to_string(), "iox2_sf_cfg-test.h2_");
    }
}
