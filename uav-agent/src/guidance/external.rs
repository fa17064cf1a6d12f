//! Decisions by an external planner: a process of the user's (Python, say) that answers an
//! agent's requests on `{run}/uav/{i}/plan` (docs/python.md, [`protocol::plan`]).
//!
//! [`Request`] gathers what a decision looks at (the agent's fused sets counted per planning
//! cell, the map, the plans ahead) and writes it in place into the loaned request sample.
//! [`ExternalPlanner`] sends it, and [`ExternalPlanner::poll`] reads the answer or says why
//! there is none ([`Fallback`]). The agent's loop does the waiting, bounded by
//! `timing.external_planner_ms`, and decides with its own planner whenever no valid answer
//! comes: only decisions change, so the guarantee does not depend on the planner.

use std::time::Instant;

use fleet_process::stats::Stats;
use iceoryx2::pending_response::PendingResponse;
use iceoryx2::port::client::Client;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::service::port_factory::PortFactory as _;
use protocol::camera::CameraPose;
use protocol::ipc::{EventService, Ipc, IpcOpenError, PlanService, RunNode};
use protocol::plan::Steer;
use protocol::plan::{
    Answer, ArrayId, OTHER_ROW_BYTES, RequestHeader, RequestShape, RequestWriter, TARGET_ROW_BYTES,
};
use protocol::scenario::Scenario;
use protocol::wire::PlannedView;
use serde::Serialize;
use sets::raster::{CellBox, CellSet};

use crate::guidance::{self, CoarseGrid, Cost, Decision, GuidanceParams, PlanningInput};
use estimator::EstimatorState;

/// Initial size of a request sample; it grows (powers of two) for a larger request.
const REQUEST_INITIAL_BYTES: usize = 256 * 1024;

/// Why the fallback planner took a decision.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Fallback {
    /// No answer within the deadline.
    Late,
    /// The answer was refused.
    Malformed,
    /// No planner serves this UAV (none came, or it died).
    Absent,
}

impl Fallback {
    /// The reason's name in logs and reports.
    pub fn name(self) -> &'static str {
        match self {
            Fallback::Late => "late",
            Fallback::Malformed => "malformed",
            Fallback::Absent => "absent",
        }
    }
}

/// Everything a request carries, borrowed from the agent.
pub struct Request<'a> {
    /// The scalar fields; the counts are filled in from the arrays.
    pub header: RequestHeader,
    /// The planning grid.
    pub grids: &'a CoarseGrid,
    /// The yaw increments `U`.
    pub increments: &'a [f64],
    /// The agent's state (sets, map).
    pub state: &'a EstimatorState,
    /// Recently hidden ground.
    pub recently_hidden: &'a CellSet,
    /// The plans ahead in the token.
    pub others: &'a [PlannedView],
    /// The round's fleet, in token order.
    pub fleet: &'a [u32],
}

