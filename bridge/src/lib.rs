//! setfleet's Zenoh bridge: one process per host joins the run's iceoryx2 services on that
//! host to the same run's services on the other hosts.
//!
//! The world-server, the agents and the observer do not change: they speak iceoryx2 on their
//! own host, and the bridge forwards what another host needs ([`placement::HostPlan`] says what,
//! [`keys`] how it is named on Zenoh, [`envelope`] how it is written). Besides data, the
//! bridges carry *liveliness*: each announces its host's live processes, and each keeps a
//! proxy iceoryx2 node for every process announced by another host, so the processes, which
//! tell who is alive by listing the run's nodes, see the whole fleet ([`inbound`],
//! [`outbound`]).
//!
//! ```text
//!   host 0 (world host)                         host 1
//!   world-server, observer, agents 0, 1         agents 2, 3
//!        |  iceoryx2                                 |  iceoryx2
//!   bridge (Zenoh router) <==== QUIC (TLS 1.3) ===> bridge (Zenoh client)
//! ```
//!
//! The world host's bridge is a Zenoh router that listens; the others are clients that
//! connect to it, so messages between two agent hosts go through the world host. Links are
//! mutually authenticated and encrypted, and the router's access control limits what each
//! host may publish ([`security`]).
//!
//! # Determinism
//!
//! In lockstep every process waits for what it needs (bounded), and every message crosses
//! losslessly and in order (Zenoh's reliable channel with blocking congestion control, one
//! priority), so a run over several hosts folds the same messages in the same steps as on
//! one host and gives the same results, byte for byte.

pub mod endpoint;
pub mod envelope;
pub mod inbound;
pub mod keys;
pub mod outbound;
pub mod placement;
pub mod report;
pub mod security;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use zenoh::Wait;
use zenoh::sample::{Locality, Sample, SampleKind};

use inbound::Arrival;
use outbound::Outbound;
use placement::HostPlan;
use report::Counters;

/// Why a bridge stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// The Zenoh session could not be opened (no router to connect to, a port in use, bad
    /// certificates).
    #[error("cannot open the Zenoh session: {0}")]
    Session(zenoh::Error),
    /// A Zenoh subscriber could not be declared.
    #[error("cannot subscribe on Zenoh: {0}")]
    Subscribe(zenoh::Error),
    /// The local side could not be opened.
    #[error(transparent)]
    Open(#[from] outbound::OpenError),
    /// The inbound thread could not open its ports.
    #[error("cannot open the inbound ports: {0}")]
    Inbound(protocol::ipc::IpcOpenError),
    /// The inbound thread panicked.
    #[error("the inbound thread panicked")]
    Panicked,
}

/// How long closing the Zenoh session may take. Zenoh's own bound is 10 s, which is as long as
/// `fleet run` waits for a bridge after SIGTERM; a close that hangs (a link already gone, a
/// QUIC close handshake that never ends) must not cost the bridge its report.
pub const CLOSE_TIMEOUT: Duration = Duration::from_secs(3);

/// One host's bridge: its open Zenoh session.
///
/// [`Bridge::forward`] runs it until it is told to stop and returns what it forwarded, which
/// the caller reports before [`Bridge::close`], since closing a Zenoh session can take up to
/// [`CLOSE_TIMEOUT`].
pub struct Bridge {
    session: zenoh::Session,
}

impl Bridge {
    /// Opens the Zenoh session of configuration `zenoh` (as the router, or as a client that
    /// connects to it).
    pub fn open(zenoh: zenoh::Config) -> Result<Self, BridgeError> {
        let session = zenoh::open(zenoh).wait().map_err(BridgeError::Session)?;
        Ok(Self { session })
    }

