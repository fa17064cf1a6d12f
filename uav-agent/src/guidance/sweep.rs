//! The fleet's sweep plan for the `setfleet` planner (`guidance.sweep = "lanes"`): lanes of one
//! front, and the tracking schedule that interrupts it.
//!
//! ## Why a front
//! `X̄` grows from its whole boundary at the targets' speed `v`. A planner that clears pockets
//! wherever they are leaves cleared ground beside uncleared ground everywhere, so `X̄` regrows
//! into what was cleared along a boundary as long as all the pockets' edges. Guaranteed search
//! for evaders of known maximal speed (McGee & Hedrick's strategies for mobile evaders in the
//! plane; Francos & Bruckstein's same-direction and pincer sweeps with fan-shaped sensors)
//! confines instead: the searchers hold a *front*, the ground behind it is cleared, and an
//! evader can only cross the front through the sensors' footprint. A front of length `L` held
//! by `n` sweepers of speed `V` against evaders of speed `v` can advance when the footprint's
//! depth exceeds about `2 v L / (n V)` (the evaders' reach during the time a sweeper needs to
//! cover its `L / n` of the front). The default scenario's numbers (`L` = 500 m, `n` = 4,
//! `V` = 10 m/s, `v` = 2 m/s) ask for 50 m; the default camera's footprint is about 120 m deep.
//! So the fleet can hold one front across the region and push it from edge to edge, with
//! `X̄` confined ahead of it, regrowing only across the front line and from the pockets the
//! cameras cannot see into (shadows: the occlusion floor).
//!
//! ## The plan
//! `guidance.sweep = "sectors"` keeps the lanes only (each UAV values its lane's ground 1 and
//! the others' [`OTHER_LANES_WEIGHT`], and is pulled to its lane); `"lanes"` adds the fronts:
//! - **Lanes** ([`Lanes`]). The round's fleet (the token's order, [`super::TokenRing::fleet`])
//!   splits the region's columns into one lane per UAV, in ascending order of UAV id: a pure
//!   function of the token's contents, so every UAV of a round computes the same lanes. A UAV
//!   that dies leaves the order of the next round, whose lanes share its ground among the
//!   others; a UAV that rejoins is in the next order again. Either way within one round.
//! - **The front of a lane** ([`Lanes::front`]). Every lane is cleared from the region's south
//!   edge northwards. Its front is the first row, from the south, in which `X̄` holds more than
//!   [`CLEARED_FRACTION`] of the lane's width: the rows south of it are cleared but for narrow
//!   pockets. The front is read from `X̄` at every decision, so it advances only once the
//!   ground behind it is cleared, and falls back when `X̄` regrows behind it (a pocket that
//!   grew across a row, or a car's set that spilled).
//! - **Priorities** ([`Priority`]). The planner values `X̄`'s cells by where they lie: behind
//!   the front [`BEHIND_WEIGHT`] (ground regrown behind the front breaks the confinement), in
//!   the band of one footprint depth past the front 1, further ahead in the lane
//!   [`AHEAD_WEIGHT`], in the other lanes [`OTHER_LANES_WEIGHT`] (a UAV still clears what its
//!   views cross, and helps where its own lane is clear). The planner's distance term pulls the
//!   view towards the lane's ground behind and in the band, so a UAV whose lane is cleared
//!   turns back to where it regrew. The band's depth is the camera's footprint depth at the
//!   UAV's altitude, so the weights follow the scenario's camera, region and fleet size.
//! - **Tracking schedule** ([`TrackSchedule`]). An identified car's set `X_j` grows like a
//!   disc of radius `v t` in the time `t` since it was last seen. With a revisit period `T`
//!   (`guidance.track_revisit_s`), a set larger than `π (v T)²` is *overdue*: the UAV whose lane
//!   holds its barycentre drops the front for it (its distance term pulls towards the overdue
//!   sets only, and their cells weigh [`OVERDUE_WEIGHT`]) until it is seen again. `T` is the
//!   trade between sweeping and tracking: a short period keeps the cars' sets small and the
//!   localisation error low, at the price of UAVs away from their fronts.
//!
//! Everything here is computed from the planner's inputs at each decision, with integer
//! arithmetic on the planning grid's rows and columns: the same inputs give the same
//! priorities on any machine and thread count.

