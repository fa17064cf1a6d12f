//! Properties of the importer's geometry on random shapes.
#![cfg(feature = "import")]

use city::convex::decompose;
use city::geometry::{
    Xy, convex_contains, is_convex_ccw, lerp, point_convex_distance, ring_contains,
    segment_near_convex, signed_area,
};
use proptest::prelude::*;

/// A star-shaped ring about the origin (always simple): `n` corners at increasing angles with
/// radii in `[5, 30]`, counter-clockwise.
fn star(radii: &[f64]) -> Vec<Xy> {
    let n = radii.len() as f64;
    radii
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let a = std::f64::consts::TAU * k as f64 / n;
            [r * a.cos(), r * a.sin()]
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// The parts of a star-shaped footprint with a square courtyard are convex, cover its
    /// area exactly, and a point lies in some part exactly when it lies in the footprint.
    #[test]
    fn convex_parts_tile_the_footprint(
        radii in prop::collection::vec(8.0..30.0f64, 5..24),
        hole in prop::bool::ANY,
        probes in prop::collection::vec((-30.0..30.0f64, -30.0..30.0f64), 50),
    ) {
        let outer = star(&radii);
        // A courtyard of 6 m a side at the centre, inside every star (radii of at least 8 m).
        let holes: Vec<Vec<Xy>> = if hole {
            vec![vec![[-3.0, -3.0], [-3.0, 3.0], [3.0, 3.0], [3.0, -3.0]]]
        } else {
            vec![]
        };
        let d = decompose(&outer, &holes);
        let area = signed_area(&outer) - if hole { 36.0 } else { 0.0 };
        let total: f64 = d.parts.iter().map(|p| signed_area(p)).sum();
        prop_assert!((total - area).abs() < 1e-6 * area.max(1.0), "{total} against {area}");
        for part in &d.parts {
            prop_assert!(is_convex_ccw(part), "{part:?}");
        }
        for (x, y) in probes {
            let p = [x, y];
            let inside = ring_contains(&outer, p) && !holes.iter().any(|h| ring_contains(h, p));
            let near_edge = d.parts.iter().any(|q| point_convex_distance(p, q) < 1e-6 && !convex_contains(q, p))
                || outer.iter().zip(outer.iter().cycle().skip(1)).any(|(a, b)| city::geometry::point_segment_distance(p, *a, *b) < 1e-6);
            if near_edge {
                continue;
            }
            let hits = d.parts.iter().filter(|q| convex_contains(q, p)).count();
            prop_assert_eq!(hits > 0, inside, "{:?}", p);
        }
    }

    /// Every point of a segment closer than `d` to a convex polygon lies in the interval the
    /// cut search returns.
    #[test]
    fn the_cut_holds_every_near_point(
        a in (-40.0..40.0f64, -40.0..40.0f64),
        b in (-40.0..40.0f64, -40.0..40.0f64),
        radii in prop::collection::vec(2.0..10.0f64, 3..3 + 1),
        rot in 0.0..std::f64::consts::TAU,
        d in 0.5..12.0f64,
    ) {
        // A triangle, convex by construction.
        let poly: Vec<Xy> = radii
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let t = rot + std::f64::consts::TAU * k as f64 / 3.0;
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        let (a, b) = ([a.0, a.1], [b.0, b.1]);
        let found = segment_near_convex(a, b, &poly, d, 1e-3);
        for k in 0..=2000 {
            let t = k as f64 / 2000.0;
            if point_convex_distance(lerp(a, b, t), &poly) < d {
                let (t0, t1) = found.expect("a near point, and no interval");
                prop_assert!(t >= t0 && t <= t1, "t = {t} outside [{t0}, {t1}]");
            }
        }
    }
}
