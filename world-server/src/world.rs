//! The simulated world: scene, cars and UAVs advanced together, one CVS period at a time.

use std::path::Path;
use std::sync::Arc;

use city::scene::CityScene;
use protocol::camera::{Camera, CameraPose};
use protocol::flight::UavState;
use protocol::frame::{CvsFrame, FRAME_MAX_BOXES, TargetBox};
use protocol::scenario::{CityTraffic, Scenario};
use protocol::wire::{MAX_UAVS, TRUTH_MAX_TARGETS, TargetTruth, TruthState, UavTruth};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sets::math::{Point3, Real};

use crate::airspace::{Airspace, Uav};
use crate::error::WorldBuildError;
use crate::render::{self, FrameSpec, ObjectKind, SceneObject};
use crate::scene::City;
use crate::traffic::sumo::SumoTools;
use crate::traffic::trace::{Trace, TraceCars};
use crate::traffic::{CarPose, Cars};

/// Size of a UAV's body as the other cameras see it: length, width, height, metres.
pub const UAV_BODY_M: [Real; 3] = [1.0, 1.0, 0.3];

/// Random streams of the world's seed, one per concern, so that adding a draw in one never
/// changes another.
const CITY_STREAM: u64 = 1;
const TRAFFIC_STREAM: u64 = 2;
const SPEED_STREAM: u64 = 3;

/// The whole simulated world of one run. Deterministic: the same scenario gives the same
/// city, the same trajectories and the same frames, bit for bit. A clone shares the static
/// city, so copying a world to step it ahead costs only its cars and UAVs.
#[derive(Clone, Debug)]
pub struct World {
    scenario: Scenario,
    city: Arc<City>,
    cars: Cars,
    airspace: Airspace,
    step: u64,
}

impl World {
    /// Builds the city, the cars and the fleet from the scenario's seed, once the scenario is
    /// found valid ([`Scenario::validate`]: a scenario built in code is held to the ranges of
    /// one read from a file). The city is generated from the seed, or imported from
    /// `city.scene` ([`City::import`]); an imported city's cars are driven by the world's
    /// model, by SUMO or by a trace (`city.traffic`), a trace checked whole first
    /// ([`Trace::check`]).
    pub fn new(scenario: &Scenario) -> Result<World, WorldBuildError> {
        let (city, scene) = Self::build_city(scenario)?;
        let mut traffic_rng = ChaCha8Rng::seed_from_u64(scenario.seed);
        traffic_rng.set_stream(TRAFFIC_STREAM);
        let trace = match (&scene, scenario.city.traffic) {
            (None, _) | (Some(_), CityTraffic::Roads) => None,
            (Some(scene), CityTraffic::Sumo) => {
                Some(SumoTools::locate()?.drive(&scene.roads, scenario, &mut traffic_rng)?)
            }
            (Some(_), CityTraffic::Trace) => Some(Trace::read(
                Path::new(&scenario.city.trace),
                scenario.timing.cvs_period_s,
            )?),
        };
        let cars = match trace {
            Some(trace) => {
                trace.check(&city, scenario)?;
                Cars::Trace(TraceCars::new(trace))
            }
            None => {
                let mut speed_rng = ChaCha8Rng::seed_from_u64(scenario.seed);
                speed_rng.set_stream(SPEED_STREAM);
                Cars::place(&city.roads, scenario, traffic_rng, speed_rng)?
            }
        };
        let airspace = Airspace::launch(scenario, city.tallest())?;
        Ok(World {
            scenario: scenario.clone(),
            city: Arc::new(city),
            cars,
            airspace,
            step: 0,
        })
    }

    /// The city a world of `scenario` stands in, alone: the same buildings and roads as
    /// [`World::new`]'s, without placing cars (so without running SUMO) or launching UAVs, for
    /// what only draws the city.
    pub fn city(scenario: &Scenario) -> Result<City, WorldBuildError> {
        Ok(Self::build_city(scenario)?.0)
    }

