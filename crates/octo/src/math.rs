//! The octree's arithmetic, OctoMap 1.9's to the bit: keys and coordinates ([`Grid`]), Morton
//! codes, log-odds ([`Params`]), poses (quaternions in `f32`, in OctoMap's order of operations),
//! the ray walk (Amanatides & Woo's 3D DDA with OctoMap's stopping rule) and the brightest-colour
//! rule of `ColorOcTree`. Pure functions of numbers: the tree ([`super::tree`]) holds the state.
//!
//! Keys are 16 bits per axis (`key = floor(c / res) + 32768`); a Morton code interleaves a
//! key's bits so that its 3-bit groups, root first, are the child indices from the root down
//! (`x | y << 1 | z << 2`), which makes ascending codes the depth-first order of the tree.

use super::{Pose, Scan};

/// Where a ray's free cells go, in the order the ray meets them, one ray at a time.
pub(crate) trait RaySink {
    /// A ray starts.
    fn begin_ray(&mut self) {}
    /// The ray crosses cell `k`.
    fn add(&mut self, k: Key);
    /// The ray has ended.
    fn end_ray(&mut self) {}
}

/// Tree depth: 16 levels below the root.
pub const TREE_DEPTH: u32 = 16;
/// Key of the cell whose lower corner is at coordinate 0.
pub const KEY_CENTER: i64 = 32768;

/// A voxel key: one `u16` per axis.
pub type Key = [u16; 3];

/// OctoMap's `logodds(p)`: computed in `f64`, stored as `f32`.
pub fn logodds(probability: f64) -> f32 {
    (probability / (1.0 - probability)).ln() as f32
}

/// OctoMap's `probability(l)`.
pub fn probability(log_odds: f64) -> f64 {
    1.0 - (1.0 / (1.0 + log_odds.exp()))
}

/// The sensor model and clamping, as log-odds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Log-odds added to a voxel a point ends in (OctoMap: `logodds(0.7)`).
    pub hit_log: f32,
    /// Log-odds added to a voxel a ray crosses (OctoMap: `logodds(0.4)`).
    pub miss_log: f32,
    /// Lower clamp (OctoMap: `logodds(0.1192)`).
    pub clamp_min_log: f32,
    /// Upper clamp (OctoMap: `logodds(0.971)`).
    pub clamp_max_log: f32,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            hit_log: logodds(0.7),
            miss_log: logodds(0.4),
            clamp_min_log: logodds(0.1192),
            clamp_max_log: logodds(0.971),
        }
    }
}

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
    let (mut sum, mut n) = ([0u32; 3], 0u32);
    for c in colors.iter().filter(|c| c[3] == 1) {
        for k in 0..3 {
            sum[k] += c[k] as u32;
        }
        n += 1;
    }
    if n == 0 {
        return NO_COLOR;
    }
    color_slot(Some(sum.map(|s| (s / n) as u8)))
}

/// Appends the depth-16 codes of the node at `depth` that holds voxel `code`.
pub(crate) fn push_voxels(out: &mut Vec<u64>, code: u64, depth: u32) {
    let shift = 3 * (TREE_DEPTH - depth.min(TREE_DEPTH));
    let first = (code >> shift) << shift;
    out.extend(first..first + (1u64 << shift));
}

/// The voxel grid of a resolution: OctoMap's conversions between coordinates and keys, and
/// the cells a ray crosses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Voxel edge, m.
    resolution_m: f64,
    /// `1 / resolution_m`, as OctoMap keeps it.
    resolution_factor: f64,
}

impl Grid {
    /// The grid of voxel edge `resolution_m` metres.
    pub fn new(resolution_m: f64) -> Self {
        Grid {
            resolution_m,
            resolution_factor: 1.0 / resolution_m,
        }
    }

    /// Voxel edge in metres.
    pub fn resolution_m(&self) -> f64 {
        self.resolution_m
    }

