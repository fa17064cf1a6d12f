//! iceoryx2 -> Zenoh: what this host's processes publish for processes on other hosts, and
//! which of this host's processes are alive.
//!
//! The thread waits on the wake-up events that a remote receiver would get (the remote
//! agents' wake-ups, and the world's and observer's when they are remote), so it learns of a
//! message the moment a local process announces it; on each wake-up it drains every
//! subscriber it forwards from. Only samples of local origin cross: a token on the shared
//! guidance service goes out only when its sender is a local agent, which also keeps the
//! tokens this host's inbound thread received from going back.
//!
//! Every [`SCAN_PERIOD`] the thread lists the local nodes and keeps one Zenoh liveliness
//! token per live local process. Before forwarding anything of a process it makes sure the
//! process is announced, so a remote host creates the process's proxy before it sees the
//! process's first message ([`crate::inbound`]).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{CallbackProgression, SignalHandlingMode};
use iceoryx2::waitset::WaitSetRunResult;
use protocol::frame::CvsFrame;
use protocol::ipc::{
    EventService, Ipc, IpcOpenError, PubSubService, RunNode, WakeEvent, WireService,
    WireSubscriber, scan_nodes,
};
use protocol::wire::{UavCommand, WireHeader, WireKind};
use zenoh::Wait;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::sample::Locality;

use crate::envelope;
use crate::keys;
use crate::placement::HostPlan;
use crate::report::Counters;

/// How often the local nodes are listed for the liveliness tokens: a local process that dies
/// is announced gone within this time (and the time Zenoh takes to carry it).
pub const SCAN_PERIOD: Duration = Duration::from_millis(100);

/// A local subscriber and the Zenoh publisher its samples go out on.
struct Route<S> {
    uav: u32,
    from: S,
    to: Publisher<'static>,
}

/// A local agent's estimate service: its estimates go to every other host, its state messages
/// (sets for the observer) only to the observer's host, and nowhere when the observer is here.
struct EstimateRoute {
    uav: u32,
    from: WireSubscriber,
    estimates: Publisher<'static>,
    states: Option<Publisher<'static>>,
}

/// A UAV's frames from the local world to its remote agent.
type FrameRoute = Route<Subscriber<Ipc, CvsFrame, ()>>;

/// A local agent's commands to the remote world.
type CommandRoute = Route<Subscriber<Ipc, UavCommand, ()>>;

/// Keeps the services open for as long as the ports live.
struct Services {
    _frames: Vec<PubSubService<CvsFrame>>,
    _commands: Vec<PubSubService<UavCommand>>,
    _wire: Vec<WireService>,
    _events: Vec<EventService>,
}

/// The outbound side of a bridge: its local ports and its Zenoh publishers.
pub struct Outbound<'a> {
    plan: &'a HostPlan,
    session: &'a zenoh::Session,
    node: RunNode,
    frames: Vec<FrameRoute>,
    commands: Vec<CommandRoute>,
    estimates: Vec<EstimateRoute>,
    tokens_in: WireSubscriber,
    tokens_out: BTreeMap<u32, Publisher<'static>>,
    end_of_run: Option<Publisher<'static>>,
    listeners: Vec<Listener<Ipc>>,
    _services: Services,
    /// Liveliness tokens of the local processes announced alive, by node name.
    alive: BTreeMap<String, LivelinessToken>,
    last_scan: Option<Instant>,
    end_sent: bool,
    buf: Vec<u8>,
    counters: Counters,
}

/// Why the bridge could not start.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// A local service or port could not be opened.
    #[error(transparent)]
    Ipc(#[from] IpcOpenError),
    /// A Zenoh publisher could not be declared.
    #[error("cannot declare a Zenoh publisher: {0}")]
    Zenoh(zenoh::Error),
}

