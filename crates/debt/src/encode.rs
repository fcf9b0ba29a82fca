//! The encoder: an image within a byte budget, exactly. The planes are transformed, quantised
//! into bands and bit-plane coded until the budget is spent; a segmented stream codes each
//! segment within the whole budget first, then shares the budget so that every segment stops
//! at about the same pass, and interleaves their bytes trunk by trunk.

use super::adl::{self, DirectionMap};
use super::coder::{self, Band, BitCoder, Decision, Encoder};
use super::colour::{downscale, to_components};
use super::fec::{self, Fec};
use super::header::{Header, MAX_SEGMENTS, SegmentLayout, Segments};
use super::transform::{build_bands, default_levels, transform_planes};
use super::{Error, Image, MAX_SIDE, Rect, rangecoder};

/// Encoder settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EncodeOptions {
    /// The byte budget: the stream is exactly this long unless the image codes completely in
    /// fewer.
    pub bytes: usize,
    /// Wavelet levels (0..=7); `None` picks by image size.
    pub levels: Option<u32>,
    /// Code luma only.
    pub gray: bool,
    /// Reversible 5/3 transform and colour transform: with enough bytes, exact.
    pub lossless: bool,
    /// Encode at 1/2^scale of the size (0..=3); the decoder scales back up.
    pub scale: u32,
    /// Region of interest in pixels, coded first.
    pub roi: Option<Rect>,
    /// Bit-planes the region of interest is raised by (1..=15).
    pub roi_shift: u32,
    /// Split into independently decodable segments for lossy links.
    pub segments: Option<Segments>,
    /// End the budget with a restoration filter fitted on the stream's own decode (version 5,
    /// [`super::restore`]); only for lossy, unsegmented streams, and only from
    /// [`super::restore::MIN_BUDGET_BYTES`].
    pub restore: bool,
    /// Predict chroma from luma ([`super::cfl`], version 5) in lossy colour streams without
    /// segments from [`super::cfl::MIN_BUDGET_BYTES`].
    pub chroma_from_luma: bool,
    /// Parity trunks after the stream ([`super::fec`], version 5), inside the budget; only for
    /// lossy, unsegmented streams.
    pub fec: Option<FecOptions>,
    /// Start the coder's contexts from the trained table [`super::priors::PRIORS`] instead of
    /// one half (version 5); only for lossy streams without segments.
    pub priors: bool,
}

/// How much parity a stream carries, and for which trunks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FecOptions {
    /// Parity in percent of the stream's trunks (1..=[`fec::MAX_PERCENT`]), rounded, at least
    /// one trunk ([`fec::parity_trunks`]).
    pub percent: u32,
    /// The link's trunk size in bytes (1..=255).
    pub trunk_bytes: usize,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions {
            bytes: 1000,
            levels: None,
            gray: false,
            lossless: false,
            scale: 0,
            roi: None,
            roi_shift: 3,
            segments: None,
            restore: false,
            chroma_from_luma: true,
            fec: None,
            priors: true,
        }
    }
}

/// Completes a version 3 stream: states where its payload ends, fits the restoration filter
/// on the stream's own decode (its prefix without the filter) and appends it.
fn finish_restored(out: &mut Vec<u8>, header: &Header, img: &Image) -> Result<(), Error> {
    let at = out.len();
    if at > super::header::MAX_RESTORE_AT {
        return Err(Error::Setting {
            field: "restore",
            expected: "a payload below 16 MiB",
            found: at as u64,
        });
    }
    let header = Header {
        restore_at: Some(at),
        ..*header
    };
    let mut head = Vec::with_capacity(header.len());
    header.write(&mut head);
    out[..head.len()].copy_from_slice(&head);
    let decoded = super::decode(out)?;
    let filter = if header.gray && img.channels == 3 {
        super::restore::fit_checked(&decoded, &super::picture::to_gray(img))
    } else {
        super::restore::fit_checked(&decoded, img)
    };
    out.extend_from_slice(&filter.to_bytes());
    Ok(())
}

/// Encodes an image within `options.bytes` bytes.
pub fn encode(img: &Image, options: &EncodeOptions) -> Result<Vec<u8>, Error> {
    match options.fec {
        None => encode_stream(img, options, None, None, None).map(|(stream, _)| stream),
        Some(f) => encode_with_parity(img, options, f),
    }
}

