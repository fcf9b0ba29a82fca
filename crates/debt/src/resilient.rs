//! A loss-resilient layout, prototype (issue 18, item 3): measured, not yet a stream format.
//!
//! Creusere-style independent groups of spatial-orientation trees. The roots are the positions
//! of the LL band; a root owns its tree: the LL coefficient and, at every level `l`, the
//! `2^(L-l)` x `2^(L-l)` block of each detail band under it, for every component. The roots
//! are dealt to `G` groups by a lattice `g = (x + b*y) mod G` whose `b` keeps the roots of one
//! group far apart (and so every root's 8 neighbours in other groups). Each group's trees are
//! gathered side by side into a small dense pyramid (blocks in the same order at every level,
//! so the parent of a coefficient stays at `(x/2, y/2)`) and coded by the ordinary coder
//! ([`coder::code_planes`] over [`Band`]s) as an embedded stream of its own, with its own
//! range coder, contexts and plane count.
//!
//! The stream is cut into trunks of `T` bytes; trunk `t` carries group `t % G` (one group per
//! trunk when `G` is the trunk count). A lost trunk truncates its group from there on and
//! costs nothing else. The header is not written: [`Layout`] stands for it, and its bytes are
//! reserved (5 at the start of trunk 0 and a copy at the end of the last trunk) so that the
//! measured sizes are honest. A lost group is concealed: its LL coefficients become the mean
//! of the decoded 8-neighbour LL coefficients (per component), its details stay zero.
//!
//! Not done (the prototype measures whether the design can meet the bars): a header version,
//! the prefix property across trunks of different groups, ROI, lossless, scale.

use super::coder::{self, Band, BitCoder, Decoder};
use super::colour::{COMPONENT_MSE_WEIGHTS, from_components, to_components};
use super::decode::reconstructed;
use super::encode::encode_bands;
use super::transform::{
    FRACTION_BITS, Scratch, class_of, orientation_code, subband_weights, transform,
};
use super::wavelet::{self, Subband};
use super::{Header, Image};

/// Bytes of the header that a version-3 stream would carry, reserved at the start of trunk 0
/// and again at the end of the last trunk.
pub const HEADER_BYTES: usize = 5;

/// What encoder and decoder agree on: the header a real stream would carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// One component.
    pub gray: bool,
    /// Wavelet levels.
    pub levels: u32,
    /// Whole stream length in bytes.
    pub bytes: usize,
    /// Trunk size in bytes.
    pub trunk_bytes: usize,
    /// Number of groups (at most the number of trunks).
    pub groups: usize,
    /// Dispersed groups (the design) or, for measuring what false neighbours cost,
    /// contiguous runs of roots in raster order laid out as in the image.
    pub dispersed: bool,
}

impl Layout {
    /// The suggested layout: one group per trunk, and as many wavelet levels (at most 7) as
    /// leave at least `roots_per_group` LL positions per group.
    pub fn suggested(
        img: &Image,
        bytes: usize,
        trunk_bytes: usize,
        roots_per_group: usize,
    ) -> Layout {
        let trunks = bytes.div_ceil(trunk_bytes.max(1)).max(1);
        let mut levels = 0;
        while levels < 7 {
            let (lw, lh) = wavelet::low_size(img.width, img.height, levels + 1);
            if lw * lh < roots_per_group * trunks || lw < 2 || lh < 2 {
                break;
            }
            levels += 1;
        }
        Layout {
            width: img.width,
            height: img.height,
            gray: img.channels == 1,
            levels,
            bytes,
            trunk_bytes: trunk_bytes.max(1),
            groups: trunks,
            dispersed: true,
        }
    }

    /// Number of trunks.
    pub fn trunks(&self) -> usize {
        self.bytes.div_ceil(self.trunk_bytes).max(1)
    }

    /// Byte range of trunk `t` that carries coded data (the header's reserved bytes left out).
    fn trunk_payload(&self, t: usize) -> std::ops::Range<usize> {
        let start = t * self.trunk_bytes;
        let end = ((t + 1) * self.trunk_bytes).min(self.bytes);
        let start = if t == 0 { start + HEADER_BYTES } else { start };
        let end = if t + 1 == self.trunks() {
            end.saturating_sub(HEADER_BYTES)
        } else {
            end
        };
        start.min(end)..end
    }

