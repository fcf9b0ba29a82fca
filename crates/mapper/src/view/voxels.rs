//! The view as points: the centre of every occupied leaf, coloured, what RViz's and Foxglove's
//! point-cloud displays draw (Foxglove draws no OctoMap).

use super::key_box::KeyBox;
use rovlink_octo::tree::{KEY_CENTER, OcTree};
use rovlink_octo::{Pose, Scan};

/// The colour of an occupied leaf that has none in a coloured map (coarse voxels): grey.
pub const NO_COLOUR: [u8; 3] = [128, 128, 128];

/// One point per occupied leaf of `tree`, at its centre (metres, in the map's frame; a coarse
/// leaf is one point at the centre of its cube), with the leaf's colour when the map keeps
/// colours ([`NO_COLOUR`] for a leaf without one). The pose is the identity.
pub fn occupied_centres(tree: &OcTree) -> Scan {
    let res = tree.resolution_m();
    let coloured = tree.is_colored();
    let mut points = Vec::new();
    let mut colors = Vec::new();
    tree.for_each_leaf(|code, depth, v| {
        if v.log_odds < 0.0 {
            return;
        }
        let b = KeyBox::of_node(code, depth);
        let centre = |a: usize| {
            let mid = (f64::from(b.lo[a]) + f64::from(b.hi[a])) / 2.0;
            ((mid - KEY_CENTER as f64) * res) as f32
        };
        points.push([centre(0), centre(1), centre(2)]);
        if coloured {
            colors.push(v.color.unwrap_or(NO_COLOUR));
        }
    });
    Scan {
        points,
        colors: coloured.then_some(colors),
        pose: Pose::IDENTITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_occupied_voxel_is_a_point_at_its_centre() {
        let mut tree = OcTree::new(0.5);
        let scan = Scan {
            points: vec![[1.2, 0.1, 0.1]],
            colors: None,
            pose: Pose::IDENTITY,
        };
        tree.insert_scan(&scan, None);
        let c = occupied_centres(&tree);
        // The hit's voxel: [1.0, 1.5) x [0, 0.5) x [0, 0.5).
        assert_eq!(c.points, vec![[1.25, 0.25, 0.25]]);
        assert!(c.colors.is_none());
    }
}
