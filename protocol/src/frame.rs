//! The CVS frame: what the world-server renders for one UAV each period, in shared memory.
//!
//! The frame is a fixed-size `#[repr(C)]` plain-old-data struct (864 KB of pixels for the
//! default 360 x 480 camera) so that it can be rendered in place into a loaned iceoryx2 sample:
//! never build one on the stack; use [`CvsFrame::init_in_place`] on the loaned memory.

use std::mem::MaybeUninit;

use iceoryx2::prelude::ZeroCopySend;

use crate::camera::{Camera, CameraModel, CameraPose};
use crate::wire::UavMask;
use sets::math::Point3;

/// Pixels a frame can hold: the default camera, 360 x 480.
pub const FRAME_MAX_PIXELS: usize = 360 * 480;
/// Target boxes a frame can hold: every car a scenario may have
/// ([`crate::wire::TRUTH_MAX_TARGETS`]), so no car in view ever goes without its box.
pub const FRAME_MAX_BOXES: usize = 128;

/// The class the vision system gives a pixel.
#[repr(u8)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Label {
    /// Every ray of the pixel hits open ground.
    Ground = 0,
    /// Every ray of the pixel hits the same target.
    Target = 1,
    /// Every ray of the pixel hits the same obstacle.
    Obstacle = 2,
    /// Anything else: mixed, other UAVs, classifier doubt, invalid depth.
    Unknown = 3,
}

impl Label {
    /// Decodes a wire byte; anything unexpected is [`Label::Unknown`], the safe reading.
    pub fn from_u8(b: u8) -> Self {
        match b {
            0 => Label::Ground,
            1 => Label::Target,
            2 => Label::Obstacle,
            _ => Label::Unknown,
        }
    }
}

/// A bounding box around an identified target: pixels `r0..r1` x `c0..c1` (half-open).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("setfleet.TargetBox.v1")]
pub struct TargetBox {
    /// Target id.
    pub id: u32,
    /// First row.
    pub r0: u32,
    /// First column.
    pub c0: u32,
    /// One past the last row.
    pub r1: u32,
    /// One past the last column.
    pub c1: u32,
}

impl TargetBox {
    /// Whether the box is non-empty and lies inside a `rows x cols` image.
    pub fn is_valid(&self, rows: u32, cols: u32) -> bool {
        self.r0 < self.r1 && self.c0 < self.c1 && self.r1 <= rows && self.c1 <= cols
    }

    /// Whether pixel `(r, c)` lies in the box.
    pub fn contains(&self, r: u32, c: u32) -> bool {
        r >= self.r0 && r < self.r1 && c >= self.c0 && c < self.c1
    }
}

/// Everything about a frame but its pixels.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("setfleet.FrameHeader.v3")]
pub struct FrameHeader {
    /// Hash of the run id ([`crate::service::RunId::tag`]).
    pub run_tag: u64,
    /// Step index `k`.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// UAV index.
    pub uav: u32,
    /// Image rows.
    pub rows: u32,
    /// Image columns.
    pub cols: u32,
    /// Boxes in use.
    pub box_count: u32,
    /// The agents the world serves at this step: every one of them got this step's frame and
    /// is awaited. The same mask goes to every agent, so all agree on whose estimates and
    /// whose turn in the token ring to wait for. At offset 40, 8-aligned: the header has no
    /// padding.
    pub served: UavMask,
    /// Optical centre, world frame.
    pub camera_position: [f64; 3],
    /// Yaw of the optical axis.
    pub camera_yaw: f64,
    /// Tilt below the horizon.
    pub camera_tilt: f64,
    /// Horizontal aperture.
    pub camera_aperture: f64,
    /// Multiplicative depth noise bounds `[w_lo, w_hi]`.
    pub depth_noise: [f64; 2],
    /// Checksum of depth and labels ([`CvsFrame::checksum`]) as rendered.
    pub checksum: u64,
}

/// One camera frame: header, boxes, then depth and labels row-major (`r * cols + c`).
#[repr(C)]
#[derive(ZeroCopySend)]
#[type_name("setfleet.CvsFrame.v3")]
pub struct CvsFrame {
    /// Metadata.
    pub header: FrameHeader,
    /// Target boxes, `header.box_count` of them used.
    pub boxes: [TargetBox; FRAME_MAX_BOXES],
    /// Measured range of each pixel's centre ray, metres (NaN where nothing was measured).
    pub depth: [f32; FRAME_MAX_PIXELS],
    /// [`Label`] of each pixel as a byte.
    pub labels: [u8; FRAME_MAX_PIXELS],
}

impl CvsFrame {
    /// Zeroes a frame in place (all-zero is a valid empty frame) and returns it, so that large
    /// frames are never built on the stack. Use it on loaned shared memory or on
    /// [`CvsFrame::new_boxed`].
    pub fn init_in_place(slot: &mut MaybeUninit<CvsFrame>) -> &mut CvsFrame {
        // SAFETY: CvsFrame is #[repr(C)] plain old data (integers, floats, arrays of them) for
        // which the all-zero bit pattern is a valid value.
        unsafe {
            std::ptr::write_bytes(slot.as_mut_ptr(), 0, 1);
            slot.assume_init_mut()
        }
    }

    /// A zeroed frame on the heap.
    pub fn new_boxed() -> Box<CvsFrame> {
        let mut b = Box::<CvsFrame>::new_uninit();
        CvsFrame::init_in_place(&mut b);
        // SAFETY: init_in_place initialised every byte.
        unsafe { b.assume_init() }
    }