    /// OctoMap's `coordToKeyChecked` for one axis: `None` outside the key range.
    #[inline(always)]
    pub fn coord_to_key(&self, c: f32) -> Option<u16> {
        let scaled = floor(self.resolution_factor * c as f64);
        if !(scaled.is_finite()) {
            return None;
        }
        // `as` saturates beyond i64; the addition must too (a coordinate of 1e38 at 0.1 mm).
        let k = (scaled as i64).saturating_add(KEY_CENTER);
        if (0..2 * KEY_CENTER).contains(&k) {
            Some(k as u16)
        } else {
            None
        }
    }

    /// The key of a point, `None` outside the key range.
    #[inline(always)]
    pub fn key_of(&self, p: [f32; 3]) -> Option<Key> {
        Some([
            self.coord_to_key(p[0])?,
            self.coord_to_key(p[1])?,
            self.coord_to_key(p[2])?,
        ])
    }

    /// The centre coordinate of a key on one axis.
    pub fn key_to_coord(&self, k: u16) -> f64 {
        ((k as i64 - KEY_CENTER) as f64 + 0.5) * self.resolution_m
    }

    /// The first cell border a ray starting in cell `k` crosses on one axis, going up (`step`
    /// 1.0) or down (-1.0): OctoMap's `keyToCoord(k) + (float) (step * resolution * 0.5)`, the
    /// half cell rounded to `f32` as OctoMap rounds it.
    #[inline(always)]
    fn first_border_m(&self, k: u16, step: f64) -> f64 {
        let mut border = self.key_to_coord(k);
        border += (step * self.resolution_m * 0.5) as f32 as f64;
        border
    }

    /// The free cells of the ray from `origin` to `end` (OctoMap's `computeRayKeys`): from the
    /// origin's cell up to, not including, the end's cell. `false` when either end is outside
    /// the key range.
    #[cfg(test)]
    pub(crate) fn ray_keys(&self, origin: [f32; 3], end: [f32; 3], out: &mut impl RaySink) -> bool {
        self.ray_start(origin, end).walk_into(out)
    }

    /// The start of the walk of the ray from `origin` to `end`: OctoMap's set-up of
    /// `computeRayKeys`, up to its first cell.
    #[cfg(test)]
    pub(crate) fn ray_start(&self, origin: [f32; 3], end: [f32; 3]) -> RayStart {
        self.ray_start_keyed(self.key_of(origin), self.key_of(end), origin, end)
    }

    /// [`Grid::ray_start`] with the keys of both ends given (`key_of(origin)`,
    /// `key_of(end)`), for many rays from one origin whose end keys are needed anyway.
    #[inline(always)]
    pub(crate) fn ray_start_keyed(
        &self,
        origin_key: Option<Key>,
        end_key: Option<Key>,
        origin: [f32; 3],
        end: [f32; 3],
    ) -> RayStart {
        let (Some(ko), Some(ke)) = (origin_key, end_key) else {
            return RayStart::Outside;
        };
        if ko == ke {
            return RayStart::Empty;
        }
        let (dir, length) = ray_direction(origin, end);
        let mut step = [0i32; 3];
        let mut t_max = [f64::MAX; 3];
        let mut t_delta = [f64::MAX; 3];
        for i in 0..3 {
            if dir[i] > 0.0 {
                step[i] = 1;
            } else if dir[i] < 0.0 {
                step[i] = -1;
            }
            if step[i] != 0 {
                let border = self.first_border_m(ko[i], step[i] as f64);
                t_max[i] = (border - origin[i] as f64) / dir[i];
                t_delta[i] = self.resolution_m / dir[i].abs();
            }
        }
        // A ray crosses one cell border per step, so it reaches the end's cell in as many
        // steps as the keys differ along the three axes; a few more allow for rounding. The
        // bound makes the walk end for any input, whatever the arithmetic above gave.
        let key_steps: u32 = (0..3).map(|i| ko[i].abs_diff(ke[i]) as u32).sum();
        RayStart::Walk(RayWalk {
            t_max,
            t_delta,
            step: step.map(|s| s as i16 as u16),
            key: ko,
            end: ke,
            length,
            steps_left: key_steps + 3,
        })
    }
}

