//! The external planner's messages: what an agent asks a planner of its own process (Python,
//! say) and the answer it takes (`docs/python.md` is the reference, with the same tables).
//!
//! Both are raw little-endian bytes a numpy reader takes as views without copying:
//!
//! - the **request** is a fixed [`REQUEST_HEADER_BYTES`]-byte header ([`RequestHeader`])
//!   followed by the arrays of [`ArrayId`], each at a multiple of 8 bytes, whose offsets and
//!   lengths the header's array table gives. [`RequestShape`] lays them out and
//!   [`RequestWriter`] writes a request in place, into the loaned shared-memory sample;
//! - the **answer** is an [`ANSWER_HEADER_BYTES`]-byte header followed by the yaw increments
//!   and the planned views. [`Answer::decode`] checks every field and refuses a malformed
//!   answer with an [`AnswerError`] that names what is wrong; it never panics, whatever the
//!   bytes.
//!
//! [`layout`] holds the layout as data (every field's name, offset and type), which the
//! writers and the reader here follow and against which the tests check `docs/python.md` and
//! `python/setfleet/layout.py`.

pub mod layout;

use std::f64::consts::PI;

use layout::{ANSWER_FIELDS, HeaderWriter, OTHER_ROW_FIELDS, REQUEST_ARRAYS, REQUEST_FIELDS};
use layout::{TARGET_ROW_FIELDS, offset_of, row_bytes};

/// First four bytes of a request, `SFPQ`.
pub const REQUEST_MAGIC: u32 = u32::from_le_bytes(*b"SFPQ");
/// First four bytes of an answer, `SFPA`.
pub const ANSWER_MAGIC: u32 = u32::from_le_bytes(*b"SFPA");
/// The layout's version, in both messages.
pub const LAYOUT_VERSION: u16 = 1;
/// Size of the request's header.
pub const REQUEST_HEADER_BYTES: usize = 512;
/// Size of the answer's header.
pub const ANSWER_HEADER_BYTES: usize = 48;
/// Most yaw increments an answer may hold.
pub const MAX_ANSWER_INCREMENTS: u32 = 64;
/// Most planned views an answer may hold (they travel on in the token to every later UAV).
pub const MAX_ANSWER_POSES: u32 = 256;
/// Byte offset of the array table in the request header.
const ARRAY_TABLE_OFFSET: usize = offset_of(REQUEST_FIELDS, "arrays");
/// Bytes of one row of the targets table ([`layout::TARGET_ROW_FIELDS`]).
pub const TARGET_ROW_BYTES: usize = row_bytes(TARGET_ROW_FIELDS);
/// Bytes of one row of the others table ([`layout::OTHER_ROW_FIELDS`]).
pub const OTHER_ROW_BYTES: usize = row_bytes(OTHER_ROW_FIELDS);
/// Bytes of one pose (`x, y, z, yaw`).
pub const POSE_BYTES: usize = 32;

/// Bit of [`RequestHeader::flags`]: the request was sent at the start of the round, before
/// the token came (`guidance.external_request = "round_start"`): it holds no plans ahead.
pub const FLAG_ROUND_START: u32 = 1;

/// The arrays of a request, in their order after the header ([`layout::REQUEST_ARRAYS`] gives
/// their names and element types).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub enum ArrayId {
    /// The yaw increments `U`, `f64`.
    Increments = 0,
    /// `X̄` counted per planning cell, `u16`, `(plan_ny, plan_nx)`.
    Undetected,
    /// `S^o` counted per planning cell, `u16`.
    ObstacleNeighbourhood,
    /// `H̄` counted per planning cell, `u16`.
    Unseen,
    /// Recently hidden ground counted per planning cell, `u16`.
    RecentlyHidden,
    /// One 32-byte row per identified car: `id, x0, y0, w, h, first` (`u32`), `area_m2` (`f64`).
    Targets,
    /// The cars' counts over their boxes, `u16`.
    TargetCounts,
    /// The OEM's heights, `f32`, `(oem_ny, oem_nx)`.
    OemHeight,
    /// The OEM's status codes, `u8`.
    OemStatus,
    /// One 16-byte row per plan ahead in the token: `uav, n_poses, first, 0` (`u32`).
    Others,
    /// The plans' poses, `f64 x 4` each.
    Poses,
    /// The round's fleet in token order, `u32`.
    Fleet,
}

