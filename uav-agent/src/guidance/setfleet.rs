//! The `setfleet` planner: the project's own guidance (`guidance.planner = "setfleet"`), beside
//! the paper's MPC ([`super::paper::plan`]), which stays exactly as the paper writes it.
//!
//! Same inputs, same dynamics ([`protocol::flight::advance`]), same camera and field-of-view
//! prediction ([`super::view`]), same yaw increments `U` held for one guidance period each, same
//! token. What changes is how far it looks and what it values:
//!
//! - **Longer sequences for the same cost: a beam search.** Instead of every sequence of `U^h`,
//!   it expands `lookahead_periods` periods, keeping after each period the `beam_width` best
//!   partial sequences (each expanded by every increment of `U`). With the variant's 1 s
//!   period, 6 periods look 6 s ahead and cost about 120 expansions per decision, where the
//!   exhaustive search would cost `5^6`.
//! - **Time counts.** A sequence is scored by the mean over its periods of the predicted
//!   sets' value, not by the value at the end only, so clearing ground early beats clearing it
//!   late.
//! - **What a pocket left unobserved will cost later.** A set left alone grows at the targets'
//!   speed `v` from its whole boundary: in `G` seconds (`G = growth_horizon_s`) it becomes the
//!   set grown by `v G`. The value of a set is its area plus that growth ([`super::growth`]),
//!   which makes the planner clear pockets whole rather than shave them (shaving keeps the
//!   boundary), and revisit identified cars before their sets grow: the identified targets'
//!   sets count `target_weight` times their area, since every square metre of them is
//!   localisation error. Pockets closer than `v G` to each other grow into the same ground
//!   once, so clearing ground between shadows is never charged more than it clears. (The
//!   variant has `G = 0`, the sets' area alone, which searched better where measured.)
//! - **Somewhere to go when nothing is in reach.** The distance from the predicted view
//!   centre to the nearest set cell is charged `lambda` m² per metre, as the paper's `Φ_d`,
//!   but read from a distance map of the sets computed once per decision (and given real
//!   weight by the variant), so a UAV that has cleared its surroundings heads for the nearest
//!   remaining set instead of circling.
//! - **Spreading with the token.** Ground the UAVs ahead in the token will see is removed from
//!   the predicted sets period by period and from the distance map, as in the paper; in
//!   addition a view centre within `spread_m` of another UAV's planned view centre is charged
//!   up to one field of view's area, linearly in how close it is, so the UAVs do not follow
//!   one another beyond the others' horizon. With a finite radio range (`comms.range_m`) only
//!   the plans of UAVs in range count: this agent never learns what the others see.
//! - **Staying in radio range** (a finite `comms.range_m`). An agent out of range of another
//!   learns nothing of the ground that one sees, about `W V` m² per second (`W` the
//!   footprint's width, `V` the speed), and `d` metres beyond range take `d / V` seconds to
//!   close: a sequence is charged `W` m² per metre its UAV ends beyond range of each other UAV
//!   (at the same CVS step of their plans), so the agents keep meeting and fusing. The others
//!   are those whose plans the ring gives it ([`PlanningInput::others`]): under
//!   `comms.token_range = "radio"` and `comms.liveness = "radio"` (the defaults) only plans
//!   carried by tokens its radio read, so it is charged for drifting from the UAVs it knows
//!   of, never from one only the world could tell it about.
//! - `kappa` keeps the paper's meaning: the area of the final sets inside ground occluded in
//!   the last periods is charged `kappa` m² per m².
//! - **The fleet's share of the search** ([`super::sweep`]): the round's fleet (the token's
//!   order) splits the region into lanes. With `guidance.sweep = "sectors"` or `"lanes"` the
//!   cells of `X̄` weigh by where they lie (the UAV's lane, behind or past its front, other
//!   lanes) and the distance term pulls to the UAV's own clearable ground; with a tracking
//!   schedule (`guidance.track_revisit_s`) a car's set grown past the bound pulls the UAV whose
//!   lane holds it, and its cells weigh more; with `guidance.second_viewpoints` the distance
//!   term pulls to a viewpoint predicted to see into the densest block of `X̄` hidden from
//!   where the UAVs flew ([`super::viewpoint`]), when worth the detour.
//! - **Weights read against the default scenario** ([`super::weights`]): with
//!   `guidance.adapt_weights`, `lambda`, `spread_m` and `track_revisit_s` are scaled by the
//!   ratios of the footprint's width and the targets' speed to the default scenario's, where
//!   they were tuned.
//!
//! The planning grid has [`super::coarse::PLANNING_CELL_M`] cells like the paper's; the sets
//! grow by whole cells (8-neighbour rings) when the targets' accumulated reach crosses a cell,
//! not by a rounded-up disc every period, so the predicted growth has the targets' true speed.
//! Sequences leaving the RoI are excluded as in the paper. Ties keep the first sequence in
//! lexicographic order of the increments (stable sorts, no unordered containers), so the
//! decision is a pure function of the inputs.
//!
//! Cost: the predicted views (shadows of known buildings) are most of it. The children of a
//! beam node that turn hard to the same side fly the same first step, whose view is computed
//! once; a child's grown sets are its node's, counted again only on the rows its views can
//! reach. The beam has no bound: a bound from views without shadows is too loose to skip
//! children (it would have spared about a fifth of them on the benchmark's decisions, for the
//! price of a footprint per pose).
//!
//! Threads: while one UAV plans, the others of a lockstep round wait for the token, so the
//! planner shares its work with rayon's pool ([`GuidanceParams::parallel`]; the pool has
//! `RAYON_NUM_THREADS` threads, the machine's cores by default): the sets' downsampling, the
//! others' views of each period, the distance map beside the first period's children, and
//! each period's children in jobs of a node and half its increments. A child depends on its
//! node and increment only and the jobs' results are put back in their order, so the decision
//! is the same on any number of threads (tested, and checked by `fleet bench guidance`).

use std::borrow::Cow;

use protocol::camera::{Camera, CameraPose};
use protocol::flight::UavState;
use protocol::radio::in_comms_range;
use protocol::wire::PlannedView;
use rayon::prelude::*;
use sets::grid::GroundGrid;
use sets::math::Point2;
use sets::raster::CellSet;