impl Request<'_> {
    /// The header's fields that come from the run's settings and the agent's state (whose
    /// camera is at `pose`).
    pub fn header(
        params: &GuidanceParams,
        state: &EstimatorState,
        pose: &CameraPose,
    ) -> RequestHeader {
        let plan = &params.grids.coarse;
        let oem = state.oem.grid();
        let targets_m2 = state
            .targets
            .values()
            .map(|s| s.cells().area(&params.grids.fine))
            .sum();
        RequestHeader {
            step: state.step,
            steps_per_period: params.steps_per_period,
            horizon: params.horizon,
            time_s: state.time_s,
            dt_s: params.dt,
            speed_mps: params.speed,
            max_yaw_rate_rps: params.max_yaw_rate,
            pose: [pose.position.x, pose.position.y, pose.position.z, pose.yaw],
            camera_aperture_rad: params.camera.aperture_rad,
            camera_tilt_rad: params.camera.tilt_rad,
            camera_size: [params.camera.rows, params.camera.cols],
            plan_origin: [plan.origin.x, plan.origin.y],
            plan_cell_m: plan.cell_m,
            plan_size: [plan.nx, plan.ny],
            count_cell_m2: params.grids.fine.cell_area(),
            oem_origin: [oem.origin.x, oem.origin.y],
            oem_cell_m: oem.cell_m,
            oem_size: [oem.nx, oem.ny],
            border_half_m: params.region.max.x,
            undetected_m2: state.undetected.cells().area(&params.grids.fine),
            targets_m2,
            ..RequestHeader::default()
        }
    }

    /// The whole header of the request UAV `uav` of the run tagged `run_tag` (of `scenario`)
    /// sends at step `k` of `round` with `flags`, its state `state` (the origin when it has no
    /// pose yet).
    #[allow(clippy::too_many_arguments)]
    pub fn header_at(
        scenario: &Scenario,
        params: &GuidanceParams,
        state: &EstimatorState,
        run_tag: u64,
        uav: u32,
        round: u64,
        k: u64,
        flags: u32,
    ) -> RequestHeader {
        let pose = state.pose.unwrap_or(CameraPose {
            position: sets::math::Point3::origin(),
            yaw: 0.0,
        });
        RequestHeader {
            run_tag,
            step: k,
            round,
            total_steps: scenario.steps(),
            uav,
            fleet_size: scenario.uavs.count,
            deadline_ms: scenario.timing.external_planner_ms,
            flags,
            ..Request::header(params, state, &pose)
        }
    }

    /// The request's bytes, as an agent sends them (for a planner in the agent's process).
    pub fn to_bytes(&self) -> Vec<u8> {
        let boxes = self.target_boxes();
        let shape = self.shape(&boxes);
        let (_, total) = shape.layout();
        let mut buf = vec![0u8; total];
        self.write(&mut buf, &shape, &boxes);
        buf
    }

    /// Each identified car's box on the planning grid.
    fn target_boxes(&self) -> Vec<(u32, CellBox)> {
        let f = self.grids.factor;
        self.state
            .targets
            .iter()
            .filter_map(|(&id, set)| {
                let b = set.cells().bounding_box()?;
                Some((
                    id,
                    CellBox {
                        x0: b.x0 / f,
                        y0: b.y0 / f,
                        x1: b.x1 / f,
                        y1: b.y1 / f,
                    },
                ))
            })
            .collect()
    }

    /// How many elements each array holds.
    pub fn shape(&self, boxes: &[(u32, CellBox)]) -> RequestShape {
        let plan = &self.grids.coarse;
        let oem = self.state.oem.grid();
        RequestShape {
            increments: self.increments.len(),
            plan_cells: plan.cell_count(),
            targets: boxes.len(),
            target_counts: boxes.iter().map(|(_, b)| b.cell_count() as usize).sum(),
            oem_cells: oem.cell_count(),
            others: self.others.len(),
            poses: self.others.iter().map(|o| o.poses.len()).sum(),
            fleet: self.fleet.len(),
        }
    }

    /// The request's bytes written into `buf`, which holds exactly the size of `shape`.
    fn write(&self, buf: &mut [u8], shape: &RequestShape, boxes: &[(u32, CellBox)]) {
        let mut w = RequestWriter::new(buf, &self.header, shape);
        w.fill(
            ArrayId::Increments,
            self.increments.iter().copied(),
            f64::to_le_bytes,
        );
        let plan = &self.grids.coarse;
        let whole = CellBox {
            x0: 0,
            y0: 0,
            x1: plan.nx - 1,
            y1: plan.ny - 1,
        };
        let state = self.state;
        for (id, set) in [
            (ArrayId::Undetected, state.undetected.cells()),
            (
                ArrayId::ObstacleNeighbourhood,
                &state.obstacle_neighbourhood,
            ),
            (ArrayId::Unseen, state.hidden_history.unseen()),
            (ArrayId::RecentlyHidden, self.recently_hidden),
        ] {
            counts_into(self.grids, set, &whole, w.array(id));
        }
        let mut first = 0u32;
        let mut rows = Vec::with_capacity(boxes.len());
        let counts = w.array(ArrayId::TargetCounts);
        let mut at = 0;
        for (id, b) in boxes {
            let cells = b.cell_count() as usize;
            let set = state.targets[id].cells();
            counts_into(self.grids, set, b, &mut counts[at..at + 2 * cells]);
            at += 2 * cells;
            let area = set.area(&self.grids.fine);
            rows.push((*id, *b, first, area));
            first += cells as u32;
        }
        w.fill(ArrayId::Targets, rows, |(id, b, first, area)| {
            let mut row = [0u8; TARGET_ROW_BYTES];
            let words = [id, b.x0, b.y0, b.x1 - b.x0 + 1, b.y1 - b.y0 + 1, first];
            for (k, v) in words.into_iter().enumerate() {
                row[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
            }
            row[24..].copy_from_slice(&area.to_le_bytes());
            row
        });
        let oem = state.oem.grid();
        let nx = oem.nx as usize;
        let heights = w.array(ArrayId::OemHeight);
        for ((ix, iy), cell) in state.oem.known_cells() {
            let at = 4 * (iy as usize * nx + ix as usize);
            heights[at..at + 4].copy_from_slice(&cell.height_m.to_le_bytes());
        }
        let status = w.array(ArrayId::OemStatus);
        for ((ix, iy), cell) in state.oem.known_cells() {
            status[iy as usize * nx + ix as usize] = cell.status.code();
        }
        let mut first = 0u32;
        let others = self.others.iter().map(|o| {
            let row = (o.uav, o.poses.len() as u32, first);
            first += o.poses.len() as u32;
            row
        });
        w.fill(ArrayId::Others, others, |(uav, n, first)| {
            let mut row = [0u8; OTHER_ROW_BYTES];
            for (k, v) in [uav, n, first].into_iter().enumerate() {
                row[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
            }
            row
        });
        let poses = self.others.iter().flat_map(|o| o.poses.iter());
        w.fill(ArrayId::Poses, poses, |p| {
            let mut row = [0u8; 32];
            for (k, v) in [p.position.x, p.position.y, p.position.z, p.yaw]
                .into_iter()
                .enumerate()
            {
                row[8 * k..8 * k + 8].copy_from_slice(&v.to_le_bytes());
            }
            row
        });
        w.fill(ArrayId::Fleet, self.fleet.iter().copied(), u32::to_le_bytes);
    }
}

/// The decision at `input` given an external planner's `answer`: the UAV's own planner's
/// ([`guidance::decide`] with `params`) without an answer or when the answer defers
/// ([`Steer::Defer`]); else its yaw reference (the UAV's yaw plus its first increment, or the
/// reference it gave) and its planned views for the token, with no cost (the planner
/// evaluated no sequence of this agent's). The agent's turn and the in-process episode both
/// decide by it.
pub fn decision(
    answer: Option<Answer>,
    params: &GuidanceParams,
    input: &PlanningInput<'_>,
) -> Decision {
    let Some(Answer { steer, poses, .. }) = answer else {
        return guidance::decide(params, input);
    };
    let (increments, yaw_ref) = match steer {
        Steer::Increments(v) if !v.is_empty() => {
            let yaw_ref = input.state.yaw + v[0];
            (v, yaw_ref)
        }
        Steer::YawRef(y) => (Vec::new(), y),
        Steer::Increments(_) | Steer::Defer => return guidance::decide(params, input),
    };
    let poses = poses
        .iter()
        .map(|&[x, y, z, yaw]| CameraPose {
            position: sets::math::Point3::new(x, y, z),
            yaw,
        })
        .collect();
    Decision {
        increments,
        yaw_ref,
        cost: Cost {
            area_m2: 0.0,
            distance_m: 0.0,
            hidden_m2: 0.0,
            total: 0.0,
        },
        view: PlannedView {
            uav: input.uav,
            poses,
        },
        sequences: 0,
        excluded: 0,
    }
}

/// Writes, for each planning cell of `window` (row-major, south row first), how many fine
/// cells of `set` it holds, as little-endian `u16`s into `out` (two bytes per cell).
pub fn counts_into(grids: &CoarseGrid, set: &CellSet, window: &CellBox, out: &mut [u8]) {
    let f = grids.factor;
    let width = (window.x1 - window.x0 + 1) as usize;
    let mut row_counts = vec![0u16; width];
    for (r, cy) in (window.y0..=window.y1).enumerate() {
        row_counts.fill(0);
        let fine_rows = cy * f..((cy + 1) * f).min(grids.fine.ny);
        for fy in fine_rows {
            let row = set.row(fy);
            if row.iter().all(|&w| w == 0) {
                continue;
            }
            for (c, cx) in (window.x0..=window.x1).enumerate() {
                let lo = cx * f;
                let hi = ((cx + 1) * f).min(grids.fine.nx);
                row_counts[c] += bits_in(row, lo, hi) as u16;
            }
        }
        let out_row = &mut out[2 * r * width..2 * (r + 1) * width];
        for (chunk, n) in out_row.chunks_exact_mut(2).zip(&row_counts) {
            chunk.copy_from_slice(&n.to_le_bytes());
        }
    }
}

/// Set bits of `row` (bit `b` of word `w` is cell `64 w + b`) among cells `lo..hi`.
fn bits_in(row: &[u64], lo: u32, hi: u32) -> u32 {
    let mut n = 0;
    let mut i = lo;
    while i < hi {
        let (word, bit) = ((i / 64) as usize, i % 64);
        let take = (64 - bit).min(hi - i);
        let mask = if take == 64 {
            u64::MAX
        } else {
            ((1u64 << take) - 1) << bit
        };
        n += (row[word] & mask).count_ones();
        i += take;
    }
    n
}

/// A request on its way.
pub struct Asked {
    pending: PendingResponse<Ipc, [u8], (), [u8], ()>,
    sent: Instant,
    step: u64,
    uav: u32,
}

/// The agent's side of `{run}/uav/{i}/plan`.
pub struct ExternalPlanner {
    service: PlanService,
    client: Client<Ipc, [u8], (), [u8], ()>,
    _wake_service: EventService,
    wake: Notifier<Ipc>,
    uav: u32,
    /// The reasons already logged (each is logged once).
    logged: Vec<Fallback>,
    report: ExternalReport,
    round_trips_ms: Vec<f64>,
    overheads_ms: Vec<f64>,
}

impl ExternalPlanner {
    /// Opens agent `uav`'s plan service (creating it) and the planners' wake-up event.
    pub fn open(node: &RunNode, uav: u32) -> Result<Self, IpcOpenError> {
        let service = node.open_plan(uav)?;
        let client = service
            .client_builder()
            .initial_max_slice_len(REQUEST_INITIAL_BYTES)
            .allocation_strategy(iceoryx2::prelude::AllocationStrategy::PowerOfTwo)
            .create()?;
        let wake_service = node.open_planner_wake()?;
        let wake = wake_service.notifier_builder().create()?;
        Ok(Self {
            service,
            client,
            _wake_service: wake_service,
            wake,
            uav,
            logged: Vec::new(),
            report: ExternalReport::default(),
            round_trips_ms: Vec::new(),
            overheads_ms: Vec::new(),
        })
    }

    /// Whether a planner serves this UAV now.
    pub fn has_server(&self) -> bool {
        self.service.dynamic_config().number_of_servers() > 0
    }

    /// Sends `request` and wakes the planners; `Err` when no planner serves this UAV or the
    /// request could not be sent.
    pub fn ask(&mut self, request: &Request<'_>) -> Result<Asked, Fallback> {
        self.report.asked += 1;
        if !self.has_server() {
            return Err(Fallback::Absent);
        }
        let started = Instant::now();
        let boxes = request.target_boxes();
        let shape = request.shape(&boxes);
        let (_, total) = shape.layout();
        let mut sent_at = Instant::now();
        let sent = (|| {
            let sample = self.client.loan_slice_uninit(total).ok()?;
            let mut sample = sample.write_from_fn(|_| 0u8);
            request.write(sample.payload_mut(), &shape, &boxes);
            sent_at = Instant::now();
            sample.send().ok()
        })();
        let Some(pending) = sent else {
            tracing::warn!(
                uav = self.uav,
                "cannot send a request to the external planner"
            );
            return Err(Fallback::Absent);
        };
        if pending.number_of_server_connections() == 0 {
            return Err(Fallback::Absent);
        }
        let notify = Instant::now();
        let _ = self
            .wake
            .notify_with_custom_event_id(iceoryx2::prelude::EventId::new(self.uav as usize));
        tracing::debug!(
            build_ms = (sent_at - started).as_secs_f64() * 1e3,
            send_ms = (notify - sent_at).as_secs_f64() * 1e3,
            notify_ms = notify.elapsed().as_secs_f64() * 1e3,
            bytes = total,
            "request sent"
        );
        Ok(Asked {
            pending,
            sent: sent_at,
            step: request.header.step,
            uav: request.header.uav,
        })
    }

    /// The answer to `asked` if it came (`Some(Ok)`), why there will be none (`Some(Err)`:
    /// malformed, or the planner left), or `None` while it may still come.
    pub fn poll(&mut self, asked: &Asked) -> Option<Result<Answer, Fallback>> {
        match asked.pending.receive() {
            Ok(Some(response)) => {
                let decoded = Answer::decode(response.payload(), asked.step, asked.uav);
                Some(match decoded {
                    Ok(answer) => {
                        let round_trip = asked.sent.elapsed().as_secs_f64() * 1e3;
                        tracing::debug!(
                            step = asked.step,
                            round_trip_ms = round_trip,
                            planner_ms = answer.planner_ns as f64 / 1e6,
                            "external planner answered"
                        );
                        self.round_trips_ms.push(round_trip);
                        let own = answer.planner_ns as f64 / 1e6;
                        self.overheads_ms.push((round_trip - own).max(0.0));
                        Ok(answer)
                    }
                    Err(e) => {
                        tracing::warn!(uav = self.uav, error = %e, "external planner's answer refused");
                        Err(Fallback::Malformed)
                    }
                })
            }
            Ok(None) if !asked.pending.is_connected() || !self.has_server() => {
                Some(Err(Fallback::Absent))
            }
            Ok(None) => None,
            Err(e) => {
                tracing::warn!(uav = self.uav, error = ?e, "cannot receive the planner's answer");
                Some(Err(Fallback::Absent))
            }
        }
    }

    /// Counts a decision taken from an answer (one that defers, too).
    pub fn answered(&mut self, answer: &Answer) {
        self.report.answered += 1;
        if answer.steer == Steer::Defer {
            self.report.deferred += 1;
        }
    }

    /// Counts a fallback decision, logging the first of each reason.
    pub fn fell_back(&mut self, why: Fallback, step: u64) {
        match why {
            Fallback::Late => self.report.late += 1,
            Fallback::Malformed => self.report.malformed += 1,
            Fallback::Absent => self.report.absent += 1,
        }
        if !self.logged.contains(&why) {
            self.logged.push(why);
            tracing::warn!(
                uav = self.uav,
                step,
                reason = why.name(),
                "no usable answer from the external planner: the fallback planner decides \
                 (logged once per reason; counted in summary.json)"
            );
        }
    }

    /// What this agent's external planner did, for its report.
    pub fn report(&self) -> ExternalReport {
        ExternalReport {
            round_trip_ms: Stats::from_samples(&self.round_trips_ms),
            overhead_ms: Stats::from_samples(&self.overheads_ms),
            ..self.report.clone()
        }
    }
}

/// What an agent's external planner did (the agent's report at exit).
#[derive(Clone, Debug, Default, Serialize)]
pub struct ExternalReport {
    /// Decisions asked for.
    pub asked: u64,
    /// Decisions taken from an answer.
    pub answered: u64,
    /// Of those, answers that deferred to the UAV's own planner ([`Steer::Defer`]).
    pub deferred: u64,
    /// Fallbacks for want of an answer in time.
    pub late: u64,
    /// Fallbacks for a refused answer.
    pub malformed: u64,
    /// Fallbacks for want of a planner.
    pub absent: u64,
    /// Time from request to answer, ms.
    pub round_trip_ms: Option<Stats>,
    /// That time less the planner's own (its `planner_ns`), ms: what the IPC and the waiting
    /// cost.
    pub overhead_ms: Option<Stats>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use sets::grid::GroundGrid;
    use sets::math::Point2;
    use sets::raster::Coverage;

    #[test]
    fn counts_per_planning_cell_are_the_fine_cells_it_holds() {
        let fine = GroundGrid::new(100.0, 0.5);
        let grids = CoarseGrid::new(fine);
        assert_eq!(grids.factor, 5);
        let mut set = CellSet::empty(&fine);
        set.fill_disc(&fine, Point2::new(3.0, -7.0), 9.0, Coverage::Outer);
        let c = &grids.coarse;
        let whole = CellBox {
            x0: 0,
            y0: 0,
            x1: c.nx - 1,
            y1: c.ny - 1,
        };
        let mut out = vec![0u8; 2 * c.cell_count()];
        counts_into(&grids, &set, &whole, &mut out);
        let counts: Vec<u64> = out
            .chunks_exact(2)
            .map(|b| u64::from(u16::from_le_bytes([b[0], b[1]])))
            .collect();
        assert_eq!(counts.iter().sum::<u64>(), set.count());
        // Each coarse cell's count is the fine cells of its block, one by one.
        for (i, &n) in counts.iter().enumerate() {
            let (cx, cy) = ((i % c.nx as usize) as u32, (i / c.nx as usize) as u32);
            let mut own = 0;
            for fy in cy * 5..cy * 5 + 5 {
                for fx in cx * 5..cx * 5 + 5 {
                    own += u64::from(set.contains((fx, fy)));
                }
            }
            assert_eq!(n, own, "cell {cx},{cy}");
        }
        assert_eq!(bits_in(&[u64::MAX, 1], 60, 65), 5);
        assert_eq!(bits_in(&[u64::MAX, 0], 0, 64), 64);
    }
}
