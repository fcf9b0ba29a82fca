//! Chroma from luma in the wavelet domain (stream version 4).
//!
//! Colour edges mostly sit where luma edges are, so a chroma detail subband correlates with the
//! luma subband at the same place. The encoder fits one multiplier per chroma detail subband,
//! `alpha = sum(c * y) / sum(y * y)` over the subband's coefficients, rounds it to 1/32
//! ([`STEP`]), and codes the residual `c - alpha * y` instead of `c` (with the original luma:
//! open loop). The decoder adds `alpha * y'` back, `y'` being the luma it decoded, so where a
//! luma coefficient arrived its chroma gets the correlated part for free; where none arrived
//! nothing is predicted. The multipliers travel in the header ([`Multipliers::write`]): a
//! bit mask of the subbands that have one, then one signed byte each.
//!
//! Measured in `docs/debt-format.md` (issue 31, step 4): it pays from [`MIN_BUDGET_BYTES`].
//!
//! No-panic contract: [`Multipliers::read`] returns an [`Error`] for bytes too short for the
//! mask and values it states, and any bytes that long give some set of multipliers.

use super::Error;
use super::wavelet::{self, Orientation};

/// The smallest budget the encoder uses chroma from luma at: below it the multipliers' bytes
/// (7-50) cost more than the prediction gains.
pub const MIN_BUDGET_BYTES: usize = 4000;
/// The multipliers' quantisation step.
pub const STEP: f32 = 1.0 / 32.0;
/// Multipliers below this many steps are not sent: their gain does not pay for their byte.
const MIN_STEPS: i32 = 2;
/// Detail subband and chroma component pairs a stream of the most levels (7) has.
pub const MAX_PAIRS: usize = 2 * 3 * 7;

/// The multipliers of a stream: one per (detail subband, chroma component) pair, in coding
/// order (subbands as [`wavelet::subbands`] lists them, LL left out; Cb then Cr), in steps of
/// [`STEP`]; 0 where none is sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Multipliers {
    /// Pairs the stream has (6 per level; fewer for images too small for every subband).
    pub pairs: usize,
    /// Each pair's multiplier in steps.
    pub steps: [i8; MAX_PAIRS],
}

/// The detail subbands of a coded image in coding order.
fn details(width: usize, height: usize, levels: u32) -> Vec<wavelet::Subband> {
    wavelet::subbands(width, height, levels)
        .into_iter()
        .filter(|s| s.orientation != Orientation::Ll)
        .collect()
}

impl Multipliers {
    /// Bytes the multipliers take in the header: the mask, then a byte per multiplier sent.
    pub fn len(&self) -> usize {
        self.pairs.div_ceil(8) + self.steps.iter().filter(|&&q| q != 0).count()
    }

    /// Always false: the mask is always there (for clippy's len-without-is-empty).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Fits the multipliers of the transformed YCbCr `planes` (`width` x `height` coefficients,
    /// `levels` levels) and subtracts each prediction from its chroma subband.
    pub fn fit_and_subtract(
        planes: &mut [Vec<f32>],
        width: usize,
        height: usize,
        levels: u32,
    ) -> Multipliers {
        let mut out = Multipliers {
            pairs: 0,
            steps: [0; MAX_PAIRS],
        };
        let [luma, cb, cr] = planes else {
            return out;
        };
        let rows = |sb: &wavelet::Subband| {
            let (x0, y0, w, h) = (sb.x0, sb.y0, sb.width, sb.height);
            (y0..y0 + h).map(move |y| y * width + x0..y * width + x0 + w)
        };
        for sb in details(width, height, levels).iter().take(MAX_PAIRS / 2) {
            for chroma in [&mut *cb, &mut *cr] {
                let (mut cy, mut yy) = (0f64, 0f64);
                for r in rows(sb) {
                    for (&l, &c) in luma[r.clone()].iter().zip(&chroma[r]) {
                        cy += f64::from(l) * f64::from(c);
                        yy += f64::from(l) * f64::from(l);
                    }
                }
                let steps = if yy > 0.0 {
                    (cy / yy / f64::from(STEP)).round().clamp(-127.0, 127.0) as i32
                } else {
                    0
                };
                let steps = if steps.abs() < MIN_STEPS { 0 } else { steps };
                out.steps[out.pairs] = steps as i8;
                out.pairs += 1;
                if steps != 0 {
                    let alpha = steps as f32 * STEP;
                    for r in rows(sb) {
                        for (c, &l) in chroma[r.clone()].iter_mut().zip(&luma[r]) {
                            *c -= alpha * l;
                        }
                    }
                }
            }
        }
        out
    }

    /// Appends the mask (bit `i`, most significant first, says pair `i` has a multiplier) and
    /// the multipliers sent.
    pub fn write(&self, out: &mut Vec<u8>) {
        let mut mask = vec![0u8; self.pairs.div_ceil(8)];
        for (i, &q) in self.steps[..self.pairs].iter().enumerate() {
            if q != 0 {
                mask[i / 8] |= 0x80 >> (i % 8);
            }
        }
        out.extend_from_slice(&mask);
        out.extend(
            self.steps[..self.pairs]
                .iter()
                .filter(|&&q| q != 0)
                .map(|&q| q as u8),
        );
    }

