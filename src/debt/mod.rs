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
//! Around the codec: [`picture`] reads and writes picture files, [`metrics`] measures quality,
//! [`trial`] runs the compression trials of `debt-encode --sweep`.
//!
//! No-panic contract: [`decode`] returns an [`Error`] for a stream that is not DEBT and decodes
//! any other bytes, truncated or corrupt, to some image without panicking.

pub mod coder;
pub mod metrics;
pub mod picture;
pub mod rangecoder;
pub mod resilient;
pub mod trial;
pub mod wavelet;

use coder::{Band, BitCoder, Decoder, Encoder};
use std::borrow::Cow;
use std::ops::Range;
use wavelet::Orientation;

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
    #[error("not a DEBT stream: first byte 0x{found:02x}, expected 0xd1 or 0xd2 (DEBT)")]
    NotDebt {
        /// The byte found.
        found: u8,
    },
    /// A DEBT stream of a version this build does not know.
    #[error(
        "DEBT version {found} is not supported (this build reads {VERSION} and {VERSION_SEGMENTED})"
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

/// The bitstream version this build writes and reads: one embedded segment.
pub const VERSION: u8 = 1;
/// The same format split into trunk-interleaved segments ([`Segments`]).
pub const VERSION_SEGMENTED: u8 = 2;
/// Most segments a stream can have.
pub const MAX_SEGMENTS: usize = 16;
/// Smallest trunk a segmented stream can be cut for.
pub const MIN_TRUNK_BYTES: usize = 16;
const MAGIC: u8 = 0xd0;
/// The largest width or height.
pub const MAX_SIDE: usize = 4096;
/// Longer than any stream of a [`MAX_SIDE`]-square picture, even lossless: what a reader of
/// streams may refuse beyond.
pub const MAX_STREAM_BYTES: u64 = 256 << 20;
/// Bits of fraction kept below the weighted coefficient's unit (finest quantiser step 1/4).
const FRACTION_BITS: u32 = 2;
/// Where in its uncertainty interval a partly known coefficient is put back (0.5 = middle;
/// a little below suits the peaked distribution of wavelet coefficients).
const RECONSTRUCTION_OFFSET: f32 = 0.4;
/// Squared-error weight of Y, Cb, Cr errors in RGB (columns of the inverse ICT, averaged).
const COMPONENT_MSE_WEIGHTS: [f32; 3] = [1.0, 1.086, 0.825];

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
}

/// A segmented stream: `count` stripes of rows, each an embedded stream of its own, their bytes
/// interleaved so that trunk `k` (bytes `k*trunk_bytes..(k+1)*trunk_bytes` of the stream, the
/// header included in trunk 0) carries only segment `k % count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Segments {
    /// Number of segments, 2..=16.
    pub count: usize,
    /// Trunk size in bytes, 16..=255.
    pub trunk_bytes: usize,
}

impl Segments {
    fn check(&self) -> Result<(), Error> {
        if !(2..=MAX_SEGMENTS).contains(&self.count) {
            return Err(Error::Setting {
                field: "segments",
                expected: "2..=16",
                found: self.count as u64,
            });
        }
        if !(MIN_TRUNK_BYTES..=255).contains(&self.trunk_bytes) {
            return Err(Error::Setting {
                field: "segment trunk size",
                expected: "16..=255 bytes",
                found: self.trunk_bytes as u64,
            });
        }
        Ok(())
    }
}

/// A segmented stream's layout as its header states it: the segments and each one's share of
/// the trunks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentLayout {
    /// Count and trunk size.
    pub segments: Segments,
    /// Relative share of the trunks of each segment (1..=255; entries past `count` are 0).
    pub weights: [u8; MAX_SEGMENTS + 1],
}

