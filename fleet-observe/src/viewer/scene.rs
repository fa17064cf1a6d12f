//! What the 3D panel draws: the buildings, the UAVs with their cameras' footprints, the true
//! cars and the token's plans as `foxglove.SceneUpdate`s, and the frames as
//! `foxglove.FrameTransforms`.

use std::collections::BTreeMap;

use foxglove::messages::{
    ArrowPrimitive, Color, CubePrimitive, FrameTransform, FrameTransforms, LinePrimitive, Point3,
    Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, TextPrimitive, Timestamp,
    TriangleListPrimitive, Vector3, line_primitive,
};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion};
use protocol::camera::{Camera, CameraModel, CameraPose};
use protocol::wire::{PlannedView, TargetTruth, UavTruth};
use world_server::scene::Building;

use super::topics::{WORLD_FRAME, camera_frame, uav_frame};
use crate::pictures::palette;

/// Grey of the buildings.
const BUILDING: Color = Color {
    r: 0.62,
    g: 0.62,
    b: 0.66,
    a: 0.85,
};
/// Colour of the true cars.
const CAR: Color = Color {
    r: 0.1,
    g: 0.1,
    b: 0.1,
    a: 1.0,
};
/// Colour of a UAV whose agent the world considers dead.
const DEAD: Color = Color {
    r: 0.5,
    g: 0.5,
    b: 0.5,
    a: 0.6,
};
/// Height of the footprints above the ground, metres (over the set layers).
const FOOTPRINT_Z: f64 = 0.3;

/// UAV `i`'s colour, as the pictures give it.
pub fn uav_colour(uav: u32) -> Color {
    let c = palette(uav as usize);
    Color {
        r: f64::from(c.0) / 255.0,
        g: f64::from(c.1) / 255.0,
        b: f64::from(c.2) / 255.0,
        a: 1.0,
    }
}

/// The buildings, one entity: a generated building as a box, an imported one as triangles
/// (each convex part's roof, and its walls on the building's outline).
pub fn city(buildings: &[Building], stamp: Timestamp) -> SceneUpdate {
    let cubes = (buildings.iter().filter(|b| b.parts.is_empty()))
        .map(|b| CubePrimitive {
            pose: Some(pose(
                [
                    (b.min.x + b.max.x) / 2.0,
                    (b.min.y + b.max.y) / 2.0,
                    b.height / 2.0,
                ],
                0.0,
            )),
            size: Some(Vector3 {
                x: b.max.x - b.min.x,
                y: b.max.y - b.min.y,
                z: b.height,
            }),
            color: Some(BUILDING),
        })
        .collect();
    let mut points = Vec::new();
    for b in buildings {
        for part in &b.parts {
            let at = |p: &sets::math::Point2, z: f64| Point3 { x: p.x, y: p.y, z };
            let f = &part.footprint;
            // The roof, as a fan from the first corner (the part is convex).
            for w in f[1..].windows(2) {
                points.extend([
                    at(&f[0], b.height),
                    at(&w[0], b.height),
                    at(&w[1], b.height),
                ]);
            }
            // Each outer wall as two triangles.
            for (a, c) in part.outline_edges() {
                points.extend([at(&a, 0.0), at(&c, 0.0), at(&c, b.height)]);
                points.extend([at(&a, 0.0), at(&c, b.height), at(&a, b.height)]);
            }
        }
    }
    let triangles = if points.is_empty() {
        Vec::new()
    } else {
        vec![TriangleListPrimitive {
            pose: Some(pose([0.0, 0.0, 0.0], 0.0)),
            points,
            color: Some(BUILDING),
            ..Default::default()
        }]
    };
    single(SceneEntity {
        cubes,
        triangles,
        ..entity("buildings", stamp)
    })
}