    /// Reads the multipliers of a `width` x `height` coded image of `levels` levels from
    /// `data`, which starts at the mask; `at` is where that is in the stream (for errors).
    pub fn read(
        data: &[u8],
        at: usize,
        width: usize,
        height: usize,
        levels: u32,
    ) -> Result<Multipliers, Error> {
        let pairs = (2 * details(width, height, levels).len()).min(MAX_PAIRS);
        let mask_len = pairs.div_ceil(8);
        let mask = data.get(..mask_len).ok_or(Error::Truncated {
            expected: at + mask_len,
            found: at + data.len(),
        })?;
        let mut out = Multipliers {
            pairs,
            steps: [0; MAX_PAIRS],
        };
        let mut next = mask_len;
        for i in 0..pairs {
            if mask[i / 8] & (0x80 >> (i % 8)) != 0 {
                let &q = data.get(next).ok_or(Error::Truncated {
                    expected: at + next + 1,
                    found: at + data.len(),
                })?;
                if q == 0 {
                    return Err(Error::Setting {
                        field: "chroma-from-luma multiplier",
                        expected: "non-zero where the mask has a bit",
                        found: 0,
                    });
                }
                out.steps[i] = q as i8;
                next += 1;
            }
        }
        Ok(out)
    }

    /// The decoder's prediction: for every luma coefficient `(index, value)` that arrived in a
    /// subband with a multiplier, adds `alpha * value` at the same index to that chroma
    /// component's coefficients (`coefficients` = Y, Cb, Cr of a `width` x `height` image).
    pub fn add_prediction(
        &self,
        coefficients: &mut [Vec<(u32, f32)>],
        width: usize,
        height: usize,
        levels: u32,
    ) {
        let [luma, cb, cr] = coefficients else {
            return;
        };
        if self.steps.iter().all(|&q| q == 0) {
            return;
        }
        let subbands = details(width, height, levels);
        for &(i, v) in luma.iter() {
            let (x, y) = (i as usize % width.max(1), i as usize / width.max(1));
            let Some(k) = subbands
                .iter()
                .position(|s| x >= s.x0 && x < s.x0 + s.width && y >= s.y0 && y < s.y0 + s.height)
            else {
                continue;
            };
            for (chroma, pair) in [(&mut *cb, 2 * k), (&mut *cr, 2 * k + 1)] {
                if let Some(&q) = self.steps.get(pair).filter(|&&q| q != 0) {
                    chroma.push((i, f32::from(q) * STEP * v));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_and_values_round_trip() {
        let mut m = Multipliers {
            pairs: 42,
            steps: [0; MAX_PAIRS],
        };
        m.steps[0] = 5;
        m.steps[9] = -3;
        m.steps[41] = 127;
        let mut bytes = Vec::new();
        m.write(&mut bytes);
        assert_eq!(bytes.len(), m.len());
        assert_eq!(bytes, [0x80, 0x40, 0, 0, 0, 0x40, 5, 0xfd, 127]);
        // 7 levels on a 256 x 256 image: 21 detail subbands, 42 pairs.
        assert_eq!(Multipliers::read(&bytes, 8, 256, 256, 7), Ok(m));
        for cut in 0..bytes.len() {
            assert!(matches!(
                Multipliers::read(&bytes[..cut], 8, 256, 256, 7),
                Err(Error::Truncated { .. })
            ));
        }
    }

    #[test]
    fn a_chroma_proportional_to_luma_is_predicted_whole() {
        let (w, h, levels) = (16, 16, 2);
        let luma: Vec<f32> = (0..w * h)
            .map(|i| ((i * 7919) % 23) as f32 - 11.0)
            .collect();
        let cb: Vec<f32> = luma.iter().map(|&l| 0.5 * l).collect();
        let cr: Vec<f32> = luma.iter().map(|&l| -0.25 * l).collect();
        let mut planes = vec![luma.clone(), cb.clone(), cr.clone()];
        let m = Multipliers::fit_and_subtract(&mut planes, w, h, levels);
        assert_eq!(m.pairs, 12);
        assert!(m.steps[..12].chunks(2).all(|p| p == [16, -8]), "{m:?}");
        let ll = wavelet::subbands(w, h, levels)[0];
        // Details are left with nothing; the low band is untouched.
        let mut coefficients = vec![Vec::new(), Vec::new(), Vec::new()];
        for (i, &l) in luma.iter().enumerate() {
            let (x, y) = (i % w, i / w);
            if x < ll.width && y < ll.height {
                assert_eq!((planes[1][i], planes[2][i]), (cb[i], cr[i]));
            } else {
                assert_eq!((planes[1][i], planes[2][i]), (0.0, 0.0));
                coefficients[0].push((i as u32, l));
            }
        }
        m.add_prediction(&mut coefficients, w, h, levels);
        for (&(i, v), (&(j, b), &(k, r))) in coefficients[0]
            .iter()
            .zip(coefficients[1].iter().zip(&coefficients[2]))
        {
            assert_eq!((i, j, k), (i, i, i));
            assert_eq!((b, r), (0.5 * v, -0.25 * v));
        }
    }
}
