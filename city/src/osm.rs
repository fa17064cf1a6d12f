//! The OpenStreetMap data the importer reads: nodes, ways and relations with their tags, read
//! from a PBF file or written by hand in tests.

use std::collections::HashMap;

/// A node's position, WGS84 degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LatLon {
    /// Latitude, degrees north.
    pub lat: f64,
    /// Longitude, degrees east.
    pub lon: f64,
}

/// An element's tags, in file order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tags(pub Vec<(String, String)>);

impl Tags {
    /// Tags from `key=value` pairs.
    pub fn of(pairs: &[(&str, &str)]) -> Tags {
        Tags(
            pairs
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
        )
    }

    /// The value of `key`, if tagged.
    pub fn get(&self, key: &str) -> Option<&str> {
        self.0
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    /// Whether `key` is tagged with a value other than `no`.
    pub fn is_set(&self, key: &str) -> bool {
        self.get(key).is_some_and(|v| v != "no")
    }
}

/// A way: a polyline (or a ring, when its last node is its first) of node ids.
#[derive(Clone, Debug, PartialEq)]
pub struct Way {
    /// OSM id.
    pub id: i64,
    /// Node ids in order.
    pub nodes: Vec<i64>,
    /// Tags.
    pub tags: Tags,
}

/// A relation's member way with its role (relations' node and relation members are not used).
#[derive(Clone, Debug, PartialEq)]
pub struct Member {
    /// The way's OSM id.
    pub way: i64,
    /// `outer`, `inner` or another role.
    pub role: String,
}

/// A relation.
#[derive(Clone, Debug, PartialEq)]
pub struct Relation {
    /// OSM id.
    pub id: i64,
    /// Its way members.
    pub members: Vec<Member>,
    /// Tags.
    pub tags: Tags,
}

/// What the importer reads from a file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OsmData {
    /// Node positions by id (only nodes near the area of interest, see [`read_pbf`]).
    pub nodes: HashMap<i64, LatLon>,
    /// Every way.
    pub ways: Vec<Way>,
    /// Every relation.
    pub relations: Vec<Relation>,
    /// The box of every node in the file, `[south, west, north, east]` degrees (`None` without
    /// nodes).
    pub bounds: Option<[f64; 4]>,
}

impl OsmData {
    /// Records a node's position and widens [`OsmData::bounds`].
    pub fn add_node(&mut self, id: i64, at: LatLon, keep: bool) {
        let b = self.bounds.get_or_insert([at.lat, at.lon, at.lat, at.lon]);
        *b = [
            b[0].min(at.lat),
            b[1].min(at.lon),
            b[2].max(at.lat),
            b[3].max(at.lon),
        ];
        if keep {
            self.nodes.insert(id, at);
        }
    }
}

/// Reads a PBF file, keeping the positions of the nodes that `keep` accepts (every way and
/// relation is kept; a way's node outside `keep` is then missing, as at an extract's edge).
///
/// A file that is not PBF, or that is damaged, gives [`crate::error::CityImportError::Read`]. The reader
/// crate can panic on some malformed blocks; such a panic is caught and reported the same way.
#[cfg(feature = "import")]
pub fn read_pbf(
    path: &std::path::Path,
    keep: impl Fn(LatLon) -> bool,
) -> Result<OsmData, crate::error::CityImportError> {
    use crate::error::CityImportError;
    use osmpbf::{Element, ElementReader, RelMemberType};

    let read_error = |reason: String| CityImportError::Read {
        path: path.to_path_buf(),
        reason,
    };
    let reader = ElementReader::from_path(path).map_err(|e| read_error(e.to_string()))?;
    let tags_of = |tags: &mut dyn Iterator<Item = (&str, &str)>| {
        Tags(tags.map(|(k, v)| (k.to_string(), v.to_string())).collect())
    };
    let mut data = OsmData::default();
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        reader.for_each(|element| match element {
            Element::Node(n) => {
                let at = LatLon {
                    lat: n.lat(),
                    lon: n.lon(),
                };
                data.add_node(n.id(), at, keep(at));
            }
            Element::DenseNode(n) => {
                let at = LatLon {
                    lat: n.lat(),
                    lon: n.lon(),
                };
                data.add_node(n.id(), at, keep(at));
            }
            Element::Way(w) => data.ways.push(Way {
                id: w.id(),
                nodes: w.refs().collect(),
                tags: tags_of(&mut w.tags()),
            }),
            Element::Relation(r) => data.relations.push(Relation {
                id: r.id(),
                members: r
                    .members()
                    .filter(|m| m.member_type == RelMemberType::Way)
                    .map(|m| Member {
                        way: m.member_id,
                        role: m.role().unwrap_or("").to_string(),
                    })
                    .collect(),
                tags: tags_of(&mut r.tags()),
            }),
        })
    }));
    match outcome {
        Ok(Ok(())) => Ok(data),
        Ok(Err(e)) => Err(read_error(e.to_string())),
        Err(_) => Err(read_error(
            "the PBF reader failed on a malformed block".into(),
        )),
    }
}