/// Every UAV as an arrow along its heading with its id, and its camera's ground footprint
/// (the image's corners cast on flat ground), in its colour; grey once its agent is dead.
pub fn uavs(uavs: &[UavTruth], model: &CameraModel, stamp: Timestamp) -> SceneUpdate {
    let entities = uavs
        .iter()
        .map(|u| {
            let colour = if u.agent_live != 0 {
                uav_colour(u.id)
            } else {
                DEAD
            };
            let camera = Camera::new(*model, camera_pose(u.position, u.yaw));
            let footprint = camera
                .image_ground_footprint()
                .map(|corners| LinePrimitive {
                    r#type: line_primitive::Type::LineLoop as i32,
                    pose: Some(pose([0.0; 3], 0.0)),
                    thickness: 2.0,
                    scale_invariant: true,
                    points: corners
                        .iter()
                        .map(|c| point([c.x, c.y, FOOTPRINT_Z]))
                        .collect(),
                    color: Some(colour),
                    ..Default::default()
                });
            SceneEntity {
                arrows: vec![ArrowPrimitive {
                    pose: Some(pose(u.position, u.yaw)),
                    shaft_length: 6.0,
                    shaft_diameter: 1.2,
                    head_length: 3.0,
                    head_diameter: 3.0,
                    color: Some(colour),
                }],
                texts: vec![TextPrimitive {
                    pose: Some(pose(
                        [u.position[0], u.position[1], u.position[2] + 4.0],
                        0.0,
                    )),
                    billboard: true,
                    font_size: 14.0,
                    scale_invariant: true,
                    color: Some(colour),
                    text: format!("UAV {}", u.id),
                }],
                lines: footprint.into_iter().collect(),
                ..entity(&format!("uav/{}", u.id), stamp)
            }
        })
        .collect();
    SceneUpdate {
        deletions: Vec::new(),
        entities,
    }
}

/// The true cars as boxes of the scenario's car size along their headings, with their ids.
pub fn cars(targets: &[TargetTruth], size_m: [f64; 3], stamp: Timestamp) -> SceneUpdate {
    let [length, width, height] = size_m;
    let cubes = targets
        .iter()
        .map(|t| CubePrimitive {
            pose: Some(pose([t.ground[0], t.ground[1], height / 2.0], t.heading)),
            size: Some(Vector3 {
                x: length,
                y: width,
                z: height,
            }),
            color: Some(CAR),
        })
        .collect();
    let texts = targets
        .iter()
        .map(|t| TextPrimitive {
            pose: Some(pose([t.ground[0], t.ground[1], height + 2.0], 0.0)),
            billboard: true,
            font_size: 12.0,
            scale_invariant: true,
            color: Some(CAR),
            text: format!("car {}", t.id),
        })
        .collect();
    single(SceneEntity {
        cubes,
        texts,
        ..entity("cars", stamp)
    })
}

/// The plans of the current round: per UAV, its predicted camera positions over the horizon
/// from where it is now, as a line with a ball at each step.
pub fn plans(
    plans: &BTreeMap<u32, PlannedView>,
    uavs: &[UavTruth],
    stamp: Timestamp,
) -> SceneUpdate {
    let entities = plans
        .values()
        .map(|plan| {
            let colour = uav_colour(plan.uav);
            let now = uavs
                .iter()
                .find(|u| u.id == plan.uav)
                .map(|u| point(u.position));
            let ahead: Vec<Point3> = plan
                .poses
                .iter()
                .map(|p| point([p.position.x, p.position.y, p.position.z]))
                .collect();
            let spheres = ahead
                .iter()
                .map(|p| SpherePrimitive {
                    pose: Some(pose([p.x, p.y, p.z], 0.0)),
                    size: Some(Vector3 {
                        x: 2.0,
                        y: 2.0,
                        z: 2.0,
                    }),
                    color: Some(colour),
                })
                .collect();
            SceneEntity {
                lines: vec![LinePrimitive {
                    r#type: line_primitive::Type::LineStrip as i32,
                    pose: Some(pose([0.0; 3], 0.0)),
                    thickness: 2.0,
                    scale_invariant: true,
                    points: now.into_iter().chain(ahead).collect(),
                    color: Some(colour),
                    ..Default::default()
                }],
                spheres,
                ..entity(&format!("plan/{}", plan.uav), stamp)
            }
        })
        .collect();
    // Replaces the last round's plans: a UAV that has not decided this round has none.
    SceneUpdate {
        deletions: vec![foxglove::messages::SceneEntityDeletion {
            timestamp: Some(stamp),
            r#type: foxglove::messages::scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities,
    }
}

/// `world` to every UAV's body (at its optical centre, turned by its yaw), and each body to
/// its camera (optical convention, tilted down by the camera's tilt).
pub fn transforms(uavs: &[UavTruth], model: &CameraModel, stamp: Timestamp) -> FrameTransforms {
    let mount = camera_mount(model.tilt_rad);
    let transforms = uavs
        .iter()
        .flat_map(|u| {
            let body = FrameTransform {
                timestamp: Some(stamp),
                parent_frame_id: WORLD_FRAME.into(),
                child_frame_id: uav_frame(u.id),
                translation: Some(vector(u.position)),
                rotation: Some(yaw_quaternion(u.yaw)),
            };
            let camera = FrameTransform {
                timestamp: Some(stamp),
                parent_frame_id: uav_frame(u.id),
                child_frame_id: camera_frame(u.id),
                translation: Some(vector([0.0; 3])),
                rotation: Some(mount),
            };
            [body, camera]
        })
        .collect();
    FrameTransforms { transforms }
}

/// The camera's rotation in the UAV's body frame (x forward, y left, z up): the optical axis
/// forward and `tilt` below the horizon, image x to the right, image y down, as
/// [`Camera::new`] has it for a yaw of 0.
fn camera_mount(tilt: f64) -> Quaternion {
    let (st, ct) = tilt.sin_cos();
    let forward = nalgebra::Vector3::new(ct, 0.0, -st);
    let right = nalgebra::Vector3::new(0.0, -1.0, 0.0);
    let down = forward.cross(&right);
    let r = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[right, down, forward]));
    let q = UnitQuaternion::from_rotation_matrix(&r);
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

fn camera_pose(position: [f64; 3], yaw: f64) -> CameraPose {
    CameraPose {
        position: sets::math::Point3::new(position[0], position[1], position[2]),
        yaw,
    }
}

fn entity(id: &str, stamp: Timestamp) -> SceneEntity {
    SceneEntity {
        timestamp: Some(stamp),
        frame_id: WORLD_FRAME.into(),
        id: id.into(),
        ..Default::default()
    }
}

fn single(entity: SceneEntity) -> SceneUpdate {
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![entity],
    }
}