use super::growth::{self, Growth};
use super::sweep::Sweep;
use super::view::same_pose;
use super::viewpoint::SecondViewpoint;
use super::{
    Cost, Decision, GroundPredictor, GuidanceParams, ObstacleCell, PlanningInput, decision,
    fly_step, stray, view,
};

/// A partial sequence of the beam.
#[derive(Clone)]
struct Node {
    increments: Vec<f64>,
    state: UavState,
    poses: Vec<CameraPose>,
    undetected: CellSet,
    targets: CellSet,
    /// Sum over the periods so far of the sets' value, m².
    value_sum: f64,
    stray_m: f64,
    /// The view centre of the last pose.
    centre: Point2,
    /// The charge for crowding the others' view centres, m².
    crowding: f64,
    /// The charge for ending beyond radio range of the others, m².
    apart: f64,
    /// Ranking key: the mean value plus the distance and spread charges, m² (set by
    /// [`Node::rank_by`]).
    rank: f64,
    cost: Cost,
}

impl Node {
    /// The empty sequence from `state`, with the sets as they are now.
    fn root(state: UavState, undetected: CellSet, targets: CellSet) -> Node {
        Node {
            increments: Vec::new(),
            state,
            poses: Vec::new(),
            undetected,
            targets,
            value_sum: 0.0,
            stray_m: 0.0,
            centre: Point2::origin(),
            crowding: 0.0,
            apart: 0.0,
            rank: 0.0,
            cost: Cost {
                area_m2: 0.0,
                distance_m: 0.0,
                hidden_m2: 0.0,
                total: 0.0,
            },
        }
    }

    /// Sets the ranking key: the mean value (`cost.area_m2`), plus `lambda` per metre from the
    /// view centre to where `pull` pulls, the crowding and radio range charges and `kappa` per
    /// m² of sets in occluded ground.
    fn rank_by(&mut self, pull: &Pull, params: &GuidanceParams) {
        let distance_m = pull.distance_m(&self.centre, self.state.yaw);
        self.rank = self.cost.area_m2
            + params.lambda * distance_m
            + self.crowding
            + self.apart
            + params.kappa * self.cost.hidden_m2;
        self.cost.distance_m = distance_m;
        self.cost.total = self.rank;
    }
}

/// Picks the yaw increments with the `setfleet` planner (see the module docs).
pub fn plan(params: &GuidanceParams, input: &PlanningInput<'_>) -> Decision {
    let sp = &params.setfleet;
    let grid = params.grids.coarse;
    let mut predictor = GroundPredictor::new(&grid);
    let (undetected, targets, hidden) = coarse_inputs(params, input, &grid, &mut predictor);
    let obstacles = &view::tallest_first(if params.use_map { input.obstacles } else { &[] });
    let depth = sp.lookahead_periods.max(1) as usize;
    let sets = (&undetected, &targets);
    let others = others_in_range(params, input);
    let others_seen = others_seen(
        params,
        &others,
        &grid,
        sets,
        obstacles,
        depth,
        &mut predictor,
    );
    let others_centres = view_centres(params, &others);
    // Only a finite radio range charges the distance to the others.
    let others_positions = if params.comms_range_m.is_finite() {
        positions(input.others)
    } else {
        Vec::new()
    };
    let lookahead_s = depth as f64 * params.steps_per_period as f64 * params.dt;
    let camera = Camera::new(
        params.camera,
        CameraPose {
            position: input.state.position,
            yaw: input.state.yaw,
        },
    );
    let footprint_depth = camera.ground_footprint_depth();
    let sweep = Sweep::of(params, input, &grid, lookahead_s, footprint_depth);
    let attractive = sweep.attractive(&undetected, &targets, &others_seen);
    let fov_area = camera.ground_footprint_area();
    let footprint_width_m = camera.ground_footprint_width();
    let growth_rings = growth::horizon_rings(params, &grid);
    let root = Node::root(input.state, undetected, targets);
    let period = |d: usize| Period {
        params,
        grid,
        obstacles,
        seen_ahead: &others_seen[d],
        rings: rings(params, &grid, d),
        index: d,
        last: d + 1 == depth,
        hidden: &hidden,
        others_centres: &others_centres,
        others_positions: &others_positions,
        footprint_width_m,
        fov_area,
        growth_rings,
        sweep: &sweep,
    };
    let viewpoint = (sp.second_viewpoints && sweep.overdue.is_empty())
        .then(|| {
            let at = (&obstacles[..], footprint_depth);
            second_viewpoint(params, input, &sweep, at, &mut predictor)
        })
        .flatten();
    let (best, sequences, excluded) = beam_search(
        params,
        root,
        depth,
        (&attractive, viewpoint),
        period,
        &mut predictor,
    );
    decision(input, best, sequences, excluded)
}

/// The plans of the token that can change this agent's sets: those of the UAVs within radio
/// range of it (`comms.range_m`, judged between its pose and the first pose of each plan). An
/// agent fuses estimates from senders in range only ([`protocol::radio::in_comms_range`]), so
/// what an out-of-range UAV will see stays in this agent's sets, and flying where it looks
/// costs this agent nothing.
fn others_in_range<'a>(
    params: &GuidanceParams,
    input: &PlanningInput<'a>,
) -> Cow<'a, [PlannedView]> {
    if params.comms_range_m.is_infinite() {
        return Cow::Borrowed(input.others);
    }
    let me = CameraPose {
        position: input.state.position,
        yaw: input.state.yaw,
    };
    let in_range = |v: &&PlannedView| {
        let first = v.poses.first().copied();
        in_comms_range(params.comms_range_m, Some(me), first)
    };
    Cow::Owned(input.others.iter().filter(in_range).cloned().collect())
}