/// A stream with parity: the budget's whole trunks, of which [`fec::parity_trunks`] are parity
/// and the rest the stream (its last trunk padded with zeros). A stream that codes completely
/// in fewer trunks gets the parity its own trunk count calls for, so that a decoder that lost
/// the header finds the layout again ([`fec::repair`]).
fn encode_with_parity(
    img: &Image,
    options: &EncodeOptions,
    f: FecOptions,
) -> Result<Vec<u8>, Error> {
    if !(1..=fec::MAX_PERCENT).contains(&f.percent) {
        return Err(Error::Setting {
            field: "fec",
            expected: "1..=50 percent",
            found: f.percent.into(),
        });
    }
    if !(1..=255).contains(&f.trunk_bytes) {
        return Err(Error::Setting {
            field: "fec trunk size",
            expected: "1..=255 bytes",
            found: f.trunk_bytes as u64,
        });
    }
    if options.lossless || options.segments.is_some() {
        return Err(Error::Setting {
            field: "fec",
            expected: "a lossy stream without segments",
            found: f.percent.into(),
        });
    }
    let t = f.trunk_bytes;
    // The header states at most 16 MiB of data: a larger budget is as good as unbounded.
    let trunks = options.bytes.min(fec::MAX_DATA_BYTES) / t;
    let mut parity = fec::parity_trunks(trunks, f.percent);
    if trunks < parity + 1 {
        return Err(Error::Setting {
            field: "fec budget",
            expected: "room for a data and a parity trunk",
            found: options.bytes as u64,
        });
    }
    loop {
        let mut code = Fec {
            trunk_bytes: t,
            data_bytes: (trunks - parity) * t,
            parity_trunks: parity,
        };
        let inner = EncodeOptions {
            bytes: code.data_bytes,
            fec: None,
            ..options.clone()
        };
        let (mut out, _) = encode_stream(img, &inner, Some(code), None, None)?;
        let again = fec::parity_trunks(out.len().div_ceil(t) + parity, f.percent);
        if again < parity {
            parity = again;
            continue;
        }
        code.data_bytes = out.len();
        let header = Header {
            fec: Some(code),
            ..Header::read(&out)?
        };
        let mut head = Vec::with_capacity(header.len());
        header.write(&mut head);
        out[..head.len()].copy_from_slice(&head);
        let parity_bytes = code.parity(&out);
        out.resize(code.data_trunks() * t, 0);
        out.extend_from_slice(&parity_bytes);
        return Ok(out);
    }
}

/// The context-coded decisions of encoding `img` with `options` (without parity), one list per
/// segment (one for an unsegmented stream), each in coding order: what a priors table is
/// trained on. A segment's list runs to where its coder stopped within the whole budget, past
/// the share of the budget its stream keeps.
pub fn decisions(img: &Image, options: &EncodeOptions) -> Result<Vec<Vec<Decision>>, Error> {
    let mut log = Vec::new();
    encode_stream(img, options, None, Some(&mut log), None)?;
    Ok(log)
}

/// Encodes an image within `options.bytes` bytes with its finest levels lifted along
/// directions ([`adl`], a prototype): the stream's bit-planes take the budget less the
/// directions' coded bytes ([`DirectionMap::to_bytes`]), and the directions come back beside
/// the stream, for [`super::decode_with_directions`] (the header does not say the stream has
/// them). Lossy streams without segments, restoration or parity only.
pub fn encode_with_directions(
    img: &Image,
    options: &EncodeOptions,
    params: &adl::Params,
) -> Result<(Vec<u8>, DirectionMap), Error> {
    adl::check(
        options.lossless,
        options.segments.is_some() || options.fec.is_some(),
        options.restore,
    )?;
    let (stream, map) = encode_stream(img, options, None, None, Some(params))?;
    let map = map.ok_or(Error::Setting {
        field: "directions",
        expected: "a direction map for a directional stream",
        found: 0,
    })?;
    Ok((stream, map))
}