    /// The valid scenario's city, and the scene file it was imported from, if any.
    fn build_city(scenario: &Scenario) -> Result<(City, Option<CityScene>), WorldBuildError> {
        scenario.validate()?;
        if scenario.city.scene.is_empty() {
            let mut city_rng = ChaCha8Rng::seed_from_u64(scenario.seed);
            city_rng.set_stream(CITY_STREAM);
            return Ok((City::generate(scenario, &mut city_rng)?, None));
        }
        let scene = CityScene::read(Path::new(&scenario.city.scene))
            .map_err(|e| WorldBuildError::Scene(format!("city.scene: {e}")))?;
        let city = City::import(&scene, scenario)?;
        Ok((city, Some(scene)))
    }

    /// The scenario the world was built from.
    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    /// Steps taken so far (`k`).
    pub fn step(&self) -> u64 {
        self.step
    }

    /// Simulated time, seconds (`k * T`).
    pub fn time_s(&self) -> f64 {
        self.step as Real * self.scenario.timing.cvs_period_s
    }

    /// Number of UAVs.
    pub fn uav_count(&self) -> usize {
        self.airspace.uavs().len()
    }

    /// Sets the yaw reference of a UAV (ignored for an unknown index or a non-finite value).
    pub fn set_yaw_ref(&mut self, uav: usize, yaw_ref_rad: f64) {
        self.airspace.command(uav, yaw_ref_rad);
    }

    /// Advances cars and UAVs by one CVS period.
    pub fn advance(&mut self) {
        let dt = self.scenario.timing.cvs_period_s;
        self.cars.step(dt);
        self.airspace.step(dt);
        self.step += 1;
    }

    /// Renders UAV `uav`'s camera frame at the current step into `frame`, in place (header,
    /// boxes, depth, labels, checksum). `run_tag` goes into the header. An unknown UAV index
    /// gets an empty frame (0 x 0 pixels, no boxes).
    pub fn render(&self, uav: usize, run_tag: u64, frame: &mut CvsFrame) {
        let spec = FrameSpec {
            run_tag,
            seed: self.scenario.seed,
            step: self.step,
            time_s: self.time_s(),
            uav: uav as u32,
            depth_noise: self.scenario.camera.depth_noise,
            unknown_fraction: self.scenario.camera.unknown_fraction,
            min_pixels: self.scenario.camera.min_pixels,
            depth_ray: self.scenario.camera.depth_ray,
        };
        match self.camera(uav) {
            Some(camera) => {
                let objects = self.scene_objects(Some(uav));
                render::render(&camera, &objects, &spec, frame);
            }
            None => {
                let h = &mut frame.header;
                *h = Default::default();
                h.run_tag = run_tag;
                h.step = spec.step;
                h.time_s = spec.time_s;
                h.uav = spec.uav;
                h.depth_noise = spec.depth_noise;
                frame.boxes = [TargetBox::default(); FRAME_MAX_BOXES];
                frame.header.checksum = frame.checksum();
            }
        }
    }

    /// Writes the ground truth of the current step.
    pub fn truth(&self, run_tag: u64, out: &mut TruthState) {
        out.run_tag = run_tag;
        out.step = self.step;
        out.time_s = self.time_s();
        let cars = self.cars.poses();
        out.target_count = cars.len().min(TRUTH_MAX_TARGETS) as u32;
        for (slot, car) in out.targets.iter_mut().zip(cars) {
            *slot = TargetTruth {
                id: car.id,
                reserved: 0,
                ground: [car.position.x, car.position.y],
                heading: car.heading,
                speed: car.speed_mps,
            };
        }
        let uavs = self.airspace.uavs();
        out.uav_count = uavs.len().min(MAX_UAVS) as u32;
        for (i, (slot, u)) in out.uavs.iter_mut().zip(uavs).enumerate() {
            let p = u.state.position;
            *slot = UavTruth {
                id: i as u32,
                agent_live: 1,
                position: [p.x, p.y, p.z],
                yaw: u.state.yaw,
                yaw_ref: u.yaw_ref,
                commanded_yaw_ref: u.commanded_yaw_ref,
            };
        }
    }

    /// The static city (roads and buildings).
    pub fn scene(&self) -> &City {
        &self.city
    }