/// Arrays in a request.
pub const ARRAYS: usize = 12;

/// The scalar fields of a request ([`layout::REQUEST_FIELDS`] gives their offsets).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RequestHeader {
    /// The run's tag.
    pub run_tag: u64,
    /// The deciding step.
    pub step: u64,
    /// The guidance round.
    pub round: u64,
    /// Steps of the run.
    pub total_steps: u64,
    /// The asking UAV.
    pub uav: u32,
    /// `uavs.count`.
    pub fleet_size: u32,
    /// CVS steps per guidance period.
    pub steps_per_period: u32,
    /// The MPC's horizon, periods.
    pub horizon: u32,
    /// `timing.external_planner_ms`.
    pub deadline_ms: u32,
    /// [`FLAG_ROUND_START`] or 0.
    pub flags: u32,
    /// Simulated time of the step, s.
    pub time_s: f64,
    /// CVS period, s.
    pub dt_s: f64,
    /// Ground speed, m/s.
    pub speed_mps: f64,
    /// Yaw-rate bound, rad/s.
    pub max_yaw_rate_rps: f64,
    /// The camera's optical centre and yaw: `x, y, z` (m), `yaw` (rad).
    pub pose: [f64; 4],
    /// Horizontal aperture, rad.
    pub camera_aperture_rad: f64,
    /// Tilt below the horizon, rad.
    pub camera_tilt_rad: f64,
    /// Image rows and columns.
    pub camera_size: [u32; 2],
    /// South-west corner of planning cell (0, 0), m.
    pub plan_origin: [f64; 2],
    /// Planning cell side, m.
    pub plan_cell_m: f64,
    /// Planning cells along x and y.
    pub plan_size: [u32; 2],
    /// Area of one estimator cell, m².
    pub count_cell_m2: f64,
    /// South-west corner of OEM cell (0, 0), m.
    pub oem_origin: [f64; 2],
    /// OEM cell side, m.
    pub oem_cell_m: f64,
    /// OEM cells along x and y.
    pub oem_size: [u32; 2],
    /// Half side of the square plans stay in, m.
    pub border_half_m: f64,
    /// Area of `X̄`, m².
    pub undetected_m2: f64,
    /// Summed area of the cars' sets, m².
    pub targets_m2: f64,
}

/// How many elements each array of a request holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RequestShape {
    /// Yaw increments.
    pub increments: usize,
    /// Planning cells (`plan_nx * plan_ny`).
    pub plan_cells: usize,
    /// Identified cars.
    pub targets: usize,
    /// Cells of all the cars' boxes.
    pub target_counts: usize,
    /// OEM cells.
    pub oem_cells: usize,
    /// Plans ahead.
    pub others: usize,
    /// Their poses.
    pub poses: usize,
    /// UAVs of the round.
    pub fleet: usize,
}

impl RequestShape {
    /// Bytes of each array, in [`ArrayId`] order: its elements times an element's bytes.
    fn lengths(&self) -> [usize; ARRAYS] {
        let elements = [
            self.increments,
            self.plan_cells,
            self.plan_cells,
            self.plan_cells,
            self.plan_cells,
            self.targets,
            self.target_counts,
            self.oem_cells,
            self.oem_cells,
            self.others,
            // A pose is 4 numbers.
            4 * self.poses,
            self.fleet,
        ];
        std::array::from_fn(|i| elements[i] * REQUEST_ARRAYS[i].element.bytes())
    }

    /// Where each array starts and how long it is, and the size of the whole request: the
    /// arrays follow the header in order, each at the next multiple of 8 bytes.
    pub fn layout(&self) -> ([(usize, usize); ARRAYS], usize) {
        let mut table = [(0, 0); ARRAYS];
        let mut at = REQUEST_HEADER_BYTES;
        for (slot, len) in table.iter_mut().zip(self.lengths()) {
            *slot = (at, len);
            at = (at + len).next_multiple_of(8);
        }
        (table, at)
    }
}

/// Writes one request into a buffer of the size [`RequestShape::layout`] gives (the loaned
/// sample), the header first and then each array.
pub struct RequestWriter<'a> {
    buf: &'a mut [u8],
    table: [(usize, usize); ARRAYS],
}

