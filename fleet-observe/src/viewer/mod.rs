//! Seeing a run in Foxglove: a recording (`fleet run --record FILE.mcap`) and a live view
//! (`fleet run --live [[HOST:]PORT]`), both fed by the observer through one [`Viewer`].
//!
//! The observer hands the viewer every measured step ([`StepView`]: the truth, the chosen
//! agent's fused sets, the fleet's map, the token's plans and the metrics) and the chosen
//! UAV's camera frames; the viewer turns them into Foxglove's well-known messages on the
//! topics of [`topics`] and logs them on one Foxglove context, whose sinks are the MCAP
//! writer and the WebSocket server:
//!
//! | topic | schema | what |
//! |---|---|---|
//! | `/tf` | `foxglove.FrameTransforms` | `world` → `uav{i}` → `uav{i}/camera` |
//! | `/city` | `foxglove.SceneUpdate` | the buildings |
//! | `/uavs` | `foxglove.SceneUpdate` | the UAVs and their camera footprints |
//! | `/truth/cars` | `foxglove.SceneUpdate` | the true cars |
//! | `/guidance/plans` | `foxglove.SceneUpdate` | the plans in the token |
//! | `/sets/undetected`, `/sets/obstacle_neighbourhood`, `/sets/unseen`, `/sets/explored` | `foxglove.Grid` | `X̄`, `S^o`, `H̄`, explored ground |
//! | `/sets/targets/{j}` | `foxglove.Grid` | `X_j` |
//! | `/map/oem` | `foxglove.Grid` | the occupancy elevation map |
//! | `/camera/labels`, `/camera/depth` | `foxglove.CompressedImage` | the chosen UAV's frames |
//! | `/camera/boxes` | `foxglove.ImageAnnotations` | the identified targets' boxes |
//! | `/metrics` | `FleetMetrics` | the step's metrics |
//!
//! Log times are simulated time, so a recording replays at the world's pace and the live
//! server announces the world's clock (Foxglove's `time` capability). Viewing never changes
//! the run: the viewer only reads what the observer measured, and a message no client
//! subscribes to is not even encoded.

pub mod grids;
pub mod images;
pub mod scene;
pub mod topics;

use std::fmt;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::str::FromStr;

use foxglove::messages::Timestamp;
use foxglove::websocket::Capability;
use foxglove::{
    Context, McapCompression, McapWriteOptions, McapWriterHandle, WebSocketServerHandle,
};
use protocol::camera::CameraModel;
use protocol::frame::CvsFrame;
use protocol::scenario::Scenario;
use sets::grid::GroundGrid;
use world_server::scene::Building;

use crate::observe::StepMetrics;
use crate::observe::metrics::{FusedSets, SetMetrics};
use crate::observe::sink::{Sink, SinkError, SinkFile, SinkMaker, StepView};
use topics::{Channels, FleetMetrics, IMAGE_PERIOD_S, SLOW_PERIOD_S};

/// The port `--live` listens on when none is given (Foxglove's default).
pub const DEFAULT_LIVE_PORT: u16 = 8765;

/// What to show the run to.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewConfig {
    /// Write an MCAP recording here.
    pub record: Option<PathBuf>,
    /// Serve a live view here.
    pub live: Option<LiveAddress>,
    /// The UAV whose sets and camera are shown (when its estimate of a step is missing,
    /// the lowest UAV measured at that step stands in).
    pub uav: u32,
}

impl ViewConfig {
    /// Whether anything is to be shown.
    pub fn is_on(&self) -> bool {
        self.record.is_some() || self.live.is_some()
    }
}

/// Where the live view listens: `--live [[HOST:]PORT]`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LiveAddress {
    /// Interface to bind, `127.0.0.1` unless given.
    pub host: String,
    /// Port (0: any free one; the one taken is printed).
    pub port: u16,
}

impl Default for LiveAddress {
    fn default() -> Self {
        LiveAddress {
            host: "127.0.0.1".into(),
            port: DEFAULT_LIVE_PORT,
        }
    }
}

/// Why a `--live` value could not be read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("{0:?}: expected PORT or HOST:PORT, e.g. 8765 or 0.0.0.0:8765")]
pub struct LiveAddressError(String);

impl FromStr for LiveAddress {
    type Err = LiveAddressError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let bad = || LiveAddressError(text.to_owned());
        let (host, port) = match text.rsplit_once(':') {
            Some((host, port)) if !host.is_empty() => (host.to_owned(), port),
            Some(_) => return Err(bad()),
            None => (LiveAddress::default().host, text),
        };
        let port = port.trim().parse().map_err(|_| bad())?;
        Ok(LiveAddress { host, port })
    }
}

