//! DEBT (Depth Embedded Block Tree): an embedded wavelet image codec for links of a few kbit/s.
//!
//! An image becomes a few-byte header and one range-coded stream of bit-plane decisions (see
//! [`coder`]). The stream is embedded: cut it after any byte and the prefix decodes to the best
//! image those bytes can describe; the encoder stops at exactly the budget asked. A region of
//! interest is coded first by scaling its coefficients up by `roi_shift` bit-planes.
//!
//! Pipeline: optional downscale by 2^scale -> colour transform (YCbCr for lossy, the reversible
//! RCT for lossless) -> wavelet (9/7 lossy, 5/3 lossless, see [`wavelet`]) -> coefficients
//! weighted so that a bit-plane is worth the same squared error in every subband and component
//! (RGB error) -> block-tree bit-plane coding with adaptive contexts.
//!
//! Loss resilience (optional, [`Segments`]): the coefficients are split by rows into
//! independently coded segments whose bytes are interleaved trunk by trunk, so a lost trunk
//! truncates one segment (one horizontal stripe of the image loses detail) instead of the whole
//! rest of the stream. The bitstream is described in `docs/debt-format.md`.
//!
//! The codec's parts, each re-exported here: `header` (the stream's header and segment layout),
//! `colour` (scaling and colour transforms), `transform` (wavelet, weights, quantised bands),
//! `encode` and `decode`; the bit-plane coder is [`coder`] over [`rangecoder`].
//!
//! Around the codec: [`picture`] reads and writes picture files, [`metrics`] measures quality,
//! [`trial`] runs the compression trials of `debt-encode --sweep`.
//!
//! No-panic contract: [`decode`] returns an [`Error`] for a stream that is not DEBT and decodes
//! any other bytes, truncated or corrupt, to some image without panicking.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod adl;
pub mod cfl;
pub mod coder;
mod colour;
mod decode;
mod encode;
pub mod fec;
mod header;
pub mod metrics;
pub mod picture;
pub mod priors;
pub mod rangecoder;
pub mod resilient;
pub mod restore;
mod transform;
pub mod trial;
pub mod wavelet;

pub use decode::{decode, decode_trunks, decode_with_directions, decode_with_loss};
pub use encode::{EncodeOptions, FecOptions, decisions, encode, encode_with_directions};
pub use header::{
    Header, MAX_SEGMENTS, MIN_TRUNK_BYTES, SegmentLayout, Segments, VERSION, VERSION_CHROMA,
    VERSION_FEATURES, VERSION_SEGMENTED,
};
pub use transform::default_levels;