impl<'a> RequestWriter<'a> {
    /// A writer over `buf` for a request of `shape`: zeroes it and writes the header, whose
    /// counts come from `shape`.
    ///
    /// # Panics
    /// If `buf` is not exactly the size the layout gives (a caller's bug).
    pub fn new(buf: &'a mut [u8], header: &RequestHeader, shape: &RequestShape) -> Self {
        let (table, total) = shape.layout();
        assert_eq!(buf.len(), total, "request buffer of the wrong size");
        buf.fill(0);
        let mut w = HeaderWriter::new(&mut *buf, REQUEST_FIELDS);
        w.put("magic", REQUEST_MAGIC);
        w.put("version", LAYOUT_VERSION);
        w.put("header_bytes", REQUEST_HEADER_BYTES as u16);
        w.put("run_tag", header.run_tag);
        w.put("step", header.step);
        w.put("round", header.round);
        w.put("total_steps", header.total_steps);
        w.put("uav", header.uav);
        w.put("fleet_size", header.fleet_size);
        w.put("steps_per_period", header.steps_per_period);
        w.put("horizon", header.horizon);
        w.put("deadline_ms", header.deadline_ms);
        w.put("flags", header.flags);
        w.put("time_s", header.time_s);
        w.put("dt_s", header.dt_s);
        w.put("speed_mps", header.speed_mps);
        w.put("max_yaw_rate_rps", header.max_yaw_rate_rps);
        w.put_all(&["x", "y", "z", "yaw"], &header.pose);
        w.put("camera_aperture_rad", header.camera_aperture_rad);
        w.put("camera_tilt_rad", header.camera_tilt_rad);
        w.put_all(&["camera_rows", "camera_cols"], &header.camera_size);
        w.put_all(&["plan_origin_x", "plan_origin_y"], &header.plan_origin);
        w.put("plan_cell_m", header.plan_cell_m);
        w.put_all(&["plan_nx", "plan_ny"], &header.plan_size);
        w.put("count_cell_m2", header.count_cell_m2);
        w.put_all(&["oem_origin_x", "oem_origin_y"], &header.oem_origin);
        w.put("oem_cell_m", header.oem_cell_m);
        w.put_all(&["oem_nx", "oem_ny"], &header.oem_size);
        w.put("border_half_m", header.border_half_m);
        w.put("undetected_m2", header.undetected_m2);
        w.put("targets_m2", header.targets_m2);
        w.put("n_increments", shape.increments as u32);
        w.put("n_targets", shape.targets as u32);
        w.put("n_others", shape.others as u32);
        w.put("n_poses", shape.poses as u32);
        w.put("n_fleet", shape.fleet as u32);
        w.put("n_target_counts", shape.target_counts as u32);
        w.array_table(&table);
        w.finish();
        Self { buf, table }
    }

    /// The bytes of array `id`, to fill (zeroed).
    pub fn array(&mut self, id: ArrayId) -> &mut [u8] {
        let (offset, len) = self.table[id as usize];
        &mut self.buf[offset..offset + len]
    }

    /// Fills array `id` with `values`, each as `N` little-endian bytes, by `put`; values
    /// beyond the array are ignored and missing ones stay 0.
    pub fn fill<T, const N: usize>(
        &mut self,
        id: ArrayId,
        values: impl IntoIterator<Item = T>,
        put: impl Fn(T) -> [u8; N],
    ) {
        for (chunk, v) in self.array(id).chunks_exact_mut(N).zip(values) {
            chunk.copy_from_slice(&put(v));
        }
    }
}

/// Reads a request's array table back (for tests and tools): the offset and length of each
/// array, checked against the buffer.
pub fn request_arrays(buf: &[u8]) -> Option<[(usize, usize); ARRAYS]> {
    if buf.len() < REQUEST_HEADER_BYTES || le_u32(buf, 0)? != REQUEST_MAGIC {
        return None;
    }
    let mut table = [(0, 0); ARRAYS];
    for (i, slot) in table.iter_mut().enumerate() {
        let at = ARRAY_TABLE_OFFSET + 16 * i;
        let offset = usize::try_from(le_u64(buf, at)?).ok()?;
        let len = usize::try_from(le_u64(buf, at + 8)?).ok()?;
        (offset.checked_add(len)? <= buf.len()).then_some(())?;
        *slot = (offset, len);
    }
    Some(table)
}

