//! What a camera can see besides the ground: boxes and upright convex prisms (the parts of an
//! imported building, [`super::prism`]), each with what it is.
//!
//! [`SceneObject::cast`] is parry3d's ray cast against the posed cuboid. A frame casts every
//! ray from the same optical centre, so [`SceneObject::seen_from`] does once per frame the
//! part of that cast that depends on the origin only, and [`SeenFrom::cast`] the rest, with
//! parry3d's arithmetic operation for operation: both give the same floats (a test pins it).

use std::sync::Arc;

use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::Cuboid;
use sets::math::{Isometry3, Point3, Real, Vector3};

use super::prism::Prism;

/// What an object is, for labelling.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ObjectKind {
    /// A building (index into the city's buildings): its pixels may be labelled O.
    Obstacle(u32),
    /// A car (its target id): its pixels may be labelled T.
    Target(u32),
    /// Another UAV (its index): its pixels are U.
    Uav(u32),
}

/// The shape of a scene object.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A box centred on the object's pose (the generated city's buildings, cars, UAVs).
    Cuboid(Cuboid),
    /// An upright convex prism in world coordinates (a part of an imported building); the
    /// object's pose is the identity.
    Prism(Arc<Prism>),
}

/// An object in the scene: a shape posed in the world.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneObject {
    /// What it is.
    pub kind: ObjectKind,
    /// Its shape, centred on its local origin.
    pub shape: Shape,
    /// Where it is: the world pose of its centre.
    pub pose: Isometry3,
}

impl SceneObject {
    /// A box with the given centre, half extents and yaw about the vertical axis.
    pub fn new(kind: ObjectKind, centre: Point3, half_extents: [Real; 3], yaw: Real) -> Self {
        let [hx, hy, hz] = half_extents;
        SceneObject {
            kind,
            shape: Shape::Cuboid(Cuboid::new(Vector3::new(hx, hy, hz))),
            pose: Isometry3::new(centre.coords, Vector3::z() * yaw),
        }
    }

    /// A part of a building: an upright convex prism in world coordinates.
    pub fn prism(kind: ObjectKind, prism: Arc<Prism>) -> Self {
        SceneObject {
            kind,
            shape: Shape::Prism(prism),
            pose: Isometry3::identity(),
        }
    }

    /// The corners in the world frame: a box's eight, a prism's floor then roof.
    pub fn vertices(&self) -> Vec<Point3> {
        match &self.shape {
            Shape::Cuboid(cuboid) => {
                let h = cuboid.half_extents;
                (0..8)
                    .map(|i| {
                        let sx = if i & 1 == 0 { -h.x } else { h.x };
                        let sy = if i & 2 == 0 { -h.y } else { h.y };
                        let sz = if i & 4 == 0 { -h.z } else { h.z };
                        self.pose * Point3::new(sx, sy, sz)
                    })
                    .collect()
            }
            Shape::Prism(prism) => prism.vertices().collect(),
        }
    }

    /// The edges, as pairs of indices into [`SceneObject::vertices`].
    pub fn edges(&self) -> Vec<(usize, usize)> {
        match &self.shape {
            // The 12 edges of a box join vertices differing in exactly one index bit.
            Shape::Cuboid(_) => (0..8usize)
                .flat_map(|a| [1usize, 2, 4].map(|bit| (a, a | bit)))
                .filter(|&(a, b)| a != b)
                .collect(),
            Shape::Prism(prism) => prism.vertex_edges().collect(),
        }
    }

    /// The cuboid, for a box.
    pub fn as_cuboid(&self) -> Option<&Cuboid> {
        match &self.shape {
            Shape::Cuboid(cuboid) => Some(cuboid),
            Shape::Prism(_) => None,
        }
    }

    /// The prism, for a part of an imported building.
    pub fn as_prism(&self) -> Option<&Prism> {
        match &self.shape {
            Shape::Prism(prism) => Some(prism),
            Shape::Cuboid(_) => None,
        }
    }

    /// Distance along the unit ray `dir` from `origin` to the first point of the object, if
    /// the ray meets it within `max_range` (0 if `origin` is inside).
    pub fn cast(&self, origin: &Point3, dir: &Vector3, max_range: Real) -> Option<Real> {
        match &self.shape {
            Shape::Cuboid(cuboid) => {
                cuboid.cast_ray(&self.pose, &Ray::new(*origin, *dir), max_range, true)
            }
            Shape::Prism(prism) => prism.cast(origin, dir, max_range).map(|(t, _)| t),
        }
    }