/// [`encode`] without parity; `fec`, when given, is stated in the header (its protected length
/// as the budget, until [`encode_with_parity`] writes the true one); each segment's decisions
/// appended to `log` when given; with directional lifting when `directions` is set (see
/// [`encode_with_directions`]), and the directions picked.
fn encode_stream(
    img: &Image,
    options: &EncodeOptions,
    fec: Option<Fec>,
    mut log: Option<&mut Vec<Vec<Decision>>>,
    directions: Option<&adl::Params>,
) -> Result<(Vec<u8>, Option<DirectionMap>), Error> {
    if img.width == 0 || img.height == 0 || img.width > MAX_SIDE || img.height > MAX_SIDE {
        return Err(Error::Size {
            width: img.width,
            height: img.height,
        });
    }
    if img.channels != 1 && img.channels != 3 {
        return Err(Error::Setting {
            field: "channels",
            expected: "1 or 3",
            found: img.channels as u64,
        });
    }
    let expected = img.width * img.height * img.channels;
    if img.data.len() != expected {
        return Err(Error::Data {
            expected,
            found: img.data.len(),
        });
    }
    if options.scale > 3 {
        return Err(Error::Setting {
            field: "scale",
            expected: "0..=3",
            found: options.scale.into(),
        });
    }
    let coded = downscale(img, options.scale);
    let levels = options
        .levels
        .unwrap_or_else(|| default_levels(coded.width, coded.height));
    if levels > 7 {
        return Err(Error::Setting {
            field: "levels",
            expected: "0..=7",
            found: levels.into(),
        });
    }
    let roi = match options.roi {
        None => None,
        Some(r) => {
            if !(1..=15).contains(&options.roi_shift) {
                return Err(Error::Setting {
                    field: "roi_shift",
                    expected: "1..=15",
                    found: options.roi_shift.into(),
                });
            }
            if r.x0 >= r.x1 || r.y0 >= r.y1 || r.x1 > img.width || r.y1 > img.height {
                return Err(Error::Roi {
                    rect: r,
                    width: img.width,
                    height: img.height,
                });
            }
            Some((
                Header::roi_cells(&r, img.width, img.height),
                options.roi_shift,
            ))
        }
    };
    if options.restore && (options.lossless || options.segments.is_some()) {
        return Err(Error::Setting {
            field: "restore",
            expected: "a lossy stream without segments",
            found: 1,
        });
    }
    let restore = options.restore && options.bytes >= crate::restore::MIN_BUDGET_BYTES;
    let header = Header {
        width: img.width,
        height: img.height,
        gray: options.gray || img.channels == 1,
        lossless: options.lossless,
        levels,
        scale: options.scale,
        roi,
        segments: options.segments.map(|segments| SegmentLayout {
            segments,
            weights: [1; MAX_SEGMENTS + 1],
        }),
        restore_at: restore.then_some(0),
        cfl: None,
        fec,
        priors: options.priors && !options.lossless && options.segments.is_none(),
    };
    if let Some(seg) = options.segments {
        seg.check()?;
    }
    header.check_trunk()?;
    // Nothing is allocated from the budget: a stream grows with what the image needs, and
    // stops when it is complete (a budget of 2^64 - 1 bytes is as good as unbounded).
    let mut out = Vec::with_capacity(header.len());
    header.write(&mut out);
    if options.bytes < out.len() {
        return Err(Error::Budget {
            found: options.bytes,
            header: out.len(),
        });
    }
    let (w, h) = header.coded_size();
    let mut planes = to_components(&coded, header.gray, header.lossless);
    let map = match directions {
        Some(params) => Some(adl::forward_planes(&mut planes, w, h, levels, params)),
        None => {
            transform_planes(&mut planes, w, h, &header, true);
            None
        }
    };
    let map_bytes = map.as_ref().map_or(0, |m| m.to_bytes().len());
    let mut header = header;
    if options.chroma_from_luma
        && options.bytes >= super::cfl::MIN_BUDGET_BYTES
        && planes.len() == 3
        && !header.lossless
        && header.segments.is_none()
    {
        let m = super::cfl::Multipliers::fit_and_subtract(&mut planes, w, h, levels);
        header.cfl = Some(m);
        out.clear();
        header.write(&mut out);
    }
    let Some(layout) = header.segments else {
        let trailer = if restore {
            super::restore::Filter::len_for(header.components())
        } else {
            0
        };
        let budget = options
            .bytes
            .saturating_sub(out.len() + trailer + map_bytes);
        let (bands, _) = build_bands(&header, Some(&planes), 0, 1);
        out.extend_from_slice(&encode_bands(bands, budget, header.priors, log).0);
        if restore {
            finish_restored(&mut out, &header, img)?;
        }
        return Ok((out, map));
    };
    let count = layout.segments.count + 1;
    let header_bytes = header.len();
    // Every segment is coded once within the whole budget, noting where each pass ends; the
    // budget is then split so that all segments stop at about the same pass (equal
    // distortion-rate slope), and each keeps the prefix of its stream that fits its trunks.
    let budget = options.bytes.saturating_sub(header_bytes);
    let mut streams = Vec::with_capacity(count);
    let mut ends = Vec::with_capacity(count);
    let mut all_complete = true;
    for part in 0..count {
        let (bands, _) = build_bands(&header, Some(&planes), part, count);
        let (payload, complete, marks) =
            encode_bands(bands, budget, header.priors, log.as_deref_mut());
        ends.push(pass_ends(&marks, complete));
        all_complete &= complete;
        streams.push(payload);
    }
    // When every segment is complete the image needs no more than their sum: a larger budget
    // would only pad, so the stream stops once every segment has had its bytes.
    // Each then gets weight for the whole trunks it fills, so that small segments get their
    // trunks early instead of once per round of the large ones.
    let trunk = layout.segments.trunk_bytes;
    let shares = if all_complete {
        streams
            .iter()
            .map(|s| s.len().div_ceil(trunk).max(1) * trunk)
            .collect()
    } else {
        split_budget(&ends, budget)
    };
    let largest = shares.iter().copied().max().unwrap_or(1).max(1) as u128;
    let mut weights = [0u8; MAX_SEGMENTS + 1];
    for (w, &share) in weights.iter_mut().zip(&shares) {
        *w = (share as u128 * 255).div_ceil(largest).clamp(1, 255) as u8;
    }
    let layout = SegmentLayout {
        segments: layout.segments,
        weights,
    };
    let header = Header {
        segments: Some(layout),
        ..header
    };
    out.clear();
    header.write(&mut out);
    // Past its end a segment's trunks are zeros (a complete stream ends in zeros anyway).
    let mut taken = vec![0; count];
    let mut needed_end = out.len();
    for (range, part) in layout.chunks(header_bytes, options.bytes) {
        if all_complete && taken.iter().zip(&streams).all(|(&t, s)| t >= s.len()) {
            break;
        }
        let stream = streams[part].get(taken[part]..).unwrap_or_default();
        let real = stream.len().min(range.len());
        out.extend_from_slice(&stream[..real]);
        out.resize(out.len() + range.len() - real, 0);
        taken[part] += range.len();
        if real > 0 {
            needed_end = range.start + real;
        }
    }
    if all_complete {
        out.truncate(needed_end);
    }
    Ok((out, None))
}

