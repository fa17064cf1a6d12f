//! Buildings from OpenStreetMap: closed ways and multipolygon relations tagged `building`,
//! with their holes, in the local frame, cut into convex parts and clipped to the region.

use std::collections::{HashMap, HashSet};

use crate::convex::decompose;
use crate::geometry::{Xy, clip_convex_to_square, ring_contains, signed_area, simplify_ring};
use crate::osm::{OsmData, Tags, Way};
use crate::projection::LocalFrame;
use crate::scene::SceneBuilding;

/// Parts smaller than this after clipping are dropped, m².
const MIN_PART_AREA_M2: f64 = 0.01;
/// A footprint whose convex parts cover less or more of it than this share is reported as
/// broken (its rings cross): the parts, not the rings, are then the building.
const AREA_RATIO_TOLERANCE: f64 = 0.01;

/// What reading the buildings found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BuildingCounts {
    /// Buildings kept (with at least one part inside the region).
    pub kept: usize,
    /// Of those, multipolygon relations.
    pub multipolygons: usize,
    /// Holes kept.
    pub holes: usize,
    /// Convex parts.
    pub parts: usize,
    /// Buildings skipped because a node or a ring was missing (at the extract's edge).
    pub incomplete: usize,
    /// Buildings whose rings cross themselves or each other: their parts cover their rings' area
    /// to worse than 1 %.
    pub broken: usize,
}

/// The buildings of `data` that reach into the square `[-h, h]²` of `frame`.
pub fn buildings(
    data: &OsmData,
    frame: &LocalFrame,
    h: f64,
) -> (Vec<SceneBuilding>, BuildingCounts) {
    let ways: HashMap<i64, &Way> = data.ways.iter().map(|w| (w.id, w)).collect();
    let project = |ids: &[i64]| -> Option<Vec<Xy>> {
        ids.iter()
            .map(|id| data.nodes.get(id).map(|&p| frame.project(p)))
            .collect()
    };
    let mut counts = BuildingCounts::default();
    let mut out = Vec::new();

    // Ways that are the outline of a building relation are that relation's, not buildings of
    // their own.
    let mut relation_rings: HashSet<i64> = HashSet::new();
    for r in &data.relations {
        if is_building(&r.tags) && r.tags.get("type") == Some("multipolygon") {
            relation_rings.extend(r.members.iter().map(|m| m.way));
        }
    }

    for w in &data.ways {
        if !is_building(&w.tags) || relation_rings.contains(&w.id) {
            continue;
        }
        if w.nodes.len() < 4 || w.nodes.first() != w.nodes.last() {
            counts.incomplete += 1;
            continue;
        }
        let Some(ring) = project(&w.nodes[..w.nodes.len() - 1]) else {
            counts.incomplete += 1;
            continue;
        };
        if let Some(b) = building(
            format!("way/{}", w.id),
            &w.tags,
            vec![ring],
            vec![],
            h,
            &mut counts,
        ) {
            out.push(b);
        }
    }

    for r in &data.relations {
        if !is_building(&r.tags) || r.tags.get("type") != Some("multipolygon") {
            continue;
        }
        let mut outer_ways = Vec::new();
        let mut inner_ways = Vec::new();
        let mut missing = false;
        for m in &r.members {
            match ways.get(&m.way) {
                Some(w) if m.role == "inner" => inner_ways.push(w.nodes.clone()),
                Some(w) => outer_ways.push(w.nodes.clone()),
                None => missing = true,
            }
        }
        let rings = |parts| -> Option<Vec<Vec<Xy>>> {
            assemble_rings(parts)?.iter().map(|r| project(r)).collect()
        };
        match (missing, rings(outer_ways), rings(inner_ways)) {
            (false, Some(outers), Some(inners)) if !outers.is_empty() => {
                if let Some(b) = building(
                    format!("relation/{}", r.id),
                    &r.tags,
                    outers,
                    inners,
                    h,
                    &mut counts,
                ) {
                    counts.multipolygons += 1;
                    out.push(b);
                }
            }
            _ => counts.incomplete += 1,
        }
    }
    counts.kept = out.len();
    (out, counts)
}

/// Whether an element is a building.
fn is_building(tags: &Tags) -> bool {
    tags.is_set("building")
}

