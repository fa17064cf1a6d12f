//! How the bridge carries iceoryx2 samples over Zenoh: plain little-endian fields, written and
//! read field by field, so no struct's memory layout ever crosses a host and every length is
//! checked before anything is copied.
//!
//! | payload | iceoryx2 type | bytes |
//! |---|---|---|
//! | frame | [`CvsFrame`] | version, header fields, the boxes in use, `rows * cols` depths and labels |
//! | command | [`UavCommand`] | version, its six fields (44 bytes) |
//! | wire message | [`WireHeader`] + `[u8]` | version, the header's seven fields, the payload |
//!
//! Only the pixels in use travel: a frame of the default camera is 864 KB of pixels, 120
//! bytes of header and 20 bytes per box. Each payload starts with [`ENVELOPE_VERSION`], so a host of another version is
//! refused rather than misread. The receivers of the payloads (agents, world) check their
//! run tags, steps, senders and the frame's checksum as they do for local samples.

use protocol::frame::{CvsFrame, FRAME_MAX_BOXES, FRAME_MAX_PIXELS, FrameHeader, TargetBox};
use protocol::wire::{UavCommand, WireHeader};

/// Version of the envelope layout, first in every payload. 2: a frame's `served` mask is 64
/// bits ([`protocol::wire::UavMask`]).
pub const ENVELOPE_VERSION: u32 = 2;

/// Largest wire payload (estimate or token) accepted from another host, bytes. The largest
/// estimate of a default run is a few hundred KB; anything above this is refused unread.
pub const MAX_WIRE_PAYLOAD: usize = 64 << 20;

/// Bytes of an encoded [`FrameHeader`].
const FRAME_HEADER_BYTES: usize = 8 + 8 + 8 + 4 * 4 + 8 + 3 * 8 + 3 * 8 + 2 * 8 + 8;
/// Bytes of an encoded [`TargetBox`].
const BOX_BYTES: usize = 5 * 4;
/// Bytes of an encoded [`UavCommand`] after the version.
const COMMAND_BYTES: usize = 8 + 8 + 4 + 4 + 8 + 8;
/// Bytes of an encoded [`WireHeader`] after the version.
const WIRE_HEADER_BYTES: usize = 4 + 4 + 8 + 4 + 4 + 8 + 8;

/// Why a payload from another host was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EnvelopeError {
    /// Fewer bytes than the layout needs.
    #[error("truncated: {needed} bytes needed, {got} received")]
    Truncated {
        /// Bytes the layout needs.
        needed: usize,
        /// Bytes received.
        got: usize,
    },
    /// More bytes than the layout says.
    #[error("{0} bytes left over after the message")]
    TrailingBytes(usize),
    /// Another envelope version.
    #[error("envelope version {0}, this host speaks {ENVELOPE_VERSION}")]
    Version(u32),
    /// A frame whose image or boxes do not fit a [`CvsFrame`].
    #[error("a frame of {rows} x {cols} pixels and {boxes} boxes does not fit")]
    FrameSize {
        /// Image rows.
        rows: u32,
        /// Image columns.
        cols: u32,
        /// Boxes in use.
        boxes: u32,
    },
    /// A wire payload whose header disagrees with its length, or one too long.
    #[error("a wire payload of {got} bytes whose header says {said} (at most {MAX_WIRE_PAYLOAD})")]
    WireLength {
        /// Length the header gives.
        said: u32,
        /// Bytes that follow the header.
        got: usize,
    },
}

/// Appends `frame`'s header, boxes and pixels in use to `out` (cleared first).
pub fn encode_frame(frame: &CvsFrame, out: &mut Vec<u8>) {
    let h = &frame.header;
    let n = frame.pixel_count();
    let boxes = frame.boxes();
    out.clear();
    out.reserve(4 + FRAME_HEADER_BYTES + boxes.len() * BOX_BYTES + n * 5);
    put_u32(out, ENVELOPE_VERSION);
    put_u64(out, h.run_tag);
    put_u64(out, h.step);
    put_f64(out, h.time_s);
    for v in [h.uav, h.rows, h.cols, boxes.len() as u32] {
        put_u32(out, v);
    }
    put_u64(out, h.served);
    for v in h.camera_position {
        put_f64(out, v);
    }
    for v in [h.camera_yaw, h.camera_tilt, h.camera_aperture] {
        put_f64(out, v);
    }
    for v in h.depth_noise {
        put_f64(out, v);
    }
    put_u64(out, h.checksum);
    for b in boxes {
        for v in [b.id, b.r0, b.c0, b.r1, b.c1] {
            put_u32(out, v);
        }
    }
    for d in &frame.depth[..n] {
        out.extend_from_slice(&d.to_le_bytes());
    }
    out.extend_from_slice(&frame.labels[..n]);
}

