//! Boxes of fine-voxel keys and the Morton-code arithmetic of the scene's units: a node's box,
//! its cut at the fine region's edge, and the fine region itself (the ROI widened to whole
//! coarse voxels).

use rovlink_octo::delta::ViewSpec;
use rovlink_octo::tree::{KEY_CENTER, TREE_DEPTH, unmorton};

/// A box of fine-voxel keys, `lo` inclusive, `hi` exclusive (up to 65 536).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct KeyBox {
    pub(super) lo: [u32; 3],
    pub(super) hi: [u32; 3],
}

impl KeyBox {
    /// The box of the node of depth-16 code `code` at `depth`.
    pub(super) fn of_node(code: u64, depth: u32) -> KeyBox {
        let k = unmorton(code);
        let n = 1u32 << (TREE_DEPTH - depth.min(TREE_DEPTH));
        let lo = k.map(|c| c as u32 & !(n - 1));
        KeyBox {
            lo,
            hi: lo.map(|c| c + n),
        }
    }

    fn is_empty(&self) -> bool {
        (0..3).any(|a| self.lo[a] >= self.hi[a])
    }
}

/// Pushes the parts of `b` inside `r` to `inside` and the rest (at most six boxes) to
/// `outside`.
pub(super) fn split_box(
    b: KeyBox,
    r: &KeyBox,
    inside: &mut Vec<KeyBox>,
    outside: &mut Vec<KeyBox>,
) {
    let mut rest = b;
    for a in 0..3 {
        if rest.is_empty() {
            return;
        }
        if rest.lo[a] < r.lo[a] {
            let mut piece = rest;
            piece.hi[a] = rest.hi[a].min(r.lo[a]);
            outside.push(piece);
            rest.lo[a] = rest.lo[a].max(r.lo[a]);
        }
        if rest.is_empty() {
            return;
        }
        if rest.hi[a] > r.hi[a] {
            let mut piece = rest;
            piece.lo[a] = rest.lo[a].max(r.hi[a]);
            outside.push(piece);
            rest.hi[a] = rest.hi[a].min(r.hi[a]);
        }
    }
    if !rest.is_empty() {
        inside.push(rest);
    }
}

/// Bits of the depth-16 Morton code below a node of `depth`.
pub(super) fn code_span(depth: u32) -> u64 {
    1u64 << (3 * (TREE_DEPTH - depth.min(TREE_DEPTH)))
}

/// The depth-16 code of the node of `depth` holding the voxel `code`.
pub(super) fn node_code(code: u64, depth: u32) -> u64 {
    code & !(code_span(depth) - 1)
}

/// The key box of the coarse voxels that meet the ROI (the same test as
/// [`ViewSpec::coarse_in_roi`], axis by axis); `None` without an ROI.
pub(super) fn fine_region(spec: &ViewSpec) -> Option<KeyBox> {
    let roi = spec.roi?;
    let depth = spec.coarse_depth.clamp(1, TREE_DEPTH);
    let shift = TREE_DEPTH - depth;
    let edge_m = spec.resolution_m * (1u64 << shift) as f64;
    let mut region = KeyBox {
        lo: [0; 3],
        hi: [0; 3],
    };
    for a in 0..3 {
        let meets = |i: u32| {
            let lo_m = ((i << shift) as i64 - KEY_CENTER) as f64 * spec.resolution_m;
            lo_m <= roi.max_m[a] && lo_m + edge_m >= roi.min_m[a]
        };
        let mut hits = (0..1u32 << depth).filter(|&i| meets(i));
        let Some(first) = hits.next() else {
            return Some(KeyBox {
                lo: [0; 3],
                hi: [0; 3],
            });
        };
        let last = hits.next_back().unwrap_or(first);
        region.lo[a] = first << shift;
        region.hi[a] = (last + 1) << shift;
    }
    Some(region)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rovlink_octo::delta::Roi;
    use rovlink_octo::tree::morton;

    #[test]
    fn the_fine_region_is_the_coarse_voxels_that_meet_the_roi() {
        for (res, depth, roi) in [
            (0.1, 5u32, ([-1.0e3, -30.0, -0.05], [1.0e3, 12.3, 0.05])),
            (0.3, 4, ([-1.0, -1.0, -1.0], [-1.0, -1.0, -1.0])),
            (0.1, 3, ([5e6, 5e6, 5e6], [6e6, 6e6, 6e6])),
        ] {
            let spec = ViewSpec {
                resolution_m: res,
                coarse_depth: depth,
                roi: Some(Roi {
                    min_m: roi.0,
                    max_m: roi.1,
                }),
            };
            let region = fine_region(&spec).unwrap();
            for c in 0..1u64 << (3 * depth) {
                let k = spec.coarse_key(c);
                let inside =
                    (0..3).all(|a| (region.lo[a]..region.hi[a]).contains(&u32::from(k[a])));
                assert_eq!(inside, spec.coarse_in_roi(c), "{spec:?} {k:?}");
            }
        }
    }

    #[test]
    fn a_box_splits_into_disjoint_pieces_that_cover_it() {
        let r = KeyBox {
            lo: [4, 4, 4],
            hi: [8, 12, 6],
        };
        let boxes = [
            KeyBox::of_node(0, 12),
            KeyBox::of_node(morton([6, 6, 4]), 15),
            KeyBox::of_node(morton([32, 0, 0]), 13),
            KeyBox {
                lo: [0; 3],
                hi: [65536; 3],
            },
        ];
        for b in boxes {
            let (mut inside, mut outside) = (Vec::new(), Vec::new());
            split_box(b, &r, &mut inside, &mut outside);
            assert!(inside.len() <= 1 && outside.len() <= 6);
            let vol = |b: &KeyBox| {
                (0..3)
                    .map(|a| u64::from(b.hi[a] - b.lo[a]))
                    .product::<u64>()
            };
            let total: u64 = inside.iter().chain(&outside).map(vol).sum();
            assert_eq!(total, vol(&b), "{b:?}");
            for p in &inside {
                assert!((0..3).all(|a| p.lo[a] >= r.lo[a] && p.hi[a] <= r.hi[a]));
            }
            for p in &outside {
                assert!(
                    (0..3).any(|a| p.hi[a] <= r.lo[a] || p.lo[a] >= r.hi[a]),
                    "{p:?}"
                );
            }
        }
    }
}