/// The second viewpoint of the decision of `input` ([`super::viewpoint`]), for the pockets
/// of `X̄ ∩ H̄` in the UAV's own ground (`sweep.own`), among the planner's `obstacles`, with
/// the camera's footprint `footprint_depth` m deep. (The planner asks for one only when no
/// car is overdue.)
fn second_viewpoint(
    params: &GuidanceParams,
    input: &PlanningInput<'_>,
    sweep: &Sweep,
    (obstacles, footprint_depth): (&[ObstacleCell], f64),
    predictor: &mut GroundPredictor,
) -> Option<SecondViewpoint> {
    let grid = params.grids.coarse;
    let mut pockets = input.sets.first().copied()?.clone();
    pockets.and_assign(input.unseen);
    let mut pockets = params.grids.downsample(&pockets);
    pockets.and_assign(&sweep.own);
    let at = (input.state.position, input.state.yaw);
    SecondViewpoint::choose(
        params,
        &grid,
        &pockets,
        at,
        footprint_depth,
        obstacles,
        predictor,
    )
}

/// The inputs on the planning grid `grid`: `X̄` (`sets[0]`), the union of the identified
/// targets' sets (the others) and the recently hidden ground.
fn coarse_inputs(
    params: &GuidanceParams,
    input: &PlanningInput<'_>,
    grid: &GroundGrid,
    predictor: &mut GroundPredictor,
) -> (CellSet, CellSet, CellSet) {
    let grids = &params.grids;
    let (coarse, hidden) = join_if(
        params.parallel,
        || {
            in_parallel(input.sets, params.parallel, grid, predictor, |s, _| {
                grids.downsample(s)
            })
        },
        || grids.downsample(input.recently_hidden),
    );
    let mut coarse = coarse.into_iter();
    let undetected = coarse.next().unwrap_or_else(|| CellSet::empty(grid));
    let mut targets = CellSet::empty(grid);
    for set in coarse {
        targets.or_assign(&set);
    }
    (undetected, targets, hidden)
}

/// Rings of cells the sets grow by in period `d` of the lookahead: the whole cells the
/// targets' accumulated reach crosses in it.
fn rings(params: &GuidanceParams, grid: &GroundGrid, d: usize) -> usize {
    let period_s = params.steps_per_period as f64 * params.dt;
    let reach = |d: usize| (params.target_max_speed * period_s * d as f64 / grid.cell_m).floor();
    (reach(d + 1) - reach(d)) as usize
}

/// The ground the UAVs ahead in the token will see in each of the `depth` periods, where it
/// can change the sets: where they can be by then, `sets` (`X̄`, the targets') grown by every
/// ring added so far (the predictions only lose cells besides).
fn others_seen(
    params: &GuidanceParams,
    others: &[PlannedView],
    grid: &GroundGrid,
    (undetected, targets): (&CellSet, &CellSet),
    obstacles: &[ObstacleCell],
    depth: usize,
    predictor: &mut GroundPredictor,
) -> Vec<CellSet> {
    if others.is_empty() {
        return vec![CellSet::empty(grid); depth];
    }
    let per = params.steps_per_period as usize;
    let mut reachable = undetected.clone();
    reachable.or_assign(targets);
    let reachable: Vec<CellSet> = (0..depth)
        .map(|d| {
            for _ in 0..rings(params, grid, d) {
                reachable = reachable.dilate(grid, 0.0);
            }
            reachable.clone()
        })
        .collect();
    let periods: Vec<(usize, CellSet)> = reachable.into_iter().enumerate().collect();
    in_parallel(
        &periods,
        params.parallel,
        grid,
        predictor,
        |(d, reachable), predictor| {
            seen_by_others(
                params,
                grid,
                others,
                d * per..(d + 1) * per,
                obstacles,
                predictor,
                reachable,
            )
        },
    )
}

/// Where the others' plans leave their view centres, per CVS step of this horizon.
fn view_centres(params: &GuidanceParams, others: &[PlannedView]) -> Vec<Vec<Point2>> {
    others
        .iter()
        .map(|v| {
            v.poses
                .iter()
                .filter(|p| p.position.iter().all(|c| c.is_finite()) && p.yaw.is_finite())
                .map(|p| view::view_centre(&params.camera, p))
                .collect::<Vec<_>>()
        })
        .filter(|c| !c.is_empty())
        .collect()
}

/// The best sequence found by the beam search, with its cost and poses.
type Best = (Vec<f64>, Cost, Vec<CameraPose>);

/// The beam search of the module docs from `root` over `depth` periods (`period(d)` values
/// the children of period `d`): each period's children ranked, pulled to the viewpoint if
/// there is one, else by the distance map to `attractive` (made while the first period's
/// children are expanded), and the best `beam_width` kept. Returns the best sequence, the
/// sequences of the last period and those of them that leave the region.
fn beam_search<'p>(
    params: &GuidanceParams,
    root: Node,
    depth: usize,
    (attractive, viewpoint): (&CellSet, Option<SecondViewpoint>),
    period: impl Fn(usize) -> Period<'p> + Sync,
    predictor: &mut GroundPredictor,
) -> (Option<Best>, usize, usize) {
    let grid = params.grids.coarse;
    // The pull ranks the children only: made while the first period's are expanded.
    let (pull, first) = join_if(
        params.parallel,
        || match viewpoint {
            Some(v) => Pull::Viewpoint(v),
            None => Pull::Map(DistanceMap::new(&grid, attractive)),
        },
        || period(0).expand_beam(std::slice::from_ref(&root), params.parallel, predictor),
    );
    let mut first = Some(first);
    let mut beam = Vec::new();
    let mut sequences = 0;
    let mut excluded = 0;
    for d in 0..depth {
        let mut children = match first.take() {
            Some(children) => children,
            None => period(d).expand_beam(&beam, params.parallel, predictor),
        };
        for child in &mut children {
            child.rank_by(&pull, params);
        }
        if d + 1 == depth {
            sequences = children.len();
            excluded = children.iter().filter(|c| c.stray_m > 0.0).count();
        }
        // Inside the RoI first, then the least stray, then the rank; the sort is stable, so
        // equals keep the lexicographic order of their increments.
        children.sort_by(|a, b| {
            a.stray_m
                .total_cmp(&b.stray_m)
                .then(a.rank.total_cmp(&b.rank))
        });
        children.truncate(params.setfleet.beam_width.max(1) as usize);
        beam = children;
    }
    let best = beam
        .into_iter()
        .next()
        .map(|node| (node.increments, node.cost, node.poses));
    (best, sequences, excluded)
}

/// Where the planner's distance term pulls a sequence's view.
enum Pull {
    /// To the nearest cell of the attractive sets.
    Map(DistanceMap),
    /// To a second viewpoint of a pocket.
    Viewpoint(SecondViewpoint),
}