/// Codec errors.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    /// The stream is shorter than its header.
    #[error("DEBT header: need {expected} bytes, found {found}")]
    Truncated {
        /// Bytes the header needs.
        expected: usize,
        /// Bytes available.
        found: usize,
    },
    /// The first byte does not say DEBT.
    #[error("not a DEBT stream: first byte 0x{found:02x}, expected 0xd1 to 0xd5 (DEBT)")]
    NotDebt {
        /// The byte found.
        found: u8,
    },
    /// A DEBT stream of a version this build does not know.
    #[error(
        "DEBT version {found} is not supported (this build reads {VERSION} to {VERSION_FEATURES})"
    )]
    Version {
        /// The version found.
        found: u8,
    },
    /// An image this format cannot hold.
    #[error("image {width}x{height}: DEBT holds 1x1 to {MAX_SIDE}x{MAX_SIDE} pixels")]
    Size {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
    /// Pixel data that does not match the stated size.
    #[error("image data: expected {expected} bytes for the size and channels, found {found}")]
    Data {
        /// Bytes expected.
        expected: usize,
        /// Bytes found.
        found: usize,
    },
    /// A region of interest that is empty or reaches outside the image.
    #[error(
        "ROI {},{},{},{}: expected x0 < x1 <= {width} and y0 < y1 <= {height} (the image's size)",
        rect.x0, rect.y0, rect.x1, rect.y1
    )]
    Roi {
        /// The rectangle asked for.
        rect: Rect,
        /// Image width.
        width: usize,
        /// Image height.
        height: usize,
    },
    /// A byte budget smaller than the header that must start the stream.
    #[error("bytes: expected at least the header ({header} bytes), found {found}")]
    Budget {
        /// The budget asked for.
        found: usize,
        /// Bytes the header takes.
        header: usize,
    },
    /// A segmented stream whose header does not fit in its first trunk (the format puts the
    /// whole header in trunk 0).
    #[error(
        "a segmented header of {header} bytes does not fit in the first {trunk}-byte trunk: \
         trunks of at least {header} bytes, or fewer segments, are needed"
    )]
    HeaderTrunk {
        /// Bytes the header takes.
        header: usize,
        /// The trunk size.
        trunk: usize,
    },
    /// The trunk with the header was lost and no parity brought it back.
    #[error(
        "trunk 0 (the header) was lost and no parity brought it back ({trunk}-byte trunks): \
         nothing to decode"
    )]
    HeaderLost {
        /// The trunk size.
        trunk: usize,
    },
    /// A setting out of range.
    #[error("{field}: expected {expected}, found {found}")]
    Setting {
        /// The setting.
        field: &'static str,
        /// What it takes.
        expected: &'static str,
        /// The value found.
        found: u64,
    },
}
/// The largest width or height.
pub const MAX_SIDE: usize = 4096;
/// Longer than any stream of a [`MAX_SIDE`]-square picture, even lossless: what a reader of
/// streams may refuse beyond.
pub const MAX_STREAM_BYTES: u64 = 256 << 20;

/// An 8-bit image, 1 (grey) or 3 (RGB) interleaved channels.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// 1 or 3.
    pub channels: usize,
    /// Row-major, interleaved samples.
    pub data: Vec<u8>,
}

/// A rectangle of pixels, `x1`/`y1` exclusive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// Left.
    pub x0: usize,
    /// Top.
    pub y0: usize,
    /// Right, exclusive.
    pub x1: usize,
    /// Bottom, exclusive.
    pub y1: usize,
}

#[cfg(test)]
mod tests {
    use super::metrics::psnr;
    use super::*;

    /// A smooth synthetic colour image with some edges and texture.
    pub(super) fn synthetic(width: usize, height: usize, channels: usize) -> Image {
        let mut data = Vec::with_capacity(width * height * channels);
        for y in 0..height {
            for x in 0..width {
                let fx = x as f32 / width as f32;
                let fy = y as f32 / height as f32;
                let base = 128.0 + 80.0 * (fx * 6.0).sin() * (fy * 4.0).cos();
                let edge = if (x / 16 + y / 16) % 2 == 0 {
                    30.0
                } else {
                    -30.0
                };
                for c in 0..channels {
                    let v = base + edge * (c as f32 - 1.0) + ((x * 7 + y * 13 + c * 5) % 11) as f32;
                    data.push(v.clamp(0.0, 255.0) as u8);
                }
            }
        }
        Image {
            width,
            height,
            channels,
            data,
        }
    }

    /// A colour picture whose chroma is an affine function of a textured luma.
    fn luma_coloured(width: usize, height: usize) -> Image {
        let mut data = Vec::with_capacity(width * height * 3);
        for y in 0..height {
            for x in 0..width {
                let v = 128.0
                    + 60.0 * ((x as f32) * 0.31).sin() * ((y as f32) * 0.17).cos()
                    + if (x / 8 + y / 12) % 2 == 0 {
                        40.0
                    } else {
                        -40.0
                    };
                for (gain, offset) in [(1.0, 0.0), (0.6, 40.0), (0.2, 100.0)] {
                    data.push((gain * v + offset).clamp(0.0, 255.0) as u8);
                }
            }
        }
        Image {
            width,
            height,
            channels: 3,
            data,
        }
    }

