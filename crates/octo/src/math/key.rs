//! Voxel keys and Morton codes: the 16-level key space (`key = floor(c / res) + 32768` per
//! axis), the interleaving of a key's bits into the child indices from the root down, and the
//! codes of a node's voxels.

/// Tree depth: 16 levels below the root.
pub const TREE_DEPTH: u32 = 16;
/// Key of the cell whose lower corner is at coordinate 0.
pub const KEY_CENTER: i64 = 32768;

/// A voxel key: one `u16` per axis.
pub type Key = [u16; 3];

/// Spreads the 16 bits of `v` to every third bit (bit i -> bit 3i).
fn spread3(v: u16) -> u64 {
    let mut x = v as u64;
    x = (x | (x << 16)) & 0x0000_ff00_00ff;
    x = (x | (x << 8)) & 0x00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x2492_4924_9249;
    x
}

/// Gathers every third bit (bit 3i -> bit i).
fn compact3(m: u64) -> u16 {
    let mut x = m & 0x2492_4924_9249;
    x = (x | (x >> 2)) & 0x0c30_c30c_30c3;
    x = (x | (x >> 4)) & 0x00f0_0f00_f00f;
    x = (x | (x >> 8)) & 0x0000_ff00_00ff;
    x = (x | (x >> 16)) & 0xffff;
    x as u16
}

/// The Morton code of a key: the child indices from the root down, 3 bits each, root first.
pub fn morton(key: Key) -> u64 {
    spread3(key[0]) | (spread3(key[1]) << 1) | (spread3(key[2]) << 2)
}

/// The key of a Morton code.
pub fn unmorton(code: u64) -> Key {
    [compact3(code), compact3(code >> 1), compact3(code >> 2)]
}

/// Appends the depth-16 codes of the node at `depth` that holds voxel `code`.
pub(crate) fn push_voxels(out: &mut Vec<u64>, code: u64, depth: u32) {
    let shift = 3 * (TREE_DEPTH - depth.min(TREE_DEPTH));
    let first = (code >> shift) << shift;
    out.extend(first..first + (1u64 << shift));
}

/// The Morton code of cell `i` of a cube of `2^bits` cells a side, where
/// `i = x | y << bits | z << 2 bits` (a table entry of a block whose cells are kept in Morton
/// order).
pub(crate) const fn local_morton(i: usize, bits: usize) -> u16 {
    let side = (1 << bits) - 1;
    let (x, y, z) = (i & side, (i >> bits) & side, (i >> (2 * bits)) & side);
    let mut m = 0;
    let mut b = 0;
    while b < bits {
        m |= ((x >> b) & 1) << (3 * b);
        m |= ((y >> b) & 1) << (3 * b + 1);
        m |= ((z >> b) & 1) << (3 * b + 2);
        b += 1;
    }
    m as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_round_trip_and_child_order() {
        for k in [
            [0u16, 0, 0],
            [1, 2, 3],
            [65535, 0, 32768],
            [12345, 54321, 777],
        ] {
            assert_eq!(unmorton(morton(k)), k);
        }
        // Bit 15 of x, y, z is the root's child index bits 0, 1, 2.
        assert_eq!(morton([0x8000, 0, 0]) >> 45, 1);
        assert_eq!(morton([0, 0x8000, 0]) >> 45, 2);
        assert_eq!(morton([0, 0, 0x8000]) >> 45, 4);
    }
}
