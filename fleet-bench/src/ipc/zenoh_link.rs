//! The Zenoh cases: a frame or an estimate from one host's bridge to another's, on loopback,
//! set up as `fleet-bridge` sets up its sessions.
//!
//! The publisher is the world host `h0`, a Zenoh router listening on a loopback port; the
//! subscriber is the agent host `h1`, a client connecting to it. Their configurations are
//! [`zenoh_config`]'s: over QUIC or TLS over TCP with the fleet's certificates (made by the
//! parent with [`write_fleet_certs`]) and the run's access policy ([`placement::access_policy`],
//! `h0=0,1`, `h1=2,3`), or plain TCP without either. The keys are the run's own: frames go to UAV 2 on
//! [`keys::frame`], estimates come from UAV 0 on [`keys::estimate`], so the access policy
//! admits them as in a run. The publisher is the bridge's own: [`declare_publisher`], the
//! function the bridge declares its publishers with, so the bench times the bridge's settings
//! (reliable, blocking congestion control, express, remote destinations only) and not a copy
//! of them. It sends what the bridge sends: the [`envelope`] encoding, copied out of the
//! reused buffer. The bench's [`Stamp`] travels as the Zenoh attachment, so the payload is
//! exactly the bridge's.
//!
//! Latency runs from the send start (the frame written, before it is encoded) to the decoded
//! message on the subscriber (`decode_frame_into` a frame, or `decode_wire`); the checks
//! (checksum, header, content) come after.
//!
//! # Acks, and what Zenoh 1.10.2's TLS link does
//!
//! The subscriber acknowledges over iceoryx2 (the bench's ack service), not over Zenoh, so the
//! three links are timed alike. With the acks on the Zenoh link too, the TLS cases failed:
//! zenoh-link-tls reads and writes one rustls stream from two tasks at once through an
//! `UnsafeCell`, and when both directions are busy a write fails with rustls'
//! `handshake not complete` (the reader holds the connection state), the link drops, the client
//! reconnects within milliseconds and whatever was in flight is lost; a few runs aborted on a
//! corrupted heap (`memory allocation of 139732197604672 bytes failed` in rustls). With 200
//! frames per phase every TLS run failed; TCP never did. With the data going one way the
//! collision needs a keepalive (about every 2.5 s), so it is rare, and the publisher survives
//! it: after [`RESEND_AFTER`] without an ack it sends every unacknowledged message again, with
//! its first stamp, and counts them (`resent`). The bridge's links carry traffic both ways, so
//! they are exposed to this bug over TLS; QUIC, the bridge's default, keeps its send and
//! receive streams apart and is not.

use std::collections::VecDeque;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, anyhow, bail};
use bridge::endpoint::{Transport, free_loopback_port};
use bridge::envelope;
use bridge::keys;
use bridge::outbound::declare_publisher;
use bridge::placement::{self, HostShare};
use bridge::security::{
    HostName, HostTlsFiles, LinkMode, LinkPlan, write_fleet_certs, zenoh_config,
};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber as IoxSubscriber;
use iceoryx2::prelude::*;
use protocol::frame::CvsFrame;
use protocol::ipc::{Ipc, RunNode};
use protocol::service::RunId;
use protocol::wire::{WireHeader, WireKind, unix_now_ns};
use zenoh::Wait;
use zenoh::pubsub::Publisher;
use zenoh::sample::Locality;

use super::handshake::{BenchChildArgs, IDLE, ZenohTransport, ready_then_go};
use super::message::{
    Ack, ChildReport, PHASE_LATENCY, PHASE_RATE, Stamp, WINDOW, fill_frame, monotonic_ns,
};
use super::services::BenchServices;