/// One building from its outer rings and holes (several outer rings become one building with
/// every ring's parts), or `None` when nothing of it lies inside the region.
fn building(
    osm: String,
    tags: &Tags,
    outers: Vec<Vec<Xy>>,
    inners: Vec<Vec<Xy>>,
    h: f64,
    counts: &mut BuildingCounts,
) -> Option<SceneBuilding> {
    let mut parts = Vec::new();
    let mut broken = false;
    let mut kept_outer = Vec::new();
    let mut kept_holes = Vec::new();
    for outer in outers {
        let outer = ccw(simplify_ring(&outer, 0.0));
        if outer.len() < 3 {
            continue;
        }
        let holes: Vec<Vec<Xy>> = inners
            .iter()
            .filter(|hole| hole.first().is_some_and(|&p| ring_contains(&outer, p)))
            .map(|hole| cw(simplify_ring(hole, 0.0)))
            .filter(|hole| hole.len() >= 3)
            .collect();
        let d = decompose(&outer, &holes);
        broken |= (d.area_ratio - 1.0).abs() > AREA_RATIO_TOLERANCE;
        let before = parts.len();
        for part in d.parts {
            let clipped = simplify_ring(&clip_convex_to_square(&part, h), 1e-9);
            if clipped.len() >= 3 && signed_area(&clipped) >= MIN_PART_AREA_M2 {
                parts.push(clipped);
            }
        }
        if parts.len() > before {
            kept_outer.push(outer);
            kept_holes.extend(holes);
        }
    }
    if parts.is_empty() {
        return None;
    }
    counts.parts += parts.len();
    counts.holes += kept_holes.len();
    counts.broken += usize::from(broken);
    // The scene keeps one outer ring per building: a building of several rings (rare: a
    // relation of detached wings) keeps its largest as the outline; its parts hold them all.
    let outer = kept_outer
        .into_iter()
        .max_by(|a, b| signed_area(a).total_cmp(&signed_area(b)))
        .unwrap_or_default();
    Some(SceneBuilding {
        osm,
        height_tag_m: tags.get("height").and_then(parse_metres),
        levels: tags.get("building:levels").and_then(parse_positive),
        outer,
        holes: kept_holes,
        parts,
    })
}

/// Joins ways into closed rings by their shared end nodes; `None` if one stays open.
fn assemble_rings(mut pieces: Vec<Vec<i64>>) -> Option<Vec<Vec<i64>>> {
    let mut rings = Vec::new();
    while let Some(mut ring) = pieces.pop() {
        while ring.len() < 2 || ring.first() != ring.last() {
            let end = *ring.last()?;
            let k = pieces
                .iter()
                .position(|p| p.first() == Some(&end) || p.last() == Some(&end))?;
            let mut next = pieces.swap_remove(k);
            if next.first() != Some(&end) {
                next.reverse();
            }
            ring.extend_from_slice(&next[1..]);
        }
        ring.pop();
        if ring.len() >= 3 {
            rings.push(ring);
        }
    }
    Some(rings)
}

fn ccw(mut ring: Vec<Xy>) -> Vec<Xy> {
    if signed_area(&ring) < 0.0 {
        ring.reverse();
    }
    ring
}

fn cw(mut ring: Vec<Xy>) -> Vec<Xy> {
    if signed_area(&ring) > 0.0 {
        ring.reverse();
    }
    ring
}

/// A `height` value in metres: a number, optionally followed by `m` (other units are not
/// read, and the building falls back to its levels).
fn parse_metres(v: &str) -> Option<f64> {
    let v = v.trim();
    let number = v.strip_suffix('m').map_or(v, str::trim_end);
    parse_positive(number)
}

/// A positive finite number.
fn parse_positive(v: &str) -> Option<f64> {
    v.trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite() && *x > 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_parse_in_metres_only() {
        assert_eq!(parse_metres("12"), Some(12.0));
        assert_eq!(parse_metres("12.5 m"), Some(12.5));
        assert_eq!(parse_metres("7m"), Some(7.0));
        assert_eq!(parse_metres("40'"), None);
        assert_eq!(parse_metres("-3"), None);
        assert_eq!(parse_positive("3;4"), None);
    }

    #[test]
    fn rings_are_joined_from_pieces_in_any_direction() {
        let rings = assemble_rings(vec![vec![1, 2, 3], vec![5, 4, 3], vec![5, 6, 1]]).unwrap();
        assert_eq!(rings.len(), 1);
        assert_eq!(rings[0].len(), 6);
        assert!(assemble_rings(vec![vec![1, 2, 3], vec![3, 4]]).is_none());
    }
}
