//! `fleet-bench-child`: the processes of `fleet bench ipc`, one role each. A child opens its
//! ports, prints `ready`, waits for `go` on stdin, measures, and prints `result {json}` (a
//! [`ChildReport`]). It never waits longer than [`IDLE`] for a peer: a silent peer is an error,
//! not a hang. It dies with the parent (`fleet_process::startup::die_with_parent`).

use std::collections::BTreeSet;
use std::io::Write;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow, bail};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use protocol::camera::CameraPose;
use protocol::codec;
use protocol::frame::CvsFrame;
use protocol::ipc::{Ipc, RunNode, WakeEvent};
use protocol::scenario::Liveness;
use protocol::service::RunId;
use protocol::wire::{GuidanceToken, PlannedView, WireHeader, WireKind, unix_now_ns};
use sets::math::Point3;
use uav_agent::guidance::ring::ROUND_COMPLETE;
use uav_agent::guidance::{TokenRing, Turn};

use super::handshake::{BenchChildArgs, IDLE, RESULT, Role, ready_then_go};
use super::message::{
    Ack, ChildReport, PHASE_LATENCY, PHASE_RATE, Stamp, WINDOW, fill_frame, monotonic_ns,
};
use super::services::BenchServices;
use super::socket::{self, SocketFrame};
use super::zenoh_link::{self, Payload};

/// Poses in a plan of the token: the default horizon, 2 periods of 6 CVS steps.
const POSES_PER_PLAN: usize = 12;

/// Runs the child's role and prints its report.
pub fn run(args: &BenchChildArgs) -> anyhow::Result<()> {
    let run = RunId::new(&args.run)?;
    let indexed = args.role != Role::FramePublisher;
    if args.peers == 0 || (indexed && args.index >= args.peers) {
        bail!(
            "--index {} must be below --peers {}",
            args.index,
            args.peers
        );
    }
    let report = match args.role {
        Role::FramePublisher => frame_publisher(&run, args),
        Role::FrameSubscriber => frame_subscriber(&run, args),
        Role::SocketPublisher => socket_publisher(args),
        Role::SocketSubscriber => socket_subscriber(args),
        Role::Estimates => estimates(&run, args),
        Role::Token => token(&run, args),
        Role::ZenohFramePublisher => zenoh_link::publisher(&run, args, Payload::Frame),
        Role::ZenohFrameSubscriber => zenoh_link::subscriber(&run, args, Payload::Frame),
        Role::ZenohEstimatePublisher => zenoh_link::publisher(&run, args, Payload::Estimate),
        Role::ZenohEstimateSubscriber => zenoh_link::subscriber(&run, args, Payload::Estimate),
    }
    .with_context(|| format!("{} {}", args.role.as_arg(), args.index))?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{RESULT}{}", serde_json::to_string(&report)?)?;
    out.flush()?;
    Ok(())
}

/// Waits for a wake-up on `listener` until `deadline`; an error naming `what` once it passed.
fn wait_event(
    waitset: &WaitSet<Ipc>,
    listener: &Listener<Ipc>,
    deadline: Instant,
    what: &str,
) -> anyhow::Result<()> {
    let left = deadline.saturating_duration_since(Instant::now());
    if left.is_zero() {
        bail!("no {what} within {IDLE:?}");
    }
    waitset
        .wait_and_process_once_with_timeout(
            |_| {
                // Consume the notifications; the data is in the samples.
                let _ = listener.try_wait(|_| {});
                CallbackProgression::Continue
            },
            left,
        )
        .map_err(|e| anyhow!("waiting for {what} failed: {e:?}"))?;
    Ok(())
}

/// Tracks which frames every subscriber acknowledged (each acknowledges in order).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Credit {
    /// Next sequence number expected from each subscriber.
    next: Vec<u64>,
}

impl Credit {
    /// `subscribers` that will acknowledge from `first` on.
    pub fn new(subscribers: u32, first: u64) -> Self {
        Self {
            next: vec![first; subscribers as usize],
        }
    }

