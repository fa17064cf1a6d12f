//! The topics a run is seen on, their schemas and how often each is written.
//!
//! Every message's log time is the simulated time of its step (nanoseconds from the start of
//! the run), so a recording plays back at simulated speed and a live view's clock is the
//! world's. Positions are metres in the `world` frame: x east, y north, z up, the origin at
//! the centre of the region.

use std::collections::BTreeMap;
use std::sync::Arc;

use foxglove::messages::{CompressedImage, FrameTransforms, Grid, ImageAnnotations, SceneUpdate};
use foxglove::{Channel, Context};

/// The fixed frame of the city.
pub const WORLD_FRAME: &str = "world";

/// The frame of UAV `uav`'s body: at its camera's optical centre, x along its heading.
pub fn uav_frame(uav: u32) -> String {
    format!("uav{uav}")
}

/// The frame of UAV `uav`'s camera, optical convention: z along the optical axis, x to the
/// right of the image, y down it.
pub fn camera_frame(uav: u32) -> String {
    format!("uav{uav}/camera")
}

/// `foxglove.FrameTransforms`: `world` to every UAV, and every UAV to its camera, per step.
pub const TRANSFORMS: &str = "/tf";
/// `foxglove.SceneUpdate`: the buildings, as boxes; at the first step and every
/// [`SLOW_PERIOD_S`] after, so a live view that connects late still gets them.
pub const CITY: &str = "/city";
/// `foxglove.SceneUpdate`: every UAV (an arrow along its heading and its id) and its camera's
/// footprint on the ground, per step.
pub const UAVS: &str = "/uavs";
/// `foxglove.SceneUpdate`: the true cars, per step. Kept apart from the estimates on purpose:
/// hide it to see what the fleet knows.
pub const TRUTH: &str = "/truth/cars";
/// `foxglove.SceneUpdate`: the plans of the current guidance round, as the token carries them
/// (each UAV's predicted camera positions over the horizon), per step.
pub const PLANS: &str = "/guidance/plans";
/// `foxglove.Grid`: `X̄`, the ground where a target not yet identified may be, per step.
pub const UNDETECTED: &str = "/sets/undetected";
/// `foxglove.Grid`: `S^o`, the ground within the safety distance of an obstacle, where no car
/// can be, per step.
pub const OBSTACLE_NEIGHBOURHOOD: &str = "/sets/obstacle_neighbourhood";
/// `foxglove.Grid`: `H̄`, the ground never seen, per step.
pub const UNSEEN: &str = "/sets/unseen";
/// `foxglove.Grid`: the explored ground, per step.
pub const EXPLORED: &str = "/sets/explored";
/// `foxglove.Grid`: `X_j`, target `j`'s set, on topic `/sets/targets/{j}` once `j` is
/// identified, per step.
pub const TARGET_PREFIX: &str = "/sets/targets/";
/// `foxglove.Grid`: the fleet's occupancy elevation map (every agent's map merged): fields
/// `height_m` (float32) and `status` (uint8: 0 unknown, 1 obstacle, 2 ground); when it
/// changed, at most every [`SLOW_PERIOD_S`].
pub const OEM: &str = "/map/oem";
/// `foxglove.CompressedImage` (PNG): the chosen UAV's labels, a colour per class; every
/// [`IMAGE_PERIOD_S`].
pub const LABELS: &str = "/camera/labels";
/// `foxglove.CompressedImage` (PNG, 8-bit grey): the chosen UAV's measured range per pixel,
/// in whole metres (0 where nothing was measured, 255 from 255 m on); with the labels.
pub const DEPTH: &str = "/camera/depth";
/// `foxglove.ImageAnnotations`: the identified targets' boxes and ids on those images.
pub const BOXES: &str = "/camera/boxes";
/// `FleetMetrics` (protobuf, the SDK's derived encoding): the step's metrics, as `timeseries.csv`
/// has them, per step.
pub const METRICS: &str = "/metrics";