    #[test]
    fn chroma_from_luma_makes_version_4_from_its_budget_and_every_prefix_decodes() {
        let img = luma_coloured(256, 192);
        let bytes = cfl::MIN_BUDGET_BYTES + 500;
        let with = |chroma_from_luma, bytes, restore| EncodeOptions {
            bytes,
            chroma_from_luma,
            restore,
            priors: false,
            ..EncodeOptions::default()
        };
        let v4 = encode(&img, &with(true, bytes, false)).unwrap();
        assert_eq!((v4[0], v4.len()), (0xd5, bytes));
        let header = Header::read(&v4).unwrap();
        let m = header.cfl.unwrap();
        assert!(m.steps.iter().any(|&q| q != 0), "{m:?}");
        assert_eq!(header.restore_at, None);
        let v1 = encode(&img, &with(false, bytes, false)).unwrap();
        assert_eq!(v1[0], 0xd1);
        assert_eq!(
            encode(&img, &with(true, bytes - 501, false)).unwrap()[0],
            0xd1
        );
        assert!(
            psnr(&decode(&v4).unwrap(), &img) > psnr(&decode(&v1).unwrap(), &img) + 0.1,
            "{} vs {}",
            psnr(&decode(&v4).unwrap(), &img),
            psnr(&decode(&v1).unwrap(), &img)
        );
        for cut in (0..bytes).step_by(61) {
            let decoded = decode(&v4[..cut]);
            assert_eq!(decoded.is_ok(), cut >= header.len(), "{cut}");
        }
        // With the filter too: version 4 still, the filter at the end, a prefix without it is
        // the unfiltered picture.
        let both = encode(&img, &with(true, bytes, true)).unwrap();
        assert_eq!((both[0], both.len()), (0xd5, bytes));
        let at = Header::read(&both).unwrap().restore_at.unwrap();
        assert_eq!(at + restore::Filter::len_for(3), bytes);
        let unfiltered = decode(&both[..at]).unwrap();
        assert!(psnr(&decode(&both).unwrap(), &img) >= psnr(&unfiltered, &img));
    }

    #[test]
    fn a_restored_stream_is_the_plain_payload_then_its_filter_and_every_prefix_decodes() {
        for channels in [1, 3] {
            let img = synthetic(96, 64, channels);
            let bytes = restore::MIN_BUDGET_BYTES + 37;
            let opts = EncodeOptions {
                bytes,
                restore: true,
                priors: false,
                ..EncodeOptions::default()
            };
            let v3 = encode(&img, &opts).unwrap();
            assert_eq!(v3.len(), bytes);
            assert_eq!(v3[0], 0xd5);
            let header = Header::read(&v3).unwrap();
            let at = header.restore_at.unwrap();
            let filter_bytes = restore::Filter::len_for(channels);
            assert_eq!(at + filter_bytes, bytes);
            // The payload is a version 1 stream's of the bytes left for it.
            let v1 = encode(
                &img,
                &EncodeOptions {
                    bytes: bytes - 4 - filter_bytes,
                    priors: false,
                    ..EncodeOptions::default()
                },
            )
            .unwrap();
            assert_eq!(v1[0], 0xd1);
            assert_eq!(&v3[header.len()..at], &v1[5..]);
            // Without (all of) its filter a prefix decodes as the plain stream; with it, the
            // picture is at least as close to the original.
            let plain = decode(&v1).unwrap();
            assert_eq!(decode(&v3[..at]).unwrap(), plain);
            assert_eq!(decode(&v3[..bytes - 1]).unwrap(), plain);
            let restored = decode(&v3).unwrap();
            assert!(
                psnr(&restored, &img) >= psnr(&plain, &img),
                "{channels} channels"
            );
            for cut in (0..bytes).step_by(97) {
                let _ = decode(&v3[..cut]);
            }
            // A lost filter byte leaves the picture unfiltered.
            let lost: Vec<std::ops::Range<usize>> = std::iter::once(at + 2..at + 3).collect();
            assert_eq!(decode_with_loss(&v3, &lost).unwrap(), plain);
        }
    }