/// Points whose ray starts [`Fan::starts`] computes at once.
pub(crate) const FAN_BATCH: usize = 64;

/// The rays of one scan, all from one origin: what their walks' starts share, so that
/// [`Fan::starts`] can set up many at once, side by side, in the arithmetic of
/// [`Grid::ray_start_keyed`] (the same `f32` and `f64` operations in the same order, hence the
/// same walks).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Fan {
    /// The sensor.
    origin: [f32; 3],
    /// The sensor's cell.
    origin_key: Key,
    /// `border - origin` on each axis, for a ray going up (`[0]`) and down (`[1]`) that axis:
    /// the numerator of the first border's ray parameter.
    to_border_m: [[f64; 2]; 3],
    /// Voxel edge, m.
    resolution_m: f64,
    /// `1 / resolution_m`.
    resolution_factor: f64,
    /// The maximum range, when it cuts rays (a negative one does not).
    max_range_m: Option<f64>,
}

impl Fan {
    /// The rays from `origin`, cut at `max_range_m` if given and not negative; `None` when
    /// the origin is outside the key range (no ray has cells).
    pub(crate) fn new(grid: &Grid, origin: [f32; 3], max_range_m: Option<f64>) -> Option<Fan> {
        let origin_key = grid.key_of(origin)?;
        let to_border_m = [0, 1, 2].map(|i| {
            [1.0, -1.0].map(|step| grid.first_border_m(origin_key[i], step) - origin[i] as f64)
        });
        Some(Fan {
            origin,
            origin_key,
            to_border_m,
            resolution_m: grid.resolution_m,
            resolution_factor: grid.resolution_factor,
            max_range_m: max_range_m.filter(|r| *r >= 0.0),
        })
    }

    /// The sensor's cell, where every ray starts.
    pub(crate) fn origin_key(&self) -> Key {
        self.origin_key
    }