use protocol::scenario::SweepPlan;
use sets::grid::GroundGrid;
use sets::math::Point2;
use sets::raster::{CellBox, CellSet};

use super::{GuidanceParams, PlanningInput};

/// Fraction of a lane's width `X̄` may hold in a row that counts as cleared.
pub const CLEARED_FRACTION: f64 = 0.25;
/// Weight of `X̄`'s cells behind the front of the deciding UAV's lane.
pub const BEHIND_WEIGHT: f64 = 2.0;
/// Weight of `X̄`'s cells past the front's band in the deciding UAV's lane.
pub const AHEAD_WEIGHT: f64 = 0.5;
/// Weight of `X̄`'s cells in the other lanes.
pub const OTHER_LANES_WEIGHT: f64 = 0.25;
/// Weight of the cells of the overdue sets the deciding UAV revisits, per m², against `X̄`'s 1
/// in the band.
pub const OVERDUE_WEIGHT: f64 = 4.0;

/// What the sweep asks of one decision: how the deciding UAV weighs `X̄` and the cars' sets,
/// and where its view is pulled.
#[derive(Clone, Debug)]
pub struct Sweep {
    /// How `X̄`'s cells weigh.
    pub priority: Priority,
    /// The overdue sets the deciding UAV revisits, on the planning grid, grown by the
    /// targets' reach over the lookahead (the cells of its predicted sets they become).
    pub overdue: CellSet,
    /// Weight of the overdue sets' cells beyond the cars' sets' own (`target_weight`).
    overdue_extra: f64,
    /// `X̄` less `H̄` on the planning grid: the ground a pass can clear (with lanes only).
    clearable: Option<CellSet>,
    /// The deciding UAV's own ground: its lane (behind its front with the lanes' sweep), or
    /// the whole grid when it has no lane.
    pub own: CellSet,
}

impl Sweep {
    /// The sweep of the decision of `input` on the planning grid `grid`, with a lookahead of
    /// `lookahead_s` seconds and the camera's footprint `footprint_depth_m` deep: the lanes'
    /// priorities with `guidance.sweep = "lanes"` (else uniform weights), and the overdue cars
    /// of the UAV's lane with a tracking schedule (`guidance.track_revisit_s > 0`).
    pub fn of(
        params: &GuidanceParams,
        input: &PlanningInput<'_>,
        grid: &GroundGrid,
        lookahead_s: f64,
        footprint_depth_m: f64,
    ) -> Sweep {
        // The lanes are who owns what: the front's ground with lanes, the overdue cars with a
        // schedule.
        let lanes = Lanes::new(grid, input.fleet);
        let schedule = TrackSchedule {
            revisit_s: params.track_revisit_s(),
            target_speed: params.target_max_speed,
        };
        let fine = &params.grids.fine;
        let targets = input.sets.iter().skip(1).copied();
        let mine = schedule.revisits(fine, &lanes, grid, input.uav, targets);
        let overdue = if mine.is_empty() {
            CellSet::empty(grid)
        } else {
            params
                .grids
                .downsample(&mine)
                .dilate(grid, params.target_max_speed * lookahead_s)
        };
        let overdue_extra = (OVERDUE_WEIGHT - params.setfleet.target_weight).max(0.0);
        // The pull, and the fronts, read the ground the cameras can clear: `X̄` less `H̄` (the
        // pockets hidden from where the UAVs flew, which a pass in the lane's direction does
        // not clear either).
        let sweep = params.setfleet.sweep;
        let clearable = match input.sets.first() {
            Some(&undetected) if sweep != SweepPlan::None => {
                let mut clearable = undetected.clone();
                clearable.and_not_assign(input.unseen);
                Some(params.grids.downsample(&clearable))
            }
            _ => None,
        };
        let (priority, front) = match (&clearable, sweep) {
            (Some(clearable), SweepPlan::Lanes) => {
                let band_rows = (footprint_depth_m / grid.cell_m).ceil().max(1.0) as u32;
                let priority = Priority::of_lane(grid, &lanes, input.uav, clearable, band_rows);
                (priority, lanes.front(input.uav, clearable))
            }
            (Some(_), SweepPlan::Sectors) => (Priority::of_sector(grid, &lanes, input.uav), None),
            _ => (Priority::Uniform, None),
        };
        let own = lanes
            .ground(grid, input.uav, 0..front.unwrap_or(grid.ny))
            .unwrap_or_else(|| CellSet::full(grid));
        Sweep {
            priority,
            overdue,
            overdue_extra,
            clearable,
            own,
        }
    }

