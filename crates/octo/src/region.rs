//! Region messages (kind 3 of the stream): the view inside a set of coarse voxels, replacing
//! the receiver's there and leaving the rest of its view as it is. A live mapper answers two
//! of the operator's requests with one: a full map inside a box, and a moved region of interest
//! (the coarse voxels whose resolution changes are sent again: fine with colour where the ROI
//! now is, coarse where it was).
//!
//! Payload (docs/octo-delta-format.md, "Region"): a flag byte (bit 0: colours follow), the list
//! of coarse voxels (a path tree at the coarse depth, as a delta's lists), then for each listed
//! voxel in list order its content as one code, 0 unknown, 1 free leaf, 2 occupied leaf, 3 a
//! subtree whose `.bt` records (2 bytes per inner node, pre-order) follow; then, with the flag,
//! r, g, b of every occupied leaf in the order met.
//!
//! Which coarse voxels a request names is bounded ([`MAX_REGION_COARSE`]): the search follows
//! the view's leaves, splitting a leaf larger than a coarse voxel only where it meets the
//! requested boxes, and gives up past the bound (the caller then sends the whole map).

use std::collections::BTreeSet;

use super::delta::{Roi, ViewSpec};
use super::tree::{NodeRef, OcTree, TREE_DEPTH, unmorton};

/// Message kind of a region.
pub const KIND_REGION: u8 = 3;
/// The most coarse voxels one region message replaces; a request naming more is answered with
/// the whole map.
pub const MAX_REGION_COARSE: usize = 1 << 18;

/// Which coarse voxels a region message replaces.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Selection {
    /// The coarse voxels that meet a box (the operator's "full map inside this box").
    Box(Roi),
    /// The coarse voxels whose side of the ROI differs between two ROIs (a moved ROI; `None`
    /// is "everywhere").
    RoiChange {
        /// The ROI before.
        old: Option<Roi>,
        /// The ROI after.
        new: Option<Roi>,
    },
}

/// Whether the node of first voxel `code` at `depth` meets `roi` (closed intervals; `None`:
/// everywhere).
fn meets(resolution_m: f64, code: u64, depth: u32, roi: Option<&Roi>) -> bool {
    let Some(roi) = roi else { return true };
    let k = unmorton(code);
    let edge = resolution_m * (1u64 << (TREE_DEPTH - depth)) as f64;
    (0..3).all(|i| {
        let lo = (k[i] as i64 - 32768) as f64 * resolution_m;
        lo <= roi.max_m[i] && lo + edge >= roi.min_m[i]
    })
}

impl Selection {
    /// Whether a coarse voxel (first voxel `code`) is selected.
    fn picks(&self, spec: &ViewSpec, code: u64) -> bool {
        let (res, d) = (spec.resolution_m, spec.coarse_depth);
        match self {
            Selection::Box(b) => meets(res, code, d, Some(b)),
            Selection::RoiChange { old, new } => {
                meets(res, code, d, old.as_ref()) != meets(res, code, d, new.as_ref())
            }
        }
    }

    /// Whether a node may hold a selected coarse voxel (a bound, for pruning the search).
    fn may_hold(&self, spec: &ViewSpec, code: u64, depth: u32) -> bool {
        let res = spec.resolution_m;
        match self {
            Selection::Box(b) => meets(res, code, depth, Some(b)),
            Selection::RoiChange { old, new } => {
                meets(res, code, depth, old.as_ref()) || meets(res, code, depth, new.as_ref())
            }
        }
    }
}

/// The known coarse voxels of `view` that `sel` picks, ascending (codes at the coarse depth);
/// `None` when there would be more than [`MAX_REGION_COARSE`], or when the selection is
/// unbounded (a ROI change from or to "everywhere"): send the whole map instead.
pub fn select(view: &OcTree, spec: &ViewSpec, sel: &Selection) -> Option<Vec<u64>> {
    if let Selection::RoiChange { old, new } = sel
        && (old.is_none() || new.is_none())
    {
        return None;
    }
    let d = spec.coarse_depth;
    let shift = spec.coarse_shift();
    let mut out: BTreeSet<u64> = BTreeSet::new();
    let mut over = false;
    view.for_each_leaf(|code, depth, _| {
        if over {
            return;
        }
        if depth >= d {
            if sel.picks(spec, code) {
                out.insert(code >> shift);
            }
        } else {
            split(spec, sel, code, depth, &mut out, &mut over);
        }
        over |= out.len() > MAX_REGION_COARSE;
    });
    (!over).then(|| out.into_iter().collect())
}