/// Reads a frame into `frame` (a zeroed frame, e.g. a loaned sample after
/// [`CvsFrame::init_in_place`]); on error `frame` may be partly written and must not be sent.
pub fn decode_frame_into(bytes: &[u8], frame: &mut CvsFrame) -> Result<(), EnvelopeError> {
    let mut r = Reader::versioned(bytes)?;
    r.need(FRAME_HEADER_BYTES)?;
    let run_tag = r.u64();
    let step = r.u64();
    let time_s = r.f64();
    let [uav, rows, cols, box_count] = [r.u32(), r.u32(), r.u32(), r.u32()];
    let served = r.u64();
    let n = rows as usize * cols as usize;
    if n > FRAME_MAX_PIXELS || box_count as usize > FRAME_MAX_BOXES {
        return Err(EnvelopeError::FrameSize {
            rows,
            cols,
            boxes: box_count,
        });
    }
    frame.header = FrameHeader {
        run_tag,
        step,
        time_s,
        uav,
        rows,
        cols,
        box_count,
        served,
        camera_position: [r.f64(), r.f64(), r.f64()],
        camera_yaw: r.f64(),
        camera_tilt: r.f64(),
        camera_aperture: r.f64(),
        depth_noise: [r.f64(), r.f64()],
        checksum: r.u64(),
    };
    r.need(box_count as usize * BOX_BYTES + n * 5)?;
    for b in frame.boxes.iter_mut().take(box_count as usize) {
        *b = TargetBox {
            id: r.u32(),
            r0: r.u32(),
            c0: r.u32(),
            r1: r.u32(),
            c1: r.u32(),
        };
    }
    let depth = r.take(n * 4);
    for (d, b) in frame.depth[..n].iter_mut().zip(depth.chunks_exact(4)) {
        *d = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    }
    frame.labels[..n].copy_from_slice(r.take(n));
    r.finish()
}

/// A command's bytes.
pub fn encode_command(cmd: &UavCommand) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 + COMMAND_BYTES);
    put_u32(&mut out, ENVELOPE_VERSION);
    put_u64(&mut out, cmd.run_tag);
    put_u64(&mut out, cmd.step);
    put_u32(&mut out, cmd.uav);
    put_u32(&mut out, cmd.has_yaw_ref);
    put_f64(&mut out, cmd.yaw_ref_rad);
    put_u64(&mut out, cmd.incarnation);
    out
}

/// Reads a command.
pub fn decode_command(bytes: &[u8]) -> Result<UavCommand, EnvelopeError> {
    let mut r = Reader::versioned(bytes)?;
    r.need(COMMAND_BYTES)?;
    let cmd = UavCommand {
        run_tag: r.u64(),
        step: r.u64(),
        uav: r.u32(),
        has_yaw_ref: r.u32(),
        yaw_ref_rad: r.f64(),
        incarnation: r.u64(),
    };
    r.finish()?;
    Ok(cmd)
}

/// A variable-size message's header and payload, into `out` (cleared first).
pub fn encode_wire(header: &WireHeader, payload: &[u8], out: &mut Vec<u8>) {
    out.clear();
    out.reserve(4 + WIRE_HEADER_BYTES + payload.len());
    put_u32(out, ENVELOPE_VERSION);
    put_u32(out, header.version);
    put_u32(out, header.kind);
    put_u64(out, header.run_tag);
    put_u32(out, header.sender);
    put_u32(out, header.len);
    put_u64(out, header.step);
    put_u64(out, header.sent_unix_ns);
    out.extend_from_slice(payload);
}