impl Pull {
    /// How far a sequence ending with its view centre at `centre` and heading `yaw` is, m.
    fn distance_m(&self, centre: &Point2, yaw: f64) -> f64 {
        match self {
            Pull::Map(map) => map.at(centre),
            Pull::Viewpoint(v) => v.distance_m(centre, yaw),
        }
    }
}

/// One period of the beam search: what every child of the beam's nodes is valued against.
struct Period<'a> {
    params: &'a GuidanceParams,
    grid: GroundGrid,
    obstacles: &'a [ObstacleCell],
    /// The ground the UAVs ahead in the token will see in this period.
    seen_ahead: &'a CellSet,
    /// Rings of cells the sets grow by in this period.
    rings: usize,
    /// The period's index in the lookahead (0 for the first).
    index: usize,
    /// Whether it is the lookahead's last period, whose sets in occluded ground are charged.
    last: bool,
    /// The ground occluded in the last periods (coarse).
    hidden: &'a CellSet,
    /// The others' planned view centres, per CVS step.
    others_centres: &'a [Vec<Point2>],
    /// Every other UAV's planned positions, per CVS step of this horizon.
    others_positions: &'a [Vec<Point2>],
    /// The footprint's mean width, m: the charge per metre beyond radio range of another.
    footprint_width_m: f64,
    /// The area of the UAV's field of view, m² (the most a crowded view is charged).
    fov_area: f64,
    /// Rings of cells the sets grow by in the growth horizon ([`super::growth`]).
    growth_rings: u32,
    /// How the fleet's sweep weighs the sets.
    sweep: &'a Sweep,
}

impl Period<'_> {
    /// The value of predicted sets `undetected` (`X̄`) and `targets` (the cars') whose grown
    /// sets have `grown` cells (`X̄`'s, the cars'): their cells weighed by the sweep, plus
    /// the cells they would grow by.
    fn value(&self, undetected: &CellSet, targets: &CellSet, grown: (u64, u64)) -> f64 {
        let w = self.params.setfleet.target_weight;
        let area = self.sweep.weigh(undetected, targets, w);
        let growth = (grown.0 - undetected.count()) as f64 + w * (grown.1 - targets.count()) as f64;
        (area + growth) * self.grid.cell_area()
    }

    /// The children of every node of `beam`, in the order of the nodes and then of the
    /// increments. In `parallel`, each node's increments are split in two halves (the turns
    /// to either side, which share first views), expanded as separate jobs. Each child
    /// depends on its node and increment only, so the children, and the decision, are the
    /// same either way.
    fn expand_beam(
        &self,
        beam: &[Node],
        parallel: bool,
        predictor: &mut GroundPredictor,
    ) -> Vec<Node> {
        let increments = &self.params.increments[..];
        let chunk = if parallel {
            increments.len().div_ceil(2)
        } else {
            increments.len()
        };
        let work: Vec<(&Node, &[f64])> = beam
            .iter()
            .flat_map(|node| {
                increments
                    .chunks(chunk.max(1))
                    .map(move |incs| (node, incs))
            })
            .collect();
        in_parallel(
            &work,
            parallel,
            &self.grid,
            predictor,
            |&(node, incs), predictor| self.expand(node, incs, predictor),
        )
        .into_iter()
        .flatten()
        .collect()
    }

    /// The children of `node` by the increments `increments`, in their order.
    fn expand(
        &self,
        node: &Node,
        increments: &[f64],
        predictor: &mut GroundPredictor,
    ) -> Vec<Node> {
        let grown = self.grown(node);
        // The views of the children's first poses, by pose: the increments the yaw rate
        // cannot reach in one CVS step (the large turns to either side) fly the same
        // first step, whose view is computed once.
        let mut first_views: Vec<(CameraPose, CellSet)> = Vec::with_capacity(increments.len());
        let mut children = Vec::with_capacity(increments.len());
        for &inc in increments {
            let flight = self.fly(node, inc, &grown.relevant, &mut first_views, predictor);
            children.push(self.child(node, inc, &grown, flight));
        }
        children
    }

    /// `node`'s sets grown by the period's rings, less the ground the UAVs ahead will see in
    /// it: what each of its children starts the period from.
    fn grown(&self, node: &Node) -> Grown {
        let grid = self.grid;
        let (mut u0, mut t0) = (node.undetected.clone(), node.targets.clone());
        for _ in 0..self.rings {
            // Radius 0 adds exactly the 8 neighbours: one ring of cells.
            u0 = u0.dilate(&grid, 0.0);
            t0 = t0.dilate(&grid, 0.0);
        }
        u0.and_not_assign(self.seen_ahead);
        t0.and_not_assign(self.seen_ahead);
        // Only the ground of the grown sets can change them.
        let mut relevant = u0.clone();
        relevant.or_assign(&t0);
        // A child's sets differ from these only on the rows its views meet, and their
        // grown sets only within the growth's rings of those: counted again there only.
        let growth = (
            Growth::of(&u0, self.growth_rings),
            Growth::of(&t0, self.growth_rings),
        );
        Grown {
            undetected: u0,
            targets: t0,
            relevant,
            growth,
        }
    }

    /// The period's flight of `node`'s child by the increment `inc`: its poses (after
    /// `node`'s), how far it strays and the ground of `relevant` its views see. The view of a
    /// first pose is taken from `first_views`, or computed and kept there.
    fn fly(
        &self,
        node: &Node,
        inc: f64,
        relevant: &CellSet,
        first_views: &mut Vec<(CameraPose, CellSet)>,
        predictor: &mut GroundPredictor,
    ) -> Flight {
        let params = self.params;
        let grid = self.grid;
        let per = params.steps_per_period as usize;
        let yaw_ref = node.state.yaw + inc;
        let mut state = node.state;
        let mut poses = node.poses.clone();
        let mut seen = CellSet::empty(&grid);
        let mut stray_m = node.stray_m;
        for step in 0..per {
            let pose;
            (state, pose) = fly_step(params, state, yaw_ref);
            stray_m = stray_m.max(stray(&params.region, &state.position));
            if step == 0 {
                let known = first_views.iter().position(|(p, _)| same_pose(p, &pose));
                let i = known.unwrap_or_else(|| {
                    let mut view = CellSet::empty(&grid);
                    predictor.add_visible_ground_within(
                        &mut view,
                        &grid,
                        &params.camera,
                        &pose,
                        self.obstacles,
                        relevant,
                    );
                    first_views.push((pose, view));
                    first_views.len() - 1
                });
                seen.or_assign(&first_views[i].1);
            } else {
                predictor.add_visible_ground_within(
                    &mut seen,
                    &grid,
                    &params.camera,
                    &pose,
                    self.obstacles,
                    relevant,
                );
            }
            poses.push(pose);
        }
        Flight {
            state,
            poses,
            seen,
            stray_m,
        }
    }

    /// `node`'s child by `inc` after its `flight`: the `grown` sets less what it saw, their
    /// value (their growth counted again where the views changed them), its view
    /// centre, the charges for crowding the others and for ending beyond radio range of them
    /// and, in the last period, its sets in occluded ground.
    fn child(&self, node: &Node, inc: f64, grown: &Grown, flight: Flight) -> Node {
        let params = self.params;
        let grid = self.grid;
        let Flight {
            state,
            poses,
            seen,
            stray_m,
        } = flight;
        let (u0, t0) = (&grown.undetected, &grown.targets);
        let mut u = u0.clone();
        u.and_not_assign(&seen);
        let mut t = t0.clone();
        t.and_not_assign(&seen);
        let changed = occupied_rows(&seen);
        let grown_cells = (
            grown.growth.0.grown_cells_after(&u, changed),
            grown.growth.1.grown_cells_after(&t, changed),
        );
        let value_sum = node.value_sum + self.value(&u, &t, grown_cells);
        let centre = poses.last().map_or(Point2::new(0.0, 0.0), |p| {
            view::view_centre(&params.camera, p)
        });
        let crowding = spread_charge(
            params.spread_m(),
            self.fov_area,
            &centre,
            self.others_centres,
            poses.len(),
        );
        let apart = self.footprint_width_m
            * beyond_range_m(
                params.comms_range_m,
                &state.position.xy(),
                self.others_positions,
                poses.len(),
            );
        let hidden_m2 = if self.last {
            (u.intersection_count(self.hidden) + t.intersection_count(self.hidden)) as f64
                * grid.cell_area()
        } else {
            0.0
        };
        let mut increments = node.increments.clone();
        increments.push(inc);
        Node {
            increments,
            state,
            poses,
            undetected: u,
            targets: t,
            value_sum,
            stray_m,
            centre,
            crowding,
            apart,
            rank: 0.0,
            cost: Cost {
                area_m2: value_sum / (self.index + 1) as f64,
                distance_m: 0.0,
                hidden_m2,
                total: 0.0,
            },
        }
    }
}

