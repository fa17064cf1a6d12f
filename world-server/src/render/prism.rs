//! Upright convex prisms: an imported building's parts (a convex footprint extruded from the
//! ground to its roof), cast against the way [`super::objects`] casts boxes.
//!
//! A ray meets the prism where it is inside every face's half-space at once. Each face, the
//! floor `z = 0`, the roof `z = h` and one wall per footprint edge, clips the ray's parameter
//! interval `[0, max_range]` (Cyrus and Beck): the ray enters at the largest entering
//! parameter and leaves at the smallest leaving one, and misses when the first exceeds the
//! second. The face the ray enters through tells a roof hit from a wall hit, which the
//! labelling of a pixel that sees two parts of one building needs.

use sets::math::{Point2, Point3, Real, Vector3};

/// Which face a ray enters a prism through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Face {
    /// The roof, `z = height`.
    Roof,
    /// The floor, `z = 0` (only from below the ground).
    Floor,
    /// The wall over footprint edge `i` (from corner `i` to corner `i + 1`).
    Wall(u32),
    /// The ray starts inside the prism.
    Inside,
}

/// An upright prism over a convex counter-clockwise footprint, from `z = 0` to `z = height`:
/// one part of a building.
#[derive(Clone, Debug, PartialEq)]
pub struct Prism {
    /// The footprint's corners, counter-clockwise, strictly convex.
    pub footprint: Vec<Point2>,
    /// The roof's height, metres.
    pub height: Real,
    /// Per footprint edge `i` (corner `i` to `i + 1`): whether it lies on the building's
    /// outline, rather than against another part of the same building.
    pub outline: Vec<bool>,
}

impl Prism {
    /// The prism over `footprint` (counter-clockwise, strictly convex) up to `height`, a
    /// building of its own: every edge is on the outline.
    pub fn new(footprint: Vec<Point2>, height: Real) -> Prism {
        let outline = vec![true; footprint.len()];
        Prism {
            footprint,
            height,
            outline,
        }
    }

    /// The parts of one building, each edge on the outline unless another part has the same
    /// edge reversed (the parts of a convex decomposition share their inner edges exactly).
    pub fn building(parts: Vec<Vec<Point2>>, height: Real) -> Vec<Prism> {
        let key = |p: &Point2| (p.x.to_bits(), p.y.to_bits());
        let mut edges = std::collections::HashSet::new();
        for part in &parts {
            let n = part.len();
            for i in 0..n {
                edges.insert((key(&part[i]), key(&part[(i + 1) % n])));
            }
        }
        parts
            .into_iter()
            .map(|footprint| {
                let n = footprint.len();
                let outline = (0..n)
                    .map(|i| !edges.contains(&(key(&footprint[(i + 1) % n]), key(&footprint[i]))))
                    .collect();
                Prism {
                    footprint,
                    height,
                    outline,
                }
            })
            .collect()
    }