    /// The walks of the rays to the first [`FAN_BATCH`] points of `pts`, into `walks`: bit
    /// `i` of the result is set when point `i`'s ray is *plain*, and `walks[i]` is then what
    /// [`Grid::ray_start_keyed`] starts (its end is the point's key, its end a hit). A plain
    /// ray's point is finite, inside the key range, within the maximum range, outside the
    /// origin's cell, and far enough for `f32` to give its direction; any other point goes
    /// the general way ([`Grid::ray_start_keyed`] and the maximum range's rule).
    ///
    /// Written as loops over arrays with selects instead of branches, which the compiler turns
    /// into vector operations: `f32` and `f64` divisions and square roots are exact to the
    /// last bit whatever the width, so each ray's numbers are those of the one-ray code.
    #[inline(always)]
    pub(crate) fn starts(&self, pts: &[[f32; 3]], walks: &mut [RayWalk; FAN_BATCH]) -> u64 {
        const B: usize = FAN_BATCH;
        let n = pts.len().min(B);
        let mut p = [[0f32; B]; 3];
        for (i, q) in pts[..n].iter().enumerate() {
            for a in 0..3 {
                p[a][i] = q[a];
            }
        }
        let mut ok = [true; B];
        for (i, k) in ok.iter_mut().enumerate() {
            *k = i < n;
        }
        let mut diff = [[0f32; B]; 3];
        let mut end = [[0u16; B]; 3];
        let mut key_steps = [3u32; B];
        for a in 0..3 {
            let ko = self.origin_key[a];
            for i in 0..B {
                let c = p[a][i];
                diff[a][i] = c - self.origin[a];
                // coord_to_key: floor(c / res) + KEY_CENTER inside 0..2^16. Inside that range
                // the scaled value truncates exactly in an i32, and floor is the truncation
                // less one when that rounded up.
                let scaled = self.resolution_factor * c as f64;
                let inside = (scaled >= -(KEY_CENTER as f64)) & (scaled < KEY_CENTER as f64);
                let s = if inside { scaled } else { 0.0 };
                let t = s as i32;
                let floor = t - ((t as f64) > s) as i32;
                let k = (floor + KEY_CENTER as i32) as u16;
                end[a][i] = k;
                key_steps[i] += ko.abs_diff(k) as u32;
                ok[i] &= c.abs() < f32::INFINITY && inside;
            }
        }
        let mut length = [0f32; B];
        let mut length_sq = [0f32; B];
        for i in 0..B {
            let (x, y, z) = (diff[0][i], diff[1][i], diff[2][i]);
            let sq = x * x + y * y + z * z;
            length_sq[i] = sq;
            let l = (sq as f64).sqrt() as f32;
            length[i] = l;
            let same_cell = (end[0][i] == self.origin_key[0])
                & (end[1][i] == self.origin_key[1])
                & (end[2][i] == self.origin_key[2]);
            ok[i] &= (l > 0.0) & (l < f32::INFINITY) & !same_cell;
        }
        if let Some(r) = self.max_range_m {
            for i in 0..B {
                ok[i] &= (length_sq[i] as f64).sqrt() <= r;
            }
        }
        let mut t_max = [[0f64; B]; 3];
        let mut t_delta = [[0f64; B]; 3];
        let mut step = [[0u16; B]; 3];
        for a in 0..3 {
            let [up, down] = self.to_border_m[a];
            for i in 0..B {
                let d = diff[a][i] / length[i];
                ok[i] &= d.abs() < f32::INFINITY;
                let d = d as f64;
                let moving = d != 0.0;
                let num = if d > 0.0 { up } else { down };
                t_max[a][i] = if moving { num / d } else { f64::MAX };
                t_delta[a][i] = if moving {
                    self.resolution_m / d.abs()
                } else {
                    f64::MAX
                };
                step[a][i] = if d > 0.0 {
                    1
                } else if d < 0.0 {
                    u16::MAX
                } else {
                    0
                };
            }
        }
        let mut plain = 0u64;
        for i in 0..n {
            walks[i] = RayWalk {
                t_max: [t_max[0][i], t_max[1][i], t_max[2][i]],
                t_delta: [t_delta[0][i], t_delta[1][i], t_delta[2][i]],
                step: [step[0][i], step[1][i], step[2][i]],
                key: self.origin_key,
                end: [end[0][i], end[1][i], end[2][i]],
                length: length[i] as f64,
                steps_left: key_steps[i],
            };
            plain |= (ok[i] as u64) << i;
        }
        plain
    }
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

/// `v.floor()`, inlined: without SSE4.1 the standard one is a call into the C library, and a
/// key is computed for every ray's end.
#[inline(always)]
fn floor(v: f64) -> f64 {
    // Below 2^52 in magnitude the conversion truncates exactly; larger values, infinities and
    // NaN are their own floor or go to the library.
    if v.abs() < 4_503_599_627_370_496.0 {
        let t = v as i64 as f64;
        if t > v { t - 1.0 } else { t }
    } else {
        v.floor()
    }
}

/// How a ray's walk starts ([`Grid::ray_start`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum RayStart {
    /// An end is outside the key range: no cells (OctoMap's `computeRayKeys` fails).
    Outside,
    /// Both ends in one cell: no free cells.
    Empty,
    /// The walk, at its first cell.
    Walk(RayWalk),
}

impl RayStart {
    /// Walks the ray, putting its free cells into `out`; false if an end is outside the key
    /// range (no cells).
    #[inline(always)]
    pub(crate) fn walk_into(self, out: &mut impl RaySink) -> bool {
        match self {
            RayStart::Outside => false,
            RayStart::Empty => true,
            RayStart::Walk(mut w) => {
                out.add(w.key);
                while let Some(k) = w.step() {
                    out.add(k);
                }
                true
            }
        }
    }
}