    /// The weighted cells of predicted sets `undetected` (`X̄`) and `targets` (the cars'),
    /// the cars' weighing `target_weight` each, plus the overdue ones' extra.
    pub fn weigh(&self, undetected: &CellSet, targets: &CellSet, target_weight: f64) -> f64 {
        let overdue = if self.overdue_extra > 0.0 && !self.overdue.is_empty() {
            self.overdue_extra * targets.intersection_count(&self.overdue) as f64
        } else {
            0.0
        };
        self.priority.weigh(undetected) + target_weight * targets.count() as f64 + overdue
    }

    /// Where the deciding UAV's view is pulled (the planner's distance term), less the ground
    /// the UAVs ahead in the token will see (`seen_ahead`, per period): the overdue sets it
    /// revisits, else the ground its lane can clear behind the front and in the band, else
    /// (and without lanes) all of `X̄` (`undetected`) and of the cars' sets `targets`.
    pub fn attractive(
        &self,
        undetected: &CellSet,
        targets: &CellSet,
        seen_ahead: &[CellSet],
    ) -> CellSet {
        let less_seen = |mut set: CellSet| {
            for seen in seen_ahead {
                set.and_not_assign(seen);
            }
            set
        };
        let overdue = less_seen(self.overdue.clone());
        if !overdue.is_empty() {
            return overdue;
        }
        let pulling = self
            .clearable
            .as_ref()
            .and_then(|c| self.priority.pulling(c));
        if let Some(pulling) = pulling.map(less_seen)
            && !pulling.is_empty()
        {
            return pulling;
        }
        let mut all = undetected.clone();
        all.or_assign(targets);
        less_seen(all)
    }
}

/// The lanes of a round: the columns of the planning grid split among the fleet.
#[derive(Clone, Debug, PartialEq)]
pub struct Lanes {
    /// The fleet, ascending, without repeats.
    fleet: Vec<u32>,
    /// First column of each lane, and the grid's column count last.
    starts: Vec<u32>,
    /// Rows of the planning grid.
    rows: u32,
}

impl Lanes {
    /// The lanes of `fleet` (any order, repeats ignored) on `grid`: lane `r` holds the columns
    /// `[r nx / n, (r + 1) nx / n)` (integer division) for the `r`-th UAV of the fleet in
    /// ascending order of id. An empty fleet has no lanes.
    pub fn new(grid: &GroundGrid, fleet: &[u32]) -> Lanes {
        let mut fleet = fleet.to_vec();
        fleet.sort_unstable();
        fleet.dedup();
        let n = fleet.len() as u64;
        let nx = u64::from(grid.nx);
        let starts = (0..=n)
            .map(|r| (r * nx).checked_div(n).unwrap_or(0) as u32)
            .collect();
        Lanes {
            fleet,
            starts,
            rows: grid.ny,
        }
    }

    /// The UAVs the lanes belong to, ascending.
    pub fn fleet(&self) -> &[u32] {
        &self.fleet
    }

    /// The columns of `uav`'s lane, inclusive; `None` if it has none (not in the fleet, or a
    /// fleet wider than the grid).
    pub fn columns(&self, uav: u32) -> Option<(u32, u32)> {
        let r = self.fleet.binary_search(&uav).ok()?;
        let (start, end) = (self.starts[r], self.starts[r + 1]);
        (end > start).then(|| (start, end - 1))
    }

    /// The cells of `uav`'s lane on `grid` in the rows `rows` (`None` without a lane).
    pub fn ground(
        &self,
        grid: &GroundGrid,
        uav: u32,
        rows: std::ops::Range<u32>,
    ) -> Option<CellSet> {
        let (x0, x1) = self.columns(uav)?;
        let mut set = CellSet::empty(grid);
        for iy in rows.start..rows.end.min(grid.ny) {
            set.fill_row_span(iy, x0, x1);
        }
        Some(set)
    }

    /// The UAV whose lane holds column `ix`.
    pub fn owner_of_column(&self, ix: u32) -> Option<u32> {
        let r = self.starts.partition_point(|&s| s <= ix).checked_sub(1)?;
        (r < self.fleet.len()).then(|| self.fleet[r])
    }

