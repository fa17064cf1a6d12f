//! The renderer honours the paper's assumptions, checked against the scene geometry itself with
//! independent ray casts (every object, no culling) on random scenes and viewpoints.

use std::f64::consts::PI;

use parry3d_f64::query::{Ray, RayCast};
use protocol::camera::{Camera, range_interval};
use protocol::flight::UavState;
use protocol::frame::{CvsFrame, Label};
use protocol::scenario::{DepthRay, Scenario};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sets::math::{Point2, Point3, Real, Vector3};
use world_server::World;
use world_server::render::noise::RowRayPoints;
use world_server::render::{ObjectKind, SceneObject};

/// What a ray meets first.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Hit {
    Ground,
    Object(ObjectKind),
    Nothing,
}

/// First hit of a unit ray against the ground and every object, with its range.
fn first_hit(objects: &[(SceneObject, Point3, Real)], o: &Point3, d: &Vector3) -> (Hit, Real) {
    let (mut hit, mut best) = if d.z < 0.0 {
        (Hit::Ground, -o.z / d.z)
    } else {
        (Hit::Nothing, Real::INFINITY)
    };
    for (obj, centre, radius) in objects {
        // Bounding-sphere rejection only, so that the test stays quick.
        let oc = centre - o;
        let along = oc.dot(d);
        if (oc - d * along).norm() > *radius || along + radius < 0.0 {
            continue;
        }
        let cuboid = obj.as_cuboid().expect("the generated city is boxes");
        if let Some(t) = cuboid.cast_ray(&obj.pose, &Ray::new(*o, *d), best, true)
            && t <= best
        {
            best = t;
            hit = Hit::Object(obj.kind);
        }
    }
    (hit, best)
}

fn scenario(seed: u64) -> Scenario {
    let mut s = Scenario {
        seed,
        ..Scenario::default()
    };
    s.camera.rows = 48;
    s.camera.cols = 64;
    s.camera.min_pixels = 3;
    s.targets.count = 40;
    s.region.building_fraction = 0.12;
    s.camera.unknown_fraction = if seed.is_multiple_of(2) { 0.05 } else { 0.0 };
    // Half the scenes measure depth along a random ray of each pixel, and let the cars come
    // as close to the walls as the paper allows.
    if seed > 3 {
        s.camera.depth_ray = DepthRay::Random;
        s.targets.building_clearance_m = s.targets.safety_distance_m;
    }
    s
}

#[derive(Default)]
struct Seen {
    ground: usize,
    target: usize,
    obstacle: usize,
    boxes: usize,
}