impl SegmentLayout {
    /// The chunks of a stream of `total_bytes` whose header takes `header_bytes`: each chunk's
    /// byte range in the stream and the segment it carries, in stream order. Trunk `k` is
    /// chunk `k` (less the header in trunk 0); trunks go to segments by smooth weighted round
    /// robin: each trunk, every segment gains its weight in credit, the segment with the most
    /// credit (the first on ties) takes the trunk and pays the total weight. Lazy, so that an
    /// encoder can stop early; a range is never inverted (a trunk inside the header is empty).
    fn chunks(
        &self,
        header_bytes: usize,
        total_bytes: usize,
    ) -> impl Iterator<Item = (Range<usize>, usize)> + use<> {
        let trunk = self.segments.trunk_bytes.max(1);
        let count = self.segments.count;
        let weights = self.weights;
        let total_weight: i64 = weights[..=count].iter().map(|&w| i64::from(w)).sum();
        let mut credit = [0i64; MAX_SEGMENTS + 1];
        (0..total_bytes.div_ceil(trunk)).map(move |k| {
            let mut best = 0;
            for (i, &w) in weights[..=count].iter().enumerate() {
                credit[i] += i64::from(w);
                // Trunk 0, with the header, always carries the base.
                if k > 0 && credit[i] > credit[best] {
                    best = i;
                }
            }
            credit[best] -= total_weight;
            let start = k.saturating_mul(trunk);
            let end = start.saturating_add(trunk).min(total_bytes);
            (start.max(header_bytes).min(end)..end, best)
        })
    }
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
        }
    }
}

/// What the header says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// Width of the image the decoder produces.
    pub width: usize,
    /// Height of the image the decoder produces.
    pub height: usize,
    /// One component (grey) or three.
    pub gray: bool,
    /// Reversible coding.
    pub lossless: bool,
    /// Wavelet levels.
    pub levels: u32,
    /// Downscale exponent.
    pub scale: u32,
    /// ROI as 1/32 cells: first and last column cell, first and last row cell; and its shift.
    pub roi: Option<([u8; 4], u32)>,
    /// Segmenting, for version 2 streams.
    pub segments: Option<SegmentLayout>,
}

/// ROI cells per image side in the header.
const ROI_CELLS: usize = 32;

impl Header {
    /// Bytes the header takes: 5, or 8 with a region of interest; 2 more when segmented.
    pub fn len(&self) -> usize {
        let base = if self.roi.is_some() { 8 } else { 5 };
        base + self.segments.map_or(0, |l| 3 + l.segments.count)
    }

    /// Always false: a header is never empty (for clippy's len-without-is-empty).
    pub fn is_empty(&self) -> bool {
        false
    }

    fn write(&self, out: &mut Vec<u8>) {
        out.push(
            MAGIC
                | if self.segments.is_some() {
                    VERSION_SEGMENTED
                } else {
                    VERSION
                },
        );
        let size = ((self.width as u32 - 1) << 12) | (self.height as u32 - 1);
        out.extend_from_slice(&size.to_be_bytes()[1..]);
        out.push(
            u8::from(self.gray) << 7
                | u8::from(self.lossless) << 6
                | (self.levels as u8) << 3
                | (self.scale as u8) << 1
                | u8::from(self.roi.is_some()),
        );
        if let Some((c, shift)) = self.roi {
            let bits = (shift << 20)
                | (u32::from(c[0]) << 15)
                | (u32::from(c[1]) << 10)
                | (u32::from(c[2]) << 5)
                | u32::from(c[3]);
            out.extend_from_slice(&bits.to_be_bytes()[1..]);
        }
        if let Some(layout) = self.segments {
            out.push((layout.segments.count - 1) as u8);
            out.push(layout.segments.trunk_bytes as u8);
            out.extend_from_slice(&layout.weights[..=layout.segments.count]);
        }
    }