    /// The UAV whose lane holds point `p` of `grid` (`None` off the grid).
    pub fn owner_at(&self, grid: &GroundGrid, p: &Point2) -> Option<u32> {
        self.owner_of_column(grid.cell_of(p)?.0)
    }

    /// The front of `uav`'s lane against `undetected` (`X̄` on the planning grid): the first
    /// row from the south in which `X̄` holds more than [`CLEARED_FRACTION`] of the lane's
    /// width, or the row count when the whole lane is cleared. `None` without a lane.
    pub fn front(&self, uav: u32, undetected: &CellSet) -> Option<u32> {
        let (x0, x1) = self.columns(uav)?;
        let width = f64::from(x1 - x0 + 1);
        let front = (0..self.rows)
            .find(|&iy| {
                let row = CellBox {
                    x0,
                    y0: iy,
                    x1,
                    y1: iy,
                };
                undetected.count_in_box(&row) as f64 > CLEARED_FRACTION * width
            })
            .unwrap_or(self.rows);
        Some(front)
    }
}

/// How the planner weighs the cells of `X̄`: all alike, or by where they lie in the sweep.
#[derive(Clone, Debug)]
pub enum Priority {
    /// Every cell weighs 1 (`guidance.sweep = "none"`, and a UAV without a lane).
    Uniform,
    /// Cells weigh by class: each class a set of cells and its weight; the classes partition
    /// the grid.
    Classes(Vec<(CellSet, f64)>),
}

impl Priority {
    /// The priorities of `uav`'s sweep on `grid`: its lane's ground behind the front, in the
    /// band of `band_rows` rows from the front, and further ahead, and the other lanes'
    /// ground, with the module's weights. Uniform when `uav` has no lane.
    pub fn of_lane(
        grid: &GroundGrid,
        lanes: &Lanes,
        uav: u32,
        undetected: &CellSet,
        band_rows: u32,
    ) -> Priority {
        let Some(front) = lanes.front(uav, undetected) else {
            return Priority::Uniform;
        };
        let band_end = front.saturating_add(band_rows).min(grid.ny);
        let rows = |range| {
            lanes
                .ground(grid, uav, range)
                .unwrap_or_else(|| CellSet::empty(grid))
        };
        let behind = rows(0..front);
        let band = rows(front..band_end);
        let ahead = rows(band_end..grid.ny);
        let mut others = CellSet::full(grid);
        for lane in [&behind, &band, &ahead] {
            others.and_not_assign(lane);
        }
        Priority::Classes(vec![
            (behind, BEHIND_WEIGHT),
            (band, 1.0),
            (ahead, AHEAD_WEIGHT),
            (others, OTHER_LANES_WEIGHT),
        ])
    }

    /// The priorities of `uav`'s sector on `grid`: its lane's ground weighs 1, the other
    /// lanes' [`OTHER_LANES_WEIGHT`]. Uniform when `uav` has no lane.
    pub fn of_sector(grid: &GroundGrid, lanes: &Lanes, uav: u32) -> Priority {
        let Some(lane) = lanes.ground(grid, uav, 0..grid.ny) else {
            return Priority::Uniform;
        };
        let mut others = CellSet::full(grid);
        others.and_not_assign(&lane);
        Priority::Classes(vec![(lane, 1.0), (others, OTHER_LANES_WEIGHT)])
    }

    /// The weighted cell count of `set`: its cells' weights summed.
    pub fn weigh(&self, set: &CellSet) -> f64 {
        match self {
            Priority::Uniform => set.count() as f64,
            Priority::Classes(classes) => classes
                .iter()
                .map(|(cells, w)| w * set.intersection_count(cells) as f64)
                .sum(),
        }
    }

    /// The cells of the classes that pull the UAV's view (the lane's ground behind the front
    /// and in the band: those weighing at least 1) that lie in `set`; `None` when uniform.
    pub fn pulling(&self, set: &CellSet) -> Option<CellSet> {
        let Priority::Classes(classes) = self else {
            return None;
        };
        // The classes partition the grid: what the light ones leave is the pulling ones'.
        let mut pulling = set.clone();
        for (cells, w) in classes {
            if *w < 1.0 {
                pulling.and_not_assign(cells);
            }
        }
        Some(pulling)
    }
}