/// Where each pass ends in a segment's stream, in bytes a decoder needs to have it all, indexed
/// by [`coder::pass_index`]; `u64::MAX` for passes the stream stopped before finishing.
fn pass_ends(marks: &[(usize, u64)], complete: bool) -> Vec<u64> {
    let bytes = |bits: u64| (bits + u64::from(rangecoder::MARGIN_BITS)).div_ceil(8);
    (0..coder::PASS_INDICES)
        .map(|i| match marks.iter().rev().find(|m| m.0 <= i) {
            // Planes above the segment's largest magnitude: nothing but the plane count.
            None => bytes(5),
            Some(&(index, bits)) if index == i || complete => bytes(bits),
            Some(_) => u64::MAX,
        })
        .collect()
}

/// Splits `budget` bytes among segments whose pass ends are `ends`: each gets what reaches the
/// last pass that all can complete together, and the rest in proportion to the next pass.
fn split_budget(ends: &[Vec<u64>], budget: usize) -> Vec<usize> {
    let budget = budget as u64;
    let total = |i: usize| -> u64 { ends.iter().map(|e| e[i]).fold(0, u64::saturating_add) };
    let reached = (0..coder::PASS_INDICES)
        .take_while(|&i| total(i) <= budget)
        .last();
    let base: Vec<u64> = ends.iter().map(|e| reached.map_or(0, |i| e[i])).collect();
    let next = reached.map_or(0, |i| i + 1).min(coder::PASS_INDICES - 1);
    let left = budget - base.iter().sum::<u64>().min(budget);
    let growth: Vec<u64> = ends
        .iter()
        .zip(&base)
        .map(|(e, &b)| e[next].min(budget).saturating_sub(b).max(1))
        .collect();
    let growth_sum: u64 = growth.iter().sum();
    base.iter()
        .zip(&growth)
        .map(|(&b, &g)| (b + left * g / growth_sum) as usize)
        .collect()
}

/// Codes a band list in at most `budget` bytes, its contexts starting from the priors table
/// if `priors`: the bytes (exactly `budget` unless complete), whether every plane was coded,
/// and where each pass ended ([`Encoder::marks`]). The decisions are appended to `log` as one
/// more list when given.
pub(super) fn encode_bands(
    mut bands: Vec<Band>,
    budget: usize,
    priors: bool,
    log: Option<&mut Vec<Vec<Decision>>>,
) -> (Vec<u8>, bool, Vec<(usize, u64)>) {
    let max = bands.iter().map(Band::max_magnitude).max().unwrap_or(0);
    let plane_count = 32 - max.leading_zeros();
    let mut enc = if priors {
        Encoder::with_priors(budget, super::priors::PRIORS)
    } else {
        Encoder::new(budget)
    };
    if log.is_some() {
        enc.decisions = Some(Vec::new());
    }
    let complete = enc.raw(plane_count, 5).is_ok()
        && coder::code_planes(&mut bands, plane_count, &mut enc).is_ok();
    if let Some(log) = log {
        log.push(enc.decisions.take().unwrap_or_default());
    }
    let marks = std::mem::take(&mut enc.marks);
    let mut payload = enc.finish(complete);
    if complete {
        payload.truncate(budget);
    } else {
        payload.resize(budget, 0);
    }
    (payload, complete, marks)
}
