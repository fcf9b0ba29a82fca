//! The decoder: any prefix of a stream, or a segmented stream with trunks lost, to the best
//! image its bytes describe. Significant coefficients are gathered per component and rebuilt
//! within their uncertainty interval; lossy pictures are synthesised one RGB channel at a time
//! straight from the coefficients.

use std::ops::Range;

use super::adl::{self, DirectionMap};
use super::coder::{self, BitCoder, Decoder};
use super::colour::{YCBCR_TO_RGB, from_components, to_sample, upscale};
use super::header::Header;
use super::transform::{FRACTION_BITS, build_bands, in_roi, transform_planes};
use super::{Error, Image, wavelet};

/// Where in its uncertainty interval a partly known coefficient is put back (0.5 = middle;
/// a little below suits the peaked distribution of wavelet coefficients).
const RECONSTRUCTION_OFFSET: f32 = 0.4;

/// Decodes a stream (or any prefix of one).
pub fn decode(data: &[u8]) -> Result<Image, Error> {
    decode_with_loss(data, &[])
}

/// Decodes a stream cut into trunks of `trunk_bytes` of which the trunks `lost` (0-based) never
/// arrived (their contents are ignored): a stream with parity ([`super::fec`]) first gets back
/// what its parity can recover, the header too; then as [`decode_with_loss`].
pub fn decode_trunks(data: &[u8], trunk_bytes: usize, lost: &[usize]) -> Result<Image, Error> {
    let repaired = super::fec::repair(data, trunk_bytes, lost);
    if repaired.lost.iter().any(|r| r.start == 0) {
        return Err(Error::HeaderLost { trunk: trunk_bytes });
    }
    decode_with_loss(&repaired.data, &repaired.lost)
}

/// Decodes a stream of which the byte ranges `lost` never arrived (their contents are ignored).
/// A single-segment stream decodes up to its first lost byte; a segmented one loses, in each
/// segment, the chunks from its first lost one on. The header must have arrived.
pub fn decode_with_loss(data: &[u8], lost: &[Range<usize>]) -> Result<Image, Error> {
    decode_inner(data, lost, None)
}

/// Decodes a stream of [`super::encode_with_directions`] (or any prefix of one) with the
/// directions that came beside it.
pub fn decode_with_directions(data: &[u8], directions: &DirectionMap) -> Result<Image, Error> {
    decode_inner(data, &[], Some(directions))
}

/// [`decode_with_loss`], the lossy synthesis along `directions` when set.
fn decode_inner(
    data: &[u8],
    lost: &[Range<usize>],
    directions: Option<&DirectionMap>,
) -> Result<Image, Error> {
    let header = match Header::read(data) {
        Ok(header) => header,
        // A version 5 prefix that ends inside its features: the picture's size is known, so
        // it decodes, as every prefix of a version 1 stream past its 5 bytes does.
        Err(e @ Error::Truncated { .. }) => {
            return match Header::base_of_features(data) {
                Some(base) => decode_with_loss(&base, &[]),
                None => Err(e),
            };
        }
        Err(e) => return Err(e),
    };
    let header_bytes = header.len();
    let first_lost = lost
        .iter()
        .filter(|r| !r.is_empty())
        .map(|r| r.start)
        .min()
        .unwrap_or(usize::MAX);
    if first_lost < header_bytes {
        return Err(Error::Truncated {
            expected: header_bytes,
            found: first_lost,
        });
    }
    let (w, h) = header.coded_size();
    // The coefficients that arrived, per component: (index in the plane, value).
    let mut coefficients = vec![Vec::new(); header.components()];
    match header.segments {
        None => {
            let end = data
                .len()
                .min(first_lost)
                .min(header.restore_at.unwrap_or(usize::MAX))
                .min(header.fec.map_or(usize::MAX, |f| f.data_bytes));
            decode_part(
                &header,
                &data[header_bytes.min(end)..end],
                (0, 1),
                header.priors,
                &mut coefficients,
            );
        }
        Some(layout) => {
            let count = layout.segments.count + 1;
            let mut payloads = vec![Vec::new(); count];
            let mut alive = vec![true; count];
            for (range, part) in layout.chunks(header_bytes, data.len()) {
                let hit = lost
                    .iter()
                    .any(|l| l.start < range.end && range.start < l.end);
                alive[part] &= !hit;
                if alive[part] {
                    payloads[part].extend_from_slice(&data[range]);
                }
            }
            for (part, payload) in payloads.iter().enumerate() {
                decode_part(
                    &header,
                    payload,
                    (part, count),
                    header.priors,
                    &mut coefficients,
                );
            }
        }
    }
    let img = if header.lossless {
        let mut planes: Vec<Vec<f32>> = coefficients
            .iter()
            .map(|coefs| scattered(coefs, w * h))
            .collect();
        transform_planes(&mut planes, w, h, &header, false);
        from_components(&planes, w, h, true)
    } else {
        if let Some(m) = header.cfl {
            m.add_prediction(&mut coefficients, w, h, header.levels);
        }
        match directions {
            Some(map) => adl::synthesise(&coefficients, w, h, header.levels, map),
            None => {
                synthesise_channels(&coefficients, w, h, header.levels, synthesis_threads(w * h))
            }
        }
    };
    let img = upscale(img, header.width, header.height);
    // The restoration filter, when the whole of it arrived.
    if let Some(at) = header.restore_at {
        let len = super::restore::Filter::len_for(img.channels);
        let arrived = data.len() >= at + len && first_lost >= at + len;
        if let Some(filter) = arrived
            .then(|| super::restore::Filter::from_bytes(&data[at..], img.channels))
            .flatten()
        {
            let mut img = img;
            super::restore::apply_in_place(&mut img, &filter);
            return Ok(img);
        }
    }
    Ok(img)
}