fn check_frame(world: &World, uav: usize, frame: &CvsFrame, rng: &mut ChaCha8Rng, seen: &mut Seen) {
    let s = world.scenario();
    let camera: Camera = world.camera(uav).expect("UAV exists");
    assert_eq!(frame.header.uav as usize, uav);
    assert_eq!(frame.checksum(), frame.header.checksum);
    let objects: Vec<(SceneObject, Point3, Real)> = world
        .scene_objects(Some(uav))
        .into_iter()
        .map(|o| {
            let c = Point3::from(o.pose.translation.vector);
            let r = o
                .as_cuboid()
                .expect("the generated city is boxes")
                .half_extents
                .norm();
            (o, c, r + 1e-6)
        })
        .collect();
    let o = camera.origin();
    let (rows, cols) = (s.camera.rows, s.camera.cols);
    let step = frame.header.step;
    let mut pixel_hits: Vec<Vec<Hit>> = Vec::with_capacity((rows * cols) as usize);
    for r in 0..rows {
        // The points of this row's depth rays, drawn again as the world draws them.
        let mut depth_points = RowRayPoints::new(s.seed, step, uav as u32, r);
        for c in 0..cols {
            let mut pts = vec![(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.5, 0.5)];
            let depth_point = match s.camera.depth_ray {
                DepthRay::Centre => (0.5, 0.5),
                DepthRay::Random => depth_points.next_point(),
            };
            let label = frame.label(r, c);
            if label != Label::Unknown {
                for _ in 0..4 {
                    pts.push((rng.random::<Real>(), rng.random::<Real>()));
                }
            }
            let hits: Vec<(Hit, Real)> = pts
                .iter()
                .map(|&(du, dv)| {
                    first_hit(&objects, &o, &camera.ray(c as Real + du, r as Real + dv))
                })
                .collect();
            let all = |want: fn(&Hit) -> bool| hits.iter().all(|(h, _)| want(h));
            match label {
                Label::Ground => {
                    seen.ground += 1;
                    assert!(all(|h| *h == Hit::Ground), "G pixel ({r}, {c}): {hits:?}");
                }
                Label::Target | Label::Obstacle => {
                    let first = hits[0].0;
                    assert!(
                        hits.iter().all(|(h, _)| *h == first),
                        "({r}, {c}): {hits:?}"
                    );
                    match (label, first) {
                        (Label::Target, Hit::Object(ObjectKind::Target(_))) => seen.target += 1,
                        (Label::Obstacle, Hit::Object(ObjectKind::Obstacle(_))) => {
                            seen.obstacle += 1
                        }
                        _ => panic!("{label:?} pixel ({r}, {c}) sees {first:?}"),
                    }
                }
                Label::Unknown => {}
            }
            // Depth: the true range of the depth ray (the centre ray, or the ray through the
            // pixel's random point) lies in the interval the depth allows.
            let depth = frame.depth_at(r, c);
            let (du, dv) = depth_point;
            assert!((0.0..1.0).contains(&du) && (0.0..1.0).contains(&dv));
            let (centre, range) =
                first_hit(&objects, &o, &camera.ray(c as Real + du, r as Real + dv));
            if label != Label::Unknown {
                assert_eq!(
                    centre, hits[0].0,
                    "({r}, {c}): the depth ray sees another thing"
                );
            }
            if centre == Hit::Nothing {
                assert!(depth.is_nan());
            } else {
                let (lo, hi) =
                    range_interval(depth, s.camera.depth_noise).expect("finite positive depth");
                assert!(
                    lo <= range && range <= hi,
                    "({r}, {c}): {range} not in [{lo}, {hi}]"
                );
            }
            pixel_hits.push(hits[..5].iter().map(|(h, _)| *h).collect());
        }
    }
    // Boxes: every pixel any of whose 5 rays hit target j lies in j's box; a target with
    // enough T pixels has a box.
    let boxes = frame.boxes();
    seen.boxes += boxes.len();
    for car in world.targets() {
        let j = car.id;
        let kind = Hit::Object(ObjectKind::Target(j));
        let b = boxes.iter().find(|b| b.id == j);
        let mut labelled = 0;
        for r in 0..rows {
            for c in 0..cols {
                let hits = &pixel_hits[(r * cols + c) as usize];
                if hits.contains(&kind) {
                    if let Some(b) = b {
                        assert!(
                            b.contains(r, c),
                            "pixel ({r}, {c}) of target {j} outside {b:?}"
                        );
                    }
                    if frame.label(r, c) == Label::Target && hits.iter().all(|h| *h == kind) {
                        labelled += 1;
                    }
                }
            }
        }
        assert_eq!(
            b.is_some(),
            labelled >= s.camera.min_pixels,
            "target {j}: {labelled}"
        );
        if b.is_some() {
            // Assumption 11: the segment from the camera to the target's ground point crosses
            // the car's body.
            let body = world.target_object(&car);
            let g = Point3::new(car.position.x, car.position.y, 0.0);
            let seg = g - o;
            let ray = Ray::new(o, seg);
            let cuboid = body.as_cuboid().expect("a car is a box");
            assert!(cuboid.cast_ray(&body.pose, &ray, 1.0, true).is_some());
        }
    }
}

#[test]
fn frames_honour_the_assumptions_on_random_scenes_and_poses() {
    let mut seen = Seen::default();
    let mut frame = CvsFrame::new_boxed();
    for seed in 1..=6u64 {
        let s = scenario(seed);
        let mut world = World::new(&s).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed * 77);
        for step in 0..8 {
            for _ in 0..3 {
                world.advance();
            }
            // UAV 0 looks at a random car from a random height and bearing; the others keep
            // their own course.
            let cars = world.targets();
            let car = &cars[rng.random_range(0..cars.len())];
            // A viewpoint outside every building (a UAV never flies inside one).
            let (pos, yaw) = loop {
                let alt = rng.random_range(15.0..120.0);
                let yaw: Real = rng.random_range(-PI..PI);
                let back = alt / s.camera.tilt_rad.tan() * rng.random_range(0.7..1.3);
                let pos = Point3::new(
                    car.position.x - back * yaw.cos(),
                    car.position.y - back * yaw.sin(),
                    alt,
                );
                let inside = world.scene().buildings.iter().any(|b| {
                    b.height + 1.0 > alt && b.footprint_distance(&Point2::new(pos.x, pos.y)) < 1.0
                });
                if !inside {
                    break (pos, yaw);
                }
            };
            world.set_uav_state(0, UavState { position: pos, yaw });
            for uav in [0, 1 + step % 3] {
                world.render(uav, 9, &mut frame);
                check_frame(&world, uav, &frame, &mut rng, &mut seen);
            }
        }
    }
    // The checks above only bite if every kind of pixel showed up.
    assert!(seen.ground > 1000 && seen.target > 20 && seen.obstacle > 100 && seen.boxes > 5);
}