/// The world host: the router, and the publisher.
const ROUTER_HOST: &str = "h0";
/// The agent host: the client, and the subscriber.
const CLIENT_HOST: &str = "h1";
/// The UAVs of the world host.
const ROUTER_UAVS: [u32; 2] = [0, 1];
/// The UAVs of the agent host.
const CLIENT_UAVS: [u32; 2] = [2, 3];
/// The UAV whose estimates the router sends.
const ESTIMATE_UAV: u32 = ROUTER_UAVS[0];
/// The UAV whose frames the router sends (it runs on the client's host).
const FRAME_UAV: u32 = CLIENT_UAVS[0];
/// How long the router waits for an ack before it sends the unacknowledged messages again:
/// far above any delivery on loopback (milliseconds), far below [`IDLE`].
const RESEND_AFTER: Duration = Duration::from_millis(100);

/// What a Zenoh case sends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Payload {
    /// The 864 KB frame, [`envelope::encode_frame`].
    Frame,
    /// The estimate message, [`envelope::encode_wire`].
    Estimate,
}

/// Which end of the link a session is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Router,
    Client,
}

/// Writes the fleet's certificates of the two hosts into `dir`.
pub(super) fn write_certs(dir: &Path) -> anyhow::Result<()> {
    let hosts = [ROUTER_HOST.to_owned(), CLIENT_HOST.to_owned()];
    write_fleet_certs(dir, &hosts, &[], false).with_context(|| {
        format!(
            "cannot write the bench's certificates into {}",
            dir.display()
        )
    })?;
    Ok(())
}

/// A loopback port free right now, for a router to listen on over `transport` (UDP for QUIC).
pub(super) fn free_port(transport: ZenohTransport) -> anyhow::Result<u16> {
    free_loopback_port(match transport {
        ZenohTransport::Quic => Transport::Udp,
        ZenohTransport::Tcp | ZenohTransport::Tls => Transport::Tcp,
    })
    .context("cannot find a free loopback port for the router")
}

/// The two hosts, as `fleet-bridge --member` names them.
fn members() -> anyhow::Result<Vec<HostShare>> {
    Ok(vec![
        HostShare {
            name: HostName::new(ROUTER_HOST)?,
            agents: ROUTER_UAVS.into(),
        },
        HostShare {
            name: HostName::new(CLIENT_HOST)?,
            agents: CLIENT_UAVS.into(),
        },
    ])
}

/// The Zenoh configuration of one side, as `fleet-bridge` builds it.
fn config(
    run: &RunId,
    transport: ZenohTransport,
    side: Side,
    port: u16,
    certs: &Path,
) -> anyhow::Result<zenoh::Config> {
    let endpoint = format!("{}/127.0.0.1:{port}", transport.as_arg());
    let (mode, host, listen, connect) = match side {
        Side::Router => (LinkMode::Router, ROUTER_HOST, vec![endpoint], Vec::new()),
        Side::Client => (LinkMode::Client, CLIENT_HOST, Vec::new(), vec![endpoint]),
    };
    let link = LinkPlan {
        mode,
        listen,
        connect,
    };
    let mut config = match transport {
        ZenohTransport::Tcp => zenoh_config(&link, None, None)?,
        ZenohTransport::Tls | ZenohTransport::Quic => {
            let tls = HostTlsFiles::in_dir(certs, &HostName::new(host)?);
            let policy = placement::access_policy(run, &members()?)?;
            zenoh_config(&link, Some(&tls), Some(&policy))?
        }
    };
    if side == Side::Client {
        // fleet-bridge's retries, bounded: the router listens before the client starts, and a
        // router that never answers is an error, not a hang.
        config
            .insert_json5("connect/timeout_ms", &IDLE.as_millis().to_string())
            .and_then(|()| {
                config.insert_json5(
                    "connect/retry",
                    "{ period_init_ms: 50, period_max_ms: 1000, period_increase_factor: 2 }",
                )
            })
            .map_err(|e| anyhow!("cannot configure the connection: {e}"))?;
    }
    Ok(config)
}

fn open(run: &RunId, args: &BenchChildArgs, side: Side) -> anyhow::Result<zenoh::Session> {
    let config = config(run, args.transport, side, args.port, &args.certs)?;
    zenoh::open(config)
        .wait()
        .map_err(|e| anyhow!("cannot open the Zenoh session: {e}"))
}