    fn header(&self) -> Header {
        Header {
            width: self.width,
            height: self.height,
            gray: self.gray,
            lossless: false,
            levels: self.levels,
            scale: 0,
            roi: None,
            segments: None,
            restore_at: None,
            cfl: None,
            fec: None,
            priors: false,
        }
    }

    fn groups(&self) -> usize {
        self.groups.clamp(1, self.trunks())
    }
}

/// The lattice step `b` of `g = (x + b*y) mod groups` that makes the shortest nonzero vector
/// between two roots of one group longest (ties: the smallest `b`), so that a group's roots are
/// spread evenly and 8-neighbours fall in different groups when `groups` >= 5.
pub fn lattice_step(groups: usize) -> usize {
    if groups < 3 {
        return groups.saturating_sub(1);
    }
    let span = (groups as f64).sqrt().ceil() as i64 + 2;
    let n = groups as i64;
    (1..groups)
        .max_by_key(|&b| {
            let b = b as i64;
            let shortest = (0..=span)
                .flat_map(|dy| (-span..=span).map(move |k| (dy, k)))
                .filter_map(|(dy, k)| {
                    // x + b*y == 0 (mod n): dx = -b*dy + k*n.
                    let dx = -b * dy + k * n;
                    (dx != 0 || dy != 0).then_some(dx * dx + dy * dy)
                })
                .min()
                .unwrap_or(0);
            (shortest, -b)
        })
        .unwrap_or(1)
}

/// Group of each LL position (`lw` x `lh`, row-major).
fn assign(layout: &Layout, lw: usize, lh: usize) -> Vec<usize> {
    let groups = layout.groups();
    let b = lattice_step(groups);
    let n = lw * lh;
    (0..n)
        .map(|i| {
            if layout.dispersed {
                (i % lw + b * (i / lw)) % groups
            } else {
                i * groups / n
            }
        })
        .collect()
}

/// One group's gathered pyramid: its roots, and the grid they are laid out on.
struct Gathered {
    /// LL positions (x, y) of the roots, in raster order.
    roots: Vec<(usize, usize)>,
    /// Roots per row of the gathered grid.
    cols: usize,
    /// Empty slots before the first root.
    offset: usize,
    /// Rows of the gathered grid.
    rows: usize,
}

impl Gathered {
    /// A square grid, or when `row` is given, rows of that many roots with the first one at
    /// its column in the LL band (contiguous groups: neighbours stay neighbours).
    fn new(roots: Vec<(usize, usize)>, row: Option<usize>) -> Gathered {
        let n = roots.len().max(1);
        let (cols, offset) = match row {
            Some(lw) => (lw, roots.first().map_or(0, |r| r.0)),
            None => ((n as f64).sqrt().ceil() as usize, 0),
        };
        Gathered {
            roots,
            cols,
            offset,
            rows: (n + offset).div_ceil(cols),
        }
    }

    /// For every coefficient of the gathered band of `sb` (block side `side`), the position in
    /// the subband it comes from, or `None` for padding.
    fn positions(&self, sb: &Subband, side: usize) -> Vec<Option<(usize, usize)>> {
        let (gw, gh) = (self.cols * side, self.rows * side);
        (0..gw * gh)
            .map(|i| {
                let (gx, gy) = (i % gw, i / gw);
                let k = ((gy / side) * self.cols + gx / side).checked_sub(self.offset)?;
                let &(rx, ry) = self.roots.get(k)?;
                let (x, y) = (rx * side + gx % side, ry * side + gy % side);
                (x < sb.width && y < sb.height).then_some((x, y))
            })
            .collect()
    }
}

/// Per (component, subband) of a group, in coding order: where each coefficient comes from,
/// and its weight.
type Plan = Vec<(usize, Subband, f32, Vec<Option<(usize, usize)>>)>;

fn plan(layout: &Layout, gathered: &Gathered) -> (Plan, Vec<Option<usize>>, usize) {
    let header = layout.header();
    let (w, h) = (layout.width, layout.height);
    let subbands = wavelet::subbands(w, h, layout.levels);
    let weights = subband_weights(&header, &subbands);
    let comps = if layout.gray { 1 } else { 3 };
    let mut out = Vec::new();
    let mut keys = Vec::new();
    for (sb, &weight) in subbands.iter().zip(&weights) {
        let side = 1usize << (layout.levels - sb.level);
        let pos = gathered.positions(sb, side);
        for (comp, mse) in COMPONENT_MSE_WEIGHTS.iter().enumerate().take(comps) {
            let cw = if layout.gray { 1.0 } else { mse.sqrt() };
            out.push((comp, *sb, weight * cw, pos.clone()));
            keys.push((comp, orientation_code(sb.orientation), sb.level));
        }
    }
    (out, coder::parents(&keys), w)
}