/// A ray's 3D DDA walk in progress: OctoMap's `computeRayKeys` loop, one cell at a time.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct RayWalk {
    /// Ray parameter (m along the ray) of the next cell border on each axis.
    pub(crate) t_max: [f64; 3],
    /// Ray parameter between two borders on each axis.
    pub(crate) t_delta: [f64; 3],
    /// Key step on each axis: 1, 0 or -1 (as `u16`, added with wrapping).
    pub(crate) step: [u16; 3],
    /// The current cell.
    pub(crate) key: Key,
    /// The end's cell.
    pub(crate) end: Key,
    /// Ray length, m.
    pub(crate) length: f64,
    /// Steps the walk may still take (the bound that makes it end).
    pub(crate) steps_left: u32,
}

impl RayWalk {
    /// The next free cell, `None` once the walk has ended (at the end's cell, past the length,
    /// or at the step bound).
    #[inline(always)]
    pub(crate) fn step(&mut self) -> Option<Key> {
        // One variable per axis (not arrays indexed by the moving axis): the loop then keeps
        // everything in registers.
        let [tx, ty, tz] = &mut self.t_max;
        let [dx, dy, dz] = self.t_delta;
        let [sx, sy, sz] = self.step;
        let [kx, ky, kz] = &mut self.key;
        // OctoMap's choice of axis, ties included.
        if *tx < *ty {
            if *tx < *tz {
                *kx = kx.wrapping_add(sx);
                *tx += dx;
            } else {
                *kz = kz.wrapping_add(sz);
                *tz += dz;
            }
        } else if *ty < *tz {
            *ky = ky.wrapping_add(sy);
            *ty += dy;
        } else {
            *kz = kz.wrapping_add(sz);
            *tz += dz;
        }
        if self.key == self.end {
            return None;
        }
        let [tx, ty, tz] = self.t_max;
        let m = if ty < tx { ty } else { tx };
        let dist = if tz < m { tz } else { m };
        if dist > self.length {
            return None;
        }
        self.steps_left -= 1;
        if self.steps_left == 0 {
            return None;
        }
        Some(self.key)
    }
}

/// Quaternion product in `f32`, in OctoMap's order of operations.
fn qmul(a: [f32; 4], b: [f32; 4]) -> [f32; 4] {
    let [au, ax, ay, az] = a;
    let [bu, bx, by, bz] = b;
    [
        au * bu - ax * bx - ay * by - az * bz,
        ay * bz - by * az + au * bx + bu * ax,
        az * bx - bz * ax + au * by + bu * ay,
        ax * by - bx * ay + au * bz + bu * az,
    ]
}

/// `q * v * q^-1` as OctoMap's `Quaternion::rotate` computes it (no normalisation).
fn rotate(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
    let inv = [q[0], -q[1], -q[2], -q[3]];
    let r = qmul(qmul(q, [0.0, v[0], v[1], v[2]]), inv);
    [r[1], r[2], r[3]]
}

fn normalized(q: [f32; 4]) -> [f32; 4] {
    let mut n = 0.0f64;
    for c in q {
        n += (c * c) as f64;
    }
    let len = n.sqrt() as f32;
    if len > 0.0 {
        [q[0] / len, q[1] / len, q[2] / len, q[3] / len]
    } else {
        q
    }
}

fn transform(pose: &Pose, v: [f32; 3]) -> [f32; 3] {
    let r = rotate(pose.rotation, v);
    let t = pose.translation_m;
    [r[0] + t[0], r[1] + t[1], r[2] + t[2]]
}

fn inverse(pose: &Pose) -> Pose {
    let q = normalized([
        pose.rotation[0],
        -pose.rotation[1],
        -pose.rotation[2],
        -pose.rotation[3],
    ]);
    let t = pose.translation_m;
    Pose {
        translation_m: rotate(q, [-t[0], -t[1], -t[2]]),
        rotation: q,
    }
}