    /// Where the cars are, by target id.
    pub fn targets(&self) -> Vec<CarPose> {
        self.cars.poses()
    }

    /// The UAVs, by index.
    pub fn uavs(&self) -> &[Uav] {
        self.airspace.uavs()
    }

    /// State of UAV `uav`, if it exists.
    pub fn uav_state(&self, uav: usize) -> Option<UavState> {
        self.airspace.uavs().get(uav).map(|u| u.state)
    }

    /// Moves UAV `uav` to `state`, with the state's yaw as reference (for tools and tests that
    /// need a given viewpoint; ignored for an unknown index).
    pub fn set_uav_state(&mut self, uav: usize, state: UavState) {
        self.airspace.teleport(uav, state);
    }

    /// The posed camera of UAV `uav`, if it exists.
    pub fn camera(&self, uav: usize) -> Option<Camera> {
        let s = self.uav_state(uav)?;
        Some(Camera::new(
            self.scenario.camera_model(),
            CameraPose {
                position: s.position,
                yaw: s.yaw,
            },
        ))
    }

    /// The box of a car as the cameras see it: standing on the ground, along its heading.
    pub fn target_object(&self, car: &CarPose) -> SceneObject {
        let [l, w, h] = self.scenario.targets.size_m;
        SceneObject::new(
            ObjectKind::Target(car.id),
            Point3::new(car.position.x, car.position.y, h / 2.0),
            [l / 2.0, w / 2.0, h / 2.0],
            car.heading,
        )
    }

    /// Every object in the scene at the current step: buildings (a box, or the convex parts of
    /// an imported one), cars, and the UAVs other than `viewer` (a camera does not see its own
    /// UAV).
    pub fn scene_objects(&self, viewer: Option<usize>) -> Vec<SceneObject> {
        let parts: usize = self
            .city
            .buildings
            .iter()
            .map(|b| b.parts.len().max(1))
            .sum();
        let mut out = Vec::with_capacity(parts + self.cars.len() + self.uav_count());
        for (k, b) in self.city.buildings.iter().enumerate() {
            let kind = ObjectKind::Obstacle(k as u32);
            if b.parts.is_empty() {
                out.push(SceneObject::new(kind, b.centre(), b.half_extents(), 0.0));
            } else {
                out.extend(
                    b.parts
                        .iter()
                        .map(|part| SceneObject::prism(kind, Arc::clone(part))),
                );
            }
        }
        for car in self.cars.poses() {
            out.push(self.target_object(&car));
        }
        let [l, w, h] = UAV_BODY_M;
        for (i, u) in self.airspace.uavs().iter().enumerate() {
            if Some(i) != viewer {
                out.push(SceneObject::new(
                    ObjectKind::Uav(i as u32),
                    u.state.position,
                    [l / 2.0, w / 2.0, h / 2.0],
                    u.state.yaw,
                ));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use protocol::scenario::ScenarioError;

    use super::*;

    fn key_refused(scenario: &Scenario) -> Option<String> {
        match World::new(scenario) {
            Err(WorldBuildError::Scenario(ScenarioError::OutOfRange { key, .. })) => Some(key),
            _ => None,
        }
    }

    #[test]
    fn the_world_refuses_what_the_scenario_loader_refuses() {
        let mut s = Scenario::default();
        s.region.building_fraction = 0.5;
        assert!(s.validate().is_err());
        assert_eq!(key_refused(&s).as_deref(), Some("region.building_fraction"));
        let mut s = Scenario::default();
        s.camera.unknown_fraction = 1.0;
        assert_eq!(key_refused(&s).as_deref(), Some("camera.unknown_fraction"));
    }

    #[test]
    fn the_building_fraction_range_ends_where_the_loader_says() {
        let mut s = Scenario::default();
        s.region.building_fraction = 0.3;
        assert!(s.validate().is_ok());
        let world = World::new(&s).unwrap();
        assert!((world.scene().building_fraction() - 0.3).abs() < 1e-6);
        s.region.building_fraction = 0.3 + 1e-9;
        assert_eq!(key_refused(&s).as_deref(), Some("region.building_fraction"));
    }
}
