//! What the bench's processes exchange: the stamp every message carries, the frame acks, the
//! frame content, the clock, and each child's report.

use iceoryx2::prelude::*;
use protocol::frame::{CvsFrame, FRAME_MAX_PIXELS};
use serde::{Deserialize, Serialize};

/// Frames in flight while measuring the frame rate (the real frame service buffers 2).
pub const WINDOW: u64 = 2;
/// Rows of the benchmark frame (the default camera's).
const ROWS: u32 = 360;
/// Columns of the benchmark frame.
const COLS: u32 = 480;
const _: () = assert!((ROWS * COLS) as usize == FRAME_MAX_PIXELS);

/// The send time and sequence number every benchmark message carries (an iceoryx2 user
/// header).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("setfleet.bench.Stamp.v1")]
pub struct Stamp {
    /// Sequence number within the case.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` at the send start, ns.
    pub sent_mono_ns: u64,
    /// Sending process's index.
    pub sender: u32,
    /// 0: latency (one message in flight); 1: rate.
    pub phase: u32,
}

/// A subscriber's acknowledgement of a frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("setfleet.bench.Ack.v1")]
pub struct Ack {
    /// The frame's sequence number.
    pub seq: u64,
    /// The subscriber.
    pub subscriber: u32,
    /// 1 if the checksum held.
    pub ok: u32,
}

impl Stamp {
    /// Bytes of [`Stamp::to_le_bytes`].
    pub const BYTES: usize = 24;

    /// The stamp as little-endian fields, for a transport without user headers (a Zenoh
    /// attachment).
    pub fn to_le_bytes(&self) -> [u8; Self::BYTES] {
        let mut b = [0u8; Self::BYTES];
        b[..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..16].copy_from_slice(&self.sent_mono_ns.to_le_bytes());
        b[16..20].copy_from_slice(&self.sender.to_le_bytes());
        b[20..].copy_from_slice(&self.phase.to_le_bytes());
        b
    }

    /// Reads [`Stamp::to_le_bytes`]; `None` if `bytes` is not [`Stamp::BYTES`] long.
    pub fn from_le_bytes(bytes: &[u8]) -> Option<Stamp> {
        let b: &[u8; Self::BYTES] = bytes.try_into().ok()?;
        let (seq, rest) = b.split_first_chunk::<8>()?;
        let (sent, rest) = rest.split_first_chunk::<8>()?;
        let (sender, phase) = rest.split_first_chunk::<4>()?;
        Some(Stamp {
            seq: u64::from_le_bytes(*seq),
            sent_mono_ns: u64::from_le_bytes(*sent),
            sender: u32::from_le_bytes(*sender),
            phase: u32::from_le_bytes(phase.try_into().ok()?),
        })
    }
}

impl Ack {
    /// Bytes of [`Ack::to_le_bytes`].
    pub const BYTES: usize = 16;

    /// The ack as little-endian fields, for a transport of bytes (Zenoh).
    pub fn to_le_bytes(&self) -> [u8; Self::BYTES] {
        let mut b = [0u8; Self::BYTES];
        b[..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..12].copy_from_slice(&self.subscriber.to_le_bytes());
        b[12..].copy_from_slice(&self.ok.to_le_bytes());
        b
    }

    /// Reads [`Ack::to_le_bytes`]; `None` if `bytes` is not [`Ack::BYTES`] long.
    pub fn from_le_bytes(bytes: &[u8]) -> Option<Ack> {
        let b: &[u8; Self::BYTES] = bytes.try_into().ok()?;
        let (seq, rest) = b.split_first_chunk::<8>()?;
        let (subscriber, ok) = rest.split_first_chunk::<4>()?;
        Some(Ack {
            seq: u64::from_le_bytes(*seq),
            subscriber: u32::from_le_bytes(*subscriber),
            ok: u32::from_le_bytes(ok.try_into().ok()?),
        })
    }
}

/// The latency phase of a case.
pub const PHASE_LATENCY: u32 = 0;
/// The rate phase of a case.
pub const PHASE_RATE: u32 = 1;

/// What a child measured, printed as its last line.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ChildReport {
    /// Latencies of the messages it received in the latency phase, ns (for the token: round
    /// times measured by the round's first holder).
    pub latency_ns: Vec<u64>,
    /// Messages it sent (publishers) or received (others) in the rate phase.
    pub messages: u64,
    /// Bytes of those messages.
    pub bytes: u64,
    /// Duration of the rate phase, ns.
    pub elapsed_ns: u64,
    /// Messages whose content check failed.
    pub corrupt: u64,
    /// Messages sent again because their ack did not come (Zenoh cases: a link that dropped).
    #[serde(default)]
    pub resent: u64,
}

/// `CLOCK_MONOTONIC`, ns: one clock for every process of the machine.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes into the timespec we own; CLOCK_MONOTONIC always exists on
    // Linux.
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    (ts.tv_sec as u64).saturating_mul(1_000_000_000) + ts.tv_nsec as u64
}

/// Writes frame `seq` into `frame` as a renderer would: header, every pixel's depth and label
/// (varying with `seq`, so a stale or torn frame fails its checksum), then the checksum.
pub fn fill_frame(frame: &mut CvsFrame, seq: u64) {
    let h = &mut frame.header;
    h.rows = ROWS;
    h.cols = COLS;
    h.step = seq;
    h.time_s = seq as f64 * 0.5;
    h.box_count = 0;
    let n = frame.pixel_count();
    let salt = (seq as u32).wrapping_mul(0x9E37_79B9);
    for (i, (d, l)) in frame.depth[..n]
        .iter_mut()
        .zip(&mut frame.labels[..n])
        .enumerate()
    {
        let v = i as u32 ^ salt;
        *d = 20.0 + (v & 0xFFFF) as f32 * 1e-3;
        *l = ((v >> 7) & 3) as u8;
    }
    frame.header.checksum = frame.checksum();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filled_frames_differ_by_sequence_and_carry_their_checksum() {
        let mut a = CvsFrame::new_boxed();
        let mut b = CvsFrame::new_boxed();
        fill_frame(&mut a, 1);
        fill_frame(&mut b, 2);
        assert_eq!(a.pixel_count(), FRAME_MAX_PIXELS);
        assert_eq!(a.checksum(), a.header.checksum);
        assert_ne!(a.header.checksum, b.header.checksum);
    }

    #[test]
    fn stamps_and_acks_round_trip_through_bytes() {
        let stamp = Stamp {
            seq: u64::MAX - 1,
            sent_mono_ns: 123_456_789,
            sender: 3,
            phase: PHASE_RATE,
        };
        assert_eq!(Stamp::from_le_bytes(&stamp.to_le_bytes()), Some(stamp));
        assert_eq!(Stamp::from_le_bytes(&stamp.to_le_bytes()[1..]), None);
        let ack = Ack {
            seq: 7,
            subscriber: 2,
            ok: 1,
        };
        assert_eq!(Ack::from_le_bytes(&ack.to_le_bytes()), Some(ack));
        assert_eq!(Ack::from_le_bytes(&[0u8; 17]), None);
    }

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        let b = monotonic_ns();
        assert!(a > 0 && b >= a);
    }
}