    /// Frames before this one are acknowledged by everyone.
    pub fn all_acked(&self) -> u64 {
        self.next.iter().copied().min().unwrap_or(u64::MAX)
    }

    /// Records an ack; an unknown subscriber or an ack out of order (a lost frame) is an error.
    pub fn ack(&mut self, subscriber: u32, seq: u64) -> anyhow::Result<()> {
        let next = self
            .next
            .get_mut(subscriber as usize)
            .ok_or_else(|| anyhow!("ack from unknown subscriber {subscriber}"))?;
        if seq != *next {
            bail!("subscriber {subscriber} acknowledged frame {seq}, expected {next}");
        }
        *next += 1;
        Ok(())
    }
}

/// Sends frames and collects acks, whatever the transport.
trait FrameLink {
    /// Writes frame `seq` and sends it, stamped with the send start.
    fn send(&mut self, seq: u64, phase: u32) -> anyhow::Result<()>;
    /// Adds to `out` at least one ack, waiting until `deadline` at most.
    fn acks(&mut self, deadline: Instant, out: &mut Vec<Ack>) -> anyhow::Result<()>;
}

/// Sends frames `first..first + n` keeping at most `window` unacknowledged by some subscriber;
/// returns how many acks reported a failed checksum.
fn credit_loop(
    link: &mut impl FrameLink,
    subscribers: u32,
    window: u64,
    first: u64,
    n: u64,
    phase: u32,
) -> anyhow::Result<u64> {
    let mut credit = Credit::new(subscribers, first);
    let end = first + n;
    let mut next = first;
    let mut corrupt = 0;
    let mut acks = Vec::new();
    while credit.all_acked() < end {
        while next < end && next - credit.all_acked() < window {
            link.send(next, phase)?;
            next += 1;
        }
        acks.clear();
        link.acks(Instant::now() + IDLE, &mut acks)?;
        for a in &acks {
            credit.ack(a.subscriber, a.seq)?;
            corrupt += u64::from(a.ok == 0);
        }
    }
    Ok(corrupt)
}

/// Runs the latency phase (one frame in flight) then the rate phase (a window of frames).
fn frame_phases(
    link: &mut impl FrameLink,
    subscribers: u32,
    n: u64,
) -> anyhow::Result<ChildReport> {
    let mut corrupt = credit_loop(link, subscribers, 1, 0, n, PHASE_LATENCY)?;
    let start = Instant::now();
    corrupt += credit_loop(link, subscribers, WINDOW, n, n, PHASE_RATE)?;
    Ok(ChildReport {
        latency_ns: Vec::new(),
        messages: n,
        bytes: n * std::mem::size_of::<CvsFrame>() as u64,
        elapsed_ns: start.elapsed().as_nanos() as u64,
        corrupt,
        resent: 0,
    })
}

struct IoxFrameLink<'a> {
    publisher: &'a Publisher<Ipc, CvsFrame, Stamp>,
    wake_subscribers: &'a Notifier<Ipc>,
    acks: &'a Subscriber<Ipc, Ack, ()>,
    waitset: &'a WaitSet<Ipc>,
    listener: &'a Listener<Ipc>,
}

impl FrameLink for IoxFrameLink<'_> {
    fn send(&mut self, seq: u64, phase: u32) -> anyhow::Result<()> {
        let mut sample = self.publisher.loan_uninit()?;
        fill_frame(CvsFrame::init_in_place(sample.payload_mut()), seq);
        *sample.user_header_mut() = Stamp {
            seq,
            sent_mono_ns: monotonic_ns(),
            sender: 0,
            phase,
        };
        // SAFETY: init_in_place initialised the whole payload.
        unsafe { sample.assume_init() }.send()?;
        self.wake_subscribers.notify()?;
        Ok(())
    }

    fn acks(&mut self, deadline: Instant, out: &mut Vec<Ack>) -> anyhow::Result<()> {
        loop {
            while let Some(a) = self.acks.receive()? {
                out.push(*a.payload());
            }
            if !out.is_empty() {
                return Ok(());
            }
            wait_event(self.waitset, self.listener, deadline, "frame ack")?;
        }
    }
}