    /// Reads a header from the start of a stream.
    pub fn read(data: &[u8]) -> Result<Header, Error> {
        let first = *data.first().ok_or(Error::Truncated {
            expected: 5,
            found: 0,
        })?;
        if first & 0xf0 != MAGIC {
            return Err(Error::NotDebt { found: first });
        }
        let version = first & 0x0f;
        if version != VERSION && version != VERSION_SEGMENTED {
            return Err(Error::Version {
                found: first & 0x0f,
            });
        }
        if data.len() < 5 {
            return Err(Error::Truncated {
                expected: 5,
                found: data.len(),
            });
        }
        let size = u32::from_be_bytes([0, data[1], data[2], data[3]]);
        let flags = data[4];
        let mut header = Header {
            width: (size >> 12) as usize + 1,
            height: (size & 0xfff) as usize + 1,
            gray: flags & 0x80 != 0,
            lossless: flags & 0x40 != 0,
            levels: u32::from((flags >> 3) & 0x07),
            scale: u32::from((flags >> 1) & 0x03),
            roi: None,
            segments: None,
        };
        if flags & 1 != 0 {
            if data.len() < 8 {
                return Err(Error::Truncated {
                    expected: 8,
                    found: data.len(),
                });
            }
            let bits = u32::from_be_bytes([0, data[5], data[6], data[7]]);
            let cell = |shift: u32| ((bits >> shift) & 0x1f) as u8;
            let cells = [cell(15), cell(10), cell(5), cell(0)];
            let shift = bits >> 20;
            if cells[1] < cells[0] || cells[3] < cells[2] || shift == 0 {
                return Err(Error::Setting {
                    field: "ROI",
                    expected: "first cell <= last cell, shift 1..=15",
                    found: u64::from(bits),
                });
            }
            header.roi = Some(([cells[0], cells[1], cells[2], cells[3]], shift));
        }
        if version == VERSION_SEGMENTED {
            let at = if header.roi.is_some() { 8 } else { 5 };
            let Some(&[count, trunk]) = data.get(at..at + 2) else {
                return Err(Error::Truncated {
                    expected: at + 2,
                    found: data.len(),
                });
            };
            let segments = Segments {
                count: usize::from(count) + 1,
                trunk_bytes: usize::from(trunk),
            };
            segments.check()?;
            let at = at + 2;
            let Some(read) = data.get(at..=at + segments.count) else {
                return Err(Error::Truncated {
                    expected: at + segments.count + 1,
                    found: data.len(),
                });
            };
            if let Some(&zero) = read.iter().find(|&&w| w == 0) {
                return Err(Error::Setting {
                    field: "segment weight",
                    expected: "1..=255",
                    found: zero.into(),
                });
            }
            let mut weights = [0; MAX_SEGMENTS + 1];
            weights[..=segments.count].copy_from_slice(read);
            header.segments = Some(SegmentLayout { segments, weights });
            header.check_trunk()?;
        }
        Ok(header)
    }

    /// A segmented header must fit in trunk 0 (a lost trunk 1 would otherwise lose it).
    fn check_trunk(&self) -> Result<(), Error> {
        match self.segments {
            Some(layout) if self.len() > layout.segments.trunk_bytes => Err(Error::HeaderTrunk {
                header: self.len(),
                trunk: layout.segments.trunk_bytes,
            }),
            _ => Ok(()),
        }
    }

    /// Size of the coded (downscaled) image.
    pub fn coded_size(&self) -> (usize, usize) {
        (
            self.width.div_ceil(1 << self.scale),
            self.height.div_ceil(1 << self.scale),
        )
    }

    /// The ROI in coded-image pixels.
    fn roi_rect(&self) -> Option<(Rect, u32)> {
        let (cw, ch) = self.coded_size();
        self.roi.map(|(c, shift)| {
            let edge = |cell: usize, side: usize| cell * side / ROI_CELLS;
            (
                Rect {
                    x0: edge(c[0].into(), cw),
                    x1: edge(usize::from(c[1]) + 1, cw).max(edge(c[0].into(), cw) + 1),
                    y0: edge(c[2].into(), ch),
                    y1: edge(usize::from(c[3]) + 1, ch).max(edge(c[2].into(), ch) + 1),
                },
                shift,
            )
        })
    }

    fn components(&self) -> usize {
        if self.gray { 1 } else { 3 }
    }
}

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

fn orientation_code(o: Orientation) -> u8 {
    match o {
        Orientation::Ll => 0,
        Orientation::Hl => 1,
        Orientation::Lh => 2,
        Orientation::Hh => 3,
    }
}