/// Declares the publisher of `key` with the bridge's settings, the one place they are written
/// (the bridge's publishers and `fleet bench`'s Zenoh cases both declare theirs here):
///
/// - reliable (Zenoh's default channel) with [`CongestionControl::Block`]: a lockstep run must
///   not lose a message to a full queue;
/// - Zenoh's default priority, the same for every key, so messages keep their order;
/// - express: each message goes out at once instead of waiting to be batched;
/// - remote destinations only ([`Locality::Remote`]).
pub fn declare_publisher(
    session: &zenoh::Session,
    key: String,
) -> Result<Publisher<'static>, OpenError> {
    session
        .declare_publisher(key)
        // Lossless: a lockstep run must not lose a message to a full queue; a receiver that
        // is gone is dropped by Zenoh when its link closes.
        .congestion_control(CongestionControl::Block)
        .express(true)
        // The inbound thread of this host does not need what it sends.
        .allowed_destination(Locality::Remote)
        .wait()
        .map_err(OpenError::Zenoh)
}

/// The ports toward the agents of other hosts.
struct RemoteAgents {
    /// The local world's frames for them (none when the world is remote).
    frames: Vec<FrameRoute>,
    /// Listeners of what wakes a remote receiver: their wake-ups, and the world's and the
    /// observer's when those are remote.
    listeners: Vec<Listener<Ipc>>,
}

impl RemoteAgents {
    /// Opens the ports toward the agents of other hosts, keeping their services in `services`.
    fn open(
        node: &RunNode,
        session: &zenoh::Session,
        plan: &HostPlan,
        services: &mut Services,
    ) -> Result<Self, OpenError> {
        let run = &plan.run;
        let mut frames = Vec::new();
        let mut listeners = Vec::new();
        for uav in plan.remote_agents() {
            if plan.world {
                let service = node.open_cvs(uav)?;
                frames.push(Route {
                    uav,
                    from: service
                        .subscriber_builder()
                        .create()
                        .map_err(IpcOpenError::from)?,
                    to: declare_publisher(session, keys::frame(run, uav))?,
                });
                services._frames.push(service);
            }
            let wake = node.open_agent_wake(uav)?;
            listeners.push(
                wake.listener_builder()
                    .create()
                    .map_err(IpcOpenError::from)?,
            );
            services._events.push(wake);
        }
        if !plan.world {
            for wake in [node.open_world_wake()?, node.open_observer_wake()?] {
                listeners.push(
                    wake.listener_builder()
                        .create()
                        .map_err(IpcOpenError::from)?,
                );
                services._events.push(wake);
            }
        }
        Ok(RemoteAgents { frames, listeners })
    }
}

/// What this host's agents publish for other hosts.
struct LocalAgents {
    /// Their commands, for a remote world (none when the world is local).
    commands: Vec<CommandRoute>,
    /// Their estimates and state messages.
    estimates: Vec<EstimateRoute>,
    /// The Zenoh publisher of each one's tokens.
    tokens_out: BTreeMap<u32, Publisher<'static>>,
}

impl LocalAgents {
    /// Opens the ports of this host's agents, keeping their services in `services`.
    fn open(
        node: &RunNode,
        session: &zenoh::Session,
        plan: &HostPlan,
        services: &mut Services,
    ) -> Result<Self, OpenError> {
        let run = &plan.run;
        let mut commands = Vec::new();
        let mut estimates = Vec::new();
        let mut tokens_out = BTreeMap::new();
        for &uav in &plan.agents {
            if !plan.world {
                let service = node.open_cmd(uav)?;
                commands.push(Route {
                    uav,
                    from: service
                        .subscriber_builder()
                        .create()
                        .map_err(IpcOpenError::from)?,
                    to: declare_publisher(session, keys::command(run, uav))?,
                });
                services._commands.push(service);
            }
            let service = node.open_estimate(uav)?;
            estimates.push(EstimateRoute {
                uav,
                from: service
                    .subscriber_builder()
                    .create()
                    .map_err(IpcOpenError::from)?,
                estimates: declare_publisher(session, keys::estimate(run, uav))?,
                states: if plan.world {
                    None
                } else {
                    Some(declare_publisher(session, keys::state(run, uav))?)
                },
            });
            services._wire.push(service);
            tokens_out.insert(uav, declare_publisher(session, keys::token(run, uav))?);
        }
        Ok(LocalAgents {
            commands,
            estimates,
            tokens_out,
        })
    }
}