fn frame_publisher(run: &RunId, args: &BenchChildArgs) -> anyhow::Result<ChildReport> {
    let node = RunNode::new(run, "bench-frame-pub", SignalHandlingMode::Disabled)?;
    let services = BenchServices::new(&node);
    let frames = services.frames()?;
    let publisher = frames.publisher_builder().max_loaned_samples(2).create()?;
    let ack_service = services.acks()?;
    let acks = ack_service.subscriber_builder().create()?;
    let frame_wake = services.event("frame-wake")?;
    let notifier = frame_wake.notifier_builder().create()?;
    let ack_wake = services.event("ack-wake")?;
    let listener = ack_wake.listener_builder().create()?;
    let waitset = node.waitset()?;
    let _guard = waitset.attach_notification(&listener)?;
    ready_then_go()?;
    let mut link = IoxFrameLink {
        publisher: &publisher,
        wake_subscribers: &notifier,
        acks: &acks,
        waitset: &waitset,
        listener: &listener,
    };
    frame_phases(&mut link, args.peers, args.iterations)
}

fn frame_subscriber(run: &RunId, args: &BenchChildArgs) -> anyhow::Result<ChildReport> {
    let me = args.index;
    let node = RunNode::new(
        run,
        &format!("bench-frame-sub-{me}"),
        SignalHandlingMode::Disabled,
    )?;
    let services = BenchServices::new(&node);
    let frames = services.frames()?;
    let subscriber = frames.subscriber_builder().create()?;
    let ack_service = services.acks()?;
    let ack_out = ack_service.publisher_builder().create()?;
    let frame_wake = services.event("frame-wake")?;
    let listener = frame_wake.listener_builder().create()?;
    let ack_wake = services.event("ack-wake")?;
    let notifier = ack_wake.notifier_builder().create()?;
    let waitset = node.waitset()?;
    let _guard = waitset.attach_notification(&listener)?;
    ready_then_go()?;
    let total = 2 * args.iterations;
    let mut report = ChildReport::default();
    let mut deadline = Instant::now() + IDLE;
    while report.messages < total {
        while let Some(sample) = subscriber.receive()? {
            let received = monotonic_ns();
            let stamp = *sample.user_header();
            if stamp.phase == PHASE_LATENCY {
                report
                    .latency_ns
                    .push(received.saturating_sub(stamp.sent_mono_ns));
            }
            let frame = sample.payload();
            let ok = frame.header.step == stamp.seq && frame.checksum() == frame.header.checksum;
            drop(sample);
            ack_out.send_copy(Ack {
                seq: stamp.seq,
                subscriber: me,
                ok: u32::from(ok),
            })?;
            notifier.notify()?;
            report.messages += 1;
            report.bytes += std::mem::size_of::<CvsFrame>() as u64;
            report.corrupt += u64::from(!ok);
            deadline = Instant::now() + IDLE;
        }
        if report.messages < total {
            wait_event(&waitset, &listener, deadline, "frame")?;
        }
    }
    Ok(report)
}

struct SocketFrameLink {
    stream: UnixStream,
    frame: Box<CvsFrame>,
}

impl FrameLink for SocketFrameLink {
    fn send(&mut self, seq: u64, phase: u32) -> anyhow::Result<()> {
        fill_frame(&mut self.frame, seq);
        let sent = monotonic_ns();
        let bytes = codec::encode(&SocketFrame::of(&self.frame, seq, phase, sent))?;
        socket::write_message(&mut self.stream, &bytes).context("cannot send a frame")?;
        Ok(())
    }