    #[test]
    fn restore_is_for_lossy_plain_streams_from_its_smallest_budget() {
        let img = synthetic(32, 32, 3);
        let small = EncodeOptions {
            bytes: restore::MIN_BUDGET_BYTES - 1,
            restore: true,
            priors: false,
            ..EncodeOptions::default()
        };
        assert_eq!(encode(&img, &small).unwrap()[0], 0xd1);
        for lossless in [true, false] {
            let opts = EncodeOptions {
                lossless,
                segments: (!lossless).then_some(Segments {
                    count: 2,
                    trunk_bytes: 39,
                }),
                ..small.clone()
            };
            assert!(matches!(
                encode(&img, &opts),
                Err(Error::Setting {
                    field: "restore",
                    ..
                })
            ));
        }
        // A version 3 header whose offset is inside the header is refused, not a panic.
        let mut bad = encode(
            &img,
            &EncodeOptions {
                bytes: 4000,
                restore: true,
                ..EncodeOptions::default()
            },
        )
        .unwrap();
        bad[5..8].copy_from_slice(&[0, 0, 4]);
        assert!(decode(&bad).is_err());
        assert!(decode(&bad[..6]).is_err());
    }

    #[test]
    fn bad_roi_is_named() {
        let img = synthetic(16, 8, 1);
        let roi = Some(Rect {
            x0: 4,
            y0: 0,
            x1: 20,
            y1: 8,
        });
        let err = encode(
            &img,
            &EncodeOptions {
                roi,
                ..Default::default()
            },
        )
        .unwrap_err();
        assert_eq!(
            err.to_string(),
            "ROI 4,0,20,8: expected x0 < x1 <= 16 and y0 < y1 <= 8 (the image's size)"
        );
    }

    #[test]
    fn exact_budget_and_rising_quality() {
        let img = synthetic(96, 64, 3);
        let mut last = 0.0;
        for bytes in [40, 100, 300, 1000, 3000] {
            let stream = encode(
                &img,
                &EncodeOptions {
                    bytes,
                    ..Default::default()
                },
            )
            .unwrap();
            assert_eq!(stream.len(), bytes);
            let out = decode(&stream).unwrap();
            assert_eq!((out.width, out.height, out.channels), (96, 64, 3));
            let q = psnr(&img, &out);
            assert!(q > last, "{bytes} bytes: {q:.2} dB after {last:.2} dB");
            last = q;
        }
        assert!(last > 30.0, "3000 bytes give only {last:.2} dB");
    }

    #[test]
    // Lists of one lost range are what this test means, not ranges meant as lists.
    #[allow(clippy::single_range_in_vec_init)]
    fn segmented_streams_survive_lost_trunks() {
        let img = synthetic(160, 128, 3);
        let trunk = 39;
        let options = |segments| EncodeOptions {
            bytes: 1500,
            segments,
            ..Default::default()
        };
        let plain = encode(&img, &options(None)).unwrap();
        let seg = Segments {
            count: 4,
            trunk_bytes: trunk,
        };
        let stream = encode(&img, &options(Some(seg))).unwrap();
        assert_eq!(stream.len(), 1500);
        let whole = psnr(&img, &decode(&stream).unwrap());
        let plain_whole = psnr(&img, &decode(&plain).unwrap());
        assert!(whole > plain_whole - 1.0, "{whole} vs {plain_whole}");
        // Every trunk carries one segment; the base has trunk 0 and each segment some trunks.
        let header = Header::read(&stream).unwrap();
        let layout = header.segments.unwrap();
        let chunks: Vec<_> = layout.chunks(header.len(), stream.len()).collect();
        assert_eq!(chunks.len(), 1500usize.div_ceil(trunk));
        assert_eq!(chunks[0], (header.len()..trunk, 0));
        for part in 0..=4 {
            assert!(
                chunks.iter().any(|c| c.1 == part),
                "segment {part} has no trunk"
            );
        }
        // Losing trunk 5 costs the plain stream everything after it; the segmented stream
        // only the rest of one segment.
        let lost = [5 * trunk..6 * trunk];
        let plain_lossy = psnr(&img, &decode_with_loss(&plain, &lost).unwrap());
        let seg_lossy = psnr(&img, &decode_with_loss(&stream, &lost).unwrap());
        assert!(
            seg_lossy > plain_lossy + 1.0,
            "{seg_lossy} vs {plain_lossy}"
        );
        assert!(seg_lossy < whole);
        // Losing a trunk is the same as never getting that segment's later chunks.
        assert_eq!(
            decode_with_loss(&plain, &lost).unwrap(),
            decode(&plain[..5 * trunk]).unwrap()
        );
        // The header must arrive.
        assert!(matches!(
            decode_with_loss(&stream, &[3..4]),
            Err(Error::Truncated { .. })
        ));
        // A cut segmented stream still decodes, and better with more bytes.
        let short = psnr(&img, &decode(&stream[..400]).unwrap());
        assert!(short < whole && short > 10.0, "{short}");
    }

