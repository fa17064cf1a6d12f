//! The baseline transport a user would otherwise pick: a Unix domain stream socket carrying
//! bincode messages ([`protocol::codec`]), each preceded by its length as a little-endian
//! `u32`, and fixed 16-byte acks in the other direction.

use std::borrow::Cow;
use std::io::{self, Read, Write};

use protocol::frame::CvsFrame;
use serde::{Deserialize, Serialize};

/// Bytes of the length prefix.
const LEN_BYTES: usize = 4;
/// Bytes of an ack: the sequence number and the check result, both `u64` little-endian.
pub const ACK_BYTES: usize = 16;

/// Writes one length-prefixed message.
pub fn write_message(w: &mut impl Write, bytes: &[u8]) -> io::Result<()> {
    let len = u32::try_from(bytes.len())
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "message over 4 GiB"))?;
    w.write_all(&len.to_le_bytes())?;
    w.write_all(bytes)?;
    w.flush()
}

/// Reads one length-prefixed message into `buf` (resized to it); a length over `max` is
/// refused before anything is allocated.
pub fn read_message(r: &mut impl Read, buf: &mut Vec<u8>, max: usize) -> io::Result<()> {
    let mut len = [0u8; LEN_BYTES];
    r.read_exact(&mut len)?;
    let len = u32::from_le_bytes(len) as usize;
    if len > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("message of {len} bytes exceeds the {max}-byte limit"),
        ));
    }
    buf.resize(len, 0);
    r.read_exact(buf)
}

/// Writes an ack of frame `seq`.
pub fn write_ack(w: &mut impl Write, seq: u64, ok: bool) -> io::Result<()> {
    let mut a = [0u8; ACK_BYTES];
    a[..8].copy_from_slice(&seq.to_le_bytes());
    a[8..].copy_from_slice(&u64::from(ok).to_le_bytes());
    w.write_all(&a)?;
    w.flush()
}

/// Reads an ack: the frame's sequence number and whether its checksum held.
pub fn read_ack(r: &mut impl Read) -> io::Result<(u64, bool)> {
    let mut a = [0u8; ACK_BYTES];
    r.read_exact(&mut a)?;
    let mut seq = [0u8; 8];
    seq.copy_from_slice(&a[..8]);
    Ok((u64::from_le_bytes(seq), a[8..].iter().any(|&b| b != 0)))
}

/// A frame as the baseline sends it: the header fields a receiver needs and the pixels,
/// borrowed from the rendered frame when sending (no copy before encoding), owned when
/// received.
#[derive(Serialize, Deserialize)]
pub struct SocketFrame<'a> {
    /// Sequence number.
    pub seq: u64,
    /// Benchmark phase.
    pub phase: u32,
    /// `CLOCK_MONOTONIC` at the send start, ns.
    pub sent_mono_ns: u64,
    /// Step.
    pub step: u64,
    /// Simulated time.
    pub time_s: f64,
    /// Image rows.
    pub rows: u32,
    /// Image columns.
    pub cols: u32,
    /// Checksum of depth and labels.
    pub checksum: u64,
    /// Depth of the pixels in use.
    pub depth: Cow<'a, [f32]>,
    /// Labels of the pixels in use.
    pub labels: Cow<'a, [u8]>,
}

impl<'a> SocketFrame<'a> {
    /// The message for `frame`.
    pub fn of(frame: &'a CvsFrame, seq: u64, phase: u32, sent_mono_ns: u64) -> Self {
        let n = frame.pixel_count();
        Self {
            seq,
            phase,
            sent_mono_ns,
            step: frame.header.step,
            time_s: frame.header.time_s,
            rows: frame.header.rows,
            cols: frame.header.cols,
            checksum: frame.header.checksum,
            depth: Cow::Borrowed(&frame.depth[..n]),
            labels: Cow::Borrowed(&frame.labels[..n]),
        }
    }

    /// Copies the message into `frame`; false if it does not fit or its checksum fails.
    pub fn restore_and_check(&self, frame: &mut CvsFrame) -> bool {
        let n = self.rows as usize * self.cols as usize;
        if n > frame.depth.len() || self.depth.len() != n || self.labels.len() != n {
            return false;
        }
        frame.header.rows = self.rows;
        frame.header.cols = self.cols;
        frame.header.step = self.step;
        frame.header.time_s = self.time_s;
        frame.header.checksum = self.checksum;
        frame.depth[..n].copy_from_slice(&self.depth);
        frame.labels[..n].copy_from_slice(&self.labels);
        frame.checksum() == self.checksum
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ipc::fill_frame;

    #[test]
    fn messages_and_acks_round_trip_through_a_byte_stream() {
        let mut wire = Vec::new();
        write_message(&mut wire, b"hello").unwrap();
        write_message(&mut wire, b"").unwrap();
        write_ack(&mut wire, 7, true).unwrap();
        let mut r = wire.as_slice();
        let mut buf = Vec::new();
        read_message(&mut r, &mut buf, 100).unwrap();
        assert_eq!(buf, b"hello");
        read_message(&mut r, &mut buf, 100).unwrap();
        assert!(buf.is_empty());
        assert_eq!(read_ack(&mut r).unwrap(), (7, true));
        assert!(r.is_empty());
    }

    #[test]
    fn an_oversized_or_truncated_message_is_refused() {
        let mut wire = Vec::new();
        write_message(&mut wire, &[1u8; 64]).unwrap();
        let mut buf = Vec::new();
        let e = read_message(&mut wire.as_slice(), &mut buf, 63).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        let e = read_message(&mut &wire[..40], &mut buf, 100).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::UnexpectedEof);
    }

    #[test]
    fn a_frame_survives_the_baseline_encoding() {
        let mut frame = CvsFrame::new_boxed();
        fill_frame(&mut frame, 3);
        let bytes = protocol::codec::encode(&SocketFrame::of(&frame, 3, 1, 99)).unwrap();
        let back: SocketFrame<'static> = protocol::codec::decode(&bytes).unwrap();
        assert_eq!((back.seq, back.phase, back.sent_mono_ns), (3, 1, 99));
        let mut copy = CvsFrame::new_boxed();
        assert!(back.restore_and_check(&mut copy));
        assert_eq!(copy.checksum(), frame.header.checksum);
        let mut bad: SocketFrame<'static> = protocol::codec::decode(&bytes).unwrap();
        bad.labels.to_mut()[10] ^= 1;
        assert!(!bad.restore_and_check(&mut copy));
    }
}
