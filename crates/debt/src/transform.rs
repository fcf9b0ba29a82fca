//! From component planes to the coder's bands, and back: the wavelet transform of each plane
//! (9/7 lossy, 5/3 lossless, [`wavelet`]), the weights that make a bit-plane worth the same
//! squared error in every subband and component, the quantisation to magnitudes and signs with
//! the region of interest raised, and the rows of each subband a segment holds.

use std::ops::Range;

use super::Rect;
use super::coder::{self, Band};
use super::colour::COMPONENT_MSE_WEIGHTS;
use super::header::Header;
use super::wavelet::{self, Orientation};

/// Bits of fraction kept below the weighted coefficient's unit (finest quantiser step 1/4).
pub(super) const FRACTION_BITS: u32 = 2;

/// Wavelet levels for a coded image: as many as keep the low-pass band at least 2 pixels a side, at most
/// 7 levels.
pub fn default_levels(width: usize, height: usize) -> u32 {
    let side = width.min(height);
    let mut levels = 0;
    while levels < 7 && side >> (levels + 1) >= 2 {
        levels += 1;
    }
    levels
}

/// The subband orientation as the coder's context keys number it.
pub(super) fn orientation_code(o: Orientation) -> u8 {
    match o {
        Orientation::Ll => 0,
        Orientation::Hl => 1,
        Orientation::Lh => 2,
        Orientation::Hh => 3,
    }
}

/// The coder's context class of a subband orientation.
pub(super) fn class_of(o: Orientation) -> usize {
    match o {
        Orientation::Ll => 0,
        Orientation::Hl => 1,
        Orientation::Lh => 2,
        Orientation::Hh => 3,
    }
}

/// True if coefficient (`x`, `y`) of a subband at `level` lies over the ROI (its rectangle
/// scaled down by 2^level, rounded outwards). Widening it by the filters' support was measured
/// to lower the ROI's PSNR: the bytes go to background coefficients instead.
pub(super) fn in_roi(roi: &Rect, level: u32, x: usize, y: usize) -> bool {
    let x0 = roi.x0 >> level;
    let y0 = roi.y0 >> level;
    let x1 = roi.x1.div_ceil(1 << level);
    let y1 = roi.y1.div_ceil(1 << level);
    x >= x0 && x < x1 && y >= y0 && y < y1
}

/// Per-subband weights (one per subband in coding order).
pub(super) fn subband_weights(header: &Header, bands: &[wavelet::Subband]) -> Vec<f32> {
    if header.lossless {
        return vec![1.0; bands.len()];
    }
    let norms = wavelet::synthesis_norms_97(header.levels.max(1));
    bands
        .iter()
        .map(|b| {
            if header.levels == 0 {
                return 1.0;
            }
            norms
                .iter()
                .find(|n| n.0 == b.level && n.1 == b.orientation)
                .map_or(1.0, |n| n.2)
        })
        .collect()
}

/// Scratch buffers of the wavelet transforms, kept from one plane to the next so that each is
/// allocated (and its pages touched) once per thread rather than once per plane.
#[derive(Default)]
pub(super) struct Scratch {
    /// The 9/7 transform's (or the 5/3's) working rows and columns.
    floats: Vec<f32>,
    /// A lossless plane as integers.
    ints: Vec<i32>,
    /// The 5/3 transform's working rows and columns.
    int_lines: Vec<i32>,
}

/// Runs the forward (or inverse) transform of the header's kind on one component plane.
pub(super) fn transform(
    plane: &mut [f32],
    width: usize,
    height: usize,
    header: &Header,
    forward: bool,
    scratch: &mut Scratch,
) {
    if header.lossless {
        let ints = &mut scratch.ints;
        ints.clear();
        ints.extend(plane.iter().map(|&v| v.round() as i32));
        let levels = header.levels;
        wavelet::run_53(ints, width, height, levels, forward, &mut scratch.int_lines);
        for (p, &i) in plane.iter_mut().zip(ints.iter()) {
            *p = i as f32;
        }
    } else {
        wavelet::run_97(
            plane,
            width,
            height,
            header.levels,
            forward,
            &mut scratch.floats,
        );
    }
}