fn band_of(
    gathered: &Gathered,
    sb: &Subband,
    levels: u32,
    parent: Option<usize>,
) -> (usize, usize, usize, Option<usize>) {
    let side = 1usize << (levels - sb.level);
    (
        gathered.cols * side,
        gathered.rows * side,
        class_of(sb.orientation),
        parent,
    )
}

fn groups_of(layout: &Layout) -> Vec<Gathered> {
    let (lw, lh) = wavelet::low_size(layout.width, layout.height, layout.levels);
    let g = layout.groups();
    let owner = assign(layout, lw, lh);
    let mut roots = vec![Vec::new(); g];
    for (i, &o) in owner.iter().enumerate() {
        roots[o].push((i % lw, i / lw));
    }
    let row = (!layout.dispersed).then_some(lw);
    roots.into_iter().map(|r| Gathered::new(r, row)).collect()
}

/// Encodes `img` (lossy, 9/7) in the resilient layout: exactly `layout.bytes` bytes, the
/// reserved header bytes zero.
pub fn encode_groups(img: &Image, layout: &Layout) -> Vec<u8> {
    let header = layout.header();
    let (w, h) = (layout.width, layout.height);
    let mut planes = to_components(img, layout.gray, false);
    let mut scratch = Scratch::default();
    for plane in &mut planes {
        transform(plane, w, h, &header, true, &mut scratch);
    }
    let groups = groups_of(layout);
    let g = groups.len();
    let trunks: Vec<_> = (0..layout.trunks())
        .map(|t| layout.trunk_payload(t))
        .collect();
    let mut out = vec![0u8; layout.bytes];
    for (gi, gathered) in groups.iter().enumerate() {
        let (plan, parents, stride) = plan(layout, gathered);
        let bands = plan
            .iter()
            .zip(&parents)
            .map(|((comp, sb, weight, pos), &parent)| {
                let scale = weight * (1 << FRACTION_BITS) as f32;
                let plane = &planes[*comp];
                let (mag, neg) = pos
                    .iter()
                    .map(|p| {
                        p.map_or((0, false), |(x, y)| {
                            let c = plane[(sb.y0 + y) * stride + sb.x0 + x];
                            ((c.abs() * scale) as u32, c < 0.0)
                        })
                    })
                    .unzip();
                let (bw, bh, class, parent) = band_of(gathered, sb, layout.levels, parent);
                Band::new(bw, bh, class, parent, Some((mag, neg)))
            })
            .collect();
        let mine: Vec<_> = trunks.iter().skip(gi).step_by(g).cloned().collect();
        let budget = mine.iter().map(|r| r.len()).sum();
        let payload = encode_bands(bands, budget, false, None).0;
        let mut rest = &payload[..];
        for r in mine {
            let n = r.len().min(rest.len());
            out[r.start..r.start + n].copy_from_slice(&rest[..n]);
            rest = &rest[n..];
        }
    }
    out
}

/// Decodes a resilient stream of which the trunks `lost` never arrived; each group decodes up
/// to its first lost trunk, and a group that lost its first trunk is concealed.
pub fn decode_groups(data: &[u8], layout: &Layout, lost: &[usize]) -> Image {
    let header = layout.header();
    let (w, h) = (layout.width, layout.height);
    let comps = if layout.gray { 1 } else { 3 };
    let mut planes: Vec<Vec<f32>> = (0..comps).map(|_| vec![0.0; w * h]).collect();
    let groups = groups_of(layout);
    let g = groups.len();
    let mut decoded = vec![false; g];
    for (gi, gathered) in groups.iter().enumerate() {
        let mut payload = Vec::new();
        for t in (gi..layout.trunks()).step_by(g) {
            if lost.contains(&t) {
                break;
            }
            let r = layout.trunk_payload(t);
            payload.extend_from_slice(data.get(r).unwrap_or_default());
        }
        if payload.is_empty() {
            continue;
        }
        decoded[gi] = true;
        let (plan, parents, stride) = plan(layout, gathered);
        let mut bands: Vec<Band> = plan
            .iter()
            .zip(&parents)
            .map(|((_, sb, _, _), &parent)| {
                let (bw, bh, class, parent) = band_of(gathered, sb, layout.levels, parent);
                Band::new(bw, bh, class, parent, None)
            })
            .collect();
        let mut dec = Decoder::new(&payload);
        if let Ok(plane_count) = dec.raw(0, 5) {
            let _ = coder::code_planes(&mut bands, plane_count, &mut dec);
        }
        for (band, (comp, sb, weight, pos)) in bands.iter().zip(&plan) {
            let scale = weight * (1 << FRACTION_BITS) as f32;
            for &i in band.significant() {
                let i = i as usize;
                let Some((x, y)) = pos[i] else { continue };
                let value = reconstructed(band.mag[i], band.known[i], false) / scale;
                planes[*comp][(sb.y0 + y) * stride + sb.x0 + x] =
                    if band.neg[i] { -value } else { value };
            }
        }
    }
    conceal(layout, &mut planes, &decoded);
    let mut scratch = Scratch::default();
    for plane in &mut planes {
        transform(plane, w, h, &header, false, &mut scratch);
    }
    from_components(&planes, w, h, false)
}