    /// The footprint's edges on the building's outline.
    pub fn outline_edges(&self) -> impl Iterator<Item = (Point2, Point2)> + '_ {
        self.edges()
            .zip(&self.outline)
            .filter_map(|(e, &on)| on.then_some(e))
    }

    /// Whether the ground point `p` lies inside or on the footprint.
    pub fn contains(&self, p: &Point2) -> bool {
        self.edges().all(|(a, b)| (b - a).perp(&(p - a)) >= 0.0)
    }

    /// The corners: the footprint at the floor, then at the roof.
    pub fn vertices(&self) -> impl Iterator<Item = Point3> + '_ {
        [0.0, self.height]
            .into_iter()
            .flat_map(move |z| self.footprint.iter().map(move |p| Point3::new(p.x, p.y, z)))
    }

    /// The prism's edges as pairs of indices into [`Prism::vertices`]: the floor's, the
    /// roof's, then the vertical ones.
    pub fn vertex_edges(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let n = self.footprint.len();
        (0..n)
            .map(move |i| (i, (i + 1) % n))
            .chain((0..n).map(move |i| (n + i, n + (i + 1) % n)))
            .chain((0..n).map(move |i| (i, n + i)))
    }

    /// The footprint's edges as (start, end) corners.
    pub fn edges(&self) -> impl Iterator<Item = (Point2, Point2)> + '_ {
        let n = self.footprint.len();
        (0..n).map(move |i| (self.footprint[i], self.footprint[(i + 1) % n]))
    }

    /// Distance along the unit ray `dir` from `origin` to the first point of the prism, if the
    /// ray meets it within `max_range`, and the face it enters through (0 and
    /// [`Face::Inside`] if `origin` is inside).
    pub fn cast(&self, origin: &Point3, dir: &Vector3, max_range: Real) -> Option<(Real, Face)> {
        let mut enter: Real = 0.0;
        let mut leave = max_range;
        let mut face = Face::Inside;
        // Each face as `n · (p - q) <= 0` inside: with `p = origin + t dir`, the ray is inside
        // where `num + t den <= 0`, `num = n · (origin - q)`, `den = n · dir`.
        let mut clip = |num: Real, den: Real, which: Face| -> bool {
            if den == 0.0 {
                return num <= 0.0;
            }
            let t = -num / den;
            if den < 0.0 {
                if t > enter {
                    enter = t;
                    face = which;
                }
            } else if t < leave {
                leave = t;
            }
            enter <= leave
        };
        if !clip(origin.z - self.height, dir.z, Face::Roof) || !clip(-origin.z, -dir.z, Face::Floor)
        {
            return None;
        }
        for (i, (a, b)) in self.edges().enumerate() {
            // Outward normal of a counter-clockwise edge: its direction turned clockwise.
            let (nx, ny) = (b.y - a.y, a.x - b.x);
            let num = nx * (origin.x - a.x) + ny * (origin.y - a.y);
            let den = nx * dir.x + ny * dir.y;
            if !clip(num, den, Face::Wall(i as u32)) {
                return None;
            }
        }
        Some((enter, face))
    }

    /// Distance from `p` to the nearest point of the prism (0 inside).
    pub fn nearest_distance(&self, p: &Point3) -> Real {
        let flat = Point2::new(p.x, p.y);
        let inside = self.edges().all(|(a, b)| (b - a).perp(&(flat - a)) >= 0.0);
        let horizontal = if inside {
            0.0
        } else {
            self.edges()
                .map(|(a, b)| segment_distance(&flat, &a, &b))
                .fold(Real::INFINITY, Real::min)
        };
        let vertical = (-p.z).max(p.z - self.height).max(0.0);
        horizontal.hypot(vertical)
    }

    /// Distance from `p` to the farthest corner of the prism (so to every point of it).
    pub fn farthest_distance(&self, p: &Point3) -> Real {
        self.vertices().map(|v| (v - p).norm()).fold(0.0, Real::max)
    }
}