    /// The object as rays from `origin` see it: [`SeenFrom::cast`] is [`SceneObject::cast`]
    /// from `origin`.
    pub fn seen_from(&self, origin: &Point3) -> SeenFrom {
        let cuboid = match &self.shape {
            Shape::Cuboid(cuboid) => cuboid,
            Shape::Prism(prism) => {
                return SeenFrom::Prism {
                    prism: Arc::clone(prism),
                    origin: *origin,
                };
            }
        };
        // parry3d-f64 0.25 casts a ray against a posed cuboid (`RayCast::cast_ray`) by moving
        // the ray into the box's frame (`Ray::inverse_transform_by`) and clipping it against
        // the box's slabs (`Aabb::cast_local_ray`, the box `[-h, h]`); the slab bounds'
        // offsets from the moved origin are the same for every ray of the frame.
        let local = self.pose.inverse_transform_point(origin);
        let maxs = Point3::from(cuboid.half_extents);
        let mins = Point3::from(-cuboid.half_extents);
        let q = &self.pose.rotation;
        SeenFrom::Box(BoxSeen {
            pose: self.pose,
            square: q.i == 0.0 && q.j == 0.0 && q.k == 0.0 && q.w.is_finite(),
            origin: local,
            mins,
            maxs,
            to_mins: [0, 1, 2].map(|i| mins[i] - local[i]),
            to_maxs: [0, 1, 2].map(|i| maxs[i] - local[i]),
        })
    }

    /// Distance from `p` to the nearest point of the object (0 inside).
    pub fn nearest_distance(&self, p: &Point3) -> Real {
        let h = match &self.shape {
            Shape::Cuboid(cuboid) => cuboid.half_extents,
            Shape::Prism(prism) => return prism.nearest_distance(p),
        };
        let local = self.pose.inverse_transform_point(p);
        let d = Vector3::new(
            (local.x.abs() - h.x).max(0.0),
            (local.y.abs() - h.y).max(0.0),
            (local.z.abs() - h.z).max(0.0),
        );
        d.norm()
    }

    /// Distance from `p` to the farthest corner of the object (so to every point of it).
    pub fn farthest_distance(&self, p: &Point3) -> Real {
        self.vertices()
            .iter()
            .map(|v| (v - p).norm())
            .fold(0.0, Real::max)
    }
}

/// A [`SceneObject`] as the rays from one fixed origin see it ([`SceneObject::seen_from`]).
#[derive(Clone, Debug, PartialEq)]
pub enum SeenFrom {
    /// A box, with what every ray's slab test shares.
    Box(BoxSeen),
    /// A prism and the rays' origin.
    Prism {
        /// The prism.
        prism: Arc<Prism>,
        /// The rays' origin.
        origin: Point3,
    },
}

/// A box as the rays from one fixed origin see it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxSeen {
    /// The box's world pose.
    pose: Isometry3,
    /// Whether the pose does not turn the box (its rotation's vector part is zero).
    square: bool,
    /// The rays' origin in the box's frame.
    origin: Point3,
    /// The box's lower corner in its own frame.
    mins: Point3,
    /// The box's upper corner in its own frame.
    maxs: Point3,
    /// `mins - origin`, per axis.
    to_mins: [Real; 3],
    /// `maxs - origin`, per axis.
    to_maxs: [Real; 3],
}

impl SeenFrom {
    /// [`SceneObject::cast`] from the origin this view was made for: distance along the unit
    /// ray `dir` to the first point of the object, if the ray meets it within `max_range`.
    ///
    /// For a box, the operations are those of parry3d-f64 0.25.3's `Aabb::cast_local_ray`
    /// (solid) on the ray moved into the box's frame, in the same order, so the result is the
    /// same float.
    #[inline]
    pub fn cast(&self, dir: &Vector3, max_range: Real) -> Option<Real> {
        match self {
            SeenFrom::Box(b) => {
                let d = b.pose.inverse_transform_vector(dir);
                b.clip(&d, &[1.0 / d.x, 1.0 / d.y, 1.0 / d.z], max_range)
            }
            SeenFrom::Prism { prism, origin } => prism.cast(origin, dir, max_range).map(|(t, _)| t),
        }
    }

    /// Whether the object is a box that is not turned: a square box sees a ray with the world
    /// direction.
    pub fn is_square(&self) -> bool {
        matches!(self, SeenFrom::Box(b) if b.square)
    }