/// The points of a scan in the map frame and the sensor origin, computed exactly as
/// `graph2tree` does (the origin goes through the inverse pose and back, in `f32`).
pub fn world_points(scan: &Scan) -> (Vec<[f32; 3]>, [f32; 3]) {
    let pose = &scan.pose;
    let sensor = transform(&inverse(pose), pose.translation_m);
    let origin = transform(pose, sensor);
    let pts = scan.points.iter().map(|&p| transform(pose, p)).collect();
    (pts, origin)
}

/// The length of `v`: squared in `f32`, as OctoMap does, the root in `f64`.
#[inline(always)]
pub(crate) fn norm_f32(v: [f32; 3]) -> f64 {
    ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) as f64).sqrt()
}

/// The unit direction and the length of the ray from `origin` to `end` (two different points),
/// as OctoMap computes them: in `f32`, the squared length summed in `f32`.
///
/// That arithmetic breaks down at the extremes: a squared length below `f32`'s smallest
/// subnormal (points within ~1e-23 m of the origin) underflows to 0, one above ~3e38
/// overflows to infinity, and the direction comes out infinite or NaN (OctoMap's own ray walk
/// then never ends). There, and only there, both are computed in `f64` from the differences
/// scaled by their largest component, which neither underflows nor overflows.
#[inline(always)]
pub(crate) fn ray_direction(origin: [f32; 3], end: [f32; 3]) -> ([f64; 3], f64) {
    let mut dir = [end[0] - origin[0], end[1] - origin[1], end[2] - origin[2]];
    let length = norm_f32(dir) as f32;
    for d in &mut dir {
        *d /= length;
    }
    if length > 0.0 && length.is_finite() && dir.iter().all(|d| d.is_finite()) {
        return (dir.map(f64::from), length as f64);
    }
    let diff = [0, 1, 2].map(|i| end[i] as f64 - origin[i] as f64);
    let largest = diff.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    if !(largest > 0.0 && largest.is_finite()) {
        // The same point twice (or a non-finite one): no direction, no length.
        return ([0.0; 3], 0.0);
    }
    let scaled = diff.map(|d| d / largest);
    let norm = (scaled[0] * scaled[0] + scaled[1] * scaled[1] + scaled[2] * scaled[2]).sqrt();
    (scaled.map(|d| d / norm), norm * largest)
}