    /// Forwards `plan`'s host's share of the run until `shutdown` is raised or a termination
    /// signal arrives; returns what it forwarded.
    pub fn forward(&self, plan: &HostPlan, shutdown: &AtomicBool) -> Result<Counters, BridgeError> {
        let session = &self.session;
        tracing::info!(host = %plan.host, zid = %session.zid(), "Zenoh session open");
        // The local subscribers exist before anything from the other hosts is published
        // here: what this host's processes publish in answer (the first estimates answer the
        // first frames, which answer the remote hellos) is never sent before the bridge
        // listens.
        let outbound = Outbound::open(plan, session)?;
        let (arrivals, queue) = mpsc::channel();
        let _subscribers = subscribe(session, plan, &arrivals)?;
        drop(arrivals);
        std::thread::scope(|scope| {
            let (ready_tx, ready_rx) = mpsc::channel();
            let inbound = scope.spawn(|| {
                inbound::run(
                    plan,
                    queue,
                    move |r| {
                        let _ = ready_tx.send(r);
                    },
                    shutdown,
                )
            });
            let started = match ready_rx.recv() {
                Ok(Ok(())) => Ok(outbound.run(shutdown)),
                Ok(Err(e)) => Err(BridgeError::Inbound(e)),
                Err(_) => Err(BridgeError::Panicked),
            };
            shutdown.store(true, Ordering::Relaxed);
            let inbound = inbound.join().map_err(|_| BridgeError::Panicked);
            let mut counters = started?;
            counters.merge(inbound?);
            Ok(counters)
        })
    }

    /// Closes the Zenoh session, waiting at most [`CLOSE_TIMEOUT`]: a close that does not end
    /// in time is logged and left to its thread, since the process is about to exit.
    pub fn close(self) {
        let (done_tx, done_rx) = mpsc::channel();
        let session = self.session;
        std::thread::spawn(move || {
            let _ = done_tx.send(session.close().wait());
        });
        match done_rx.recv_timeout(CLOSE_TIMEOUT) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::warn!(error = %e, "closing the Zenoh session"),
            Err(_) => tracing::warn!(
                timeout_s = CLOSE_TIMEOUT.as_secs(),
                "the Zenoh session did not close in time: left open"
            ),
        }
    }
}

/// The Zenoh subscribers of `plan`'s host, which queue what arrives for the inbound thread.
fn subscribe(
    session: &zenoh::Session,
    plan: &HostPlan,
    arrivals: &mpsc::Sender<Arrival>,
) -> Result<Vec<Box<dyn std::any::Any>>, BridgeError> {
    let run = &plan.run;
    let root = keys::run_root(run);
    let mut data_keys = vec![
        format!("{root}/uav/*/estimate"),
        format!("{root}/guidance/*"),
    ];
    if plan.world {
        // The agents' sets for the observer, which runs here.
        data_keys.extend([format!("{root}/uav/*/cmd"), format!("{root}/uav/*/state")]);
    } else {
        data_keys.extend(plan.agents.iter().map(|&u| keys::frame(run, u)));
        data_keys.push(keys::end_of_run(run));
    }
    let mut held: Vec<Box<dyn std::any::Any>> = Vec::new();
    for key in data_keys {
        let tx = arrivals.clone();
        let run = run.clone();
        let subscriber = session
            .declare_subscriber(key)
            .allowed_origin(Locality::Remote)
            .callback(move |sample: Sample| {
                let key = sample.key_expr().as_str();
                match keys::topic(&run, key) {
                    Some(topic) => {
                        let bytes = sample.payload().to_bytes().into_owned();
                        let _ = tx.send(Arrival::Data { topic, bytes });
                    }
                    None => tracing::warn!(key, "message on an unknown key ignored"),
                }
            })
            .wait()
            .map_err(BridgeError::Subscribe)?;
        held.push(Box::new(subscriber));
    }
    let tx = arrivals.clone();
    let run = run.clone();
    let liveliness = session
        .liveliness()
        .declare_subscriber(keys::all_alive(&run))
        .history(true)
        .callback(move |sample: Sample| {
            let key = sample.key_expr().as_str();
            match keys::alive_of(&run, key) {
                Some((host, node)) => {
                    let _ = tx.send(Arrival::Alive {
                        host: host.to_owned(),
                        node: node.to_owned(),
                        up: sample.kind() == SampleKind::Put,
                    });
                }
                None => tracing::warn!(key, "liveliness on an unknown key ignored"),
            }
        })
        .wait()
        .map_err(BridgeError::Subscribe)?;
    held.push(Box::new(liveliness));
    Ok(held)
}