impl fmt::Display for LiveAddress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.host, self.port)
    }
}

/// Why the viewer could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The recording could not be created or completed.
    #[error("cannot write the recording {path}")]
    Record {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: foxglove::FoxgloveError,
    },
    /// The live server could not start.
    #[error("cannot serve the live view on {address}")]
    Live {
        /// Where it was to listen.
        address: LiveAddress,
        /// Why.
        #[source]
        source: foxglove::FoxgloveError,
    },
}

/// The recording and the live view of a run.
pub struct Viewer {
    channels: Channels,
    mcap: Option<(PathBuf, McapWriterHandle<BufWriter<File>>)>,
    /// The live server and the interface it listens on.
    server: Option<(WebSocketServerHandle, String)>,
    buildings: foxglove::messages::SceneUpdate,
    camera: CameraModel,
    car_size_m: [f64; 3],
    grid: GroundGrid,
    /// When the slow topics and the images were last logged, simulated seconds.
    last_city_s: Option<f64>,
    last_oem_s: Option<f64>,
    last_image_s: Option<f64>,
    /// Whether the map changed since it was last logged.
    oem_changed: bool,
    /// The UAV whose camera frames are shown.
    uav: u32,
}

impl Viewer {
    /// The viewer `config` asks for, as one of the run's sinks (none when it asks for
    /// nothing). A viewer that cannot start fails the run.
    pub fn maker(config: ViewConfig) -> SinkMaker {
        Box::new(move |scenario, buildings| {
            Ok(Viewer::start(&config, scenario, buildings)?.map(|v| Box::new(v) as Box<dyn Sink>))
        })
    }

    /// Opens the recording and starts the live server that `config` asks for, for a run of
    /// `scenario` in a city of `buildings`; `None` when it asks for neither. Call it outside
    /// any tokio runtime: the live server runs on the Foxglove SDK's own.
    pub fn start(
        config: &ViewConfig,
        scenario: &Scenario,
        buildings: &[Building],
    ) -> Result<Option<Viewer>, ViewerError> {
        if !config.is_on() {
            return Ok(None);
        }
        let ctx = Context::new();
        let mcap = match &config.record {
            Some(path) => {
                let record = |source| ViewerError::Record {
                    path: path.clone(),
                    source,
                };
                let file =
                    File::create(path).map_err(|e| record(foxglove::FoxgloveError::IoError(e)))?;
                let options = McapWriteOptions::default().compression(Some(McapCompression::Lz4));
                let handle = ctx
                    .mcap_writer_with_options(options)
                    .create(BufWriter::new(file))
                    .map_err(record)?;
                Some((path.clone(), handle))
            }
            None => None,
        };
        let server = match &config.live {
            Some(address) => Some((
                ctx.websocket_server()
                    .name("setfleet")
                    .bind(address.host.clone(), address.port)
                    .capabilities([Capability::Time])
                    .start_blocking()
                    .map_err(|source| ViewerError::Live {
                        address: address.clone(),
                        source,
                    })?,
                address.host.clone(),
            )),
            None => None,
        };
        Ok(Some(Viewer {
            channels: Channels::new(&ctx),
            mcap,
            server,
            buildings: scene::city(buildings, Timestamp::new(0, 0)),
            uav: config.uav,
            camera: scenario.camera_model(),
            car_size_m: scenario.targets.size_m,
            grid: scenario.grid(),
            last_city_s: None,
            last_oem_s: None,
            last_image_s: None,
            oem_changed: true,
        }))
    }

    /// The live view's address as a Foxglove user connects to it, once it listens.
    pub fn live_url(&self) -> Option<String> {
        let (server, host) = self.server.as_ref()?;
        Some(format!("ws://{host}:{}", server.port()))
    }