impl<'a> Outbound<'a> {
    /// Opens the local subscribers and listeners and the Zenoh publishers of `plan`: toward
    /// the remote agents, from the local agents, the guidance token and the end of the run.
    pub fn open(plan: &'a HostPlan, session: &'a zenoh::Session) -> Result<Self, OpenError> {
        let node = RunNode::new(
            &plan.run,
            "bridge-out",
            SignalHandlingMode::HandleTerminationRequests,
        )?;
        let mut services = Services {
            _frames: Vec::new(),
            _commands: Vec::new(),
            _wire: Vec::new(),
            _events: Vec::new(),
        };
        let remote = RemoteAgents::open(&node, session, plan, &mut services)?;
        let local = LocalAgents::open(&node, session, plan, &mut services)?;
        let guidance = node.open_guidance()?;
        let tokens_in = guidance
            .subscriber_builder()
            .create()
            .map_err(IpcOpenError::from)?;
        services._wire.push(guidance);
        let end_of_run = if plan.world {
            Some(declare_publisher(session, keys::end_of_run(&plan.run))?)
        } else {
            None
        };
        Ok(Outbound {
            plan,
            session,
            node,
            frames: remote.frames,
            commands: local.commands,
            estimates: local.estimates,
            tokens_in,
            tokens_out: local.tokens_out,
            end_of_run,
            listeners: remote.listeners,
            _services: services,
            alive: BTreeMap::new(),
            last_scan: None,
            end_sent: false,
            buf: Vec::new(),
            counters: Counters::default(),
        })
    }

    /// Forwards until `shutdown` is raised or a termination signal arrives (which raises it).
    pub fn run(mut self, shutdown: &AtomicBool) -> Counters {
        let waitset = match self.node.waitset() {
            Ok(w) => w,
            Err(e) => {
                tracing::error!(error = %e, "cannot wait for wake-ups");
                shutdown.store(true, Ordering::Relaxed);
                return self.counters;
            }
        };
        // The guards borrow the listeners while the loop borrows `self`.
        let listeners = std::mem::take(&mut self.listeners);
        let mut guards = Vec::new();
        for l in &listeners {
            match waitset.attach_notification(l) {
                Ok(g) => guards.push(g),
                Err(e) => tracing::error!(error = ?e, "cannot wait on a wake-up event"),
            }
        }
        while !shutdown.load(Ordering::Relaxed) {
            if self.last_scan.is_none_or(|t| t.elapsed() >= SCAN_PERIOD) {
                self.scan();
            }
            let mut end_of_run = false;
            let result = waitset.wait_and_process_once_with_timeout(
                |_| {
                    for l in &listeners {
                        let _ = l.try_wait(|activation| {
                            end_of_run |=
                                WakeEvent::from_id(activation.id) == Some(WakeEvent::EndOfRun);
                        });
                    }
                    CallbackProgression::Continue
                },
                SCAN_PERIOD,
            );
            match result {
                Ok(WaitSetRunResult::TerminationRequest) => {
                    shutdown.store(true, Ordering::Relaxed);
                }
                Ok(_) => {}
                Err(e) => {
                    tracing::warn!(error = ?e, "wait failed");
                    std::thread::sleep(Duration::from_millis(5));
                }
            }
            self.forward();
            if end_of_run {
                self.send_end_of_run();
            }
        }
        drop(guards);
        self.counters
    }