    fn acks(&mut self, _deadline: Instant, out: &mut Vec<Ack>) -> anyhow::Result<()> {
        // The socket's read timeout (IDLE) bounds this wait.
        let (seq, ok) = socket::read_ack(&mut self.stream).context("no frame ack")?;
        out.push(Ack {
            seq,
            subscriber: 0,
            ok: u32::from(ok),
        });
        Ok(())
    }
}

fn set_timeouts(stream: &UnixStream) -> anyhow::Result<()> {
    stream.set_read_timeout(Some(IDLE))?;
    stream.set_write_timeout(Some(IDLE))?;
    Ok(())
}

fn socket_publisher(args: &BenchChildArgs) -> anyhow::Result<ChildReport> {
    let _ = std::fs::remove_file(&args.socket);
    let listener = UnixListener::bind(&args.socket)
        .with_context(|| format!("cannot listen on {}", args.socket.display()))?;
    ready_then_go()?;
    // The subscriber connected before it said ready, so this returns at once.
    let (stream, _) = listener.accept()?;
    set_timeouts(&stream)?;
    let mut link = SocketFrameLink {
        stream,
        frame: CvsFrame::new_boxed(),
    };
    frame_phases(&mut link, 1, args.iterations)
}

fn connect(path: &Path) -> anyhow::Result<UnixStream> {
    let deadline = Instant::now() + IDLE;
    loop {
        match UnixStream::connect(path) {
            Ok(s) => return Ok(s),
            Err(e) if Instant::now() >= deadline => {
                return Err(e).with_context(|| format!("cannot connect to {}", path.display()));
            }
            // The parent starts the publisher first; this only covers a slow bind.
            Err(_) => std::thread::sleep(Duration::from_millis(10)),
        }
    }
}

fn socket_subscriber(args: &BenchChildArgs) -> anyhow::Result<ChildReport> {
    let mut stream = connect(&args.socket)?;
    set_timeouts(&stream)?;
    ready_then_go()?;
    let mut buf = Vec::new();
    let mut frame = CvsFrame::new_boxed();
    let mut report = ChildReport::default();
    for _ in 0..2 * args.iterations {
        socket::read_message(&mut stream, &mut buf, codec::MAX_MESSAGE_BYTES)
            .context("no frame")?;
        let msg: SocketFrame<'static> = codec::decode(&buf)?;
        let received = monotonic_ns();
        if msg.phase == PHASE_LATENCY {
            report
                .latency_ns
                .push(received.saturating_sub(msg.sent_mono_ns));
        }
        let ok = msg.step == msg.seq && msg.restore_and_check(&mut frame);
        socket::write_ack(&mut stream, msg.seq, ok)?;
        report.messages += 1;
        report.bytes += buf.len() as u64;
        report.corrupt += u64::from(!ok);
    }
    Ok(report)
}

/// The wake-up ports of process `me` among `peers`: its own listener (the run's agent wake
/// service) and a notifier for each other process.
struct Wakes {
    listener: Listener<Ipc>,
    others: Vec<Notifier<Ipc>>,
    _services: Vec<protocol::ipc::EventService>,
}

impl Wakes {
    fn open(node: &RunNode, me: u32, peers: u32) -> anyhow::Result<Wakes> {
        let mut services = Vec::new();
        let mut others = Vec::new();
        let mut listener = None;
        for j in 0..peers {
            let service = node.open_agent_wake(j)?;
            if j == me {
                listener = Some(service.listener_builder().create()?);
            } else {
                others.push(service.notifier_builder().create()?);
            }
            services.push(service);
        }
        Ok(Wakes {
            listener: listener.ok_or_else(|| anyhow!("process {me} is not among {peers}"))?,
            others,
            _services: services,
        })
    }

    fn notify_others(&self, event: WakeEvent) -> anyhow::Result<()> {
        for n in &self.others {
            n.notify_with_custom_event_id(event.id())?;
        }
        Ok(())
    }
}

