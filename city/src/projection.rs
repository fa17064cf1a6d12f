//! The local metric frame: east-north coordinates on the plane tangent to the WGS84 ellipsoid
//! at the city's centre.
//!
//! A point on the ellipsoid is taken to earth-centred coordinates and projected orthogonally on
//! the tangent plane at the centre. Within `d` of the centre, horizontal distances shrink by a
//! factor of at most about `1 - d²/(2R²)` (`R` ≈ 6,371 km): about 0.01 mm over 1 km. The frame
//! is flat, while the ground falls below the tangent plane by `d²/(2R)`: 2 cm at 500 m and 3.8
//! cm at the corner of a 500 m half-extent. The world's ground is the plane `z = 0`, so that
//! drop is the frame's error, and [`LocalFrame::flatness_error_m`] states it for a region.

use crate::osm::LatLon;

/// WGS84 semi-major axis, metres.
const A: f64 = 6_378_137.0;
/// WGS84 flattening.
const F: f64 = 1.0 / 298.257_223_563;
/// Mean Earth radius, metres.
const MEAN_RADIUS_M: f64 = 6_371_008.8;

/// The tangent plane at a centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalFrame {
    centre: LatLon,
    origin: [f64; 3],
}

impl LocalFrame {
    /// The frame centred on `centre`.
    pub fn new(centre: LatLon) -> LocalFrame {
        LocalFrame {
            centre,
            origin: ecef(centre),
        }
    }

    /// The centre.
    pub fn centre(&self) -> LatLon {
        self.centre
    }

    /// `[east, north]` of a point, metres.
    pub fn project(&self, p: LatLon) -> [f64; 2] {
        let q = ecef(p);
        let d = [
            q[0] - self.origin[0],
            q[1] - self.origin[1],
            q[2] - self.origin[2],
        ];
        let (sp, cp) = self.centre.lat.to_radians().sin_cos();
        let (sl, cl) = self.centre.lon.to_radians().sin_cos();
        let east = -sl * d[0] + cl * d[1];
        let north = -sp * cl * d[0] - sp * sl * d[1] + cp * d[2];
        [east, north]
    }

    /// The latitude and longitude of a local point, to within 1 mm inside 10 km (Newton's
    /// method on [`LocalFrame::project`]).
    pub fn unproject(&self, xy: [f64; 2]) -> LatLon {
        let m_per_deg_lat = MEAN_RADIUS_M.to_radians();
        let m_per_deg_lon = m_per_deg_lat * self.centre.lat.to_radians().cos().max(1e-6);
        let mut p = LatLon {
            lat: self.centre.lat + xy[1] / m_per_deg_lat,
            lon: self.centre.lon + xy[0] / m_per_deg_lon,
        };
        for _ in 0..5 {
            let at = self.project(p);
            p.lat += (xy[1] - at[1]) / m_per_deg_lat;
            p.lon += (xy[0] - at[0]) / m_per_deg_lon;
        }
        p
    }

    /// How far the ground falls below the flat frame at the corners of the square of half-side
    /// `half_extent_m` about the centre, metres.
    pub fn flatness_error_m(half_extent_m: f64) -> f64 {
        let d = half_extent_m * std::f64::consts::SQRT_2;
        d * d / (2.0 * MEAN_RADIUS_M)
    }
}

/// Earth-centred coordinates of a point on the ellipsoid's surface.
fn ecef(p: LatLon) -> [f64; 3] {
    let e2 = F * (2.0 - F);
    let (sp, cp) = p.lat.to_radians().sin_cos();
    let (sl, cl) = p.lon.to_radians().sin_cos();
    let n = A / (1.0 - e2 * sp * sp).sqrt();
    [n * cp * cl, n * cp * sl, n * (1.0 - e2) * sp]
}

#[cfg(test)]
mod tests {
    use super::*;

    const HELSINKI: LatLon = LatLon {
        lat: 60.1699,
        lon: 24.9384,
    };

    #[test]
    fn the_centre_is_the_origin() {
        let f = LocalFrame::new(HELSINKI);
        let o = f.project(HELSINKI);
        assert!(o[0].abs() < 1e-9 && o[1].abs() < 1e-9);
    }

    #[test]
    fn a_degree_of_latitude_and_of_longitude() {
        // At 60.17° N a thousandth of a degree is 111.415 m of latitude (the WGS84 meridian's
        // radius of curvature there is 6,383.6 km) and 55.514 m of longitude (the parallel's
        // radius is 3,180.7 km).
        let f = LocalFrame::new(HELSINKI);
        let north = f.project(LatLon {
            lat: HELSINKI.lat + 0.001,
            ..HELSINKI
        });
        let east = f.project(LatLon {
            lon: HELSINKI.lon + 0.001,
            ..HELSINKI
        });
        assert!(
            (north[1] - 111.415).abs() < 0.001 && north[0].abs() < 1e-6,
            "{north:?}"
        );
        assert!(
            (east[0] - 55.514).abs() < 0.001 && east[1].abs() < 0.001,
            "{east:?}"
        );
    }

    #[test]
    fn unproject_inverts_project() {
        let f = LocalFrame::new(HELSINKI);
        for xy in [[500.0, -300.0], [-800.0, 900.0], [0.0, 0.0]] {
            let back = f.project(f.unproject(xy));
            assert!(
                (back[0] - xy[0]).abs() < 1e-3 && (back[1] - xy[1]).abs() < 1e-3,
                "{back:?}"
            );
        }
    }

    #[test]
    fn flatness_at_half_a_kilometre() {
        let e = LocalFrame::flatness_error_m(250.0);
        assert!((e - 0.0098).abs() < 0.0002, "{e}");
    }
}