fn class_of(o: Orientation) -> usize {
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
fn in_roi(roi: &Rect, level: u32, x: usize, y: usize) -> bool {
    let x0 = roi.x0 >> level;
    let y0 = roi.y0 >> level;
    let x1 = roi.x1.div_ceil(1 << level);
    let y1 = roi.y1.div_ceil(1 << level);
    x >= x0 && x < x1 && y >= y0 && y < y1
}

/// Per-subband weights (one per subband in coding order).
fn subband_weights(header: &Header, bands: &[wavelet::Subband]) -> Vec<f32> {
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

/// Box-filter downscale by 2^scale (scale 0: the image itself, not a copy).
fn downscale(img: &Image, scale: u32) -> Cow<'_, Image> {
    if scale == 0 {
        return Cow::Borrowed(img);
    }
    let f = 1usize << scale;
    let (w, h) = (img.width.div_ceil(f), img.height.div_ceil(f));
    let c = img.channels;
    let mut data = vec![0u8; w * h * c];
    for y in 0..h {
        for x in 0..w {
            for ch in 0..c {
                let (mut sum, mut n) = (0u32, 0u32);
                for yy in y * f..((y + 1) * f).min(img.height) {
                    for xx in x * f..((x + 1) * f).min(img.width) {
                        sum += u32::from(img.data[(yy * img.width + xx) * c + ch]);
                        n += 1;
                    }
                }
                data[(y * w + x) * c + ch] = ((sum + n / 2) / n) as u8;
            }
        }
    }
    Cow::Owned(Image {
        width: w,
        height: h,
        channels: c,
        data,
    })
}

/// Bilinear upscale to `width` x `height` (an image of that size is returned as it is).
fn upscale(img: Image, width: usize, height: usize) -> Image {
    if img.width == width && img.height == height {
        return img;
    }
    let c = img.channels;
    let (sx, sy) = (
        img.width as f32 / width as f32,
        img.height as f32 / height as f32,
    );
    let mut data = vec![0u8; width * height * c];
    for y in 0..height {
        let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (img.height - 1) as f32);
        let (y0, ty) = (fy.floor() as usize, fy - fy.floor());
        let y1 = (y0 + 1).min(img.height - 1);
        for x in 0..width {
            let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (img.width - 1) as f32);
            let (x0, tx) = (fx.floor() as usize, fx - fx.floor());
            let x1 = (x0 + 1).min(img.width - 1);
            for ch in 0..c {
                let p = |xx: usize, yy: usize| f32::from(img.data[(yy * img.width + xx) * c + ch]);
                let top = p(x0, y0) * (1.0 - tx) + p(x1, y0) * tx;
                let bottom = p(x0, y1) * (1.0 - tx) + p(x1, y1) * tx;
                data[(y * width + x) * c + ch] =
                    (top * (1.0 - ty) + bottom * ty).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Image {
        width,
        height,
        channels: c,
        data,
    }
}

/// Component planes of an image, as `f32` (lossy: level-shifted YCbCr) or exact integers held
/// in `f32` (lossless: RCT).
fn to_components(img: &Image, gray: bool, lossless: bool) -> Vec<Vec<f32>> {
    let n = img.width * img.height;
    let px = |i: usize| -> (f32, f32, f32) {
        if img.channels == 1 {
            let v = f32::from(img.data[i]);
            (v, v, v)
        } else {
            let p = &img.data[i * 3..i * 3 + 3];
            (f32::from(p[0]), f32::from(p[1]), f32::from(p[2]))
        }
    };
    if gray {
        let y = (0..n)
            .map(|i| {
                let (r, g, b) = px(i);
                if img.channels == 1 {
                    r - 128.0
                } else if lossless {
                    ((r + 2.0 * g + b) / 4.0).floor() - 128.0
                } else {
                    0.299 * r + 0.587 * g + 0.114 * b - 128.0
                }
            })
            .collect();
        return vec![y];
    }
    // One pass over the pixels per plane, as chunks collected (exact length, no bounds checks
    // or capacity checks in the loop).
    let plane = |f: fn(f32, f32, f32) -> f32| -> Vec<f32> {
        if img.channels == 1 {
            img.data[..n]
                .iter()
                .map(|&v| f(f32::from(v), f32::from(v), f32::from(v)))
                .collect()
        } else {
            img.data[..n * 3]
                .chunks_exact(3)
                .map(|p| f(f32::from(p[0]), f32::from(p[1]), f32::from(p[2])))
                .collect()
        }
    };
    if lossless {
        vec![
            plane(|r, g, b| ((r + 2.0 * g + b) / 4.0).floor() - 128.0),
            plane(|_, g, b| b - g),
            plane(|r, g, _| r - g),
        ]
    } else {
        vec![
            plane(|r, g, b| 0.299 * r + 0.587 * g + 0.114 * b - 128.0),
            plane(|r, g, b| -0.168_736 * r - 0.331_264 * g + 0.5 * b),
            plane(|r, g, b| 0.5 * r - 0.418_688 * g - 0.081_312 * b),
        ]
    }
}

/// YCbCr -> RGB (JPEG's, full range): row `c` holds the weights of Y, Cb and Cr in channel `c`.
const YCBCR_TO_RGB: [[f32; 3]; 3] = [
    [1.0, 0.0, 1.402],
    [1.0, -0.344_136, -0.714_136],
    [1.0, 1.772, 0.0],
];

/// A sample from a reconstructed value: clamped first, so adding one half and truncating
/// rounds to nearest.
fn to_sample(v: f32) -> u8 {
    (v.clamp(0.0, 255.0) + 0.5) as u8
}

fn from_components(planes: &[Vec<f32>], width: usize, height: usize, lossless: bool) -> Image {
    let n = width * height;
    if planes.len() == 1 {
        let data = planes[0].iter().map(|&y| to_sample(y + 128.0)).collect();
        return Image {
            width,
            height,
            channels: 1,
            data,
        };
    }
    // Appended into the exact capacity (never zeroed, never regrown); iterating the planes
    // together lets the compiler drop the bounds checks.
    let mut data = Vec::with_capacity(n * 3);
    let pixels = planes[0][..n]
        .iter()
        .zip(&planes[1][..n])
        .zip(&planes[2][..n]);
    for ((&y, &cb), &cr) in pixels {
        let y = y + 128.0;
        let (r, g, b) = if lossless {
            let g = y - ((cb + cr) / 4.0).floor();
            (cr + g, g, cb + g)
        } else {
            let [r, g, b] = YCBCR_TO_RGB;
            (y + r[2] * cr, y + g[1] * cb + g[2] * cr, y + b[1] * cb)
        };
        data.extend_from_slice(&[to_sample(r), to_sample(g), to_sample(b)]);
    }
    Image {
        width,
        height,
        channels: 3,
        data,
    }
}

/// Scratch buffers of the wavelet transforms, kept from one plane to the next so that each is
/// allocated (and its pages touched) once per thread rather than once per plane.
#[derive(Default)]
struct Scratch {
    /// The 9/7 transform's (or the 5/3's) working rows and columns.
    floats: Vec<f32>,
    /// A lossless plane as integers.
    ints: Vec<i32>,
    /// The 5/3 transform's working rows and columns.
    int_lines: Vec<i32>,
}

/// Runs the forward (or inverse) transform of the header's kind on one component plane.
fn transform(
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
fn transform_planes(
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
type Placement = (usize, wavelet::Subband, f32, usize);

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
fn build_bands(
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

/// Encodes an image within `options.bytes` bytes.
pub fn encode(img: &Image, options: &EncodeOptions) -> Result<Vec<u8>, Error> {
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
            let cell = |v: usize, side: usize| ((v * ROI_CELLS) / side).min(ROI_CELLS - 1) as u8;
            let last = |v: usize, side: usize| {
                ((v * ROI_CELLS).div_ceil(side) - 1).min(ROI_CELLS - 1) as u8
            };
            Some((
                [
                    cell(r.x0, img.width),
                    last(r.x1, img.width),
                    cell(r.y0, img.height),
                    last(r.y1, img.height),
                ],
                options.roi_shift,
            ))
        }
    };
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
    transform_planes(&mut planes, w, h, &header, true);
    let Some(layout) = header.segments else {
        let budget = options.bytes - out.len();
        let (bands, _) = build_bands(&header, Some(&planes), 0, 1);
        out.extend_from_slice(&encode_bands(bands, budget).0);
        return Ok(out);
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
        let (payload, complete, marks) = encode_bands(bands, budget);
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
    Ok(out)
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

/// Codes a band list in at most `budget` bytes: the bytes (exactly `budget` unless complete),
/// whether every plane was coded, and where each pass ended ([`Encoder::marks`]).
fn encode_bands(mut bands: Vec<Band>, budget: usize) -> (Vec<u8>, bool, Vec<(usize, u64)>) {
    let max = bands.iter().map(Band::max_magnitude).max().unwrap_or(0);
    let plane_count = 32 - max.leading_zeros();
    let mut enc = Encoder::new(budget);
    let complete = enc.raw(plane_count, 5).is_ok()
        && coder::code_planes(&mut bands, plane_count, &mut enc).is_ok();
    let marks = std::mem::take(&mut enc.marks);
    let mut payload = enc.finish(complete);
    if complete {
        payload.truncate(budget);
    } else {
        payload.resize(budget, 0);
    }
    (payload, complete, marks)
}

/// Decodes a stream (or any prefix of one).
pub fn decode(data: &[u8]) -> Result<Image, Error> {
    decode_with_loss(data, &[])
}

/// Decodes a stream of which the byte ranges `lost` never arrived (their contents are ignored).
/// A single-segment stream decodes up to its first lost byte; a segmented one loses, in each
/// segment, the chunks from its first lost one on. The header must have arrived.
pub fn decode_with_loss(data: &[u8], lost: &[Range<usize>]) -> Result<Image, Error> {
    let header = Header::read(data)?;
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
            let end = data.len().min(first_lost);
            decode_part(
                &header,
                &data[header_bytes.min(end)..end],
                0,
                1,
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
                decode_part(&header, payload, part, count, &mut coefficients);
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
        synthesise_channels(&coefficients, w, h, &header)
    };
    Ok(upscale(img, header.width, header.height))
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

/// Writes channel `c` of the `N`-channel picture `data` from a synthesised plane: samples
/// rounded and clamped a run at a time (vectorised), then stored at their stride.
fn put_channel<const N: usize>(data: &mut [u8], plane: &[f32], c: usize) {
    const RUN: usize = 256;
    let (pixels, _) = data.as_chunks_mut::<N>();
    let mut run = [0u8; RUN];
    for (pixels, values) in pixels.chunks_mut(RUN).zip(plane.chunks(RUN)) {
        for (q, &v) in run.iter_mut().zip(values) {
            *q = to_sample(v + 128.0);
        }
        for (pixel, &q) in pixels.iter_mut().zip(&run) {
            pixel[c] = q;
        }
    }
}

/// The lossy picture from its coefficients, one output channel at a time through one plane.
///
/// The 9/7 synthesis and YCbCr -> RGB are both linear, so each RGB channel is the synthesis of
/// its own mix of the component coefficients (only the significant ones, a few thousand at
/// narrow-link budgets), rounded and clamped once at the end. One plane and the picture are
/// all the memory the decoder touches: a third of the page faults of three component planes
/// and a separate colour conversion. Floating point differs from converting after synthesis
/// in the last bits only (a sample may round the other way).
fn synthesise_channels(
    coefficients: &[Vec<(u32, f32)>],
    width: usize,
    height: usize,
    header: &Header,
) -> Image {
    const GREY: [[f32; 3]; 1] = [[1.0, 0.0, 0.0]];
    let mix: &[[f32; 3]] = match coefficients.len() {
        1 => &GREY,
        _ => &YCBCR_TO_RGB,
    };
    let channels = mix.len();
    let n = width * height;
    // Written once per channel below; a fresh page's first access is a write (one fault).
    let mut data = vec![0u8; n * channels];
    let mut plane: Vec<f32> = Vec::new();
    let mut scratch = Vec::new();
    for (c, weights) in mix.iter().enumerate() {
        plane.clear();
        plane.resize(n, 0.0);
        for (coefs, &weight) in coefficients.iter().zip(weights) {
            if weight != 0.0 {
                for &(i, v) in coefs {
                    plane[i as usize] += weight * v;
                }
            }
        }
        // The synthesis hands over each row as its last step: quantised straight into the
        // picture, never written back into the plane.
        let put_row = |r: usize, row: &[f32]| {
            let pixels = &mut data[r * width * channels..(r + 1) * width * channels];
            match channels {
                1 => put_channel::<1>(pixels, row, c),
                _ => put_channel::<3>(pixels, row, c),
            }
        };
        wavelet::inverse_97_rows(
            &mut plane,
            width,
            height,
            header.levels,
            &mut scratch,
            put_row,
        );
    }
    Image {
        width,
        height,
        channels,
        data,
    }
}

/// The magnitude a significant coefficient is rebuilt at from its known bits `mag`, `known`
/// low bits being unknown: the middle of the last interval when every plane is known (exactly
/// `mag` when lossless), else `RECONSTRUCTION_OFFSET` of the way into it.
fn reconstructed(mag: u32, known: u8, lossless: bool) -> f32 {
    if known == 0 {
        mag as f32 + if lossless { 0.0 } else { 0.5 }
    } else {
        mag as f32 + RECONSTRUCTION_OFFSET * (1u64 << known) as f32
    }
}

/// Decodes segment `part` of `parts` from its bytes and appends its significant coefficients
/// to `coefficients` (per component: index in the plane, value).
fn decode_part(
    header: &Header,
    payload: &[u8],
    part: usize,
    parts: usize,
    coefficients: &mut [Vec<(u32, f32)>],
) {
    let (w, _) = header.coded_size();
    let (mut bands, layout) = build_bands(header, None, part, parts);
    let mut dec = Decoder::new(payload);
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
    use super::metrics::psnr;
    use super::*;

    #[test]
    fn channels_synthesised_from_mixed_coefficients_match_converting_after_synthesis() {
        for (channels, bytes) in [(3, 300), (3, 3000), (3, 30000), (1, 3000)] {
            let img = synthetic(97, 61, channels);
            let options = EncodeOptions {
                bytes,
                ..EncodeOptions::default()
            };
            let stream = encode(&img, &options).unwrap();
            let header = Header::read(&stream).unwrap();
            let (w, h) = header.coded_size();
            let mut coefficients = vec![Vec::new(); header.components()];
            decode_part(&header, &stream[header.len()..], 0, 1, &mut coefficients);
            let mut planes: Vec<Vec<f32>> =
                coefficients.iter().map(|c| scattered(c, w * h)).collect();
            transform_planes(&mut planes, w, h, &header, false);
            let after = from_components(&planes, w, h, false);
            let mixed = synthesise_channels(&coefficients, w, h, &header);
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

    /// A smooth synthetic colour image with some edges and texture.
    fn synthetic(width: usize, height: usize, channels: usize) -> Image {
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
    fn header_round_trip() {
        let h = Header {
            width: 640,
            height: 360,
            gray: false,
            lossless: true,
            levels: 5,
            scale: 2,
            roi: Some(([1, 30, 2, 29], 7)),
            segments: None,
        };
        let mut out = Vec::new();
        h.write(&mut out);
        assert_eq!(out.len(), 8);
        assert_eq!(Header::read(&out).unwrap(), h);
        let mut weights = [0; MAX_SEGMENTS + 1];
        weights[..4].copy_from_slice(&[9, 255, 1, 40]);
        let segmented = Header {
            segments: Some(SegmentLayout {
                segments: Segments {
                    count: 3,
                    trunk_bytes: 39,
                },
                weights,
            }),
            ..h
        };
        let mut out = Vec::new();
        segmented.write(&mut out);
        assert_eq!(out[0], 0xd2);
        assert_eq!(&out[8..], &[2, 39, 9, 255, 1, 40]);
        assert_eq!(segmented.len(), out.len());
        assert_eq!(Header::read(&out).unwrap(), segmented);
        // A zero weight, a segment count or trunk out of range, a cut header: errors.
        let mut bad = out.clone();
        bad[12] = 0;
        assert!(matches!(Header::read(&bad), Err(Error::Setting { .. })));
        bad = out.clone();
        bad[9] = 15;
        assert!(matches!(Header::read(&bad), Err(Error::Setting { .. })));
        bad = out.clone();
        bad[8] = 0;
        assert!(matches!(Header::read(&bad), Err(Error::Setting { .. })));
        assert_eq!(
            Header::read(&out[..12]),
            Err(Error::Truncated {
                expected: 14,
                found: 12
            })
        );
        assert_eq!(
            Header::read(&[0x55, 0, 0, 0, 0]),
            Err(Error::NotDebt { found: 0x55 })
        );
        assert_eq!(
            Header::read(&[0xd7, 0, 0, 0, 0]),
            Err(Error::Version { found: 7 })
        );
        assert_eq!(
            Header::read(&[0xd1, 0]),
            Err(Error::Truncated {
                expected: 5,
                found: 2
            })
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
                header: 5
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
        for cut in [5, 20, 60, 200, 600, 2000] {
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