/// Closes the session, which first sends what is still queued (the last ack).
fn close(session: zenoh::Session) {
    if let Err(e) = session.close().wait() {
        tracing::debug!(error = %e, "closing the Zenoh session");
    }
}

/// Waits until `publisher` has a remote subscriber (at most [`IDLE`]).
fn wait_matching(publisher: &Publisher<'_>, what: &str) -> anyhow::Result<()> {
    let listener = publisher
        .matching_listener()
        .wait()
        .map_err(|e| anyhow!("cannot watch the subscribers of {what}: {e}"))?;
    let deadline = Instant::now() + IDLE;
    loop {
        match listener.recv_deadline(deadline) {
            Ok(Some(status)) if status.matching() => return Ok(()),
            Ok(Some(_)) => {}
            Ok(None) => bail!("no subscriber of {what} within {IDLE:?}"),
            Err(e) => bail!("cannot watch the subscribers of {what}: {e}"),
        }
    }
}

fn data_key(run: &RunId, payload: Payload) -> String {
    match payload {
        Payload::Frame => keys::frame(run, FRAME_UAV),
        Payload::Estimate => keys::estimate(run, ESTIMATE_UAV),
    }
}

/// What the publisher writes into its messages.
enum Outgoing {
    Frame(Box<CvsFrame>),
    Estimate { message: Vec<u8>, run_tag: u64 },
}

/// The publisher's end: writes, encodes and sends messages, and reads the acks.
trait AckedLink {
    /// Writes and encodes message `seq`; returns its send start (`CLOCK_MONOTONIC`, ns).
    fn encode(&mut self, seq: u64) -> anyhow::Result<u64>;
    /// Sends the message last encoded, with `stamp`.
    fn put(&mut self, stamp: &Stamp) -> anyhow::Result<()>;
    /// The next ack, or `None` once `deadline` passed.
    fn ack(&mut self, deadline: Instant) -> anyhow::Result<Option<Ack>>;
}

struct ZenohSender<'a> {
    publisher: &'a Publisher<'static>,
    acks: &'a IoxSubscriber<Ipc, Ack, ()>,
    waitset: &'a WaitSet<Ipc>,
    listener: &'a Listener<Ipc>,
    outgoing: Outgoing,
    buf: Vec<u8>,
}

impl AckedLink for ZenohSender<'_> {
    fn encode(&mut self, seq: u64) -> anyhow::Result<u64> {
        Ok(match &mut self.outgoing {
            Outgoing::Frame(frame) => {
                fill_frame(frame, seq);
                let sent = monotonic_ns();
                envelope::encode_frame(frame, &mut self.buf);
                sent
            }
            Outgoing::Estimate { message, run_tag } => {
                let sent = monotonic_ns();
                let len = u32::try_from(message.len())?;
                let header = WireHeader::new(
                    WireKind::Estimate,
                    *run_tag,
                    ESTIMATE_UAV,
                    seq,
                    len,
                    unix_now_ns(),
                );
                envelope::encode_wire(&header, message, &mut self.buf);
                sent
            }
        })
    }

    fn put(&mut self, stamp: &Stamp) -> anyhow::Result<()> {
        // The bridge's put: a copy of the encoded message, as its buffer is reused.
        self.publisher
            .put(self.buf.to_vec())
            .attachment(stamp.to_le_bytes().to_vec())
            .wait()
            .map_err(|e| anyhow!("cannot send message {}: {e}", stamp.seq))
    }

    fn ack(&mut self, deadline: Instant) -> anyhow::Result<Option<Ack>> {
        loop {
            if let Some(ack) = self.acks.receive()? {
                return Ok(Some(*ack.payload()));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            self.waitset
                .wait_and_process_once_with_timeout(
                    |_| {
                        // Consume the notifications; the acks are in the samples.
                        let _ = self.listener.try_wait(|_| {});
                        CallbackProgression::Continue
                    },
                    left,
                )
                .map_err(|e| anyhow!("waiting for acks failed: {e:?}"))?;
        }
    }
}