/// A plane of `len` zeros with `coefficients` put in it. Zeroed by writing: the wavelet reads
/// and writes every sample anyway, and a page of a lazily zeroed (calloc) allocation faults
/// twice, once read as the zero page and again when written.
fn scattered(coefficients: &[(u32, f32)], len: usize) -> Vec<f32> {
    let mut plane = Vec::new();
    plane.resize(len, 0.0);
    for &(i, v) in coefficients {
        plane[i as usize] = v;
    }
    plane
}

/// The lossy picture from its coefficients, each output channel synthesised on its own.
///
/// The 9/7 synthesis and YCbCr -> RGB are both linear, so each RGB channel is the synthesis of
/// its own mix of the component coefficients (only the significant ones, a few thousand at
/// narrow-link budgets), rounded and clamped once at the end: no separate colour conversion.
/// The channels are independent, so with `threads` > 1 each channel but the first is
/// synthesised on a thread of its own, and the three sample planes are interleaved at the end;
/// the numbers are the same on any number of threads.
/// Floating point differs from converting after synthesis in the last bits only (a sample may
/// round the other way).
fn synthesise_channels(
    coefficients: &[Vec<(u32, f32)>],
    width: usize,
    height: usize,
    levels: u32,
    threads: usize,
) -> Image {
    const GREY: [[f32; 3]; 1] = [[1.0, 0.0, 0.0]];
    let mix: &[[f32; 3]] = match coefficients.len() {
        1 => &GREY,
        _ => &YCBCR_TO_RGB,
    };
    let channels = mix.len();
    let n = width * height;
    let synthesise =
        |weights: &[f32; 3]| synthesise_channel(coefficients, weights, width, height, levels);
    let planes: Vec<Vec<u8>> = if channels > 1 && threads > 1 {
        std::thread::scope(|scope| {
            let others: Vec<_> = mix[1..]
                .iter()
                .map(|weights| scope.spawn(move || synthesise(weights)))
                .collect();
            let first = synthesise(&mix[0]);
            std::iter::once(first)
                .chain(others.into_iter().map(|t| {
                    t.join()
                        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
                }))
                .collect()
        })
    } else {
        mix.iter().map(synthesise).collect()
    };
    let data = match planes.as_slice() {
        [r, g, b] => {
            let mut data = vec![0u8; n * 3];
            for (pixel, ((&r, &g), &b)) in data.chunks_exact_mut(3).zip(r.iter().zip(g).zip(b)) {
                pixel.copy_from_slice(&[r, g, b]);
            }
            data
        }
        _ => planes.into_iter().next().unwrap_or_default(),
    };
    Image {
        width,
        height,
        channels,
        data,
    }
}

/// Pictures of at least this many samples synthesise their channels in parallel (below it a
/// thread costs more than it saves).
const PARALLEL_SAMPLES: usize = 1 << 16;

/// How many threads synthesise a picture of `samples` samples: the machine's cores from
/// [`PARALLEL_SAMPLES`] on, else one.
fn synthesis_threads(samples: usize) -> usize {
    if samples < PARALLEL_SAMPLES {
        return 1;
    }
    std::thread::available_parallelism().map_or(1, |t| t.get())
}

/// One output channel: the synthesis of the components' coefficients mixed by `weights`, its
/// samples rounded and clamped as the last step of the synthesis hands each row over.
fn synthesise_channel(
    coefficients: &[Vec<(u32, f32)>],
    weights: &[f32; 3],
    width: usize,
    height: usize,
    levels: u32,
) -> Vec<u8> {
    // Zeroed by writing, as in [`scattered`].
    let mut plane = Vec::new();
    plane.resize(width * height, 0.0f32);
    for (coefs, &weight) in coefficients.iter().zip(weights) {
        if weight != 0.0 {
            for &(i, v) in coefs {
                plane[i as usize] += weight * v;
            }
        }
    }
    let mut samples = vec![0u8; width * height];
    wavelet::inverse_97_rows(
        &mut plane,
        width,
        height,
        levels,
        &mut Vec::new(),
        |r, row| {
            for (q, &v) in samples[r * width..(r + 1) * width].iter_mut().zip(row) {
                *q = to_sample(v + 128.0);
            }
        },
    );
    samples
}