fn pose(position: [f64; 3], yaw: f64) -> Pose {
    Pose {
        position: Some(vector(position)),
        orientation: Some(yaw_quaternion(yaw)),
    }
}

fn vector([x, y, z]: [f64; 3]) -> Vector3 {
    Vector3 { x, y, z }
}

fn point([x, y, z]: [f64; 3]) -> Point3 {
    Point3 { x, y, z }
}

/// The rotation by `yaw` about z.
fn yaw_quaternion(yaw: f64) -> Quaternion {
    let (s, c) = (yaw / 2.0).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rotate(q: &Quaternion, v: [f64; 3]) -> [f64; 3] {
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
        let r = q * nalgebra::Vector3::new(v[0], v[1], v[2]);
        [r.x, r.y, r.z]
    }

    fn close(a: [f64; 3], b: [f64; 3]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
    }

    #[test]
    fn the_camera_mount_agrees_with_the_camera_model() {
        let model = CameraModel {
            rows: 36,
            cols: 48,
            aperture_rad: 0.8,
            tilt_rad: 0.6,
        };
        let yaw = 1.1;
        let camera = Camera::new(model, camera_pose([0.0, 0.0, 50.0], yaw));
        let (body, mount) = (yaw_quaternion(yaw), camera_mount(model.tilt_rad));
        // Every pixel's ray, taken from the camera frame through the mount and the body.
        for (u, v) in [(24.0, 18.0), (0.0, 0.0), (48.0, 5.0), (7.0, 36.0)] {
            let local = model.ray_camera(u, v).normalize();
            let world = rotate(&body, rotate(&mount, [local.x, local.y, local.z]));
            let ray = camera.ray(u, v);
            assert!(close(world, [ray.x, ray.y, ray.z]), "{world:?} vs {ray:?}");
        }
    }

    #[test]
    fn a_dead_uav_is_grey_and_a_live_one_has_its_footprint() {
        let model = CameraModel {
            rows: 36,
            cols: 48,
            aperture_rad: 0.8,
            tilt_rad: 0.6,
        };
        let live = UavTruth {
            id: 1,
            agent_live: 1,
            position: [10.0, 20.0, 40.0],
            yaw: 0.3,
            yaw_ref: 0.3,
            commanded_yaw_ref: 0.3,
        };
        let dead = UavTruth {
            id: 2,
            agent_live: 0,
            ..live
        };
        let update = uavs(&[live, dead], &model, Timestamp::new(3, 0));
        assert_eq!(update.entities.len(), 2);
        assert_eq!(update.entities[0].id, "uav/1");
        assert_eq!(update.entities[0].lines[0].points.len(), 4);
        assert_eq!(update.entities[0].arrows[0].color, Some(uav_colour(1)));
        assert_eq!(update.entities[1].arrows[0].color, Some(DEAD));
    }
}