/// Every topic but the target sets' ([`TARGET_PREFIX`]), which appear as targets are
/// identified.
pub const FIXED: [&str; 14] = [
    TRANSFORMS,
    CITY,
    UAVS,
    TRUTH,
    PLANS,
    UNDETECTED,
    OBSTACLE_NEIGHBOURHOOD,
    UNSEEN,
    EXPLORED,
    OEM,
    LABELS,
    DEPTH,
    BOXES,
    METRICS,
];

/// Simulated seconds between two camera images of the chosen UAV.
pub const IMAGE_PERIOD_S: f64 = 1.0;
/// Simulated seconds between two messages of the slow topics ([`CITY`], [`OEM`]).
pub const SLOW_PERIOD_S: f64 = 5.0;

/// The topic of target `id`'s set.
pub fn target_topic(id: u32) -> String {
    format!("{TARGET_PREFIX}{id}")
}

/// The step's metrics ([`METRICS`]): the mean over the agents measured, as `timeseries.csv`
/// gives it; a metric that no agent had is NaN.
#[derive(Clone, Debug, Default, foxglove::Encode)]
pub struct FleetMetrics {
    /// Step.
    pub step: u64,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// Agents the world sent the step's frame to.
    pub live_agents: u32,
    /// Estimates of the step that were measured.
    pub estimates: u32,
    /// Explored share of the region, mean over agents.
    pub explored: f64,
    /// Unobserved area `UA`, share of the region, mean over agents.
    pub ua: f64,
    /// Observed area `OA`, share of the region, mean over agents.
    pub oa: f64,
    /// Mean area of the identified targets' sets, m².
    pub target_set_area_m2: f64,
    /// Mean distance from a target to the centre of its set, metres.
    pub loc_error_m: f64,
    /// Targets identified, mean over agents.
    pub identified: f64,
    /// Targets identified by at least one agent.
    pub identified_any: u32,
    /// Guarantee violations this step (0 in every correct run).
    pub violations: u32,
}

/// The run's channels on one Foxglove context.
pub(super) struct Channels {
    ctx: Arc<Context>,
    pub(super) transforms: Channel<FrameTransforms>,
    pub(super) city: Channel<SceneUpdate>,
    pub(super) uavs: Channel<SceneUpdate>,
    pub(super) truth: Channel<SceneUpdate>,
    pub(super) plans: Channel<SceneUpdate>,
    pub(super) undetected: Channel<Grid>,
    pub(super) obstacle_neighbourhood: Channel<Grid>,
    pub(super) unseen: Channel<Grid>,
    pub(super) explored: Channel<Grid>,
    targets: BTreeMap<u32, Channel<Grid>>,
    pub(super) oem: Channel<Grid>,
    pub(super) labels: Channel<CompressedImage>,
    pub(super) depth: Channel<CompressedImage>,
    pub(super) boxes: Channel<ImageAnnotations>,
    pub(super) metrics: Channel<FleetMetrics>,
}

impl Channels {
    pub(super) fn new(ctx: &Arc<Context>) -> Channels {
        Channels {
            ctx: ctx.clone(),
            transforms: ctx.channel_builder(TRANSFORMS).build(),
            city: ctx.channel_builder(CITY).build(),
            uavs: ctx.channel_builder(UAVS).build(),
            truth: ctx.channel_builder(TRUTH).build(),
            plans: ctx.channel_builder(PLANS).build(),
            undetected: ctx.channel_builder(UNDETECTED).build(),
            obstacle_neighbourhood: ctx.channel_builder(OBSTACLE_NEIGHBOURHOOD).build(),
            unseen: ctx.channel_builder(UNSEEN).build(),
            explored: ctx.channel_builder(EXPLORED).build(),
            targets: BTreeMap::new(),
            oem: ctx.channel_builder(OEM).build(),
            labels: ctx.channel_builder(LABELS).build(),
            depth: ctx.channel_builder(DEPTH).build(),
            boxes: ctx.channel_builder(BOXES).build(),
            metrics: ctx.channel_builder(METRICS).build(),
        }
    }

    /// Target `id`'s channel, made when the target is first identified.
    pub(super) fn target(&mut self, id: u32) -> &Channel<Grid> {
        let ctx = &self.ctx;
        self.targets
            .entry(id)
            .or_insert_with(|| ctx.channel_builder(target_topic(id)).build())
    }
}