    #[test]
    // Lists of one lost range are what this test means, not ranges meant as lists.
    #[allow(clippy::single_range_in_vec_init)]
    fn segmented_header_longer_than_a_trunk_is_refused_not_a_panic() {
        // debt-encode -b 600 --segments 16 --trunk-size 16 wrote a 24-byte header into 16-byte
        // trunks, and the decoder panicked on it (issue 14).
        let img = synthetic(64, 48, 3);
        let options = |count, trunk_bytes| EncodeOptions {
            bytes: 600,
            segments: Some(Segments { count, trunk_bytes }),
            ..Default::default()
        };
        assert_eq!(
            encode(&img, &options(16, 16)),
            Err(Error::HeaderTrunk {
                header: 24,
                trunk: 16
            })
        );
        // Such a stream, however made, is refused by the decoder.
        let mut weights = [0; MAX_SEGMENTS + 1];
        weights.fill(1);
        let header = Header {
            width: 64,
            height: 48,
            gray: false,
            lossless: false,
            levels: 3,
            scale: 0,
            roi: None,
            restore_at: None,
            cfl: None,
            fec: None,
            priors: false,
            segments: Some(SegmentLayout {
                segments: Segments {
                    count: 16,
                    trunk_bytes: 16,
                },
                weights,
            }),
        };
        let mut stream = Vec::new();
        header.write(&mut stream);
        stream.resize(600, 0x5a);
        assert_eq!(
            decode(&stream),
            Err(Error::HeaderTrunk {
                header: 24,
                trunk: 16
            })
        );
        assert!(decode_with_loss(&stream, &[16..32]).is_err());
        // A header exactly one trunk long fits: trunk 0 carries only the header.
        let stream = encode(&img, &options(16, 24)).unwrap();
        assert_eq!(stream.len(), 600);
        let whole = psnr(&img, &decode(&stream).unwrap());
        let lossy = psnr(&img, &decode_with_loss(&stream, &[48..72]).unwrap());
        assert!(whole > 15.0 && lossy > 10.0, "{whole} {lossy}");
    }