/// A beam node's sets grown for one period, which its children start from.
struct Grown {
    /// `X̄`, grown.
    undetected: CellSet,
    /// The identified targets' sets, grown.
    targets: CellSet,
    /// The ground that can change them: theirs.
    relevant: CellSet,
    /// Their sets grown over the growth horizon (`X̄`'s, the targets').
    growth: (Growth, Growth),
}

/// One period's flight of a child.
struct Flight {
    /// Its state at the end of the period.
    state: UavState,
    /// Its poses so far, the period's appended.
    poses: Vec<CameraPose>,
    /// The ground its views of the period see (of the sets' ground).
    seen: CellSet,
    /// How far it strayed out of the region so far, m.
    stray_m: f64,
}

/// `(a(), b())`, side by side on rayon's pool when `parallel`.
fn join_if<A: Send, B: Send>(
    parallel: bool,
    a: impl FnOnce() -> A + Send,
    b: impl FnOnce() -> B + Send,
) -> (A, B) {
    if parallel {
        rayon::join(a, b)
    } else {
        (a(), b())
    }
}

/// `task` applied to every item, in the order of the items: on this thread with `predictor`
/// unless `parallel`, else on rayon's pool, each job with a predictor of its own for `grid`.
fn in_parallel<T: Sync, R: Send>(
    items: &[T],
    parallel: bool,
    grid: &GroundGrid,
    predictor: &mut GroundPredictor,
    task: impl Fn(&T, &mut GroundPredictor) -> R + Sync,
) -> Vec<R> {
    if !parallel || items.len() < 2 {
        return items.iter().map(|item| task(item, predictor)).collect();
    }
    items
        .par_iter()
        .map_init(
            || GroundPredictor::new(grid),
            |predictor, item| task(item, predictor),
        )
        .collect()
}

/// Ground of `relevant` the UAVs ahead in the token will see during the CVS steps `steps` of
/// this horizon (as much of it as their plans cover).
fn seen_by_others(
    params: &GuidanceParams,
    grid: &GroundGrid,
    others: &[PlannedView],
    steps: std::ops::Range<usize>,
    obstacles: &[ObstacleCell],
    predictor: &mut GroundPredictor,
    relevant: &CellSet,
) -> CellSet {
    let mut seen = CellSet::empty(grid);
    for view in others {
        let end = steps.end.min(view.poses.len());
        let start = steps.start.min(end);
        for pose in &view.poses[start..end] {
            if pose.position.iter().all(|v| v.is_finite()) && pose.yaw.is_finite() {
                predictor.add_visible_ground_within(
                    &mut seen,
                    grid,
                    &params.camera,
                    pose,
                    obstacles,
                    relevant,
                );
            }
        }
    }
    seen
}

/// Where the others' plans take them (horizontally), per CVS step of this horizon.
fn positions(others: &[PlannedView]) -> Vec<Vec<Point2>> {
    others
        .iter()
        .map(|v| {
            v.poses
                .iter()
                .map(|p| p.position.xy())
                .filter(|p| p.iter().all(|c| c.is_finite()))
                .collect::<Vec<_>>()
        })
        .filter(|c| !c.is_empty())
        .collect()
}