    /// Logs one measured step.
    pub fn step(&mut self, view: &StepView<'_>) {
        let truth = view.truth;
        let time_s = truth.time_s;
        let (stamp, nanos) = sim_time(time_s);
        let c = &self.channels;
        if let Some((server, _)) = &self.server {
            server.broadcast_time(nanos);
        }
        if due(&mut self.last_city_s, time_s, SLOW_PERIOD_S) {
            let mut city = self.buildings.clone();
            for e in &mut city.entities {
                e.timestamp = Some(stamp);
            }
            c.city.log_with_time(&city, nanos);
        }
        let uavs = truth.uavs();
        if c.transforms.has_sinks() {
            c.transforms
                .log_with_time(&scene::transforms(uavs, &self.camera, stamp), nanos);
        }
        if c.uavs.has_sinks() {
            c.uavs
                .log_with_time(&scene::uavs(uavs, &self.camera, stamp), nanos);
        }
        if c.truth.has_sinks() {
            c.truth
                .log_with_time(&scene::cars(truth.targets(), self.car_size_m, stamp), nanos);
        }
        if c.plans.has_sinks() {
            c.plans
                .log_with_time(&scene::plans(view.plans, uavs, stamp), nanos);
        }
        if let Some((_, sets)) = view.sets {
            self.log_sets(sets, stamp, nanos);
        }
        self.oem_changed |= view.oem_changed;
        if self.oem_changed && due(&mut self.last_oem_s, time_s, SLOW_PERIOD_S) {
            self.oem_changed = false;
            self.channels
                .oem
                .log_with_time(&grids::oem(view.oem, stamp), nanos);
        }
        self.channels
            .metrics
            .log_with_time(&metrics(view.metrics), nanos);
    }

    fn log_sets(&mut self, sets: &FusedSets, stamp: Timestamp, nanos: u64) {
        let grid = &self.grid;
        let c = &mut self.channels;
        for (channel, set) in [
            (&c.undetected, &*sets.undetected),
            (&c.obstacle_neighbourhood, &*sets.obstacle_neighbourhood),
            (&c.unseen, &sets.unseen),
            (&c.explored, &*sets.explored),
        ] {
            if channel.has_sinks() {
                channel.log_with_time(&grids::whole_set(set, grid, stamp), nanos);
            }
        }
        for (&id, set) in &sets.targets {
            let channel = c.target(id);
            if channel.has_sinks()
                && let Some(g) = grids::set_extent(set, grid, stamp)
            {
                channel.log_with_time(&g, nanos);
            }
        }
    }

    /// Logs a camera frame of the shown UAV, at most one per [`IMAGE_PERIOD_S`] of simulated
    /// time; a frame that cannot be encoded is skipped with a warning.
    pub fn frame(&mut self, frame: &CvsFrame) {
        let time_s = frame.header.time_s;
        if !due(&mut self.last_image_s, time_s, IMAGE_PERIOD_S) {
            return;
        }
        let (stamp, nanos) = sim_time(time_s);
        let c = &self.channels;
        let logged = (|| {
            if c.labels.has_sinks() {
                c.labels
                    .log_with_time(&images::labels(frame, stamp)?, nanos);
            }
            if c.depth.has_sinks() {
                c.depth.log_with_time(&images::depth(frame, stamp)?, nanos);
            }
            Ok::<_, images::ImageError>(())
        })();
        if let Err(e) = logged {
            tracing::warn!(error = %e, step = frame.header.step, "camera image skipped");
        }
        c.boxes.log_with_time(&images::boxes(frame, stamp), nanos);
    }

    /// Completes the recording and stops the live server.
    pub fn finish(self) -> Result<(), ViewerError> {
        if let Some((server, _)) = self.server {
            server.stop().wait_blocking();
        }
        if let Some((path, mcap)) = self.mcap {
            mcap.close()
                .map_err(|source| ViewerError::Record { path, source })?;
        }
        Ok(())
    }
}

impl Sink for Viewer {
    fn phase(&self) -> &'static str {
        crate::observe::phase::VIEW
    }

    fn essential(&self) -> bool {
        true
    }

    fn camera(&self) -> Option<u32> {
        Some(self.uav)
    }

    fn shows_plans(&self) -> bool {
        true
    }

    fn live_url(&self) -> Option<String> {
        Viewer::live_url(self)
    }

    fn frame(&mut self, frame: &CvsFrame) {
        Viewer::frame(self, frame);
    }

    fn step(&mut self, view: &StepView<'_>) -> Result<(), SinkError> {
        Viewer::step(self, view);
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<Option<SinkFile>, SinkError> {
        Viewer::finish(*self)?;
        Ok(None)
    }
}

/// Whether a periodic message is due at `now_s`; notes it as sent when it is.
fn due(last_s: &mut Option<f64>, now_s: f64, period_s: f64) -> bool {
    // A little slack so that a period that is a multiple of the step is kept exactly.
    if last_s.is_some_and(|last| now_s < last + period_s - 1e-6) {
        return false;
    }
    *last_s = Some(now_s);
    true
}

/// Simulated time as a message timestamp and as log-time nanoseconds.
fn sim_time(time_s: f64) -> (Timestamp, u64) {
    let nanos = (time_s.max(0.0) * 1e9).round() as u64;
    let stamp = Timestamp::new(
        (nanos / 1_000_000_000) as u32,
        (nanos % 1_000_000_000) as u32,
    );
    (stamp, nanos)
}