/// The tracking schedule: which identified cars' sets are overdue for a revisit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackSchedule {
    /// The revisit period `T`, seconds (0: no schedule).
    pub revisit_s: f64,
    /// The targets' speed bound `v`, m/s.
    pub target_speed: f64,
}

impl TrackSchedule {
    /// The area past which a set is overdue, m²: a disc of radius `v T` (infinite without a
    /// schedule).
    pub fn bound_m2(&self) -> f64 {
        if self.revisit_s > 0.0 {
            std::f64::consts::PI * (self.target_speed * self.revisit_s).powi(2)
        } else {
            f64::INFINITY
        }
    }

    /// Whether a set of `area_m2` is overdue.
    pub fn is_overdue(&self, area_m2: f64) -> bool {
        area_m2 > self.bound_m2()
    }

    /// The overdue sets among `targets` (on `fine`, the estimator's grid) that `uav` revisits:
    /// those whose barycentre lies in its lane. Their union, on `fine`.
    pub fn revisits<'a>(
        &self,
        fine: &GroundGrid,
        lanes: &Lanes,
        coarse: &GroundGrid,
        uav: u32,
        targets: impl IntoIterator<Item = &'a CellSet>,
    ) -> CellSet {
        let mut mine = CellSet::empty(fine);
        for set in targets {
            if !self.is_overdue(set.area(fine)) {
                continue;
            }
            let owner = set
                .barycentre(fine)
                .and_then(|b| lanes.owner_at(coarse, &b));
            if owner == Some(uav) {
                mine.or_assign(set);
            }
        }
        mine
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sets::raster::Coverage;

    fn grid() -> GroundGrid {
        GroundGrid::new(100.0, 2.5) // 80 x 80
    }

    #[test]
    fn lanes_partition_the_columns_in_the_order_of_the_ids() {
        let g = grid();
        let lanes = Lanes::new(&g, &[3, 0, 1, 3]);
        assert_eq!(lanes.fleet(), &[0, 1, 3]);
        assert_eq!(lanes.columns(0), Some((0, 25)));
        assert_eq!(lanes.columns(1), Some((26, 52)));
        assert_eq!(lanes.columns(3), Some((53, 79)));
        assert_eq!(lanes.columns(2), None);
        for ix in 0..g.nx {
            let owner = lanes.owner_of_column(ix).unwrap();
            let (a, b) = lanes.columns(owner).unwrap();
            assert!((a..=b).contains(&ix));
        }
        assert_eq!(lanes.owner_of_column(g.nx), None);
        assert_eq!(Lanes::new(&g, &[]).owner_of_column(0), None);
    }

    /// A dead UAV's lane is shared out as soon as a round's fleet leaves it out, and given
    /// back when it rejoins: the lanes are a function of the fleet only.
    #[test]
    fn a_dead_uavs_lane_is_reassigned_by_the_next_rounds_fleet() {
        let g = grid();
        let before = Lanes::new(&g, &[0, 1, 2, 3]);
        let after = Lanes::new(&g, &[0, 1, 3]);
        let (a, b) = before.columns(2).unwrap();
        assert_eq!(after.columns(2), None);
        for ix in a..=b {
            let owner = after.owner_of_column(ix).unwrap();
            assert_ne!(owner, 2);
            assert!(after.fleet().contains(&owner));
        }
        assert_eq!(Lanes::new(&g, &[3, 2, 1, 0]), before);
    }

    #[test]
    fn the_front_is_the_first_row_not_cleared() {
        let g = grid();
        let lanes = Lanes::new(&g, &[0, 1]);
        let (x0, x1) = lanes.columns(0).unwrap();
        let mut undetected = CellSet::empty(&g);
        assert_eq!(lanes.front(0, &undetected), Some(g.ny));
        // A narrow pocket in row 5 does not stop the front; a wide one in row 30 does.
        undetected.fill_row_span(5, x0, x0 + 3);
        undetected.fill_row_span(30, x0, x1);
        for iy in 40..g.ny {
            undetected.fill_row_span(iy, x0, x1);
        }
        assert_eq!(lanes.front(0, &undetected), Some(30));
        // The other lane's front reads its own columns only.
        assert_eq!(lanes.front(1, &undetected), Some(g.ny));
        assert_eq!(lanes.front(7, &undetected), None);
    }

    #[test]
    fn priorities_weigh_behind_the_front_most_and_other_lanes_least() {
        let g = grid();
        let lanes = Lanes::new(&g, &[0, 1]);
        let (x0, x1) = lanes.columns(0).unwrap();
        let mut undetected = CellSet::empty(&g);
        for iy in 20..g.ny {
            undetected.fill_row_span(iy, 0, g.nx - 1);
        }
        let p = Priority::of_lane(&g, &lanes, 0, &undetected, 10);
        let cell = |ix: u32, iy: u32| CellSet::from_cells(&g, [(ix, iy)]);
        assert_eq!(p.weigh(&cell(x0, 10)), BEHIND_WEIGHT);
        assert_eq!(p.weigh(&cell(x1, 25)), 1.0);
        assert_eq!(p.weigh(&cell(x0, 35)), AHEAD_WEIGHT);
        assert_eq!(p.weigh(&cell(x1 + 1, 10)), OTHER_LANES_WEIGHT);
        // Every cell is in one class.
        assert_eq!(
            p.weigh(&CellSet::full(&g)),
            f64::from(x1 - x0 + 1) * (20.0 * BEHIND_WEIGHT + 10.0 + 50.0 * AHEAD_WEIGHT)
                + f64::from(g.nx - (x1 - x0 + 1)) * 80.0 * OTHER_LANES_WEIGHT
        );
        // What pulls: the lane's X̄ in the band (nothing is left behind the front).
        let pulling = p.pulling(&undetected).unwrap();
        assert_eq!(pulling.count(), u64::from(x1 - x0 + 1) * 10);
        assert_eq!(
            Priority::Uniform.weigh(&undetected),
            undetected.count() as f64
        );
        assert!(Priority::Uniform.pulling(&undetected).is_none());
        // No lane, no sweep.
        assert!(matches!(
            Priority::of_lane(&g, &lanes, 5, &undetected, 10),
            Priority::Uniform
        ));
        // A sector: the whole lane weighs 1, and all of it pulls.
        let sector = Priority::of_sector(&g, &lanes, 0);
        assert_eq!(sector.weigh(&cell(x0, 10)), 1.0);
        assert_eq!(sector.weigh(&cell(x1 + 1, 10)), OTHER_LANES_WEIGHT);
        let pulling = sector.pulling(&undetected).unwrap();
        assert_eq!(pulling.count(), u64::from(x1 - x0 + 1) * 60);
        assert!(matches!(
            Priority::of_sector(&g, &lanes, 5),
            Priority::Uniform
        ));
    }

    /// The schedule sends a UAV to a car whose set passed the bound in its lane, and leaves a
    /// set under the bound, or in another lane, alone.
    #[test]
    fn the_schedule_revisits_a_car_whose_set_passes_the_bound() {
        let fine = GroundGrid::new(100.0, 1.0);
        let coarse = grid();
        let lanes = Lanes::new(&coarse, &[0, 1]);
        let schedule = TrackSchedule {
            revisit_s: 5.0,
            target_speed: 2.0,
        };
        // The bound: a disc of radius 10 m.
        assert!((schedule.bound_m2() - std::f64::consts::PI * 100.0).abs() < 1e-9);
        let disc = |x: f64, r: f64| {
            let mut s = CellSet::empty(&fine);
            s.fill_disc(&fine, Point2::new(x, 0.0), r, Coverage::Outer);
            s
        };
        let (small, large, elsewhere) = (disc(-50.0, 8.0), disc(-50.0, 14.0), disc(50.0, 14.0));
        let mine = schedule.revisits(&fine, &lanes, &coarse, 0, [&small]);
        assert!(mine.is_empty());
        let mine = schedule.revisits(&fine, &lanes, &coarse, 0, [&small, &large, &elsewhere]);
        assert_eq!(mine, large);
        let theirs = schedule.revisits(&fine, &lanes, &coarse, 1, [&small, &large, &elsewhere]);
        assert_eq!(theirs, elsewhere);
        let off = TrackSchedule {
            revisit_s: 0.0,
            ..schedule
        };
        assert!(off.revisits(&fine, &lanes, &coarse, 0, [&large]).is_empty());
    }
}