    /// Lists the local nodes and keeps the liveliness tokens of the live local processes.
    fn scan(&mut self) {
        self.last_scan = Some(Instant::now());
        let scan = match scan_nodes(&self.plan.run, true) {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "cannot list the local nodes");
                return;
            }
        };
        for node in self.plan.local_nodes() {
            if scan.is_alive(&node) {
                self.announce(&node);
            } else if self.alive.remove(&node).is_some() {
                tracing::info!(node, "local process gone: announced");
            }
        }
    }

    /// Declares `node` alive to the other hosts if it is not already.
    fn announce(&mut self, node: &str) {
        if self.alive.contains_key(node) {
            return;
        }
        let key = keys::alive(&self.plan.run, &self.plan.host, node);
        match self.session.liveliness().declare_token(key).wait() {
            Ok(token) => {
                tracing::info!(node, "local process alive: announced");
                self.counters.announced += 1;
                self.alive.insert(node.to_owned(), token);
            }
            Err(e) => tracing::warn!(node, error = %e, "cannot declare a liveliness token"),
        }
    }

    /// Makes sure the sender of a message is announced before the message goes out: a fresh
    /// listing when it is not (once per process start).
    fn announce_sender(&mut self, node: &str) {
        if !self.alive.contains_key(node) {
            self.scan();
        }
    }

    /// Sends every pending local sample that another host needs.
    fn forward(&mut self) {
        for i in 0..self.frames.len() {
            self.announce_sender(RunNode::WORLD);
            loop {
                let route = &self.frames[i];
                let sample = match route.from.receive() {
                    Ok(Some(s)) => s,
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(uav = route.uav, error = ?e, "cannot receive frames");
                        break;
                    }
                };
                envelope::encode_frame(sample.payload(), &mut self.buf);
                drop(sample);
                put(&self.frames[i].to, &self.buf, "frame", &mut self.counters);
            }
        }
        for i in 0..self.commands.len() {
            self.announce_sender(&RunNode::agent_name(self.commands[i].uav));
            loop {
                let route = &self.commands[i];
                let cmd = match route.from.receive() {
                    Ok(Some(s)) => *s.payload(),
                    Ok(None) => break,
                    Err(e) => {
                        tracing::warn!(uav = route.uav, error = ?e, "cannot receive commands");
                        break;
                    }
                };
                let bytes = envelope::encode_command(&cmd);
                put(&route.to, &bytes, "command", &mut self.counters);
            }
        }
        for i in 0..self.estimates.len() {
            self.announce_sender(&RunNode::agent_name(self.estimates[i].uav));
            loop {
                let route = &self.estimates[i];
                let Some(header) = receive_wire(&route.from, &mut self.buf) else {
                    break;
                };
                if header.kind == WireKind::State as u32 {
                    if let Some(to) = &route.states {
                        put(to, &self.buf, "state", &mut self.counters);
                    }
                } else {
                    tracing::trace!(uav = header.sender, step = header.step, "estimate out");
                    put(&route.estimates, &self.buf, "estimate", &mut self.counters);
                }
            }
        }
        while let Some(header) = receive_wire(&self.tokens_in, &mut self.buf) {
            // Only tokens passed by a local agent: the others came from other hosts.
            if let Some(to) = self.tokens_out.get(&header.sender) {
                put(to, &self.buf, "token", &mut self.counters);
            }
        }
    }

    fn send_end_of_run(&mut self) {
        if self.end_sent {
            return;
        }
        if let Some(to) = &self.end_of_run {
            self.end_sent = true;
            put(to, &[], "end_of_run", &mut self.counters);
        }
    }
}

/// Receives one variable-size message into `buf` (its envelope); `None` when there is none.
fn receive_wire(sub: &WireSubscriber, buf: &mut Vec<u8>) -> Option<WireHeader> {
    match sub.receive() {
        Ok(Some(sample)) => {
            let header = *sample.user_header();
            envelope::encode_wire(&header, sample.payload(), buf);
            Some(header)
        }
        Ok(None) => None,
        Err(e) => {
            tracing::warn!(error = ?e, "cannot receive a message");
            None
        }
    }
}

fn put(to: &Publisher<'static>, bytes: &[u8], kind: &str, counters: &mut Counters) {
    match to.put(bytes.to_vec()).wait() {
        Ok(()) => counters.sent(kind, bytes.len() as u64),
        Err(e) => {
            tracing::warn!(kind, error = %e, "cannot send to the other hosts");
            counters.send_failed(kind);
        }
    }
}