fn metrics(m: &StepMetrics) -> FleetMetrics {
    let mean = |f: fn(&SetMetrics) -> Option<f64>| m.mean.as_ref().and_then(f).unwrap_or(f64::NAN);
    FleetMetrics {
        step: m.step,
        time_s: m.time_s,
        live_agents: m.live_agents,
        estimates: m.estimates,
        explored: mean(|s| Some(s.explored)),
        ua: mean(|s| Some(s.ua)),
        oa: mean(|s| Some(s.oa)),
        target_set_area_m2: mean(|s| s.target_set_area),
        loc_error_m: mean(|s| s.loc_error_m),
        identified: mean(|s| Some(s.identified)),
        identified_any: m.identified_any,
        violations: m.violations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_address_is_a_port_or_a_host_and_a_port() {
        assert_eq!(
            "9000".parse(),
            Ok(LiveAddress {
                host: "127.0.0.1".into(),
                port: 9000
            })
        );
        assert_eq!(
            "0.0.0.0:0".parse(),
            Ok(LiveAddress {
                host: "0.0.0.0".into(),
                port: 0
            })
        );
        for bad in ["", ":80", "host", "host:", "1:99999", "x:-1"] {
            assert!(bad.parse::<LiveAddress>().is_err(), "{bad:?}");
        }
    }

    /// Every string of `v` with the key it sits under (`""` for an array element).
    fn strings<'a>(v: &'a serde_json::Value, key: &'a str, out: &mut Vec<(&'a str, &'a str)>) {
        match v {
            serde_json::Value::String(s) => out.push((key, s)),
            serde_json::Value::Array(items) => items.iter().for_each(|i| strings(i, "", out)),
            serde_json::Value::Object(map) => {
                for (k, v) in map {
                    out.push(("(key)", k));
                    strings(v, k, out);
                }
            }
            _ => {}
        }
    }

    #[test]
    fn the_layout_in_docs_names_only_topics_and_fields_the_viewer_writes() {
        let text = include_str!("../../../docs/foxglove/setfleet-layout.json");
        let layout: serde_json::Value = serde_json::from_str(text).expect("the layout is JSON");
        let mut found = Vec::new();
        strings(&layout, "", &mut found);
        let known = |topic: &str| {
            topics::FIXED.contains(&topic)
                || topic
                    .strip_prefix(topics::TARGET_PREFIX)
                    .is_some_and(|id| id.parse::<u32>().is_ok())
        };
        let fields = [
            "step",
            "time_s",
            "live_agents",
            "estimates",
            "explored",
            "ua",
            "oa",
            "target_set_area_m2",
            "loc_error_m",
            "identified",
            "identified_any",
            "violations",
        ];
        let mut topics_seen = 0;
        for (key, s) in found {
            if !s.starts_with('/') {
                continue;
            }
            topics_seen += 1;
            match s.split_once('.') {
                // A plot's message path: `/metrics.FIELD`.
                Some((topic, field)) => {
                    assert_eq!((key, topic), ("value", topics::METRICS), "{s}");
                    assert!(fields.contains(&field), "{s}: no such field");
                }
                None => assert!(
                    known(s),
                    "the layout names {s}, which the viewer never writes"
                ),
            }
        }
        assert!(topics_seen > 20, "{topics_seen} topics in the layout");
        // The 3D panel shows the city, the UAVs, the cars, the plans and every set.
        let shown = &layout["configById"]["3D!city"]["topics"];
        for topic in [
            topics::CITY,
            topics::UAVS,
            topics::TRUTH,
            topics::PLANS,
            topics::UNDETECTED,
        ] {
            assert_eq!(shown[topic]["visible"], true, "{topic}");
        }
        // ... and the set of every car a scenario may hold.
        for id in 0..protocol::wire::TRUTH_MAX_TARGETS as u32 {
            let topic = topics::target_topic(id);
            assert_eq!(shown[&topic]["visible"], true, "{topic}");
        }
    }

    #[test]
    fn periodic_messages_keep_their_period_on_the_step_grid() {
        let mut last = None;
        let sent: Vec<f64> = (0..12)
            .map(|k| f64::from(k) * 0.5)
            .filter(|&t| due(&mut last, t, 2.0))
            .collect();
        assert_eq!(sent, [0.0, 2.0, 4.0]);
        assert_eq!(sim_time(1.25).1, 1_250_000_000);
        assert_eq!(sim_time(1.25).0, Timestamp::new(1, 250_000_000));
    }
}