/// How far beyond radio range (`range_m`) a UAV at `at` is from each of the others at CVS
/// step `step` (their planned positions then, or their last), summed, metres: 0 with an
/// infinite range.
fn beyond_range_m(range_m: f64, at: &Point2, others: &[Vec<Point2>], step: usize) -> f64 {
    if range_m.is_infinite() {
        return 0.0;
    }
    others
        .iter()
        .filter_map(|c| c.get(step.saturating_sub(1)).or(c.last()))
        .map(|q| ((q - at).norm() - range_m).max(0.0))
        .sum()
}

/// The charge for a view centre near the others' planned view centres at the same CVS step
/// (or their last one): up to `fov_area` each, falling linearly to 0 at `spread_m`.
fn spread_charge(
    spread_m: f64,
    fov_area: f64,
    centre: &Point2,
    others: &[Vec<Point2>],
    step: usize,
) -> f64 {
    if spread_m <= 0.0 {
        return 0.0;
    }
    others
        .iter()
        .filter_map(|c| c.get(step.saturating_sub(1)).or(c.last()))
        .map(|q| fov_area * (1.0 - (q - centre).norm() / spread_m).max(0.0))
        .sum()
}

/// The first and last rows holding a cell of `set`, if any.
fn occupied_rows(set: &CellSet) -> Option<(u32, u32)> {
    let occupied = |y: &u32| set.row(*y).iter().any(|&w| w != 0);
    let first = (0..set.ny()).find(occupied)?;
    let last = (first..set.ny()).rev().find(occupied)?;
    Some((first, last))
}

/// `row[x] <- min(row[x], next[x] + a, next[x - 1] + b, next[x + 1] + b)`: the neighbours of a
/// row in the row passed just before.
fn relax_from_row(row: &mut [f32], next: &[f32], a: f32, b: f32) {
    let n = row.len();
    for x in 0..n {
        let mut v = row[x].min(next[x] + a);
        if x > 0 {
            v = v.min(next[x - 1] + b);
        }
        if x + 1 < n {
            v = v.min(next[x + 1] + b);
        }
        row[x] = v;
    }
}

/// `row[x] <- min(row[x], row[x - 1] + a)`, left to right.
fn scan_forward(row: &mut [f32], a: f32) {
    for x in 1..row.len() {
        row[x] = row[x].min(row[x - 1] + a);
    }
}

/// `row[x] <- min(row[x], row[x + 1] + a)`, right to left.
fn scan_backward(row: &mut [f32], a: f32) {
    for x in (0..row.len().saturating_sub(1)).rev() {
        row[x] = row[x].min(row[x + 1] + a);
    }
}

/// Distance from every planning cell to the nearest cell of a set (chamfer 3-4 distance, within
/// about 8 % of the Euclidean distance), metres.
struct DistanceMap {
    grid: GroundGrid,
    metres: Vec<f32>,
    /// Used when the set is empty: nothing to go to.
    empty: bool,
}

impl DistanceMap {
    fn new(grid: &GroundGrid, set: &CellSet) -> Self {
        let (nx, ny) = (grid.nx as usize, grid.ny as usize);
        let far = f32::INFINITY;
        let mut d = vec![far; nx * ny];
        for (x, y) in set.iter() {
            d[y as usize * nx + x as usize] = 0.0;
        }
        let (a, b) = (
            grid.cell_m as f32,
            grid.cell_m as f32 * std::f32::consts::SQRT_2,
        );
        // Each pass takes, at every cell, the least of its value and of its neighbours' already
        // passed plus the step to them. The neighbours of the previous row are taken first over
        // the whole row, then the one before in the row, in a scan: the same minimum of the
        // same sums, so the same values as cell by cell, with a shorter chain of dependent
        // operations.
        if ny > 0 {
            scan_forward(&mut d[..nx], a);
            for y in 1..ny {
                let (done, row) = d.split_at_mut(y * nx);
                relax_from_row(&mut row[..nx], &done[(y - 1) * nx..], a, b);
                scan_forward(&mut row[..nx], a);
            }
            scan_backward(&mut d[(ny - 1) * nx..], a);
            for y in (0..ny - 1).rev() {
                let (row, done) = d.split_at_mut((y + 1) * nx);
                relax_from_row(&mut row[y * nx..], &done[..nx], a, b);
                scan_backward(&mut row[y * nx..], a);
            }
        }
        Self {
            grid: *grid,
            metres: d,
            empty: set.is_empty(),
        }
    }

