//! What the view's tests share: the scene a player has after a run of updates, the check that
//! it shows exactly the view's occupied voxels, and a stream of messages that grows, replaces
//! and frees voxels.

use std::collections::HashMap;

use super::foxglove_types::{Color, Cube, SceneUpdate};
use super::key_box::KeyBox;
use super::scene::COARSE_RGBA;
use rovlink_octo::delta::{self, Delta, Message, Sender, ViewSpec};
use rovlink_octo::synth::{self, SurveyParams};
use rovlink_octo::tree::{KEY_CENTER, Key, OcTree, TREE_DEPTH, morton};

/// The header of an arrivals file, as `build --arrivals` writes it.
pub(super) const HEADER: &str = "scan,bytes,t_ready_s,t_complete_s,t_shown_s,latency_s\n";

/// The scene a player has after `updates`: entity id -> cubes.
pub(super) fn replay(scene: &mut HashMap<String, Vec<Cube>>, u: &SceneUpdate) {
    for d in &u.deletions {
        assert!(scene.remove(&d.id).is_some(), "deleted {} never sent", d.id);
    }
    for e in &u.entities {
        assert!(!e.cubes.is_empty(), "{} sent empty", e.id);
        scene.insert(e.id.clone(), e.cubes.clone());
    }
}

/// Fine voxels of the scene: key -> (fine?, colour); each voxel in one cube only.
pub(super) fn scene_voxels(
    scene: &HashMap<String, Vec<Cube>>,
    res: f64,
) -> HashMap<Key, (bool, Color)> {
    let mut out = HashMap::new();
    for (id, cubes) in scene {
        let fine = id.starts_with("fine/");
        for c in cubes {
            let p = [c.pose.position.x, c.pose.position.y, c.pose.position.z];
            let s = [c.size.x, c.size.y, c.size.z];
            let lo: Vec<i64> = (0..3)
                .map(|a| ((p[a] - s[a] / 2.0) / res).round() as i64 + KEY_CENTER)
                .collect();
            let n: Vec<i64> = (0..3).map(|a| (s[a] / res).round() as i64).collect();
            for x in 0..n[0] {
                for y in 0..n[1] {
                    for z in 0..n[2] {
                        let k = [lo[0] + x, lo[1] + y, lo[2] + z].map(|v| v as u16);
                        assert!(out.insert(k, (fine, c.color)).is_none(), "{k:?} twice");
                    }
                }
            }
        }
    }
    out
}

/// Fine voxels of the view's occupied leaves: key -> (in the ROI's coarse voxels?, colour).
fn view_voxels(view: &OcTree, spec: &ViewSpec) -> HashMap<Key, (bool, Option<[u8; 3]>)> {
    let mut out = HashMap::new();
    view.for_each_leaf(|code, depth, v| {
        if v.log_odds < 0.0 {
            return;
        }
        let b = KeyBox::of_node(code, depth);
        for x in b.lo[0]..b.hi[0] {
            for y in b.lo[1]..b.hi[1] {
                for z in b.lo[2]..b.hi[2] {
                    let k = [x as u16, y as u16, z as u16];
                    let fine = spec.coarse_in_roi(morton(k) >> spec.coarse_shift());
                    out.insert(k, (fine, v.color));
                }
            }
        }
    });
    out
}

pub(super) fn assert_same(scene: &HashMap<String, Vec<Cube>>, view: &OcTree, spec: &ViewSpec) {
    let shown = scene_voxels(scene, spec.resolution_m);
    let want = view_voxels(view, spec);
    assert_eq!(shown.len(), want.len());
    for (k, (fine, col)) in &want {
        let (sfine, scol) = shown.get(k).unwrap_or_else(|| panic!("{k:?} not shown"));
        assert_eq!(sfine, fine, "{k:?} class");
        match (fine, col) {
            (true, Some(rgb)) => {
                let got = [scol.r, scol.g, scol.b].map(|c| (c * 255.0).round() as u8);
                assert_eq!(&got, rgb, "{k:?} colour");
                assert_eq!(scol.a, 1.0);
            }
            (true, None) => assert_eq!(scol.a, 1.0),
            (false, _) => assert_eq!(scol.a, COARSE_RGBA[3]),
        }
    }
}

/// Deltas of a small coloured survey, then a full view, then deltas that free voxels.
pub(super) fn messages(spec: &ViewSpec) -> Vec<Message> {
    let params = SurveyParams {
        scans: 4,
        rays_x: 48,
        rays_y: 36,
        ..SurveyParams::default()
    };
    let mut tree = OcTree::new(spec.resolution_m);
    tree.enable_color();
    let mut tx = Sender::new(*spec);
    let mut out = Vec::new();
    for (k, scan) in synth::survey(&params).iter().enumerate() {
        let up = tree.insert_scan(scan, None);
        let d = tx.delta(&tree, &up.changes);
        out.push(Message::Delta {
            scan: k as u32,
            delta: d,
        });
    }
    let view = delta::view_of(&tree, spec);
    let full = delta::encode_full(4, &view);
    out.push(delta::decode_message(spec, &full, 0).unwrap().0);
    // Every other occupied voxel of the view becomes free.
    let mut freed = Delta::default();
    let mut i = 0;
    view.for_each_leaf(|code, depth, v| {
        i += 1;
        if v.log_odds < 0.0 || i % 2 == 0 {
            return;
        }
        if depth == TREE_DEPTH {
            freed.fine_free.push(code);
        } else if depth == spec.coarse_depth {
            freed.coarse_free.push(code >> spec.coarse_shift());
        }
    });
    assert!(!freed.fine_free.is_empty() || !freed.coarse_free.is_empty());
    out.push(Message::Delta {
        scan: 5,
        delta: freed,
    });
    out
}
