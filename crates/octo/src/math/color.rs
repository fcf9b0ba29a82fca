//! `ColorOcTree`'s colours: the colour slot a voxel keeps, the brightest-colour rule and the
//! mean colour of a node's children.

/// Luma of a colour, for the brightest-colour rule (BT.601 weights, integer).
pub fn luma(rgb: [u8; 3]) -> u32 {
    299 * rgb[0] as u32 + 587 * rgb[1] as u32 + 114 * rgb[2] as u32
}

/// The brightness order of colours: luma, then r, g, b (a total order, so "the brightest of
/// several colours" does not depend on their order).
pub fn brightness_key(rgb: [u8; 3]) -> u64 {
    ((luma(rgb) as u64) << 24) | ((rgb[0] as u64) << 16) | ((rgb[1] as u64) << 8) | rgb[2] as u64
}

/// White, `ColorOcTree`'s "no colour".
pub const WHITE: [u8; 3] = [255, 255, 255];

/// A colour slot: r, g, b and a flag (1: set, 0: the voxel has no colour, and r, g, b are
/// white). The flag is 1 exactly when the colour is not white, as `ColorOcTree::isColorSet`.
pub type ColorSlot = [u8; 4];

/// No colour: white, flag 0.
pub(crate) const NO_COLOR: ColorSlot = [255, 255, 255, 0];

/// The slot of a colour: white or none is no colour.
pub(crate) fn color_slot(c: Option<[u8; 3]>) -> ColorSlot {
    match c {
        Some(c) if c != WHITE => [c[0], c[1], c[2], 1],
        _ => NO_COLOR,
    }
}

/// Sort key of a slot: set colours above unset ones, then by brightness.
pub(crate) fn slot_order(c: ColorSlot) -> (u8, u64) {
    (c[3], brightness_key([c[0], c[1], c[2]]))
}

pub(crate) fn brighter(a: ColorSlot, b: ColorSlot) -> bool {
    brightness_key([a[0], a[1], a[2]]) > brightness_key([b[0], b[1], b[2]])
}

/// `getAverageChildColor`: the integer mean, per channel, of the set colours; none if none is.
pub(crate) fn mean_color(colors: &[ColorSlot]) -> ColorSlot {
    let mut mean = MeanColor::default();
    for c in colors.iter().filter(|c| c[3] == 1) {
        mean.add([c[0], c[1], c[2]]);
    }
    color_slot(mean.mean())
}

/// [`mean_color`] taken a colour at a time: white ("no colour") is left out.
#[derive(Default)]
pub(crate) struct MeanColor {
    sum: [u32; 3],
    n: u32,
}

impl MeanColor {
    /// Adds a colour (none if white).
    pub(crate) fn add(&mut self, color: [u8; 3]) {
        if color != WHITE {
            for (sum, c) in self.sum.iter_mut().zip(color) {
                *sum += u32::from(c);
            }
            self.n += 1;
        }
    }

    /// The integer mean, per channel, of the colours added; `None` if none was.
    pub(crate) fn mean(&self) -> Option<[u8; 3]> {
        (self.n > 0).then(|| self.sum.map(|s| (s / self.n) as u8))
    }
}