/// Distance from `p` to the segment `a b`.
pub(crate) fn segment_distance(p: &Point2, a: &Point2, b: &Point2) -> Real {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

#[cfg(test)]
mod tests {
    use parry3d_f64::query::{Ray, RayCast};
    use parry3d_f64::shape::Cuboid;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use sets::math::Isometry3;

    use super::*;

    /// A random convex footprint: corners at increasing angles on an ellipse, then rotated.
    fn footprint(rng: &mut ChaCha8Rng) -> Vec<Point2> {
        let n = rng.random_range(3..9);
        let (rx, ry) = (rng.random_range(2.0..20.0), rng.random_range(2.0..20.0));
        let (cx, cy) = (rng.random_range(-30.0..30.0), rng.random_range(-30.0..30.0));
        let turn: Real = rng.random_range(0.0..std::f64::consts::TAU);
        let mut angles: Vec<Real> = (0..n)
            .map(|_| rng.random_range(0.0..std::f64::consts::TAU))
            .collect();
        angles.sort_by(Real::total_cmp);
        angles.dedup_by(|a, b| (*a - *b).abs() < 0.05);
        let (s, c) = turn.sin_cos();
        let pts: Vec<Point2> = angles
            .iter()
            .map(|a| {
                let (x, y) = (rx * a.cos(), ry * a.sin());
                Point2::new(cx + c * x - s * y, cy + s * x + c * y)
            })
            .collect();
        if pts.len() < 3 {
            return vec![
                Point2::new(0.0, 0.0),
                Point2::new(5.0, 0.0),
                Point2::new(0.0, 5.0),
            ];
        }
        pts
    }

    fn inside(prism: &Prism, p: &Point3) -> bool {
        p.z >= 0.0
            && p.z <= prism.height
            && prism
                .edges()
                .all(|(a, b)| (b - a).perp(&(Point2::new(p.x, p.y) - a)) >= 0.0)
    }

    #[test]
    fn a_rectangle_casts_as_parrys_cuboid() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..2_000 {
            let (hx, hy, h) = (
                rng.random_range(1.0..20.0),
                rng.random_range(1.0..20.0),
                rng.random_range(3.0..60.0),
            );
            let (cx, cy) = (rng.random_range(-40.0..40.0), rng.random_range(-40.0..40.0));
            let prism = Prism::new(
                vec![
                    Point2::new(cx - hx, cy - hy),
                    Point2::new(cx + hx, cy - hy),
                    Point2::new(cx + hx, cy + hy),
                    Point2::new(cx - hx, cy + hy),
                ],
                h,
            );
            let cuboid = Cuboid::new(Vector3::new(hx, hy, h / 2.0));
            let pose = Isometry3::translation(cx, cy, h / 2.0);
            let origin = Point3::new(
                rng.random_range(-60.0..60.0),
                rng.random_range(-60.0..60.0),
                rng.random_range(-5.0..120.0),
            );
            let target = Point3::new(
                cx + rng.random_range(-1.5..1.5) * hx,
                cy + rng.random_range(-1.5..1.5) * hy,
                rng.random_range(-0.2..1.2) * h,
            );
            let Some(dir) = (target - origin).try_normalize(1e-9) else {
                continue;
            };
            let want = cuboid.cast_ray(&pose, &Ray::new(origin, dir), 500.0, true);
            let got = prism.cast(&origin, &dir, 500.0).map(|(t, _)| t);
            match (want, got) {
                (Some(w), Some(g)) => assert!((w - g).abs() < 1e-9, "{w} against {g}"),
                (None, None) => {}
                // A ray grazing an edge may round either way.
                (w, g) => {
                    let t = w.or(g).unwrap_or(0.0);
                    let p = origin + dir * t;
                    assert!(
                        prism.nearest_distance(&p) < 1e-9 || !inside(&prism, &p),
                        "{w:?} against {g:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_cast_finds_the_first_point_inside_and_its_face() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut hits = [0usize; 3];
        for _ in 0..1_000 {
            let prism = Prism::new(footprint(&mut rng), rng.random_range(5.0..50.0));
            let origin = Point3::new(
                rng.random_range(-70.0..70.0),
                rng.random_range(-70.0..70.0),
                rng.random_range(-3.0..110.0),
            );
            let aim = prism.footprint[rng.random_range(0..prism.footprint.len())];
            let target = Point3::new(
                aim.x * rng.random_range(0.5..1.1),
                aim.y * rng.random_range(0.5..1.1),
                rng.random_range(0.0..prism.height),
            );
            let Some(dir) = (target - origin).try_normalize(1e-9) else {
                continue;
            };
            let hit = prism.cast(&origin, &dir, 300.0);
            // March along the ray: the first sample inside is at (or just after) the hit.
            let step = 0.01;
            let first = (0..30_000)
                .map(|k| k as Real * step)
                .find(|&t| inside(&prism, &(origin + dir * t)));
            match (hit, first) {
                (Some((t, face)), Some(f)) => {
                    assert!(
                        f >= t - 1e-9 && f <= t + step + 1e-9,
                        "hit {t}, first inside {f}"
                    );
                    let p = origin + dir * t;
                    match face {
                        Face::Roof => {
                            assert!((p.z - prism.height).abs() < 1e-9);
                            hits[0] += 1;
                        }
                        Face::Wall(i) => {
                            let (a, b) = prism.edges().nth(i as usize).unwrap_or_default();
                            assert!(segment_distance(&Point2::new(p.x, p.y), &a, &b) < 1e-6);
                            hits[1] += 1;
                        }
                        Face::Inside => {
                            assert_eq!(t, 0.0);
                            hits[2] += 1;
                        }
                        Face::Floor => assert!(origin.z < 0.0),
                    }
                }
                (None, None) => {}
                // The ray only clips a corner or an edge, closer than the march's step: the
                // hit is still on the prism's surface.
                (Some((t, _)), None) => {
                    let p = origin + dir * t;
                    assert!(prism.nearest_distance(&p) < 1e-6, "hit {t} off the surface");
                }
                (None, Some(f)) => panic!("missed a ray that is inside at {f}"),
            }
        }
        assert!(hits[0] > 50 && hits[1] > 50, "{hits:?}");
    }

    #[test]
    fn distances_bound_every_point() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..300 {
            let prism = Prism::new(footprint(&mut rng), rng.random_range(5.0..50.0));
            let p = Point3::new(
                rng.random_range(-70.0..70.0),
                rng.random_range(-70.0..70.0),
                rng.random_range(-10.0..110.0),
            );
            let (near, far) = (prism.nearest_distance(&p), prism.farthest_distance(&p));
            for v in prism.vertices() {
                let d = (v - p).norm();
                assert!(d >= near - 1e-9 && d <= far + 1e-9);
            }
            // The nearest distance is attained: some point of the prism is that close.
            let flat = Point2::new(p.x, p.y);
            let closest_flat = if prism.edges().all(|(a, b)| (b - a).perp(&(flat - a)) >= 0.0) {
                flat
            } else {
                prism
                    .edges()
                    .map(|(a, b)| {
                        let ab = b - a;
                        let t = ((flat - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
                        a + ab * t
                    })
                    .min_by(|x, y| (x - flat).norm().total_cmp(&(y - flat).norm()))
                    .unwrap_or(flat)
            };
            let q = Point3::new(closest_flat.x, closest_flat.y, p.z.clamp(0.0, prism.height));
            assert!(((q - p).norm() - near).abs() < 1e-9);
        }
    }
}