/// The coarse voxels `sel` picks inside a leaf above the coarse depth, descending only into the
/// octants that may hold one.
fn split(
    spec: &ViewSpec,
    sel: &Selection,
    code: u64,
    depth: u32,
    out: &mut BTreeSet<u64>,
    over: &mut bool,
) {
    if *over || !sel.may_hold(spec, code, depth) {
        return;
    }
    if depth == spec.coarse_depth {
        if sel.picks(spec, code) {
            out.insert(code >> spec.coarse_shift());
            *over |= out.len() > MAX_REGION_COARSE;
        }
        return;
    }
    let shift = 3 * (TREE_DEPTH - 1 - depth);
    for i in 0..8u64 {
        split(spec, sel, code | (i << shift), depth + 1, out, over);
    }
}

/// The payload of a region message: `view` inside the coarse voxels `coarse` (ascending codes
/// at the coarse depth).
pub fn encode_payload(view: &OcTree, spec: &ViewSpec, coarse: &[u64]) -> Vec<u8> {
    let mut p = vec![view.is_colored() as u8];
    super::delta::encode_codes(coarse, spec.coarse_depth, &mut p);
    let mut colors = Vec::new();
    let shift = spec.coarse_shift();
    for &c in coarse {
        match view.search(c << shift, spec.coarse_depth) {
            None => p.push(0),
            Some((n, _)) => {
                let v = view.node(n);
                if v.has_children() {
                    p.push(3);
                    subtree(view, n, &mut p, &mut colors);
                } else if v.log_odds >= 0.0 {
                    p.push(2);
                    colors.extend_from_slice(&v.color.unwrap_or([255, 255, 255]));
                } else {
                    p.push(1);
                }
            }
        }
    }
    if view.is_colored() {
        p.extend_from_slice(&colors);
    }
    p
}

/// A subtree's `.bt` records in pre-order, and the colours of its occupied leaves in the order
/// a reader meets them.
pub(crate) fn subtree(t: &OcTree, r: NodeRef, out: &mut Vec<u8>, colors: &mut Vec<u8>) {
    out.extend_from_slice(&super::files::bt_record(t, r));
    for i in 0..8 {
        if let Some(c) = t.child(r, i) {
            let v = t.node(c);
            if v.has_children() {
                subtree(t, c, out, colors);
            } else if v.log_odds >= 0.0 {
                colors.extend_from_slice(&v.color.unwrap_or([255, 255, 255]));
            }
        }
    }
}

/// A view's leaves outside the coarse voxels `replaced` (ascending), copied into `into`: a
/// leaf that holds replaced voxels is split down to the coarse depth around them.
pub(crate) fn keep_outside(view: &OcTree, spec: &ViewSpec, replaced: &[u64], into: &mut OcTree) {
    let set: BTreeSet<u64> = replaced.iter().copied().collect();
    let shift = spec.coarse_shift();
    let d = spec.coarse_depth;
    view.for_each_leaf(|code, depth, v| {
        keep(into, &set, shift, d, code, depth, v.log_odds, v.color);
    });
}