/// LL coefficients of lost groups become the mean of their decoded 8-neighbours.
fn conceal(layout: &Layout, planes: &mut [Vec<f32>], decoded: &[bool]) {
    if decoded.iter().all(|&d| d) {
        return;
    }
    let (lw, lh) = wavelet::low_size(layout.width, layout.height, layout.levels);
    let owner = assign(layout, lw, lh);
    let w = layout.width;
    for plane in planes.iter_mut() {
        let ll: Vec<f32> = (0..lw * lh).map(|i| plane[(i / lw) * w + i % lw]).collect();
        for i in (0..lw * lh).filter(|&i| !decoded[owner[i]]) {
            let (x, y) = ((i % lw) as isize, (i / lw) as isize);
            let (mut sum, mut n) = (0.0, 0);
            for (dx, dy) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))) {
                let (nx, ny) = (x + dx, y + dy);
                if (dx, dy) == (0, 0) || nx < 0 || ny < 0 || nx >= lw as isize || ny >= lh as isize
                {
                    continue;
                }
                let j = ny as usize * lw + nx as usize;
                if decoded[owner[j]] {
                    sum += ll[j];
                    n += 1;
                }
            }
            if n > 0 {
                plane[(i / lw) * w + i % lw] = sum / n as f32;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::psnr;

    fn synthetic(width: usize, height: usize) -> Image {
        let data = (0..width * height * 3)
            .map(|i| {
                let (p, c) = (i / 3, i % 3);
                let (x, y) = ((p % width) as f32, (p / width) as f32);
                (128.0 + 60.0 * (x / 9.0).sin() * (y / 13.0).cos() + 20.0 * c as f32) as u8
            })
            .collect();
        Image {
            width,
            height,
            channels: 3,
            data,
        }
    }

    #[test]
    fn lattice_separates_neighbours() {
        for groups in 5..80 {
            let b = lattice_step(groups);
            for (dx, dy) in [(1, 0), (0, 1), (1, 1), (groups - 1, 1)] {
                assert_ne!((dx + b * dy) % groups, 0, "groups {groups} b {b}");
            }
        }
    }

    #[test]
    fn a_lost_trunk_leaves_the_others_decodable() {
        let img = synthetic(96, 64);
        let layout = Layout::suggested(&img, 600, 39, 4);
        let data = encode_groups(&img, &layout);
        assert_eq!(data.len(), 600);
        let whole = decode_groups(&data, &layout, &[]);
        let full = psnr(&img, &whole);
        assert!(full > 20.0, "{full}");
        for lost in [0, 5, layout.trunks() - 1] {
            // Trashing the lost trunk's bytes changes nothing: they are ignored.
            let mut bad = data.clone();
            let r = lost * 39..((lost + 1) * 39).min(600);
            bad[r].iter_mut().for_each(|b| *b = !*b);
            let img_lost = decode_groups(&bad, &layout, &[lost]);
            let q = psnr(&img, &img_lost);
            assert!(
                q > full - 3.0 && q <= full + 0.01,
                "lost {lost}: {q} vs {full}"
            );
        }
        let none = decode_groups(&data, &layout, &(0..layout.trunks()).collect::<Vec<_>>());
        assert_eq!(none.data.len(), img.data.len());
    }
}