/// Transforms every component plane. Forward, the first goes on a thread of its own and the
/// others one after the other on this one (two cores: luma beside the two chroma planes); the
/// planes are independent, so the result is the same as one after the other. Inverse, one
/// thread was measured faster (the second thread's scratch and arena cost more page faults
/// than the lifting it takes over).
pub(super) fn transform_planes(
    planes: &mut [Vec<f32>],
    width: usize,
    height: usize,
    header: &Header,
    forward: bool,
) {
    let run = |planes: &mut [Vec<f32>]| {
        let mut scratch = Scratch::default();
        for plane in planes {
            transform(plane, width, height, header, forward, &mut scratch);
        }
    };
    match planes.split_first_mut() {
        Some((first, rest))
            if forward && !rest.is_empty() && width * height >= PARALLEL_MIN_PIXELS =>
        {
            std::thread::scope(|scope| {
                scope.spawn(|| run(std::slice::from_mut(first)));
                run(rest);
            });
        }
        _ => run(planes),
    }
}

/// Smallest plane worth a thread for its transform (below it, starting one costs more).
const PARALLEL_MIN_PIXELS: usize = 64 * 1024;

/// Where a coder band sits: component, subband, quantisation weight, and its first row in the
/// subband (segments hold stripes of rows).
pub(super) type Placement = (usize, wavelet::Subband, f32, usize);

/// Fewest rows of a subband per stripe: shorter subbands go whole to the base segment.
const MIN_STRIPE_ROWS: usize = 8;

/// The rows of a subband `height` rows high that segment `part` of `parts` holds. One part:
/// all. Otherwise part 0 is the base, which holds the subbands too short to give every stripe
/// [`MIN_STRIPE_ROWS`] rows, and parts 1.. are the stripes, which share the rows of the others.
fn part_rows(height: usize, part: usize, parts: usize) -> Range<usize> {
    if parts == 1 {
        return 0..height;
    }
    let stripes = parts - 1;
    let base = height < stripes * MIN_STRIPE_ROWS;
    match (part, base) {
        (0, true) => 0..height,
        (0, false) | (_, true) => 0..0,
        (p, false) => (p - 1) * height / stripes..p * height / stripes,
    }
}

/// The coder's band list for a header and segment `part` of `parts` (0 of 1 when not
/// segmented): (component, subband) pairs in coding order, with the quantised data when
/// encoding.
pub(super) fn build_bands(
    header: &Header,
    planes: Option<&[Vec<f32>]>,
    part: usize,
    parts: usize,
) -> (Vec<Band>, Vec<Placement>) {
    let (w, h) = header.coded_size();
    let subbands = wavelet::subbands(w, h, header.levels);
    let weights = subband_weights(header, &subbands);
    let roi = header.roi_rect();
    let mut layout = Vec::new();
    let mut keys = Vec::new();
    for (sb, &weight) in subbands.iter().zip(&weights) {
        for (comp, mse_weight) in COMPONENT_MSE_WEIGHTS
            .iter()
            .enumerate()
            .take(header.components())
        {
            let comp_weight = if header.lossless || header.gray {
                1.0
            } else {
                mse_weight.sqrt()
            };
            let rows = part_rows(sb.height, part, parts);
            layout.push((comp, *sb, weight * comp_weight, rows.start));
            keys.push((comp, orientation_code(sb.orientation), sb.level));
        }
    }
    let parents = coder::parents(&keys);
    let bands = layout
        .iter()
        .zip(parents)
        .map(|(&(comp, sb, weight, row0), parent)| {
            let rows = part_rows(sb.height, part, parts);
            let data = planes.map(|planes| {
                let plane = &planes[comp];
                let n = sb.width * rows.len();
                let (mut mag, mut neg) = (Vec::with_capacity(n), Vec::with_capacity(n));
                let scale = if header.lossless {
                    1.0
                } else {
                    weight * (1 << FRACTION_BITS) as f32
                };
                for y in rows.clone() {
                    let row = &plane[(sb.y0 + y) * w + sb.x0..][..sb.width];
                    mag.extend(row.iter().map(|&c| (c.abs() * scale) as u32));
                    neg.extend(row.iter().map(|&c| c < 0.0));
                }
                if let Some((rect, shift)) = roi {
                    for (i, m) in mag.iter_mut().enumerate() {
                        if in_roi(&rect, sb.level, i % sb.width, row0 + i / sb.width) {
                            // Saturates (at 2^31 - 1) rather than wraps for extreme shifts.
                            *m = (u64::from(*m) << shift).min(u64::from(u32::MAX >> 1)) as u32;
                        }
                    }
                }
                (mag, neg)
            });
            let mut band = Band::new(sb.width, rows.len(), class_of(sb.orientation), parent, data);
            band.row0 = row0;
            band
        })
        .collect();
    (bands, layout)
}
