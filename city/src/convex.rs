//! Convex decomposition of a footprint with holes.
//!
//! The renderer's labels rely on convex objects, so every footprint becomes convex parts:
//! earcut triangulates the polygon with its holes, and neighbouring pieces are then merged
//! across their shared edge while the merge stays convex (Hertel and Mehlhorn's greedy merge,
//! which gives at most four times the fewest convex parts). The parts tile the triangulated
//! polygon exactly: they are its triangles, grouped.

use std::collections::HashMap;

use earcut::Earcut;

use crate::geometry::{Xy, cross, signed_area, simplify_ring};

/// Twice the area below which a triangle is dropped as degenerate, m².
const DEGENERATE_AREA2: f64 = 1e-6;

/// A footprint cut into convex parts.
#[derive(Clone, Debug, PartialEq)]
pub struct Decomposition {
    /// The convex parts, counter-clockwise, strictly convex.
    pub parts: Vec<Vec<Xy>>,
    /// The parts' total area over the polygon's (outer minus holes): 1 when the rings are a
    /// valid polygon; otherwise the rings cross themselves or each other.
    pub area_ratio: f64,
}

/// Cuts the polygon `outer` minus `holes` into convex parts.
pub fn decompose(outer: &[Xy], holes: &[Vec<Xy>]) -> Decomposition {
    let mut points: Vec<Xy> = outer.to_vec();
    let mut hole_starts = Vec::with_capacity(holes.len());
    for hole in holes {
        hole_starts.push(points.len());
        points.extend_from_slice(hole);
    }
    let mut triangles: Vec<usize> = Vec::new();
    Earcut::new().earcut(points.iter().copied(), &hole_starts, &mut triangles);

    let mut pieces: Vec<Option<Vec<usize>>> = triangles
        .chunks_exact(3)
        .filter_map(|t| {
            let twice = cross(points[t[0]], points[t[1]], points[t[2]]);
            if twice.abs() < DEGENERATE_AREA2 {
                None
            } else if twice > 0.0 {
                Some(Some(vec![t[0], t[1], t[2]]))
            } else {
                Some(Some(vec![t[0], t[2], t[1]]))
            }
        })
        .collect();
    merge_convex(&points, &mut pieces);

    let parts: Vec<Vec<Xy>> = pieces
        .into_iter()
        .flatten()
        .map(|ring| {
            simplify_ring(
                &ring.iter().map(|&i| points[i]).collect::<Vec<_>>(),
                DEGENERATE_AREA2,
            )
        })
        .filter(|ring| ring.len() >= 3)
        .collect();
    let polygon_area =
        signed_area(outer).abs() - holes.iter().map(|h| signed_area(h).abs()).sum::<f64>();
    let parts_area: f64 = parts.iter().map(|p| signed_area(p)).sum();
    let area_ratio = if polygon_area > 0.0 {
        parts_area / polygon_area
    } else {
        0.0
    };
    Decomposition { parts, area_ratio }
}

/// Merges neighbouring counter-clockwise pieces (vertex indices into `points`) across shared
/// edges while the result stays convex.
fn merge_convex(points: &[Xy], pieces: &mut [Option<Vec<usize>>]) {
    let mut owner: HashMap<(usize, usize), usize> = HashMap::new();
    for (i, piece) in pieces.iter().enumerate() {
        for (u, v) in edges(piece.as_deref().unwrap_or(&[])) {
            owner.insert((u, v), i);
        }
    }
    for i in 0..pieces.len() {
        while merge_one(points, pieces, &mut owner, i) {}
    }
}

