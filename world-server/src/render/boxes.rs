//! Target boxes: which targets a frame identifies, and the pixels they may occupy.

use protocol::frame::{FRAME_MAX_BOXES, TargetBox};

/// What one row saw of one target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowTarget {
    /// Target id.
    pub id: u32,
    /// Pixels of the row labelled T with this target.
    pub labelled: u32,
    /// First column with a ray on the target.
    pub c0: u32,
    /// Last column with a ray on the target.
    pub c1: u32,
}

/// Per-row records, in column order of discovery.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RowTargets(pub Vec<RowTarget>);

impl RowTargets {
    /// Notes that a ray of pixel column `c` hit target `id`, and whether the pixel is
    /// labelled T with it.
    pub fn hit(&mut self, id: u32, c: u32, labelled: bool) {
        let add = u32::from(labelled);
        match self.0.iter_mut().find(|t| t.id == id) {
            Some(t) => {
                t.labelled += add;
                t.c0 = t.c0.min(c);
                t.c1 = t.c1.max(c);
            }
            None => self.0.push(RowTarget {
                id,
                labelled: add,
                c0: c,
                c1: c,
            }),
        }
    }
}

/// The boxes of the targets with at least `min_pixels` T pixels, by increasing id, at most
/// [`FRAME_MAX_BOXES`]: each the pixel bounding box (half-open) of every pixel any of whose
/// rays hit the target.
pub fn identified(rows: &[RowTargets], min_pixels: u32) -> Vec<TargetBox> {
    let mut acc: Vec<(TargetBox, u64)> = Vec::new();
    for (r, row) in rows.iter().enumerate() {
        let r = r as u32;
        for t in &row.0 {
            match acc.iter_mut().find(|(b, _)| b.id == t.id) {
                Some((b, n)) => {
                    b.r1 = r + 1;
                    b.c0 = b.c0.min(t.c0);
                    b.c1 = b.c1.max(t.c1 + 1);
                    *n += t.labelled as u64;
                }
                None => acc.push((
                    TargetBox {
                        id: t.id,
                        r0: r,
                        c0: t.c0,
                        r1: r + 1,
                        c1: t.c1 + 1,
                    },
                    t.labelled as u64,
                )),
            }
        }
    }
    acc.sort_by_key(|(b, _)| b.id);
    acc.into_iter()
        .filter(|(_, n)| *n >= min_pixels as u64)
        .map(|(b, _)| b)
        .take(FRAME_MAX_BOXES)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_bounds_every_hit_and_needs_enough_labels() {
        let mut a = RowTargets::default();
        a.hit(3, 5, true);
        a.hit(3, 7, false);
        a.hit(9, 1, false);
        let mut b = RowTargets::default();
        b.hit(3, 4, true);
        let boxes = identified(&[RowTargets::default(), a, b], 2);
        assert_eq!(
            boxes,
            vec![TargetBox {
                id: 3,
                r0: 1,
                c0: 4,
                r1: 3,
                c1: 8
            }]
        );
    }
}