/// The end of a ray cut at `range_m` along `diff` (the point minus `origin`), as OctoMap's
/// `insertPointCloud` computes it for a point beyond its maximum range.
pub(crate) fn end_at_range(origin: [f32; 3], diff: [f32; 3], range_m: f64) -> [f32; 3] {
    let len = norm_f32(diff);
    let dir = if len > 0.0 {
        let l = len as f32;
        [diff[0] / l, diff[1] / l, diff[2] / l]
    } else {
        diff
    };
    let r = range_m as f32;
    [
        origin[0] + dir[0] * r,
        origin[1] + dir[1] * r,
        origin[2] + dir[2] * r,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points around a few origins (ordinary ones, and NaN, infinities, huge values, the
    /// origin itself, its cell, axis-aligned rays, points past the key range): every ray
    /// [`Fan::starts`] calls plain starts exactly as [`Grid::ray_start_keyed`] starts it, ends
    /// in a hit within the maximum range, and every ordinary ray is plain.
    #[test]
    fn fan_starts_plain_rays_as_one_ray_set_up_does() {
        let mut rng = rovlink_base::rng::Rng::new(23, 0);
        let mut u = move || rng.next_u32() as f32 / u32::MAX as f32;
        for (res, origin, range) in [
            (0.1, [0.05f32, -0.3, 2.0], None),
            (0.1, [0.1, 0.2, 0.3], Some(4.0)),
            (0.05, [-7.33, 4.0, -1.25], Some(-1.0)),
            (0.2, [3276.0, -3276.5, 0.0], None),
        ] {
            let grid = Grid::new(res);
            let fan = Fan::new(&grid, origin, range).expect("origin inside the key range");
            let mut pts: Vec<[f32; 3]> = (0..1000)
                .map(|_| {
                    let r = 0.02 + 8.0 * u();
                    [0, 1, 2].map(|i| origin[i] + r * (2.0 * u() - 1.0))
                })
                .collect();
            let ordinary = pts.len();
            for odd in [
                [f32::NAN, 0.0, 0.0],
                [0.0, f32::INFINITY, 0.0],
                [0.0, 0.0, f32::NEG_INFINITY],
                [1e30, 0.0, 0.0],
                [0.0, -1e30, 0.0],
                [f32::MAX, f32::MAX, f32::MAX],
                origin,
                [origin[0] + 1e-7, origin[1], origin[2]],
                [origin[0] + 3.0, origin[1], origin[2]],
                [origin[0], origin[1] - 0.35, origin[2]],
                [origin[0], origin[1], origin[2] + 9.0],
                [origin[0] + 1e-30, origin[1] + 1e-30, origin[2] + 2.0],
            ] {
                pts.push(odd);
            }
            let (mut plain_count, mut ordinary_plain) = (0, 0);
            for (c, chunk) in pts.chunks(FAN_BATCH - 3).enumerate() {
                let mut walks = [RayWalk::default(); FAN_BATCH];
                let plain = fan.starts(chunk, &mut walks);
                assert_eq!(plain >> chunk.len(), 0, "no bit past the points");
                for (i, &p) in chunk.iter().enumerate() {
                    let start =
                        grid.ray_start_keyed(grid.key_of(origin), grid.key_of(p), origin, p);
                    let diff = [0, 1, 2].map(|a| p[a] - origin[a]);
                    let within = range.is_none_or(|r| r < 0.0 || norm_f32(diff) <= r);
                    if plain >> i & 1 == 1 {
                        plain_count += 1;
                        assert_eq!(start, RayStart::Walk(walks[i]), "point {p:?}");
                        assert!(within, "point {p:?} beyond {range:?}");
                        ordinary_plain += (c * (FAN_BATCH - 3) + i < ordinary) as usize;
                    } else if c * (FAN_BATCH - 3) + i < ordinary {
                        assert!(
                            !within || !matches!(start, RayStart::Walk(_)),
                            "ordinary point {p:?} not plain"
                        );
                    }
                }
            }
            assert!(
                ordinary_plain > ordinary / 3,
                "{ordinary_plain} plain of {ordinary}"
            );
            assert!(
                plain_count >= ordinary_plain + 3,
                "axis-aligned rays are plain"
            );
        }
    }

    #[test]
    fn default_params_are_octomaps_floats() {
        let p = Params::default();
        assert_eq!(p.clamp_min_log.to_bits(), 0xc000_0075);
        assert_eq!(p.clamp_max_log.to_bits(), 0x4060_b4ba);
        assert_eq!(p.hit_log.to_bits(), 0x3f58_e883);
        assert_eq!(p.miss_log.to_bits(), 0xbecf_991f);
        // graph2tree re-derives them through probability(): the same floats.
        assert_eq!(logodds(probability(p.hit_log as f64)), p.hit_log);
        assert_eq!(
            logodds(probability(p.clamp_min_log as f64)),
            p.clamp_min_log
        );
    }

    #[test]
    fn inlined_floor_is_the_standard_floor() {
        let mut rng = rovlink_base::rng::Rng::new(11, 0);
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            -1.0,
            1.0,
            -1e-300,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            4_503_599_627_370_496.0,
            -4_503_599_627_370_497.0,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN,
        ];
        values.extend((0..10_000).map(|_| {
            let u = rng.next_u32() as f64 / u32::MAX as f64;
            (u - 0.5) * 10f64.powi((rng.next_u32() % 40) as i32 - 10)
        }));
        for v in values {
            assert_eq!(floor(v), v.floor(), "{v}");
        }
        assert!(floor(f64::NAN).is_nan());
    }

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