/// Sends messages `first..first + n` keeping at most `window` unacknowledged (acks are
/// cumulative); returns how many it sent again.
///
/// A message Zenoh lost (over TLS, a link that dropped and reconnected) is never acknowledged:
/// after [`RESEND_AFTER`] without an ack, every unacknowledged message is sent again with its
/// first send start, so its latency counts the loss.
fn send_phase(
    link: &mut impl AckedLink,
    window: u64,
    first: u64,
    n: u64,
    phase: u32,
) -> anyhow::Result<u64> {
    let end = first + n;
    let (mut acked, mut next) = (first, first);
    let mut in_flight: VecDeque<Stamp> = VecDeque::new();
    let mut resent = 0;
    let mut last_ack = Instant::now();
    let mut last_send = last_ack;
    while acked < end {
        while next < end && next - acked < window {
            let stamp = Stamp {
                seq: next,
                sent_mono_ns: link.encode(next)?,
                sender: 0,
                phase,
            };
            link.put(&stamp)?;
            in_flight.push_back(stamp);
            last_send = Instant::now();
            next += 1;
        }
        match link.ack(last_send.max(last_ack) + RESEND_AFTER)? {
            Some(ack) if (acked..next).contains(&ack.seq) => {
                while in_flight.front().is_some_and(|s| s.seq <= ack.seq) {
                    in_flight.pop_front();
                }
                acked = ack.seq + 1;
                last_ack = Instant::now();
            }
            // The ack of a message acknowledged already (it was sent again).
            Some(_) => {}
            None if last_ack.elapsed() >= IDLE => {
                bail!("no ack of message {acked} within {IDLE:?}")
            }
            None => {
                for stamp in &in_flight {
                    link.encode(stamp.seq)?;
                    link.put(stamp)?;
                    resent += 1;
                }
                last_send = Instant::now();
            }
        }
    }
    Ok(resent)
}

/// The router: sends `payload` to the client, one message in flight then a window.
pub(super) fn publisher(
    run: &RunId,
    args: &BenchChildArgs,
    payload: Payload,
) -> anyhow::Result<ChildReport> {
    let outgoing = match payload {
        Payload::Frame => Outgoing::Frame(CvsFrame::new_boxed()),
        Payload::Estimate => Outgoing::Estimate {
            message: std::fs::read(&args.message)
                .with_context(|| format!("cannot read {}", args.message.display()))?,
            run_tag: run.tag(),
        },
    };
    let node = RunNode::new(run, "bench-zenoh-pub", SignalHandlingMode::Disabled)?;
    let services = BenchServices::new(&node);
    let ack_service = services.acks()?;
    let acks = ack_service.subscriber_builder().create()?;
    let ack_wake = services.event("ack-wake")?;
    let listener = ack_wake.listener_builder().create()?;
    let waitset = node.waitset()?;
    let _guard = waitset.attach_notification(&listener)?;
    let session = open(run, args, Side::Router)?;
    let publisher = declare_publisher(&session, data_key(run, payload))?;
    let mut link = ZenohSender {
        publisher: &publisher,
        acks: &acks,
        waitset: &waitset,
        listener: &listener,
        outgoing,
        buf: Vec::new(),
    };
    link.encode(0)?;
    let message_bytes = link.buf.len() as u64;
    ready_then_go()?;
    // The client declared its subscriber before it said ready; this waits until the
    // declaration has reached the router.
    wait_matching(&publisher, "the messages")?;
    let n = args.iterations;
    let mut resent = send_phase(&mut link, 1, 0, n, PHASE_LATENCY)?;
    let start = Instant::now();
    resent += send_phase(&mut link, WINDOW, n, n, PHASE_RATE)?;
    let elapsed_ns = start.elapsed().as_nanos() as u64;
    drop(publisher);
    close(session);
    Ok(ChildReport {
        latency_ns: Vec::new(),
        messages: n,
        bytes: n * message_bytes,
        elapsed_ns,
        corrupt: 0,
        resent,
    })
}