/// The magnitude a significant coefficient is rebuilt at from its known bits `mag`, `known`
/// low bits being unknown: the middle of the last interval when every plane is known (exactly
/// `mag` when lossless), else `RECONSTRUCTION_OFFSET` of the way into it.
pub(super) fn reconstructed(mag: u32, known: u8, lossless: bool) -> f32 {
    if known == 0 {
        mag as f32 + if lossless { 0.0 } else { 0.5 }
    } else {
        mag as f32 + RECONSTRUCTION_OFFSET * (1u64 << known) as f32
    }
}

/// Decodes segment `part` of `parts` from its bytes, its contexts starting from the priors
/// table if `priors`, and appends its significant coefficients to `coefficients` (per
/// component: index in the plane, value).
fn decode_part(
    header: &Header,
    payload: &[u8],
    (part, parts): (usize, usize),
    priors: bool,
    coefficients: &mut [Vec<(u32, f32)>],
) {
    let (w, _) = header.coded_size();
    let (mut bands, layout) = build_bands(header, None, part, parts);
    let mut dec = if priors {
        Decoder::with_priors(payload, super::priors::PRIORS)
    } else {
        Decoder::new(payload)
    };
    if let Ok(plane_count) = dec.raw(0, 5) {
        let _ = coder::code_planes(&mut bands, plane_count, &mut dec);
    }
    let roi = header.roi_rect();
    for (band, &(comp, sb, weight, row0)) in bands.iter().zip(&layout) {
        let scale = if header.lossless {
            1.0
        } else {
            weight * (1 << FRACTION_BITS) as f32
        };
        for &i in band.significant() {
            let i = i as usize;
            let (x, y) = (i % sb.width, row0 + i / sb.width);
            let known = band.known[i];
            let mag = band.mag[i];
            let mut value = reconstructed(mag, known, header.lossless);
            if let Some((rect, shift)) = roi
                && in_roi(&rect, sb.level, x, y)
            {
                value /= (1u64 << shift) as f32;
                if header.lossless {
                    value = value.floor();
                }
            }
            let value = value / scale;
            let index = ((sb.y0 + y) * w + sb.x0 + x) as u32;
            coefficients[comp].push((index, if band.neg[i] { -value } else { value }));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::EncodeOptions;
    use crate::encode;
    use crate::tests::synthetic;

    /// `img` encoded to `bytes` with the default options, its header and the significant
    /// coefficients the decoder gathers from the whole stream.
    fn coefficients_of(img: &Image, bytes: usize) -> (Header, Vec<Vec<(u32, f32)>>) {
        let options = EncodeOptions {
            bytes,
            ..EncodeOptions::default()
        };
        let stream = encode(img, &options).unwrap();
        let header = Header::read(&stream).unwrap();
        let mut coefficients = vec![Vec::new(); header.components()];
        decode_part(
            &header,
            &stream[header.len()..],
            (0, 1),
            header.priors,
            &mut coefficients,
        );
        (header, coefficients)
    }

    #[test]
    fn channels_synthesised_from_mixed_coefficients_match_converting_after_synthesis() {
        for (channels, bytes) in [(3, 300), (3, 3000), (3, 30000), (1, 3000)] {
            let (header, coefficients) = coefficients_of(&synthetic(97, 61, channels), bytes);
            let (w, h) = header.coded_size();
            let mut planes: Vec<Vec<f32>> =
                coefficients.iter().map(|c| scattered(c, w * h)).collect();
            transform_planes(&mut planes, w, h, &header, false);
            let after = from_components(&planes, w, h, false);
            let mixed = synthesise_channels(&coefficients, w, h, header.levels, 1);
            assert_eq!(mixed.channels, after.channels);
            let differ = (mixed.data.iter().zip(&after.data))
                .filter(|(a, b)| a != b)
                .inspect(|(a, b)| assert!(a.abs_diff(**b) <= 1, "{a} vs {b}"))
                .count();
            // Only samples within a rounding error of a half differ (none at all in grey).
            assert!(
                differ * 200 <= after.data.len(),
                "{differ} of {}",
                after.data.len()
            );
            assert!(
                channels == 3 || differ == 0,
                "grey differs in {differ} samples"
            );
        }
    }

    #[test]
    fn channels_on_threads_are_the_same_bytes_as_on_one() {
        let (header, coefficients) = coefficients_of(&synthetic(301, 227, 3), 4000);
        let (w, h) = header.coded_size();
        let one = synthesise_channels(&coefficients, w, h, header.levels, 1);
        for threads in [2, 3] {
            let many = synthesise_channels(&coefficients, w, h, header.levels, threads);
            assert_eq!((many.width, many.height, many.channels), (w, h, 3));
            assert!(many.data == one.data, "{threads} threads differ from one");
        }
    }
}