/// What the answer gives.
#[derive(Clone, Debug, PartialEq)]
pub enum Steer {
    /// Yaw increments, one per guidance period; the first is applied now.
    Increments(Vec<f64>),
    /// A yaw reference, rad (and increments the planner may add for its own record).
    YawRef(f64),
    /// No decision of the planner's: the UAV's own planner decides, at once and without
    /// counting a fallback. A planner that only means to step in now and then answers this
    /// the rest of the time (increments it sends are ignored, its poses too).
    Defer,
}

/// A planner's answer, checked.
#[derive(Clone, Debug, PartialEq)]
pub struct Answer {
    /// What to steer by.
    pub steer: Steer,
    /// The planned views to pass on in the token (`x, y, z, yaw`), possibly none.
    pub poses: Vec<[f64; 4]>,
    /// The planner's own time on the decision, ns (0: not said).
    pub planner_ns: u64,
}

/// Why an answer was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum AnswerError {
    /// Shorter than the header.
    #[error("{0} bytes: shorter than the {ANSWER_HEADER_BYTES}-byte header")]
    TooShort(usize),
    /// Not an answer.
    #[error("magic {0:#010x}, not an answer's {ANSWER_MAGIC:#010x}")]
    Magic(u32),
    /// Another layout version.
    #[error("layout version {0}, this agent reads version {LAYOUT_VERSION}")]
    Version(u16),
    /// An unknown kind.
    #[error("kind {0}: 0 (increments), 1 (yaw reference) or 2 (defer)")]
    Kind(u16),
    /// The answer to another request.
    #[error("answers step {got} of UAV {got_uav}, the request was step {step} of UAV {uav}")]
    Other {
        /// Its step.
        got: u64,
        /// Its UAV.
        got_uav: u32,
        /// The request's step.
        step: u64,
        /// The request's UAV.
        uav: u32,
    },
    /// Counts out of range.
    #[error(
        "{increments} increments and {poses} poses: at most {MAX_ANSWER_INCREMENTS} and \
         {MAX_ANSWER_POSES}, and at least one increment for kind 0"
    )]
    Counts {
        /// Its increments.
        increments: u32,
        /// Its poses.
        poses: u32,
    },
    /// A length other than its counts give.
    #[error("{got} bytes where its counts give {expected}")]
    Length {
        /// Its length.
        got: usize,
        /// What the counts give.
        expected: usize,
    },
    /// A number that cannot steer a UAV.
    #[error("{what} {value} is not finite or out of range")]
    Value {
        /// Which field.
        what: &'static str,
        /// Its value.
        value: f64,
    },
}

/// Offsets of the answer's fields ([`layout::ANSWER_FIELDS`]).
mod answer_at {
    use super::{ANSWER_FIELDS, offset_of};

    pub(super) const MAGIC: usize = offset_of(ANSWER_FIELDS, "magic");
    pub(super) const VERSION: usize = offset_of(ANSWER_FIELDS, "version");
    pub(super) const KIND: usize = offset_of(ANSWER_FIELDS, "kind");
    pub(super) const STEP: usize = offset_of(ANSWER_FIELDS, "step");
    pub(super) const UAV: usize = offset_of(ANSWER_FIELDS, "uav");
    pub(super) const N_INCREMENTS: usize = offset_of(ANSWER_FIELDS, "n_increments");
    pub(super) const N_POSES: usize = offset_of(ANSWER_FIELDS, "n_poses");
    pub(super) const YAW_REF: usize = offset_of(ANSWER_FIELDS, "yaw_ref");
    pub(super) const PLANNER_NS: usize = offset_of(ANSWER_FIELDS, "planner_ns");
}

