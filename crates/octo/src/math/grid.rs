//! The voxel grid of a resolution ([`Grid`]): OctoMap's conversions between coordinates and
//! keys, to the bit, and the first cell border a ray crosses. The grid's ray set-up
//! (`Grid::ray_start_keyed`) is with the ray walk, in `ray.rs`.

use super::key::{KEY_CENTER, Key};

/// The voxel grid of a resolution: OctoMap's conversions between coordinates and keys, and
/// the cells a ray crosses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Voxel edge, m.
    pub(super) resolution_m: f64,
    /// `1 / resolution_m`, as OctoMap keeps it.
    pub(super) resolution_factor: f64,
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
    pub(super) fn first_border_m(&self, k: u16, step: f64) -> f64 {
        let mut border = self.key_to_coord(k);
        border += (step * self.resolution_m * 0.5) as f32 as f64;
        border
    }
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