fn estimates(run: &RunId, args: &BenchChildArgs) -> anyhow::Result<ChildReport> {
    let me = args.index;
    let message = std::fs::read(&args.message)
        .with_context(|| format!("cannot read {}", args.message.display()))?;
    let node = RunNode::new(
        run,
        &format!("bench-estimates-{me}"),
        SignalHandlingMode::Disabled,
    )?;
    let services = BenchServices::new(&node);
    let mut publisher = None;
    let mut inbound = Vec::new();
    let mut open = Vec::new();
    for j in 0..args.peers {
        let service = services.estimates(j)?;
        if j == me {
            publisher = Some(
                service
                    .publisher_builder()
                    .initial_max_slice_len(message.len().max(1))
                    .allocation_strategy(AllocationStrategy::PowerOfTwo)
                    .max_loaned_samples(2)
                    .create()?,
            );
        } else {
            inbound.push((j, service.subscriber_builder().create()?));
        }
        open.push(service);
    }
    let publisher = publisher.ok_or_else(|| anyhow!("process {me} has no publisher"))?;
    let wakes = Wakes::open(&node, me, args.peers)?;
    let waitset = node.waitset()?;
    let _guard = waitset.attach_notification(&wakes.listener)?;
    ready_then_go()?;
    let start = Instant::now();
    let mut report = ChildReport::default();
    let mut received = vec![0u64; inbound.len()];
    for round in 0..args.iterations {
        let sent = monotonic_ns();
        let mut sample = publisher.loan_slice_uninit(message.len())?;
        *sample.user_header_mut() = Stamp {
            seq: round,
            sent_mono_ns: sent,
            sender: me,
            phase: PHASE_LATENCY,
        };
        sample.write_from_slice(&message).send()?;
        wakes.notify_others(WakeEvent::Estimate)?;
        let deadline = Instant::now() + IDLE;
        loop {
            for ((j, sub), count) in inbound.iter().zip(&mut received) {
                while let Some(sample) = sub.receive()? {
                    let at = monotonic_ns();
                    let stamp = *sample.user_header();
                    report
                        .latency_ns
                        .push(at.saturating_sub(stamp.sent_mono_ns));
                    let ok =
                        stamp.sender == *j && stamp.seq == *count && sample.payload() == message;
                    report.corrupt += u64::from(!ok);
                    report.bytes += sample.payload().len() as u64;
                    report.messages += 1;
                    *count += 1;
                }
            }
            if received.iter().all(|&c| c > round) {
                break;
            }
            wait_event(&waitset, &wakes.listener, deadline, "peer estimate")?;
        }
    }
    report.elapsed_ns = start.elapsed().as_nanos() as u64;
    Ok(report)
}