    #[test]
    fn huge_budgets_are_capped_at_what_the_image_uses() {
        // -b 18446744073709551615 overflowed a capacity and -b 30000000000 aborted allocating
        // (issue 14): a budget is never allocated, the stream stops when complete.
        let img = synthetic(64, 48, 3);
        for bytes in [usize::MAX, 30_000_000_000] {
            for (lossless, segments) in [
                (false, None),
                (true, None),
                (
                    false,
                    Some(Segments {
                        count: 4,
                        trunk_bytes: 39,
                    }),
                ),
                (
                    true,
                    Some(Segments {
                        count: 16,
                        trunk_bytes: 255,
                    }),
                ),
            ] {
                let options = EncodeOptions {
                    bytes,
                    lossless,
                    segments,
                    ..Default::default()
                };
                let stream = encode(&img, &options).unwrap();
                assert!(
                    stream.len() < 64 * 48 * 3 + 17 * 255,
                    "{bytes} lossless {lossless} {segments:?}: {} bytes",
                    stream.len()
                );
                let out = decode(&stream).unwrap();
                if lossless {
                    assert_eq!(out, img, "{segments:?}");
                } else {
                    assert!(psnr(&img, &out) > 40.0, "{segments:?}");
                }
            }
        }
        // A capped segmented stream keeps what each segment needs: not shorter than any
        // complete budget, and no longer than the segments' sum plus a trunk per segment.
        let seg = Some(Segments {
            count: 2,
            trunk_bytes: 39,
        });
        let capped = encode(
            &img,
            &EncodeOptions {
                bytes: usize::MAX,
                segments: seg,
                ..Default::default()
            },
        )
        .unwrap();
        let padded = encode(
            &img,
            &EncodeOptions {
                bytes: capped.len() + 1000,
                segments: seg,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(decode(&capped).unwrap(), decode(&padded).unwrap());
        assert_eq!(
            encode(
                &img,
                &EncodeOptions {
                    bytes: 4,
                    ..Default::default()
                }
            ),
            Err(Error::Budget {
                found: 4,
                header: 6
            })
        );
    }

    #[test]
    fn prefixes_decode_and_improve() {
        let img = synthetic(64, 48, 3);
        let stream = encode(
            &img,
            &EncodeOptions {
                bytes: 2000,
                ..Default::default()
            },
        )
        .unwrap();
        let mut last = 0.0;
        for cut in [6, 20, 60, 200, 600, 2000] {
            let q = psnr(&img, &decode(&stream[..cut]).unwrap());
            assert!(q >= last - 0.05, "{cut} bytes: {q:.2} dB after {last:.2}");
            last = q;
        }
        // A prefix decodes like a stream encoded for that budget, give or take the margin.
        let direct = encode(
            &img,
            &EncodeOptions {
                bytes: 600,
                ..Default::default()
            },
        )
        .unwrap();
        let (a, b) = (
            psnr(&img, &decode(&stream[..600]).unwrap()),
            psnr(&img, &decode(&direct).unwrap()),
        );
        assert!((a - b).abs() < 0.5, "prefix {a:.2} dB, direct {b:.2} dB");
    }

    #[test]
    fn priors_are_said_in_the_header_and_every_prefix_decodes() {
        assert_eq!(priors::PRIORS.len(), coder::CONTEXTS);
        // Lossless and segmented streams start from one half, as before.
        let img = synthetic(33, 17, 3);
        let options = EncodeOptions {
            bytes: 1 << 20,
            lossless: true,
            ..Default::default()
        };
        let stream = encode(&img, &options).unwrap();
        assert_eq!(stream[0], 0xd1);
        assert_eq!(decode(&stream).unwrap(), img);
        let segmented = encode(
            &synthetic(64, 48, 3),
            &EncodeOptions {
                bytes: 1500,
                segments: Some(Segments {
                    count: 3,
                    trunk_bytes: 39,
                }),
                ..Default::default()
            },
        )
        .unwrap();
        assert!(!Header::read(&segmented).unwrap().priors);
        // A lossy stream: version 5, features byte 0x04 after the 5-byte base header.
        let img = synthetic(64, 48, 3);
        let options = EncodeOptions {
            bytes: 1500,
            ..Default::default()
        };
        let stream = encode(&img, &options).unwrap();
        assert_eq!((stream[0], stream[5]), (0xd5, 0x04));
        let header = Header::read(&stream).unwrap();
        assert!(header.priors);
        let mut last = 0.0;
        for cut in header.len()..=stream.len() {
            let q = psnr(&img, &decode(&stream[..cut]).unwrap());
            assert!(q >= last - 0.3, "{cut} bytes: {q:.2} dB after {last:.2}");
            last = q;
        }
        // Both sides start from the table: a decoder told otherwise goes wrong.
        // (The same payload behind a version 1 header.)
        let mut wrong = vec![0xd1];
        wrong.extend_from_slice(&stream[1..5]);
        wrong.extend_from_slice(&stream[6..]);
        let without = psnr(&img, &decode(&wrong).unwrap());
        assert!(
            last > without + 1.0,
            "{last:.2} dB with, {without:.2} without"
        );
        // Without priors: version 1.
        let plain = encode(
            &img,
            &EncodeOptions {
                priors: false,
                ..options
            },
        )
        .unwrap();
        assert_eq!(plain[0], 0xd1);
    }

    #[test]
    fn lossless_is_exact() {
        for (w, h, c) in [(33, 17, 3), (16, 16, 1), (1, 1, 3), (7, 1, 1)] {
            let img = synthetic(w, h, c);
            let stream = encode(
                &img,
                &EncodeOptions {
                    bytes: 1 << 20,
                    lossless: true,
                    ..Default::default()
                },
            )
            .unwrap();
            assert!(stream.len() < w * h * c + 64);
            assert_eq!(decode(&stream).unwrap(), img, "{w}x{h}x{c}");
        }
    }

    #[test]
    fn gray_scale_and_roi() {
        let img = synthetic(128, 96, 3);
        let gray = decode(
            &encode(
                &img,
                &EncodeOptions {
                    bytes: 500,
                    gray: true,
                    ..Default::default()
                },
            )
            .unwrap(),
        )
        .unwrap();
        assert_eq!(gray.channels, 1);
        let small = decode(
            &encode(
                &img,
                &EncodeOptions {
                    bytes: 500,
                    scale: 1,
                    ..Default::default()
                },
            )
            .unwrap(),
        )
        .unwrap();
        assert_eq!((small.width, small.height), (128, 96));
        let roi = Rect {
            x0: 32,
            y0: 32,
            x1: 64,
            y1: 64,
        };
        let crop = |im: &Image| {
            let mut data = Vec::new();
            for y in roi.y0..roi.y1 {
                data.extend_from_slice(
                    &im.data[(y * im.width + roi.x0) * 3..(y * im.width + roi.x1) * 3],
                );
            }
            Image {
                width: roi.x1 - roi.x0,
                height: roi.y1 - roi.y0,
                channels: 3,
                data,
            }
        };
        let plain = decode(
            &encode(
                &img,
                &EncodeOptions {
                    bytes: 400,
                    ..Default::default()
                },
            )
            .unwrap(),
        )
        .unwrap();
        let with_roi = decode(
            &encode(
                &img,
                &EncodeOptions {
                    bytes: 400,
                    roi: Some(roi),
                    roi_shift: 4,
                    ..Default::default()
                },
            )
            .unwrap(),
        )
        .unwrap();
        let (p, r) = (
            psnr(&crop(&img), &crop(&plain)),
            psnr(&crop(&img), &crop(&with_roi)),
        );
        assert!(r > p + 1.0, "ROI {r:.2} dB vs plain {p:.2} dB");
    }

    #[test]
    fn fuzz_regression_lossless_overflow() {
        // Found by fuzz/debt_decode: a lossless stream whose garbage coefficients overflowed
        // the 5/3 inverse transform.
        let data = [
            0xd1, 0x02, 0xf0, 0x1f, 0x60, 0xf2, 0x02, 0x40, 0x01, 0xeb, 0x57, 0xf7, 0x91, 0xf1,
            0xc1, 0xb4, 0xa0, 0xc0, 0x00, 0x00,
        ];
        let img = decode(&data).unwrap();
        assert_eq!((img.width, img.height), (48, 32));
    }

    #[test]
    fn decoder_survives_garbage() {
        let mut s = 1u64;
        for len in [5usize, 6, 9, 40, 120] {
            for _ in 0..5 {
                let mut data: Vec<u8> = (0..len)
                    .map(|_| {
                        s = s
                            .wrapping_mul(6364136223846793005)
                            .wrapping_add(1442695040888963407);
                        (s >> 33) as u8
                    })
                    .collect();
                // A valid first byte and a small size (at most 17 x 64), the rest garbage.
                data[0] = 0xd1;
                data[1] = 0x01;
                data[2] = 0x00;
                data[3] &= 0x3f;
                let _ = decode(&data);
            }
        }
    }
}