#[allow(clippy::too_many_arguments)]
fn keep(
    into: &mut OcTree,
    set: &BTreeSet<u64>,
    shift: u32,
    d: u32,
    code: u64,
    depth: u32,
    log_odds: f32,
    color: Option<[u8; 3]>,
) {
    let first = code >> shift;
    if depth >= d {
        if !set.contains(&first) {
            into.set_node(code, depth, log_odds, color);
        }
        return;
    }
    let span = 1u64 << (3 * (d - depth));
    if set.range(first..first + span).next().is_none() {
        into.set_node(code, depth, log_odds, color);
        return;
    }
    let child_shift = 3 * (TREE_DEPTH - 1 - depth);
    for i in 0..8u64 {
        keep(
            into,
            set,
            shift,
            d,
            code | (i << child_shift),
            depth + 1,
            log_odds,
            color,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::delta::{
        Message, Receiver, Sender, decode_message, encode_delta, encode_full, encode_region,
        view_of,
    };
    use crate::{Pose, Scan, files};

    fn scan(z: f32, shift: f32) -> Scan {
        let mut points = Vec::new();
        let mut colors = Vec::new();
        for i in 0..50 {
            for j in 0..50 {
                points.push([i as f32 * 0.06 - 1.5 + shift, j as f32 * 0.06 - 1.5, z]);
                colors.push([(i * 5) as u8, (j * 5) as u8, (i + j) as u8]);
            }
        }
        Scan {
            points,
            colors: Some(colors),
            pose: Pose::IDENTITY,
        }
    }

    fn roi(lo: f64, hi: f64) -> Option<Roi> {
        Some(Roi {
            min_m: [lo, lo, -5.0],
            max_m: [hi, hi, 5.0],
        })
    }

    /// A map of three scans and the receiver's view of their deltas under `spec`.
    fn mapped(spec: ViewSpec) -> (OcTree, Sender, Receiver) {
        let mut tree = OcTree::new(spec.resolution_m);
        tree.enable_color();
        let (mut tx, mut rx) = (Sender::new(spec), Receiver::new(spec));
        for (k, (z, s)) in [(-2.0, 0.0), (-2.0, 0.4), (-1.7, 0.8)]
            .into_iter()
            .enumerate()
        {
            let up = tree.insert_scan(&scan(z, s), None);
            let d = tx.delta(&tree, &up.changes);
            let bytes = encode_delta(&spec, k as u32, &d);
            rx.apply(&decode_message(&spec, &bytes, 0).unwrap().0);
        }
        (tree, tx, rx)
    }

    fn apply(rx: &mut Receiver, bytes: &[u8]) {
        let (m, n) = decode_message(rx.spec(), bytes, 0).unwrap();
        assert_eq!(n, bytes.len());
        rx.apply(&m);
    }

    #[test]
    fn a_moved_roi_gives_the_view_of_the_map_under_the_new_roi() {
        let old = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 13,
            roi: roi(-1.0, 0.0),
        };
        let (tree, mut tx, mut rx) = mapped(old);
        let new = ViewSpec {
            roi: roi(-0.2, 1.5),
            ..old
        };
        let target = view_of(&tree, &new);
        let sel = Selection::RoiChange {
            old: old.roi,
            new: new.roi,
        };
        let coarse = select(&target, &new, &sel).unwrap();
        assert!(!coarse.is_empty());
        let bytes = encode_region(&new, 3, &target, &coarse);
        rx.set_roi(new.roi);
        tx.set_roi(new.roi);
        apply(&mut rx, &bytes);
        assert_eq!(files::write_ot(rx.view()), files::write_ot(&target));
        // Voxels that stayed on their side were not sent again.
        let all = select(&target, &new, &Selection::Box(roi(-1e9, 1e9).unwrap())).unwrap();
        assert!(
            coarse.len() < all.len(),
            "{} of {}",
            coarse.len(),
            all.len()
        );
    }

    #[test]
    fn a_box_region_replaces_the_view_there_only_and_a_full_view_resyncs() {
        let spec = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 14,
            roi: roi(-0.6, 0.6),
        };
        let (tree, _, mut rx) = mapped(spec);
        let before = rx.view().clone();
        // A full message of the receiver's own view rebuilds it exactly (a resync).
        let mut fresh = Receiver::new(spec);
        apply(&mut fresh, &encode_full(2, &before));
        assert_eq!(files::write_ot(fresh.view()), files::write_ot(&before));
        // A box over everything is the map's view, colours as they are now.
        let target = view_of(&tree, &spec);
        let b = Selection::Box(roi(-100.0, 100.0).unwrap());
        let coarse = select(&target, &spec, &b).unwrap();
        apply(&mut rx, &encode_region(&spec, 2, &target, &coarse));
        assert_eq!(files::write_ot(rx.view()), files::write_ot(&target));
        // A box away from the map names nothing and changes nothing.
        let far = Selection::Box(roi(50.0, 60.0).unwrap());
        let none = select(&target, &spec, &far).unwrap();
        assert!(none.is_empty());
        let before = files::write_ot(rx.view());
        apply(&mut rx, &encode_region(&spec, 2, &target, &none));
        assert_eq!(files::write_ot(rx.view()), before);
    }

    #[test]
    fn huge_and_unbounded_selections_are_refused() {
        let mut view = OcTree::new(0.1);
        // One free leaf holding half of space.
        view.set_node(0, 1, -2.0, None);
        let spec = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 16,
            roi: None,
        };
        let huge = Selection::Box(Roi {
            min_m: [-1e300; 3],
            max_m: [1e300; 3],
        });
        assert_eq!(select(&view, &spec, &huge), None);
        let unbounded = Selection::RoiChange {
            old: None,
            new: roi(0.0, 1.0),
        };
        assert_eq!(select(&view, &spec, &unbounded), None);
        let small = Selection::Box(Roi {
            min_m: [-0.35; 3],
            max_m: [-0.05; 3],
        });
        assert_eq!(
            select(&view, &spec, &small).map(|c| c.len()),
            Some(4 * 4 * 4)
        );
    }

    #[test]
    fn bad_region_payloads_are_errors_naming_the_field() {
        let spec = ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 13,
            roi: None,
        };
        let mut view = OcTree::new(0.1);
        view.set_node(0, 13, 2.0, None);
        let good = encode_region(&spec, 1, &view, &[0]);
        assert!(matches!(
            decode_message(&spec, &good, 0).unwrap().0,
            Message::Region { .. }
        ));
        // Content code 7 at the end of the payload (before the CRC).
        let mut payload = encode_payload(&view, &spec, &[0]);
        *payload.last_mut().unwrap() = 7;
        let bad = crate::delta::frame_message(KIND_REGION, 1, &payload);
        let err = decode_message(&spec, &bad, 0).unwrap_err().to_string();
        assert!(
            err.contains("region content code: expected 0..=3, found 7"),
            "{err}"
        );
    }
}