/// The client: receives, decodes, checks and acknowledges every message, in order.
///
/// Acks are cumulative: a message out of order (one before it was lost) or one received
/// already (sent again before its ack arrived) is dropped and the last message received in
/// order acknowledged again.
pub(super) fn subscriber(
    run: &RunId,
    args: &BenchChildArgs,
    payload: Payload,
) -> anyhow::Result<ChildReport> {
    let message = match payload {
        Payload::Frame => Vec::new(),
        Payload::Estimate => std::fs::read(&args.message)
            .with_context(|| format!("cannot read {}", args.message.display()))?,
    };
    let node = RunNode::new(run, "bench-zenoh-sub", SignalHandlingMode::Disabled)?;
    let services = BenchServices::new(&node);
    let ack_service = services.acks()?;
    let ack_out = ack_service.publisher_builder().create()?;
    let ack_wake = services.event("ack-wake")?;
    let notifier = ack_wake.notifier_builder().create()?;
    let session = open(run, args, Side::Client)?;
    let inbound = session
        .declare_subscriber(data_key(run, payload))
        .allowed_origin(Locality::Remote)
        .wait()
        .map_err(|e| anyhow!("cannot declare a Zenoh subscriber: {e}"))?;
    ready_then_go()?;
    let run_tag = run.tag();
    let total = 2 * args.iterations;
    let mut frame = CvsFrame::new_boxed();
    let mut report = ChildReport::default();
    let mut expected = 0u64;
    let mut last_ok = true;
    while expected < total {
        let sample = inbound
            .recv_deadline(Instant::now() + IDLE)
            .map_err(|e| anyhow!("cannot receive messages: {e}"))?
            .ok_or_else(|| anyhow!("no message {expected} within {IDLE:?}"))?;
        let stamp = sample
            .attachment()
            .and_then(|a| Stamp::from_le_bytes(&a.to_bytes()))
            .ok_or_else(|| anyhow!("a message without its stamp"))?;
        let (seq, ok) = if stamp.seq == expected {
            let bytes = sample.payload().to_bytes();
            let (received, ok) = match payload {
                Payload::Frame => {
                    let decoded = envelope::decode_frame_into(&bytes, &mut frame);
                    let received = monotonic_ns();
                    let ok = decoded.is_ok()
                        && frame.header.step == stamp.seq
                        && frame.checksum() == frame.header.checksum;
                    (received, ok)
                }
                Payload::Estimate => {
                    let decoded = envelope::decode_wire(&bytes);
                    let received = monotonic_ns();
                    let ok = decoded.is_ok_and(|(h, p)| {
                        h.check(p.len(), WireKind::Estimate, run_tag, Some(ESTIMATE_UAV))
                            .is_ok()
                            && h.step == stamp.seq
                            && p == message
                    });
                    (received, ok)
                }
            };
            if stamp.phase == PHASE_LATENCY {
                report
                    .latency_ns
                    .push(received.saturating_sub(stamp.sent_mono_ns));
            }
            report.messages += 1;
            report.bytes += bytes.len() as u64;
            report.corrupt += u64::from(!ok);
            expected += 1;
            last_ok = ok;
            (stamp.seq, ok)
        } else if let Some(last) = expected.checked_sub(1) {
            (last, last_ok)
        } else {
            // Nothing received in order yet: the router sends message 0 again.
            continue;
        };
        ack_out.send_copy(Ack {
            seq,
            subscriber: 0,
            ok: u32::from(ok),
        })?;
        notifier.notify()?;
    }
    drop(inbound);
    close(session);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_sides_are_configured_as_the_bridge_configures_them() {
        let run = RunId::new("bench-zenoh-config").unwrap();
        let dir = std::env::temp_dir().join(format!("fleet-bench-zenoh-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        write_certs(&dir).unwrap();
        let get = |c: &zenoh::Config, key| c.get_json(key).unwrap();

        let router = config(&run, ZenohTransport::Tls, Side::Router, 7001, &dir).unwrap();
        assert_eq!(get(&router, "mode"), r#""router""#);
        assert_eq!(
            get(&router, "listen/endpoints"),
            r#"["tls/127.0.0.1:7001"]"#
        );
        assert_eq!(get(&router, "transport/link/tls/enable_mtls"), "true");
        assert_eq!(get(&router, "access_control/enabled"), "true");

        let client = config(&run, ZenohTransport::Tls, Side::Client, 7001, &dir).unwrap();
        assert_eq!(get(&client, "mode"), r#""client""#);
        assert_eq!(
            get(&client, "connect/endpoints"),
            r#"["tls/127.0.0.1:7001"]"#
        );
        assert!(get(&client, "transport/link/tls/connect_certificate").contains("h1.pem"));
        assert_eq!(
            get(&client, "connect/timeout_ms"),
            IDLE.as_millis().to_string()
        );

        let tcp = config(&run, ZenohTransport::Tcp, Side::Client, 7002, &dir).unwrap();
        assert_eq!(get(&tcp, "connect/endpoints"), r#"["tcp/127.0.0.1:7002"]"#);
        assert_eq!(get(&tcp, "transport/link/protocols"), r#"["tcp"]"#);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A link to an in-order subscriber (cumulative acks) that loses the puts and acks it is
    /// told to.
    #[derive(Default)]
    struct Lossy {
        lose_puts: Vec<u64>,
        lose_acks: Vec<u64>,
        puts: u64,
        acks: u64,
        pending: VecDeque<Ack>,
        expected: u64,
        delivered: Vec<(u64, u64)>,
    }

    impl AckedLink for Lossy {
        fn encode(&mut self, seq: u64) -> anyhow::Result<u64> {
            Ok(1000 + seq)
        }

        fn put(&mut self, stamp: &Stamp) -> anyhow::Result<()> {
            self.puts += 1;
            if self.lose_puts.contains(&(self.puts - 1)) {
                return Ok(());
            }
            if stamp.seq == self.expected {
                self.delivered.push((stamp.seq, stamp.sent_mono_ns));
                self.expected += 1;
            }
            if let Some(seq) = self.expected.checked_sub(1) {
                self.acks += 1;
                if !self.lose_acks.contains(&(self.acks - 1)) {
                    self.pending.push_back(Ack {
                        seq,
                        subscriber: 0,
                        ok: 1,
                    });
                }
            }
            Ok(())
        }

        fn ack(&mut self, _deadline: Instant) -> anyhow::Result<Option<Ack>> {
            // An empty queue stands for a wait that timed out.
            Ok(self.pending.pop_front())
        }
    }

    #[test]
    fn lost_messages_and_acks_are_sent_again_in_order_with_their_first_stamp() {
        let mut link = Lossy {
            lose_puts: vec![3],
            lose_acks: vec![6],
            ..Lossy::default()
        };
        let resent = send_phase(&mut link, 2, 0, 10, PHASE_RATE).unwrap();
        let seqs: Vec<u64> = link.delivered.iter().map(|d| d.0).collect();
        assert_eq!(seqs, (0..10).collect::<Vec<_>>());
        assert!(link.delivered.iter().all(|&(seq, sent)| sent == 1000 + seq));
        assert!(resent >= 2, "resent {resent}");
        assert_eq!(link.puts, 10 + resent);

        let mut clean = Lossy {
            expected: 5,
            ..Lossy::default()
        };
        assert_eq!(send_phase(&mut clean, 1, 5, 4, PHASE_LATENCY).unwrap(), 0);
        assert_eq!(clean.puts, 4);
    }

    #[test]
    fn only_the_router_may_publish_the_bench_messages() {
        let run = RunId::new("bench-zenoh-policy").unwrap();
        let policy = placement::access_policy(&run, &members().unwrap()).unwrap();
        let world = policy.publications(&HostName::new(ROUTER_HOST).unwrap());
        assert_eq!(world, vec![format!("{}/**", keys::run_root(&run))]);
        let client = policy.publications(&HostName::new(CLIENT_HOST).unwrap());
        for payload in [Payload::Frame, Payload::Estimate] {
            assert!(!client.contains(&data_key(&run, payload)), "{payload:?}");
        }
        assert!(client.contains(&keys::estimate(&run, CLIENT_UAVS[0])));
    }
}