impl Answer {
    /// Reads the answer to the request of `step` by `uav`, checking every field.
    pub fn decode(buf: &[u8], step: u64, uav: u32) -> Result<Answer, AnswerError> {
        let field = |at: usize| le_u64(buf, at).unwrap_or(0);
        if buf.len() < ANSWER_HEADER_BYTES {
            return Err(AnswerError::TooShort(buf.len()));
        }
        let word = |at: usize| le_u32(buf, at).unwrap_or(0);
        let half = |at: usize| u16::from_le_bytes([buf[at], buf[at + 1]]);
        if word(answer_at::MAGIC) != ANSWER_MAGIC {
            return Err(AnswerError::Magic(word(answer_at::MAGIC)));
        }
        if half(answer_at::VERSION) != LAYOUT_VERSION {
            return Err(AnswerError::Version(half(answer_at::VERSION)));
        }
        let kind = half(answer_at::KIND);
        if kind > 2 {
            return Err(AnswerError::Kind(kind));
        }
        let (got, got_uav) = (field(answer_at::STEP), word(answer_at::UAV));
        if (got, got_uav) != (step, uav) {
            return Err(AnswerError::Other {
                got,
                got_uav,
                step,
                uav,
            });
        }
        let (increments, poses) = (word(answer_at::N_INCREMENTS), word(answer_at::N_POSES));
        if increments > MAX_ANSWER_INCREMENTS
            || poses > MAX_ANSWER_POSES
            || (kind == 0 && increments == 0)
        {
            return Err(AnswerError::Counts { increments, poses });
        }
        let expected = ANSWER_HEADER_BYTES + 8 * increments as usize + POSE_BYTES * poses as usize;
        if buf.len() != expected {
            return Err(AnswerError::Length {
                got: buf.len(),
                expected,
            });
        }
        let float = |at: usize| f64::from_bits(field(at));
        let check = |what, value: f64, ok: bool| {
            if value.is_finite() && ok {
                Ok(value)
            } else {
                Err(AnswerError::Value { what, value })
            }
        };
        let incs = (0..increments as usize)
            .map(|i| {
                let u = float(ANSWER_HEADER_BYTES + 8 * i);
                check("increment", u, (-PI..=PI).contains(&u))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        let base = ANSWER_HEADER_BYTES + 8 * increments as usize;
        let poses = (0..poses as usize)
            .map(|i| {
                let mut p = [0.0; 4];
                for (k, v) in p.iter_mut().enumerate() {
                    *v = check("pose", float(base + POSE_BYTES * i + 8 * k), true)?;
                }
                Ok(p)
            })
            .collect::<Result<Vec<_>, AnswerError>>()?;
        let steer = match kind {
            0 => Steer::Increments(incs),
            1 => Steer::YawRef(check("yaw_ref", float(answer_at::YAW_REF), true)?),
            _ => Steer::Defer,
        };
        Ok(Answer {
            steer,
            poses,
            planner_ns: field(answer_at::PLANNER_NS),
        })
    }

    /// The answer's bytes for the request of `step` by `uav` (what a planner writes; the
    /// tests and the bench use it).
    pub fn encode(&self, step: u64, uav: u32) -> Vec<u8> {
        let (kind, yaw_ref, incs): (u16, f64, &[f64]) = match &self.steer {
            Steer::Increments(v) => (0, 0.0, v),
            Steer::YawRef(y) => (1, *y, &[]),
            Steer::Defer => (2, 0.0, &[]),
        };
        let mut out = vec![0; ANSWER_HEADER_BYTES];
        out.reserve(8 * incs.len() + POSE_BYTES * self.poses.len());
        let mut w = HeaderWriter::new(&mut out, ANSWER_FIELDS);
        w.put("magic", ANSWER_MAGIC);
        w.put("version", LAYOUT_VERSION);
        w.put("kind", kind);
        w.put("step", step);
        w.put("uav", uav);
        w.put("n_increments", incs.len() as u32);
        w.put("n_poses", self.poses.len() as u32);
        w.put("reserved", 0u32);
        w.put("yaw_ref", yaw_ref);
        w.put("planner_ns", self.planner_ns);
        w.finish();
        incs.iter().for_each(|u| out.extend(u.to_le_bytes()));
        self.poses
            .iter()
            .flatten()
            .for_each(|v| out.extend(v.to_le_bytes()));
        out
    }
}

fn le_u32(buf: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(buf.get(at..at + 4)?.try_into().ok()?))
}

fn le_u64(buf: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(buf.get(at..at + 8)?.try_into().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_header_fills_its_table_and_the_arrays_start_at_multiples_of_8() {
        let shape = RequestShape {
            increments: 5,
            plan_cells: 7,
            targets: 2,
            target_counts: 3,
            oem_cells: 5,
            others: 1,
            poses: 12,
            fleet: 3,
        };
        let (table, total) = shape.layout();
        let mut buf = vec![0xAA; total];
        let header = RequestHeader {
            step: 6,
            uav: 2,
            targets_m2: 12.5,
            ..RequestHeader::default()
        };
        let mut w = RequestWriter::new(&mut buf, &header, &shape);
        w.fill(ArrayId::Fleet, [2u32, 0, 1], u32::to_le_bytes);
        assert_eq!(request_arrays(&buf), Some(table));
        assert_eq!(le_u32(&buf, 0), Some(REQUEST_MAGIC));
        assert_eq!(le_u64(&buf, 16), Some(6));
        assert_eq!(le_u32(&buf, 40), Some(2));
        assert_eq!(f64::from_bits(le_u64(&buf, 240).unwrap()), 12.5);
        assert_eq!(le_u32(&buf, 248), Some(5));
        assert_eq!(le_u32(&buf, 268), Some(3));
        for (offset, _) in table {
            assert_eq!(offset % 8, 0);
        }
        let (fleet, _) = table[ArrayId::Fleet as usize];
        assert_eq!(le_u32(&buf, fleet), Some(2));
        assert_eq!(le_u32(&buf, fleet + 4), Some(0));
        assert!(buf[464..512].iter().all(|&b| b == 0));
    }

    #[test]
    fn answers_round_trip_and_bad_ones_name_what_is_wrong() {
        let good = Answer {
            steer: Steer::Increments(vec![0.5, -0.25]),
            poses: vec![[1.0, 2.0, 60.0, 0.1]],
            planner_ns: 1234,
        };
        let bytes = good.encode(9, 1);
        assert_eq!(Answer::decode(&bytes, 9, 1), Ok(good.clone()));
        let yaw = Answer {
            steer: Steer::YawRef(2.0),
            poses: vec![],
            planner_ns: 0,
        };
        assert_eq!(Answer::decode(&yaw.encode(3, 0), 3, 0), Ok(yaw));
        let defer = Answer {
            steer: Steer::Defer,
            poses: vec![],
            planner_ns: 7,
        };
        assert_eq!(Answer::decode(&defer.encode(4, 2), 4, 2), Ok(defer));
        let mut unknown = bytes.clone();
        unknown[6..8].copy_from_slice(&3u16.to_le_bytes());
        assert_eq!(Answer::decode(&unknown, 9, 1), Err(AnswerError::Kind(3)));
        assert!(matches!(
            Answer::decode(&bytes, 12, 1),
            Err(AnswerError::Other { got: 9, .. })
        ));
        assert!(matches!(
            Answer::decode(&bytes[..60], 9, 1),
            Err(AnswerError::Length { .. })
        ));
        assert_eq!(
            Answer::decode(&[0; 10], 9, 1),
            Err(AnswerError::TooShort(10))
        );
        let mut nan = bytes.clone();
        nan[48..56].copy_from_slice(&f64::NAN.to_le_bytes());
        assert!(matches!(
            Answer::decode(&nan, 9, 1),
            Err(AnswerError::Value {
                what: "increment",
                ..
            })
        ));
        let wide = Answer {
            steer: Steer::Increments(vec![4.0]),
            ..good.clone()
        };
        assert!(Answer::decode(&wide.encode(9, 1), 9, 1).is_err());
        let none = Answer {
            steer: Steer::Increments(vec![]),
            ..good
        };
        assert!(matches!(
            Answer::decode(&none.encode(9, 1), 9, 1),
            Err(AnswerError::Counts { increments: 0, .. })
        ));
    }

    proptest! {
        /// Whatever bytes come back, decoding returns an answer or an error, never panics;
        /// an accepted answer steers by finite numbers.
        #[test]
        fn any_bytes_decode_or_are_refused(bytes in proptest::collection::vec(any::<u8>(), 0..400),
                                           keep_header in any::<bool>()) {
            let mut bytes = bytes;
            if keep_header && bytes.len() >= ANSWER_HEADER_BYTES {
                bytes[..4].copy_from_slice(&ANSWER_MAGIC.to_le_bytes());
                bytes[4..6].copy_from_slice(&LAYOUT_VERSION.to_le_bytes());
            }
            if let Ok(a) = Answer::decode(&bytes, 0, 0) {
                match a.steer {
                    Steer::Increments(v) => prop_assert!(v.iter().all(|u| u.is_finite())),
                    Steer::YawRef(y) => prop_assert!(y.is_finite()),
                    Steer::Defer => {}
                }
            }
        }
    }
}
