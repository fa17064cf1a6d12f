//! The agent's iceoryx2 ports: its frames, its commands, its estimates and the peers', the
//! token, and the wake-up events, opened once with the QoS of [`protocol::ipc`].

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::{LoanError, ReceiveError, SendError};
use protocol::frame::CvsFrame;
use protocol::ipc::{
    EventService, Ipc, IpcOpenError, PubSubService, RunNode, WakeEvent, WirePublisher, WireService,
    WireSubscriber,
};
use protocol::wire::{UavCommand, WireHeader, WireKind, unix_now_ns};

/// Initial sample size of estimate messages; samples grow when a message is larger.
const ESTIMATE_INITIAL_BYTES: usize = 64 * 1024;
/// Initial sample size of tokens.
const TOKEN_INITIAL_BYTES: usize = 4 * 1024;

/// Why a message could not be sent.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// No sample could be loaned (the publisher's samples are all out).
    #[error("cannot loan a sample: {0}")]
    Loan(#[from] LoanError),
    /// The sample could not be delivered.
    #[error("cannot send: {0}")]
    Send(#[from] SendError),
    /// A subscriber could not receive.
    #[error("cannot receive: {0}")]
    Receive(#[from] ReceiveError),
    /// The message is longer than a header can say.
    #[error("a message of {0} bytes is too long to send")]
    TooLong(usize),
}

/// Keeps the services open for as long as the ports live.
struct Services {
    _cvs: PubSubService<CvsFrame>,
    _cmd: PubSubService<UavCommand>,
    _estimates: Vec<WireService>,
    _guidance: WireService,
    _events: Vec<EventService>,
}

/// Every port of one agent.
pub struct Links {
    /// This UAV's frames.
    pub frames: Subscriber<Ipc, CvsFrame, ()>,
    /// Commands and acks to the world.
    pub commands: Publisher<Ipc, UavCommand, ()>,
    /// This agent's estimates.
    pub estimate_out: WirePublisher,
    /// The peers' estimates, with the sending UAV of each service.
    pub estimates_in: Vec<(u32, WireSubscriber)>,
    /// Tokens to the ring.
    pub token_out: WirePublisher,
    /// Tokens from the ring.
    pub token_in: WireSubscriber,
    /// This agent's wake-up events.
    pub wake: Listener<Ipc>,
    /// Wakes the world-server.
    pub world_wake: Notifier<Ipc>,
    /// Wakes the observers.
    pub observer_wake: Notifier<Ipc>,
    /// Wakes each peer.
    pub peer_wakes: Vec<Notifier<Ipc>>,
    _services: Services,
}

impl Links {
    /// Opens every port of agent `uav` in a fleet of `fleet` UAVs.
    pub fn open(node: &RunNode, uav: u32, fleet: u32) -> Result<Links, IpcOpenError> {
        let cvs = node.open_cvs(uav)?;
        let frames = cvs.subscriber_builder().create()?;
        let cmd = node.open_cmd(uav)?;
        let commands = cmd.publisher_builder().create()?;
        let own = node.open_estimate(uav)?;
        let estimate_out = RunNode::wire_publisher(&own, ESTIMATE_INITIAL_BYTES)?;
        let mut estimates = vec![own];
        let mut estimates_in = Vec::new();
        let mut events = Vec::new();
        let mut peer_wakes = Vec::new();
        for j in (0..fleet).filter(|&j| j != uav) {
            let service = node.open_estimate(j)?;
            estimates_in.push((j, service.subscriber_builder().create()?));
            let wake = node.open_agent_wake(j)?;
            peer_wakes.push(wake.notifier_builder().create()?);
            events.push(wake);
            estimates.push(service);
        }
        let guidance = node.open_guidance()?;
        let token_out = RunNode::wire_publisher(&guidance, TOKEN_INITIAL_BYTES)?;
        let token_in = guidance.subscriber_builder().create()?;
        let own_wake = node.open_agent_wake(uav)?;
        let wake = own_wake.listener_builder().create()?;
        events.push(own_wake);
        let world = node.open_world_wake()?;
        let world_wake = world.notifier_builder().create()?;
        events.push(world);
        let observer = node.open_observer_wake()?;
        let observer_wake = observer.notifier_builder().create()?;
        events.push(observer);
        Ok(Links {
            frames,
            commands,
            estimate_out,
            estimates_in,
            token_out,
            token_in,
            wake,
            world_wake,
            observer_wake,
            peer_wakes,
            _services: Services {
                _cvs: cvs,
                _cmd: cmd,
                _estimates: estimates,
                _guidance: guidance,
                _events: events,
            },
        })
    }

    /// Sends a command (an ack, a hello or a yaw reference) and wakes the world.
    pub fn send_command(&self, cmd: UavCommand) -> Result<(), LinkError> {
        self.commands.send_copy(cmd)?;
        notify(&self.world_wake, WakeEvent::Command);
        Ok(())
    }

    /// Publishes a variable-size message and wakes those it concerns: the peers (estimates,
    /// tokens) and the observers (estimates, states).
    pub fn send_wire(
        &self,
        kind: WireKind,
        run_tag: u64,
        sender: u32,
        step: u64,
        bytes: &[u8],
    ) -> Result<(), LinkError> {
        let (publisher, event) = match kind {
            WireKind::Estimate | WireKind::State => (&self.estimate_out, WakeEvent::Estimate),
            WireKind::Token => (&self.token_out, WakeEvent::Token),
        };
        let mut sample = publisher.loan_slice_uninit(bytes.len())?;
        let len = u32::try_from(bytes.len()).map_err(|_| LinkError::TooLong(bytes.len()))?;
        *sample.user_header_mut() =
            WireHeader::new(kind, run_tag, sender, step, len, unix_now_ns());
        sample.write_from_slice(bytes).send()?;
        // The agents' copy of their sets for the observers concerns no peer.
        if kind != WireKind::State {
            for peer in &self.peer_wakes {
                notify(peer, event);
            }
        }
        if kind != WireKind::Token {
            notify(&self.observer_wake, event);
        }
        Ok(())
    }
}

/// Notifies, logging (not failing) when nobody listens or the event cannot be sent: a wake-up
/// is a hint, the data is in the samples.
pub fn notify(notifier: &Notifier<Ipc>, event: WakeEvent) {
    if let Err(e) = notifier.notify_with_custom_event_id(event.id()) {
        tracing::debug!(error = ?e, ?event, "notify failed");
    }
}
