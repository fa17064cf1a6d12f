//! The handshake between `fleet bench ipc` and its children: the child's arguments
//! ([`BenchChildArgs`], its [`Role`]), the lines they exchange ([`READY`], [`GO`], [`RESULT`])
//! and the longest wait for anything ([`IDLE`]). The parent's side is `children`, the
//! child's is `roles` (the `fleet-bench-child` binary).

use std::io::{BufRead, Write};
use std::path::PathBuf;
use std::time::Duration;

use anyhow::bail;
use clap::{Parser, ValueEnum};

/// The line a child prints once its ports are open.
pub const READY: &str = "ready";
/// The line that starts the children.
pub const GO: &str = "go";
/// The prefix of a child's last line, followed by its [`ChildReport`](super::message::ChildReport) as JSON.
pub const RESULT: &str = "result ";

/// Longest wait for a peer's message, an ack or the parent's `go`.
pub const IDLE: Duration = Duration::from_secs(10);
/// What a child does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Role {
    /// Writes frames into loaned iceoryx2 samples and sends them.
    FramePublisher,
    /// Receives iceoryx2 frames, checks and acknowledges them.
    FrameSubscriber,
    /// Sends bincode frames over a Unix socket (it listens).
    SocketPublisher,
    /// Receives bincode frames from a Unix socket (it connects).
    SocketSubscriber,
    /// Sends its estimate to every peer and receives theirs, round after round.
    Estimates,
    /// Takes its turns in the guidance token ring.
    Token,
    /// A Zenoh router that sends bridge-encoded frames to a client (it listens).
    ZenohFramePublisher,
    /// A Zenoh client that receives bridge-encoded frames, checks and acknowledges them.
    ZenohFrameSubscriber,
    /// A Zenoh router that sends bridge-encoded estimates to a client (it listens).
    ZenohEstimatePublisher,
    /// A Zenoh client that receives bridge-encoded estimates, checks and acknowledges them.
    ZenohEstimateSubscriber,
}

impl Role {
    /// The command-line spelling.
    pub fn as_arg(self) -> &'static str {
        match self {
            Role::FramePublisher => "frame-publisher",
            Role::FrameSubscriber => "frame-subscriber",
            Role::SocketPublisher => "socket-publisher",
            Role::SocketSubscriber => "socket-subscriber",
            Role::Estimates => "estimates",
            Role::Token => "token",
            Role::ZenohFramePublisher => "zenoh-frame-publisher",
            Role::ZenohFrameSubscriber => "zenoh-frame-subscriber",
            Role::ZenohEstimatePublisher => "zenoh-estimate-publisher",
            Role::ZenohEstimateSubscriber => "zenoh-estimate-subscriber",
        }
    }
}

/// `fleet-bench-child`: one process of `fleet bench ipc`.
#[derive(Debug, Parser)]
#[command(name = "fleet-bench-child")]
pub struct BenchChildArgs {
    /// The bench's run id.
    #[arg(long)]
    pub run: String,
    /// What this process does.
    #[arg(long, value_enum)]
    pub role: Role,
    /// This process's index among its peers.
    #[arg(long, default_value_t = 0)]
    pub index: u32,
    /// Subscribers (frame roles) or processes (estimates, token).
    #[arg(long, default_value_t = 1)]
    pub peers: u32,
    /// Messages per phase (frames) or rounds.
    #[arg(long)]
    pub iterations: u64,
    /// The socket path of the baseline.
    #[arg(long)]
    pub socket: PathBuf,
    /// The estimate message file.
    #[arg(long)]
    pub message: PathBuf,
    /// The Zenoh link of the Zenoh roles.
    #[arg(long, value_enum, default_value_t = ZenohTransport::Tcp)]
    pub transport: ZenohTransport,
    /// The loopback port the Zenoh router listens on.
    #[arg(long, default_value_t = 0)]
    pub port: u16,
    /// The fleet's certificates of the Zenoh roles over TLS (`fleet certs`' layout).
    #[arg(long)]
    pub certs: PathBuf,
}

/// The link between the two hosts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ZenohTransport {
    /// Plain TCP, no access control.
    Tcp,
    /// Mutually authenticated TLS over TCP with the run's access policy.
    Tls,
    /// Mutually authenticated QUIC (TLS 1.3) with the run's access policy, as the bridge runs
    /// by default.
    Quic,
}

impl ZenohTransport {
    /// Every link, in the bench's order.
    pub const ALL: [ZenohTransport; 3] = [
        ZenohTransport::Tcp,
        ZenohTransport::Tls,
        ZenohTransport::Quic,
    ];

    /// The command-line spelling, also the endpoint's protocol.
    pub fn as_arg(self) -> &'static str {
        match self {
            ZenohTransport::Tcp => "tcp",
            ZenohTransport::Tls => "tls",
            ZenohTransport::Quic => "quic",
        }
    }

    /// What the link is, for the report.
    pub fn description(self) -> &'static str {
        match self {
            ZenohTransport::Tcp => "tcp",
            ZenohTransport::Tls => "tls over tcp, mutual authentication, access control",
            ZenohTransport::Quic => "quic, mutual authentication, access control",
        }
    }
}

/// Says `ready` and waits for `go`.
pub fn ready_then_go() -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(out, "{READY}")?;
    out.flush()?;
    drop(out);
    // The parent sends `go` or kills this process; dying with the parent covers its death.
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line)?;
    if line.trim() != GO {
        bail!("expected {GO:?} on stdin, got {line:?}");
    }
    Ok(())
}
