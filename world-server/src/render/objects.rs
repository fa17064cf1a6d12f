//! What a camera can see besides the ground: boxes, each with what it is.

use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::Cuboid;
use protocol::math::{Isometry3, Point3, Real, Vector3};

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

/// A box in the scene: a cuboid posed in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneObject {
    /// What it is.
    pub kind: ObjectKind,
    /// Its shape, centred on its local origin.
    pub shape: Cuboid,
    /// Where it is: the world pose of its centre.
    pub pose: Isometry3,
}

impl SceneObject {
    /// A box with the given centre, half extents and yaw about the vertical axis.
    pub fn new(kind: ObjectKind, centre: Point3, half_extents: [Real; 3], yaw: Real) -> Self {
        let [hx, hy, hz] = half_extents;
        SceneObject {
            kind,
            shape: Cuboid::new(Vector3::new(hx, hy, hz)),
            pose: Isometry3::new(centre.coords, Vector3::z() * yaw),
        }
    }

    /// The eight corners in the world frame.
    pub fn vertices(&self) -> [Point3; 8] {
        let h = self.shape.half_extents;
        let mut out = [Point3::origin(); 8];
        for (i, v) in out.iter_mut().enumerate() {
            let sx = if i & 1 == 0 { -h.x } else { h.x };
            let sy = if i & 2 == 0 { -h.y } else { h.y };
            let sz = if i & 4 == 0 { -h.z } else { h.z };
            *v = self.pose * Point3::new(sx, sy, sz);
        }
        out
    }

    /// Distance along the unit ray `dir` from `origin` to the first point of the box, if the
    /// ray meets it within `max_range` (0 if `origin` is inside).
    pub fn cast(&self, origin: &Point3, dir: &Vector3, max_range: Real) -> Option<Real> {
        self.shape
            .cast_ray(&self.pose, &Ray::new(*origin, *dir), max_range, true)
    }

    /// Distance from `p` to the nearest point of the box (0 inside).
    pub fn nearest_distance(&self, p: &Point3) -> Real {
        let local = self.pose.inverse_transform_point(p);
        let h = self.shape.half_extents;
        let d = Vector3::new(
            (local.x.abs() - h.x).max(0.0),
            (local.y.abs() - h.y).max(0.0),
            (local.z.abs() - h.z).max(0.0),
        );
        d.norm()
    }

    /// Distance from `p` to the farthest corner of the box (so to every point of it).
    pub fn farthest_distance(&self, p: &Point3) -> Real {
        self.vertices()
            .iter()
            .map(|v| (v - p).norm())
            .fold(0.0, Real::max)
    }
}