/// Reads a variable-size message: its header and its payload (borrowed from `bytes`).
pub fn decode_wire(bytes: &[u8]) -> Result<(WireHeader, &[u8]), EnvelopeError> {
    let mut r = Reader::versioned(bytes)?;
    r.need(WIRE_HEADER_BYTES)?;
    let header = WireHeader {
        version: r.u32(),
        kind: r.u32(),
        run_tag: r.u64(),
        sender: r.u32(),
        len: r.u32(),
        step: r.u64(),
        sent_unix_ns: r.u64(),
    };
    let payload = r.rest();
    if header.len as usize != payload.len() || payload.len() > MAX_WIRE_PAYLOAD {
        return Err(EnvelopeError::WireLength {
            said: header.len,
            got: payload.len(),
        });
    }
    Ok((header, payload))
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_f64(out: &mut Vec<u8>, v: f64) {
    out.extend_from_slice(&v.to_le_bytes());
}

/// Reads fields in order; [`Reader::need`] checks the length once for a run of fields, so the
/// field reads that follow cannot run out.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader past the envelope version, which must be [`ENVELOPE_VERSION`].
    fn versioned(bytes: &'a [u8]) -> Result<Self, EnvelopeError> {
        let mut r = Reader { bytes, pos: 0 };
        r.need(4)?;
        match r.u32() {
            ENVELOPE_VERSION => Ok(r),
            v => Err(EnvelopeError::Version(v)),
        }
    }

    fn need(&self, n: usize) -> Result<(), EnvelopeError> {
        let got = self.bytes.len() - self.pos;
        if got < n {
            Err(EnvelopeError::Truncated {
                needed: self.pos + n,
                got: self.bytes.len(),
            })
        } else {
            Ok(())
        }
    }

    fn take(&mut self, n: usize) -> &'a [u8] {
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        s
    }

    fn array<const N: usize>(&mut self) -> [u8; N] {
        let mut a = [0; N];
        a.copy_from_slice(self.take(N));
        a
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.array())
    }

    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.array())
    }

    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.array())
    }

    fn rest(&mut self) -> &'a [u8] {
        self.take(self.bytes.len() - self.pos)
    }

    fn finish(&self) -> Result<(), EnvelopeError> {
        match self.bytes.len() - self.pos {
            0 => Ok(()),
            n => Err(EnvelopeError::TrailingBytes(n)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::wire::WireKind;

    fn frame() -> Box<CvsFrame> {
        let mut f = CvsFrame::new_boxed();
        f.header.run_tag = 7;
        f.header.step = 12;
        f.header.time_s = 0.5;
        f.header.uav = 3;
        f.header.rows = 4;
        f.header.cols = 5;
        f.header.box_count = 1;
        // UAV 63's bit too: the mask crosses whole.
        f.header.served = 0b1011 | protocol::wire::uav_bit(63);
        f.header.camera_position = [1.0, -2.0, 80.0];
        f.header.camera_yaw = 0.25;
        f.header.depth_noise = [0.95, 1.05];
        f.boxes[0] = TargetBox {
            id: 2,
            r0: 1,
            c0: 1,
            r1: 3,
            c1: 4,
        };
        for i in 0..20 {
            f.depth[i] = i as f32 * 1.5;
            f.labels[i] = (i % 4) as u8;
        }
        f.depth[3] = f32::NAN;
        f.header.checksum = f.checksum();
        f
    }

    #[test]
    fn a_frame_crosses_with_every_field_and_pixel() {
        let sent = frame();
        let mut bytes = Vec::new();
        encode_frame(&sent, &mut bytes);
        assert_eq!(bytes.len(), 4 + FRAME_HEADER_BYTES + BOX_BYTES + 20 * 5);
        assert_eq!(FRAME_HEADER_BYTES, 120);
        let mut got = CvsFrame::new_boxed();
        decode_frame_into(&bytes, &mut got).unwrap();
        assert_eq!(got.header, sent.header);
        assert_eq!(got.boxes(), sent.boxes());
        assert_eq!(got.labels[..20], sent.labels[..20]);
        let bits = |f: &CvsFrame| {
            f.depth[..20]
                .iter()
                .map(|d| d.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&got), bits(&sent));
        assert_eq!(got.checksum(), sent.header.checksum);
    }

    #[test]
    fn bad_frames_are_refused() {
        let mut bytes = Vec::new();
        encode_frame(&frame(), &mut bytes);
        let mut got = CvsFrame::new_boxed();
        for cut in [0, 3, 4, 40, bytes.len() - 1] {
            assert!(matches!(
                decode_frame_into(&bytes[..cut], &mut got),
                Err(EnvelopeError::Truncated { .. })
            ));
        }
        let mut long = bytes.clone();
        long.push(0);
        assert_eq!(
            decode_frame_into(&long, &mut got),
            Err(EnvelopeError::TrailingBytes(1))
        );
        let mut huge = bytes.clone();
        // rows: after version, run tag, step, time and uav.
        huge[4 + 24 + 4..4 + 24 + 8].copy_from_slice(&100_000u32.to_le_bytes());
        assert!(matches!(
            decode_frame_into(&huge, &mut got),
            Err(EnvelopeError::FrameSize { .. })
        ));
        let mut other = bytes;
        other[0] = 9;
        assert_eq!(
            decode_frame_into(&other, &mut got),
            Err(EnvelopeError::Version(9))
        );
    }

    #[test]
    fn commands_and_wire_messages_cross_unchanged() {
        let cmd = UavCommand {
            run_tag: 1,
            step: 2,
            uav: 3,
            has_yaw_ref: 1,
            yaw_ref_rad: -0.5,
            incarnation: 99,
        };
        let bytes = encode_command(&cmd);
        assert_eq!(decode_command(&bytes), Ok(cmd));
        assert!(decode_command(&bytes[..bytes.len() - 1]).is_err());

        let payload = [1u8, 2, 3, 4, 5];
        let header = WireHeader::new(WireKind::Token, 5, 2, 40, 5, 1234);
        let mut bytes = Vec::new();
        encode_wire(&header, &payload, &mut bytes);
        let (h, p) = decode_wire(&bytes).unwrap();
        assert_eq!(h, header);
        assert_eq!(p, payload);
        assert!(matches!(
            decode_wire(&bytes[..bytes.len() - 1]),
            Err(EnvelopeError::WireLength { said: 5, got: 4 })
        ));
    }
}