    /// The distance at `p` (clamped into the grid); 0 when the set is empty.
    fn at(&self, p: &Point2) -> f64 {
        if self.empty {
            return 0.0;
        }
        let g = &self.grid;
        let clamp = |v: f64, n: u32| v.clamp(0.0, n as f64 - 1.0) as usize;
        let x = clamp(((p.x - g.origin.x) / g.cell_m).floor(), g.nx);
        let y = clamp(((p.y - g.origin.y) / g.cell_m).floor(), g.ny);
        f64::from(self.metres[y * g.nx as usize + x])
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::guidance::GuidanceParams;
    use crate::guidance::paper::plan as paper_plan;
    use protocol::scenario::{Planner, Scenario, SweepPlan};
    use sets::math::Point3;
    use sets::raster::Coverage;

    /// The `setfleet` planner over a 300 m region, deciding every 1 s, `λ` = 10.
    pub(crate) fn params() -> GuidanceParams {
        let mut s = Scenario::default();
        s.region.half_extent_m = 150.0;
        s.guidance.planner = Planner::Setfleet;
        s.timing.guidance_period_s = 1.0;
        s.guidance.lambda = 10.0;
        GuidanceParams::from_scenario(&s)
    }

    fn blob(params: &GuidanceParams, centre: Point2, radius: f64) -> CellSet {
        let mut s = CellSet::empty(&params.grids.fine);
        s.fill_disc(&params.grids.fine, centre, radius, Coverage::Outer);
        s
    }

    fn decide(params: &GuidanceParams, sets: &[&CellSet], others: &[PlannedView]) -> Decision {
        let hidden = CellSet::empty(&params.grids.fine);
        plan(
            params,
            &PlanningInput {
                uav: 1,
                state: UavState {
                    position: Point3::new(0.0, 0.0, 60.0),
                    yaw: 0.0,
                },
                sets,
                recently_hidden: &hidden,
                unseen: &hidden,
                obstacles: &[],
                others,
                fleet: &[0, 1],
            },
        )
    }

    /// A plan counts only from a UAV in radio range: this agent never fuses what one out of
    /// range sees, so that UAV's views do not clear its predicted sets.
    #[test]
    fn a_plan_from_out_of_radio_range_clears_nothing() {
        use super::super::tests::watching_the_south;
        let mut p = params();
        let hidden = CellSet::empty(&p.grids.fine);
        let others = [watching_the_south()];
        let input = PlanningInput {
            uav: 1,
            state: UavState {
                position: Point3::new(0.0, 0.0, 60.0),
                yaw: 0.0,
            },
            sets: &[],
            recently_hidden: &hidden,
            unseen: &hidden,
            obstacles: &[],
            others: &others,
            fleet: &[0, 1],
        };
        // The watcher flies 20 m away.
        assert_eq!(others_in_range(&p, &input).len(), 1);
        p.comms_range_m = 25.0;
        assert_eq!(others_in_range(&p, &input).len(), 1);
        p.comms_range_m = 15.0;
        assert!(others_in_range(&p, &input).is_empty());
    }

    #[test]
    fn beyond_range_is_summed_over_the_others_at_the_same_step() {
        let others = vec![
            vec![Point2::new(0.0, 100.0), Point2::new(0.0, 200.0)],
            vec![Point2::new(0.0, -130.0)],
        ];
        let at = Point2::new(0.0, 0.0);
        assert_eq!(beyond_range_m(50.0, &at, &others, 1), 50.0 + 80.0);
        // Step 2: the first has flown on to 200 m, the second stays at its last, 130 m.
        assert_eq!(beyond_range_m(50.0, &at, &others, 2), 150.0 + 80.0);
        assert_eq!(beyond_range_m(150.0, &at, &others, 2), 50.0);
        assert_eq!(beyond_range_m(f64::INFINITY, &at, &others, 2), 0.0);
        assert_eq!(beyond_range_m(50.0, &at, &[], 2), 0.0);
    }

    /// Out of radio range of the others, a UAV is charged the footprint's width per metre
    /// beyond it: with the same ground to clear on either side, it turns towards the side
    /// where the other UAV flies.
    #[test]
    fn out_of_range_a_uav_turns_towards_the_others() {
        let mut p = params();
        p.comms_range_m = 60.0;
        let mut both = blob(&p, Point2::new(0.0, 100.0), 20.0);
        both.or_assign(&blob(&p, Point2::new(0.0, -100.0), 20.0));
        let other_at = |y: f64| PlannedView {
            uav: 0,
            poses: (0..12)
                .map(|_| CameraPose {
                    position: Point3::new(0.0, y, 70.0),
                    yaw: 0.0,
                })
                .collect(),
        };
        let d = decide(&p, &[&both], &[other_at(140.0)]);
        assert!(d.increments[0] > 0.0, "{d:?}");
        let d = decide(&p, &[&both], &[other_at(-140.0)]);
        assert!(d.increments[0] < 0.0, "{d:?}");
    }

    #[test]
    fn the_distance_map_measures_to_the_nearest_cell() {
        let grid = GroundGrid::new(50.0, 1.0);
        let mut s = CellSet::empty(&grid);
        s.set((50, 50), true);
        let d = DistanceMap::new(&grid, &s);
        let at = |x: f64, y: f64| d.at(&Point2::new(x, y));
        assert_eq!(at(0.5, 0.5), 0.0);
        assert!((at(10.5, 0.5) - 10.0).abs() < 1e-6);
        assert!((at(10.5, 10.5) - 10.0 * std::f64::consts::SQRT_2).abs() < 1e-3);
    }

    #[test]
    fn turns_toward_the_sets_and_plans_its_whole_lookahead() {
        let p = params();
        let north = blob(&p, Point2::new(0.0, 80.0), 20.0);
        let d = decide(&p, &[&north], &[]);
        assert!(d.increments[0] > 0.0, "{d:?}");
        let south = blob(&p, Point2::new(0.0, -80.0), 20.0);
        let d = decide(&p, &[&south], &[]);
        assert!(d.increments[0] < 0.0, "{d:?}");
        assert_eq!(d.increments.len(), p.setfleet.lookahead_periods as usize);
        assert_eq!(
            d.view.poses.len(),
            (p.setfleet.lookahead_periods * p.steps_per_period) as usize
        );
        assert_eq!(
            d.sequences,
            p.setfleet.beam_width as usize * p.increments.len()
        );
    }

    #[test]
    fn leaves_to_the_uav_ahead_what_it_will_see() {
        let p = params();
        let north = blob(&p, Point2::new(0.0, 80.0), 20.0);
        let south = blob(&p, Point2::new(0.0, -80.0), 20.0);
        let d = decide(
            &p,
            &[&north, &south],
            &[super::super::tests::watching_the_south()],
        );
        assert!(d.increments[0] > 0.0, "{d:?}");
    }

    /// A car whose set outgrew the schedule's bound, in the deciding UAV's lane, draws it
    /// away from a larger `X̄`; the same set under the bound does not.
    #[test]
    fn an_overdue_car_in_the_uavs_lane_is_revisited_first() {
        let mut p = params();
        p.setfleet.target_weight = 1.0;
        let undetected = blob(&p, Point2::new(0.0, 80.0), 25.0);
        // UAV 1's lane is the east half; the car's set lies there, south.
        let car = blob(&p, Point2::new(60.0, -80.0), 12.0);
        p.setfleet.track_revisit_s = 60.0;
        let d = decide(&p, &[&undetected, &car], &[]);
        assert!(
            d.increments[0] > 0.0,
            "under the bound it searches north: {d:?}"
        );
        p.setfleet.track_revisit_s = 1.0;
        let d = decide(&p, &[&undetected, &car], &[]);
        assert!(d.increments[0] < 0.0, "overdue, it revisits the car: {d:?}");
    }

    /// The chamfer distance computed cell by cell, each pass in scan order (the map's
    /// definition).
    fn reference_distances(grid: &GroundGrid, set: &CellSet) -> Vec<f32> {
        let (nx, ny) = (grid.nx as usize, grid.ny as usize);
        let mut d = vec![f32::INFINITY; nx * ny];
        for (x, y) in set.iter() {
            d[y as usize * nx + x as usize] = 0.0;
        }
        let (a, b) = (
            grid.cell_m as f32,
            grid.cell_m as f32 * std::f32::consts::SQRT_2,
        );
        let at = |d: &[f32], x: usize, y: usize| d[y * nx + x];
        for y in 0..ny {
            for x in 0..nx {
                let mut v = at(&d, x, y);
                if x > 0 {
                    v = v.min(at(&d, x - 1, y) + a);
                }
                if y > 0 {
                    v = v.min(at(&d, x, y - 1) + a);
                    if x > 0 {
                        v = v.min(at(&d, x - 1, y - 1) + b);
                    }
                    if x + 1 < nx {
                        v = v.min(at(&d, x + 1, y - 1) + b);
                    }
                }
                d[y * nx + x] = v;
            }
        }
        for y in (0..ny).rev() {
            for x in (0..nx).rev() {
                let mut v = at(&d, x, y);
                if x + 1 < nx {
                    v = v.min(at(&d, x + 1, y) + a);
                }
                if y + 1 < ny {
                    v = v.min(at(&d, x, y + 1) + a);
                    if x + 1 < nx {
                        v = v.min(at(&d, x + 1, y + 1) + b);
                    }
                    if x > 0 {
                        v = v.min(at(&d, x - 1, y + 1) + b);
                    }
                }
                d[y * nx + x] = v;
            }
        }
        d
    }

    proptest::proptest! {
        /// The map's row-wise passes give the cell-by-cell passes' values, bit for bit.
        #[test]
        fn the_distance_map_has_the_values_of_the_cell_by_cell_passes(
            half in 1.0_f64..40.0,
            cell in proptest::sample::select(vec![0.5, 1.0, 2.5]),
            discs in proptest::collection::vec(
                (-50.0_f64..50.0, -50.0_f64..50.0, 0.0_f64..8.0), 0..5),
        ) {
            let grid = GroundGrid::new(half, cell);
            let mut set = CellSet::empty(&grid);
            for (x, y, r) in discs {
                set.fill_disc(&grid, Point2::new(x, y), r, Coverage::Outer);
            }
            let map = DistanceMap::new(&grid, &set);
            let reference = reference_distances(&grid, &set);
            proptest::prop_assert_eq!(map.metres.len(), reference.len());
            for (got, want) in map.metres.iter().zip(&reference) {
                proptest::prop_assert_eq!(got.to_bits(), want.to_bits());
            }
        }
    }

    /// Sharing the beam with rayon's pool decides exactly as one thread does, with buildings
    /// casting shadows and plans of UAVs ahead in the token.
    #[test]
    fn the_pool_decides_as_one_thread() {
        let parallel = params();
        assert!(parallel.parallel);
        let sets = [
            blob(&parallel, Point2::new(40.0, 60.0), 25.0),
            blob(&parallel, Point2::new(-70.0, -20.0), 10.0),
            blob(&parallel, Point2::new(10.0, -90.0), 15.0),
        ];
        let sets: Vec<&CellSet> = sets.iter().collect();
        let hidden = blob(&parallel, Point2::new(-30.0, 30.0), 20.0);
        // A block of buildings of uneven heights north-east and a tower south-west.
        let mut obstacles = Vec::new();
        for i in 0..6 {
            for j in 0..4 {
                let (x, y) = (20.0 + 5.0 * f64::from(i), 20.0 + 5.0 * f64::from(j));
                obstacles.push(ObstacleCell {
                    rect: sets::grid::Rect {
                        min: Point2::new(x, y),
                        max: Point2::new(x + 5.0, y + 5.0),
                    },
                    height_m: 8.0 + 3.0 * f64::from((i * 7 + j * 3) % 5),
                });
            }
        }
        obstacles.push(ObstacleCell {
            rect: sets::grid::Rect {
                min: Point2::new(-40.0, -40.0),
                max: Point2::new(-35.0, -35.0),
            },
            height_m: 45.0,
        });
        let others = [super::super::tests::watching_the_south()];
        // Every way of sharing the search, with the schedule and the second viewpoints.
        let mut shared = Vec::new();
        for sweep in [SweepPlan::None, SweepPlan::Sectors, SweepPlan::Lanes] {
            let mut p = parallel.clone();
            p.setfleet.sweep = sweep;
            p.setfleet.track_revisit_s = 2.0;
            p.setfleet.second_viewpoints = true;
            shared.push(p);
        }
        for parallel in std::iter::once(&parallel).chain(&shared) {
            let serial = GuidanceParams {
                parallel: false,
                ..parallel.clone()
            };
            for (yaw, others) in [(0.0, &others[..0]), (2.0, &others[..]), (-1.0, &others[..])] {
                let input = PlanningInput {
                    uav: 1,
                    state: UavState {
                        position: Point3::new(-10.0, 5.0, 60.0),
                        yaw,
                    },
                    sets: &sets,
                    recently_hidden: &hidden,
                    unseen: &hidden,
                    obstacles: &obstacles,
                    others,
                    fleet: &[0, 1],
                };
                assert_eq!(plan(parallel, &input), plan(&serial, &input));
            }
        }
    }

    #[test]
    fn decisions_are_deterministic_and_the_paper_is_untouched() {
        let p = params();
        let a = blob(&p, Point2::new(40.0, 60.0), 25.0);
        let b = blob(&p, Point2::new(-70.0, -20.0), 10.0);
        assert_eq!(decide(&p, &[&a, &b], &[]), decide(&p, &[&a, &b], &[]));
        // The dispatcher runs the paper's MPC unless asked for setfleet.
        let paper = GuidanceParams::from_scenario(&Scenario::default());
        let hidden = CellSet::empty(&paper.grids.fine);
        let everything = CellSet::full(&paper.grids.fine);
        let input = PlanningInput {
            uav: 0,
            state: UavState {
                position: Point3::new(0.0, 0.0, 60.0),
                yaw: 0.0,
            },
            sets: &[&everything],
            recently_hidden: &hidden,
            unseen: &hidden,
            obstacles: &[],
            others: &[],
            fleet: &[0, 1],
        };
        assert_eq!(
            crate::guidance::decide(&paper, &input),
            paper_plan(&paper, &input)
        );
    }
}