    /// [`SeenFrom::cast`] of a square box ([`SeenFrom::is_square`]), given the direction's
    /// reciprocals `inv = [1 / dir.x, 1 / dir.y, 1 / dir.z]`, shared by every square box;
    /// any other object is cast as [`SeenFrom::cast`] casts it.
    ///
    /// The rotation parry3d applies to the direction multiplies the quaternion's vector part,
    /// here zeros, into zeros and adds them to each component: a nonzero component comes out
    /// unchanged and a zero one zero, which are all the slab test looks at.
    #[inline]
    pub fn cast_square(&self, dir: &Vector3, inv: &[Real; 3], max_range: Real) -> Option<Real> {
        match self {
            SeenFrom::Box(b) => b.clip(dir, inv, max_range),
            SeenFrom::Prism { .. } => self.cast(dir, max_range),
        }
    }
}

impl BoxSeen {
    /// `Aabb::cast_local_ray` of the box against the direction `d` in its frame, with `inv`
    /// the reciprocals of `d`'s components (used only where they are nonzero).
    #[inline]
    fn clip(&self, d: &Vector3, inv: &[Real; 3], max_range: Real) -> Option<Real> {
        let mut tmin: Real = 0.0;
        let mut tmax: Real = max_range;
        for i in 0..3 {
            if d[i] == 0.0 {
                if self.origin[i] < self.mins[i] || self.origin[i] > self.maxs[i] {
                    return None;
                }
            } else {
                let denom = inv[i];
                let mut near = self.to_mins[i] * denom;
                let mut far = self.to_maxs[i] * denom;
                if near > far {
                    std::mem::swap(&mut near, &mut far);
                }
                tmin = tmin.max(near);
                tmax = tmax.min(far);
                if tmin > tmax {
                    return None;
                }
            }
        }
        Some(tmin)
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// A random unit direction, sometimes along an axis or in an axis plane (zero
    /// components, including negative zeros), where the slab test takes its other branch.
    fn direction(rng: &mut ChaCha8Rng) -> Vector3 {
        let mut v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        for i in 0..3 {
            match rng.random_range(0..8) {
                0 => v[i] = 0.0,
                1 => v[i] = -0.0,
                _ => {}
            }
        }
        if v.norm() == 0.0 {
            v.z = -1.0;
        }
        v.normalize()
    }

    #[test]
    fn a_cast_seen_from_the_origin_is_parrys_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut hits = 0;
        let mut inside = 0;
        let mut squares = 0;
        for _ in 0..400 {
            let centre = Point3::new(
                rng.random_range(-50.0..50.0),
                rng.random_range(-50.0..50.0),
                rng.random_range(0.0..20.0),
            );
            let half = [0, 1, 2].map(|_| rng.random_range(0.2..15.0));
            // Buildings stand square (yaw 0); cars and UAVs turn.
            let yaw = match rng.random_range(0..3) {
                0 => 0.0,
                _ => rng.random_range(-4.0..4.0),
            };
            let object = SceneObject::new(ObjectKind::Obstacle(0), centre, half, yaw);
            let origin = match rng.random_range(0..4) {
                // Inside the box (a camera flown into a building).
                0 => centre + Vector3::new(0.1 * half[0], -0.2 * half[1], 0.3 * half[2]),
                _ => Point3::new(
                    rng.random_range(-80.0..80.0),
                    rng.random_range(-80.0..80.0),
                    rng.random_range(-5.0..120.0),
                ),
            };
            let seen = object.seen_from(&origin);
            for _ in 0..200 {
                // Half the rays aim at the box, so that hits are common.
                let dir = if rng.random_bool(0.5) {
                    let target = centre
                        + Vector3::new(
                            rng.random_range(-1.2..1.2) * half[0],
                            rng.random_range(-1.2..1.2) * half[1],
                            rng.random_range(-1.2..1.2) * half[2],
                        );
                    (target - origin).try_normalize(0.0).unwrap_or(Vector3::z())
                } else {
                    direction(&mut rng)
                };
                let max_range = match rng.random_range(0..3) {
                    0 => Real::INFINITY,
                    _ => rng.random_range(0.0..150.0),
                };
                let want = object.cast(&origin, &dir, max_range);
                let got = seen.cast(&dir, max_range);
                assert_eq!(got.map(Real::to_bits), want.map(Real::to_bits));
                assert_eq!(seen.is_square(), yaw == 0.0);
                if seen.is_square() {
                    let inv = [1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z];
                    let got = seen.cast_square(&dir, &inv, max_range);
                    assert_eq!(got.map(Real::to_bits), want.map(Real::to_bits));
                    squares += 1;
                }
                hits += usize::from(want.is_some_and(|t| t > 0.0));
                inside += usize::from(want == Some(0.0));
            }
        }
        // Both branches of interest were exercised many times.
        assert!(hits > 10_000, "{hits} hits");
        assert!(inside > 1_000, "{inside} casts from inside");
        assert!(squares > 10_000, "{squares} casts against square boxes");
    }
}