fn token(run: &RunId, args: &BenchChildArgs) -> anyhow::Result<ChildReport> {
    let me = args.index;
    let node = RunNode::new(
        run,
        &format!("bench-token-{me}"),
        SignalHandlingMode::Disabled,
    )?;
    let guidance = node.open_guidance()?;
    let publisher = RunNode::wire_publisher(&guidance, 4096)?;
    let subscriber = guidance.subscriber_builder().create()?;
    let wakes = Wakes::open(&node, me, args.peers)?;
    let waitset = node.waitset()?;
    let _guard = waitset.attach_notification(&wakes.listener)?;
    let live: BTreeSet<u32> = (0..args.peers).collect();
    let first = live.first().copied().unwrap_or(0);
    let view = PlannedView {
        uav: me,
        poses: vec![
            CameraPose {
                position: Point3::new(10.0 * me as f64, -20.0, 80.0),
                yaw: 0.25,
            };
            POSES_PER_PLAN
        ],
    };
    let run_tag = run.tag();
    let mut ring = TokenRing::new(me, Liveness::default());
    let mut report = ChildReport::default();
    // Reads every token received; returns when the round `complete` came back complete.
    let drain = |ring: &mut TokenRing, report: &mut ChildReport, complete: Option<u64>| {
        let mut completed_at = None;
        while let Some(sample) = subscriber.receive()? {
            let at = monotonic_ns();
            let h = *sample.user_header();
            if h.check(sample.payload().len(), WireKind::Token, run_tag, None)
                .is_err()
            {
                report.corrupt += 1;
                continue;
            }
            match codec::decode::<GuidanceToken>(sample.payload()) {
                Ok(t) => {
                    if Some(t.round) == complete && t.holder == ROUND_COMPLETE {
                        completed_at = Some(at);
                    }
                    ring.receive(t, h.sender, true);
                }
                Err(_) => report.corrupt += 1,
            }
        }
        anyhow::Ok(completed_at)
    };
    ready_then_go()?;
    let start = Instant::now();
    for round in 0..args.iterations {
        let deadline = Instant::now() + IDLE;
        loop {
            drain(&mut ring, &mut report, None)?;
            match ring.turn(round, &live) {
                Turn::Decide { .. } => break,
                Turn::Done => bail!("round {round}: already decided"),
                Turn::Wait { .. } => wait_event(&waitset, &wakes.listener, deadline, "token")?,
            }
        }
        let started = monotonic_ns();
        let mut token = ring.pass(round, round, &live, view.clone());
        // As an agent's: the sender's pose, which the radio judges the token's range by.
        token.pose = view.poses.first().copied();
        let bytes = codec::encode(&token)?;
        let mut sample = publisher.loan_slice_uninit(bytes.len())?;
        let len = u32::try_from(bytes.len())?;
        *sample.user_header_mut() =
            WireHeader::new(WireKind::Token, run_tag, me, round, len, unix_now_ns());
        sample.write_from_slice(&bytes).send()?;
        wakes.notify_others(WakeEvent::Token)?;
        report.messages += 1;
        report.bytes += bytes.len() as u64;
        if me == first {
            let completed = loop {
                if let Some(at) = drain(&mut ring, &mut report, Some(round))? {
                    break at;
                }
                wait_event(&waitset, &wakes.listener, deadline, "the token's return")?;
            };
            report.latency_ns.push(completed.saturating_sub(started));
        }
    }
    report.elapsed_ns = start.elapsed().as_nanos() as u64;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn credit_is_the_slowest_subscribers_and_refuses_gaps() {
        let mut c = Credit::new(2, 10);
        assert_eq!(c.all_acked(), 10);
        c.ack(0, 10).unwrap();
        assert_eq!(c.all_acked(), 10);
        c.ack(1, 10).unwrap();
        assert_eq!(c.all_acked(), 11);
        assert!(c.ack(0, 12).is_err());
        assert!(c.ack(2, 11).is_err());
    }

    /// A link whose subscribers acknowledge each frame as soon as it is sent.
    struct Loopback {
        subscribers: u32,
        pending: Vec<Ack>,
        max_in_flight: u64,
        acked: u64,
        sent: u64,
    }

    impl FrameLink for Loopback {
        fn send(&mut self, seq: u64, _phase: u32) -> anyhow::Result<()> {
            self.sent += 1;
            self.max_in_flight = self.max_in_flight.max(self.sent - self.acked);
            for s in 0..self.subscribers {
                self.pending.push(Ack {
                    seq,
                    subscriber: s,
                    ok: u32::from(seq != 3),
                });
            }
            Ok(())
        }

        fn acks(&mut self, _deadline: Instant, out: &mut Vec<Ack>) -> anyhow::Result<()> {
            if self.pending.is_empty() {
                bail!("nothing in flight");
            }
            out.append(&mut self.pending);
            self.acked = self.sent;
            Ok(())
        }
    }

    #[test]
    fn the_credit_loop_keeps_the_window_and_counts_bad_frames() {
        let mut link = Loopback {
            subscribers: 3,
            pending: Vec::new(),
            max_in_flight: 0,
            acked: 0,
            sent: 0,
        };
        let corrupt = credit_loop(&mut link, 3, 2, 0, 10, PHASE_RATE).unwrap();
        assert_eq!(link.sent, 10);
        assert_eq!(link.max_in_flight, 2);
        assert_eq!(corrupt, 3);
    }
}