    /// Pixels in use.
    pub fn pixel_count(&self) -> usize {
        (self.header.rows as usize * self.header.cols as usize).min(FRAME_MAX_PIXELS)
    }

    /// Label of pixel `(r, c)`.
    pub fn label(&self, r: u32, c: u32) -> Label {
        Label::from_u8(self.labels[(r * self.header.cols + c) as usize])
    }

    /// Depth of pixel `(r, c)`.
    pub fn depth_at(&self, r: u32, c: u32) -> f32 {
        self.depth[(r * self.header.cols + c) as usize]
    }

    /// The boxes in use (at most [`FRAME_MAX_BOXES`]).
    pub fn boxes(&self) -> &[TargetBox] {
        &self.boxes[..(self.header.box_count as usize).min(FRAME_MAX_BOXES)]
    }

    /// The camera model the header describes.
    pub fn camera_model(&self) -> CameraModel {
        CameraModel {
            rows: self.header.rows,
            cols: self.header.cols,
            aperture_rad: self.header.camera_aperture,
            tilt_rad: self.header.camera_tilt,
        }
    }

    /// The posed camera the header describes.
    pub fn camera(&self) -> Camera {
        let [x, y, z] = self.header.camera_position;
        Camera::new(
            self.camera_model(),
            CameraPose {
                position: Point3::new(x, y, z),
                yaw: self.header.camera_yaw,
            },
        )
    }

    /// Checksum of the depth and label bytes in use: a fast 64-bit mix over 8-byte words,
    /// for detecting corruption in transit, not for security.
    pub fn checksum(&self) -> u64 {
        let n = self.pixel_count();
        // SAFETY: f32 has no padding; reading its bytes is always defined.
        let depth_bytes =
            unsafe { std::slice::from_raw_parts(self.depth.as_ptr().cast::<u8>(), n * 4) };
        let h = mix_bytes(0x9E37_79B9_7F4A_7C15, depth_bytes);
        mix_bytes(h, &self.labels[..n])
    }

    /// Whether the header and the counts are consistent and the image fits the frame.
    pub fn is_well_formed(&self) -> bool {
        let h = &self.header;
        h.rows > 0
            && h.cols > 0
            && (h.rows as usize * h.cols as usize) <= FRAME_MAX_PIXELS
            && (h.box_count as usize) <= FRAME_MAX_BOXES
            && h.camera_position.iter().all(|v| v.is_finite())
            && h.camera_yaw.is_finite()
            && h.camera_tilt.is_finite()
            && h.camera_aperture.is_finite()
            && h.camera_aperture > 0.0
            && h.camera_aperture < std::f64::consts::PI
            && h.depth_noise[0] > -1.0
            && h.depth_noise[0] <= h.depth_noise[1]
            && h.depth_noise[1].is_finite()
    }
}

/// Prints the header and the boxes in use, not the 864 KB of pixels (iceoryx2 requires
/// `Debug` of every payload type).
impl std::fmt::Debug for CvsFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CvsFrame")
            .field("header", &self.header)
            .field("boxes", &self.boxes())
            .finish_non_exhaustive()
    }
}

fn mix_bytes(mut h: u64, bytes: &[u8]) -> u64 {
    let mut chunks = bytes.chunks_exact(8);
    for c in &mut chunks {
        let mut w = [0u8; 8];
        w.copy_from_slice(c);
        h = (h ^ u64::from_le_bytes(w))
            .wrapping_mul(0x100_0000_01B3)
            .rotate_left(29);
    }
    for &b in chunks.remainder() {
        h = (h ^ b as u64).wrapping_mul(0x100_0000_01B3).rotate_left(29);
    }
    h ^ bytes.len() as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxed_frame_is_empty_and_checksum_sees_changes() {
        let mut f = CvsFrame::new_boxed();
        f.header.rows = 4;
        f.header.cols = 5;
        let c0 = f.checksum();
        f.labels[7] = Label::Target as u8;
        assert_ne!(c0, f.checksum());
        f.labels[7] = 0;
        f.depth[3] = 1.5;
        assert_ne!(c0, f.checksum());
    }

    #[test]
    fn frame_is_864_kb_of_pixels() {
        assert!(std::mem::size_of::<CvsFrame>() >= 864_000);
        assert!(std::mem::size_of::<CvsFrame>() < 870_000);
    }

    #[test]
    fn the_header_is_packed_with_its_mask_aligned() {
        use std::mem::{align_of, offset_of, size_of};
        // Every field at its natural alignment and no hole between them: the sum of the
        // fields' sizes is the header's.
        assert_eq!(offset_of!(FrameHeader, served), 40);
        assert_eq!(offset_of!(FrameHeader, served) % align_of::<UavMask>(), 0);
        assert_eq!(offset_of!(FrameHeader, camera_position), 48);
        assert_eq!(
            size_of::<FrameHeader>(),
            3 * 8 + 4 * 4 + 8 + 3 * 8 + 3 * 8 + 2 * 8 + 8
        );
        assert_eq!(offset_of!(CvsFrame, boxes), size_of::<FrameHeader>());
        assert_eq!(offset_of!(CvsFrame, depth) % align_of::<f32>(), 0);
    }

    #[test]
    fn unknown_label_bytes_read_as_unknown() {
        assert_eq!(Label::from_u8(200), Label::Unknown);
    }
}