/// Merges piece `i` with one neighbour if the result is convex; whether it did.
fn merge_one(
    points: &[Xy],
    pieces: &mut [Option<Vec<usize>>],
    owner: &mut HashMap<(usize, usize), usize>,
    i: usize,
) -> bool {
    let Some(piece) = pieces[i].clone() else {
        return false;
    };
    for (u, v) in edges(&piece) {
        let Some(&j) = owner.get(&(v, u)) else {
            continue;
        };
        let Some(other) = pieces[j].as_deref().filter(|_| j != i) else {
            continue;
        };
        let merged = join(&piece, other, u, v);
        if is_convex(points, &merged) {
            for e in edges(other) {
                owner.remove(&e);
            }
            for e in edges(&merged) {
                owner.insert(e, i);
            }
            pieces[j] = None;
            pieces[i] = Some(merged);
            return true;
        }
    }
    false
}

/// The directed edges of a ring.
fn edges(ring: &[usize]) -> impl Iterator<Item = (usize, usize)> + '_ {
    (0..ring.len()).map(move |k| (ring[k], ring[(k + 1) % ring.len()]))
}

/// The ring of `a` and `b` joined across the edge `u -> v` of `a` (`v -> u` of `b`).
fn join(a: &[usize], b: &[usize], u: usize, v: usize) -> Vec<usize> {
    let rotate = |ring: &[usize], start: usize| -> Vec<usize> {
        let k = ring.iter().position(|&x| x == start).unwrap_or(0);
        ring[k..].iter().chain(&ring[..k]).copied().collect()
    };
    // `a` from v round to u, then `b`'s vertices strictly between u and v.
    let mut out = rotate(a, v);
    let from_u = rotate(b, u);
    out.extend(&from_u[1..from_u.len() - 1]);
    out
}

/// Whether the ring turns left or goes straight at every vertex.
fn is_convex(points: &[Xy], ring: &[usize]) -> bool {
    let n = ring.len();
    (0..n).all(|k| {
        cross(
            points[ring[k]],
            points[ring[(k + 1) % n]],
            points[ring[(k + 2) % n]],
        ) >= -1e-9
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::is_convex_ccw;

    fn check(outer: &[Xy], holes: &[Vec<Xy>], area: f64) -> Decomposition {
        let d = decompose(outer, holes);
        assert!((d.area_ratio - 1.0).abs() < 1e-9, "{}", d.area_ratio);
        let total: f64 = d.parts.iter().map(|p| signed_area(p)).sum();
        assert!((total - area).abs() < 1e-6, "{total}");
        for p in &d.parts {
            assert!(is_convex_ccw(p), "{p:?}");
        }
        d
    }

    #[test]
    fn a_square_stays_one_part() {
        let d = check(&[[0.0, 0.0], [0.0, 4.0], [4.0, 4.0], [4.0, 0.0]], &[], 16.0);
        assert_eq!(d.parts.len(), 1);
        assert_eq!(d.parts[0].len(), 4);
    }

    #[test]
    fn an_l_shape_becomes_two_parts() {
        let l = [
            [0.0, 0.0],
            [20.0, 0.0],
            [20.0, 8.0],
            [8.0, 8.0],
            [8.0, 20.0],
            [0.0, 20.0],
        ];
        let d = check(&l, &[], 20.0 * 8.0 + 8.0 * 12.0);
        assert_eq!(d.parts.len(), 2);
    }

    #[test]
    fn a_courtyard_is_left_empty() {
        let outer = [[0.0, 0.0], [30.0, 0.0], [30.0, 30.0], [0.0, 30.0]];
        let hole = vec![[10.0, 10.0], [10.0, 20.0], [20.0, 20.0], [20.0, 10.0]];
        let d = check(&outer, std::slice::from_ref(&hole), 900.0 - 100.0);
        assert!(d.parts.len() >= 4);
        for p in &d.parts {
            assert!(!crate::geometry::convex_contains(p, [15.0, 15.0]));
        }
    }

    #[test]
    fn a_self_crossing_ring_is_reported() {
        let bow = [[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]];
        let d = decompose(&bow, &[]);
        assert!((d.area_ratio - 1.0).abs() > 0.1, "{}", d.area_ratio);
    }
}
