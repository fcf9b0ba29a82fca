//! The ray walk: OctoMap's `computeRayKeys` (Amanatides & Woo's 3D DDA with OctoMap's
//! stopping rule), its set-up one ray at a time ([`Grid::ray_start_keyed`]) or many from one
//! origin at once ([`Fan::starts`]), the ray's direction and length in OctoMap's `f32`, and the
//! cut at the maximum range.

use super::grid::Grid;
use super::key::{KEY_CENTER, Key};

/// Where a ray's free cells go, in the order the ray meets them, one ray at a time.
pub(crate) trait RaySink {
    /// A ray starts.
    fn begin_ray(&mut self) {}
    /// The ray crosses cell `k`.
    fn add(&mut self, k: Key);
    /// The ray has ended.
    fn end_ray(&mut self) {}
}

impl Grid {
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
}
