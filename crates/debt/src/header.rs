//! The stream's header: what a decoder must know before the first coded bit (size, grey or
//! colour, lossy or lossless, wavelet levels, downscale, region of interest), and for a
//! segmented stream ([`Segments`]) how its trunks are shared among the segments
//! ([`SegmentLayout`]), for a restored stream where its filter starts, and for a version 4
//! stream the chroma-from-luma multipliers. 5 bytes, 8 with a region of interest; when
//! segmented 3 more and one a segment, 3 more with a filter, and 3 and the multipliers' bytes
//! more in version 4; the byte layout is in `docs/debt-format.md`.

use std::ops::Range;

use super::cfl::Multipliers;
use super::fec::Fec;
use super::{Error, Rect};

/// The bitstream version this build writes and reads: one embedded segment.
pub const VERSION: u8 = 1;
/// The same format split into trunk-interleaved segments ([`Segments`]).
pub const VERSION_SEGMENTED: u8 = 2;
/// Version 1's stream followed by a restoration filter ([`super::restore`]) at the offset the
/// header gives ([`Header::restore_at`]).
pub const VERSION_RESTORED: u8 = 3;
/// Version 1's stream with chroma predicted from luma ([`super::cfl`]): the header carries the
/// multipliers ([`Header::cfl`]) and, like version 3's, where a restoration filter starts (0:
/// none).
pub const VERSION_CHROMA: u8 = 4;
/// Version 1's stream with optional features named by a features byte ([`features`]): a
/// restoration filter, chroma predicted from luma, parity trunks. What this build writes
/// whenever a stream has one of them; versions 3 and 4 are read only.
pub const VERSION_FEATURES: u8 = 5;
/// The largest payload end a version 3 header can state.
pub const MAX_RESTORE_AT: usize = (1 << 24) - 1;
/// Most segments a stream can have.
pub const MAX_SEGMENTS: usize = 16;
/// Smallest trunk a segmented stream can be cut for.
pub const MIN_TRUNK_BYTES: usize = 16;
const MAGIC: u8 = 0xd0;

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
    pub(super) fn check(&self) -> Result<(), Error> {
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
    pub(super) fn chunks(
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
    /// For version 3 streams: the offset in the stream where the payload ends and the
    /// restoration filter starts (24 bits).
    pub restore_at: Option<usize>,
    /// For version 4 and 5 streams: the chroma-from-luma multipliers.
    pub cfl: Option<Multipliers>,
    /// For version 5 streams: the parity trunks after the stream ([`super::fec`]).
    pub fec: Option<Fec>,
    /// For version 5 streams: the coder's contexts start from [`super::priors::PRIORS`].
    pub priors: bool,
}

/// Bits of a version 5 header's features byte; each feature's fields follow in bit order.
pub mod features {
    /// A restoration filter: 3 bytes, the offset where it starts.
    pub const RESTORE: u8 = 1 << 0;
    /// Chroma from luma: the multipliers (mask, then one byte each).
    pub const CHROMA_FROM_LUMA: u8 = 1 << 1;
    /// The coder's contexts start from the trained priors table: no bytes.
    pub const PRIORS: u8 = 1 << 2;
    /// Parity trunks: 6 bytes (trunk size, protected bytes, parity trunks).
    pub const FEC: u8 = 1 << 3;
    /// Every bit this build reads.
    pub const KNOWN: u8 = RESTORE | CHROMA_FROM_LUMA | PRIORS | FEC;
}

/// ROI cells per image side in the header.
pub(super) const ROI_CELLS: usize = 32;

impl Header {
    /// Bytes the header takes: 5, or 8 with a region of interest; 2 more when segmented.
    pub fn len(&self) -> usize {
        let base = if self.roi.is_some() { 8 } else { 5 };
        if self.segments.is_some() || self.features() == 0 {
            return base + self.segments.map_or(0, |l| 3 + l.segments.count);
        }
        base + 1
            + 3 * usize::from(self.restore_at.is_some())
            + self.cfl.map_or(0, |m| m.len())
            + self.fec.map_or(0, |_| Fec::LEN)
    }

    /// The version 5 features byte this header has (0: none, the stream is version 1 or 2).
    pub fn features(&self) -> u8 {
        let bit = |on: bool, bit: u8| if on { bit } else { 0 };
        bit(self.restore_at.is_some(), features::RESTORE)
            | bit(self.cfl.is_some(), features::CHROMA_FROM_LUMA)
            | bit(self.priors, features::PRIORS)
            | bit(self.fec.is_some(), features::FEC)
    }

    /// Always false: a header is never empty (for clippy's len-without-is-empty).
    pub fn is_empty(&self) -> bool {
        false
    }

    pub(super) fn write(&self, out: &mut Vec<u8>) {
        out.push(
            MAGIC
                | if self.segments.is_some() {
                    VERSION_SEGMENTED
                } else if self.features() != 0 {
                    VERSION_FEATURES
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
        if self.segments.is_some() || self.features() == 0 {
            return;
        }
        out.push(self.features());
        if let Some(at) = self.restore_at {
            out.extend_from_slice(&(at.min(MAX_RESTORE_AT) as u32).to_be_bytes()[1..]);
        }
        if let Some(m) = self.cfl {
            m.write(out);
        }
        if let Some(fec) = self.fec {
            fec.write(out);
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
        if ![
            VERSION,
            VERSION_SEGMENTED,
            VERSION_RESTORED,
            VERSION_CHROMA,
            VERSION_FEATURES,
        ]
        .contains(&version)
        {
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
            restore_at: None,
            cfl: None,
            fec: None,
            priors: false,
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
        // Where a version 2 or 3 header's own fields start.
        let at = if header.roi.is_some() { 8 } else { 5 };
        if version == VERSION_SEGMENTED {
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
        if version == VERSION_RESTORED || version == VERSION_CHROMA {
            let restore_at = read_offset(data, at)?;
            let mut end = at + 3;
            if version == VERSION_CHROMA {
                end = header.read_multipliers(data, end, flags, "version 4 flags")?;
            }
            // Version 4 says 0 when there is no filter.
            if version == VERSION_RESTORED || restore_at != 0 {
                if restore_at < end {
                    return Err(Error::Setting {
                        field: "restoration offset",
                        expected: "at least the header's length",
                        found: restore_at as u64,
                    });
                }
                header.restore_at = Some(restore_at);
            }
        }
        if version == VERSION_FEATURES {
            header.read_features(data, at, flags)?;
        }
        Ok(header)
    }

    /// For a version 5 stream cut inside its features (or their fields): its base header (5
    /// bytes, 8 with a ROI) as a complete version 1 header, when that much arrived.
    pub(super) fn base_of_features(data: &[u8]) -> Option<Vec<u8>> {
        if data.first()? & 0x0f != VERSION_FEATURES {
            return None;
        }
        let len = if data.get(4)? & 1 != 0 { 8 } else { 5 };
        let mut base = data.get(..len)?.to_vec();
        base[0] = MAGIC | VERSION;
        Header::read(&base).ok().map(|_| base)
    }

    /// Reads the chroma-from-luma multipliers at `at` (versions 4 and 5) into `cfl`, refusing
    /// them in a grey or lossless stream (`field` names the setting in that error); returns
    /// where they end.
    fn read_multipliers(
        &mut self,
        data: &[u8],
        at: usize,
        flags: u8,
        field: &'static str,
    ) -> Result<usize, Error> {
        if self.gray || self.lossless {
            return Err(Error::Setting {
                field,
                expected: "a lossy colour stream",
                found: u64::from(flags),
            });
        }
        let (w, h) = self.coded_size();
        let m = Multipliers::read(&data[at..], at, w, h, self.levels)?;
        self.cfl = Some(m);
        Ok(at + m.len())
    }

    /// Reads a version 5 header's features byte at `at` and the fields it announces.
    fn read_features(&mut self, data: &[u8], at: usize, flags: u8) -> Result<(), Error> {
        let truncated = |expected: usize| Error::Truncated {
            expected,
            found: data.len(),
        };
        let bits = *data.get(at).ok_or(truncated(at + 1))?;
        if bits & !features::KNOWN != 0 || bits == 0 {
            return Err(Error::Setting {
                field: "version 5 features",
                expected: "a known non-empty set (bits 0 to 3)",
                found: u64::from(bits),
            });
        }
        let mut end = at + 1;
        self.priors = bits & features::PRIORS != 0;
        let mut restore_at = None;
        if bits & features::RESTORE != 0 {
            restore_at = Some(read_offset(data, end)?);
            end += 3;
        }
        if bits & features::CHROMA_FROM_LUMA != 0 {
            end = self.read_multipliers(data, end, flags, "chroma from luma with flags")?;
        }
        if bits & features::FEC != 0 {
            let fec = Fec::read(data.get(end..).unwrap_or_default(), end)?;
            end += Fec::LEN;
            if fec.data_bytes < end {
                return Err(Error::Setting {
                    field: "protected bytes",
                    expected: "at least the header's length",
                    found: fec.data_bytes as u64,
                });
            }
            self.fec = Some(fec);
        }
        if let Some(at) = restore_at {
            if at < end || self.fec.is_some_and(|f| at > f.data_bytes) {
                return Err(Error::Setting {
                    field: "restoration offset",
                    expected: "between the header's end and the protected bytes' end",
                    found: at as u64,
                });
            }
            self.restore_at = Some(at);
        }
        Ok(())
    }

    /// A segmented header must fit in trunk 0 (a lost trunk 1 would otherwise lose it).
    pub(super) fn check_trunk(&self) -> Result<(), Error> {
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

    /// The header's ROI cells of rectangle `r` of a `width` x `height` picture (first and last
    /// column cell, first and last row cell), rounded outwards: what [`Header::roi`] holds.
    pub(super) fn roi_cells(r: &Rect, width: usize, height: usize) -> [u8; 4] {
        let cell = |v: usize, side: usize| ((v * ROI_CELLS) / side).min(ROI_CELLS - 1) as u8;
        let last =
            |v: usize, side: usize| ((v * ROI_CELLS).div_ceil(side) - 1).min(ROI_CELLS - 1) as u8;
        [
            cell(r.x0, width),
            last(r.x1, width),
            cell(r.y0, height),
            last(r.y1, height),
        ]
    }

    /// The ROI in coded-image pixels.
    pub(super) fn roi_rect(&self) -> Option<(Rect, u32)> {
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

    pub(super) fn components(&self) -> usize {
        if self.gray { 1 } else { 3 }
    }
}

/// The 24-bit big-endian offset at `at` (a restoration filter's start, versions 3 to 5).
fn read_offset(data: &[u8], at: usize) -> Result<usize, Error> {
    let Some(&[a, b, c]) = data.get(at..at + 3) else {
        return Err(Error::Truncated {
            expected: at + 3,
            found: data.len(),
        });
    };
    Ok(u32::from_be_bytes([0, a, b, c]) as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

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
            restore_at: None,
            cfl: None,
            fec: None,
            priors: false,
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
        // Version 3 (read only): the base header with ROI, then the filter's offset.
        let restored = Header {
            restore_at: Some(0x01_02_03),
            ..h
        };
        let mut restored_v3 = out[..8].to_vec();
        restored_v3[0] = 0xd3;
        restored_v3.extend_from_slice(&[1, 2, 3]);
        assert_eq!(Header::read(&restored_v3).unwrap(), restored);
        assert!(matches!(
            Header::read(&restored_v3[..10]),
            Err(Error::Truncated { expected: 11, .. })
        ));
        // Written as version 5: features byte 0x01, then the offset.
        let mut restored_out = Vec::new();
        restored.write(&mut restored_out);
        assert_eq!(restored_out[0], 0xd5);
        assert_eq!(&restored_out[8..], &[0x01, 1, 2, 3]);
        assert_eq!(restored.len(), 12);
        assert_eq!(Header::read(&restored_out).unwrap(), restored);
        // Chroma from luma, a 64 x 32 image of 3 levels (9 detail subbands, 18 pairs: a 3-byte
        // mask, then two values). Version 4 (read only): 5 + 3 bytes (no filter: 0) + those.
        let mut steps = [0; crate::cfl::MAX_PAIRS];
        steps[1] = -4;
        steps[17] = 9;
        let chroma = Header {
            width: 64,
            height: 32,
            gray: false,
            lossless: false,
            levels: 3,
            scale: 0,
            roi: None,
            segments: None,
            restore_at: None,
            cfl: Some(Multipliers { pairs: 18, steps }),
            fec: None,
            priors: false,
        };
        let chroma_v4 = [
            0xd4, 0x03, 0xf0, 0x1f, 0x18, 0, 0, 0, 0x40, 0x00, 0x40, 0xfc, 0x09,
        ];
        assert_eq!(Header::read(&chroma_v4).unwrap(), chroma);
        let mut filtered_v4 = chroma_v4;
        filtered_v4[7] = 12;
        assert!(matches!(
            Header::read(&filtered_v4),
            Err(Error::Setting { .. })
        ));
        // Version 5: features 0x02, then the multipliers.
        let mut chroma_out = Vec::new();
        chroma.write(&mut chroma_out);
        assert_eq!(
            chroma_out,
            [
                0xd5, 0x03, 0xf0, 0x1f, 0x18, 0x02, 0x40, 0x00, 0x40, 0xfc, 0x09
            ]
        );
        assert_eq!(chroma.len(), chroma_out.len());
        assert_eq!(Header::read(&chroma_out).unwrap(), chroma);
        for cut in 0..chroma_out.len() {
            assert!(Header::read(&chroma_out[..cut]).is_err(), "{cut}");
        }
        // Every feature: filter at 400, multipliers, parity (39-byte trunks, 1805 protected
        // bytes, 5 parity trunks).
        let all = Header {
            restore_at: Some(400),
            fec: Some(Fec {
                trunk_bytes: 39,
                data_bytes: 1805,
                parity_trunks: 5,
            }),
            ..chroma
        };
        let mut all_out = Vec::new();
        all.write(&mut all_out);
        assert_eq!(
            all_out,
            [
                0xd5, 0x03, 0xf0, 0x1f, 0x18, 0x0b, 0x00, 0x01, 0x90, 0x40, 0x00, 0x40, 0xfc, 0x09,
                39, 0x00, 0x07, 0x0d, 0x00, 0x05
            ]
        );
        assert_eq!(all.len(), all_out.len());
        assert_eq!(Header::read(&all_out).unwrap(), all);
        for cut in 0..all_out.len() {
            assert!(Header::read(&all_out[..cut]).is_err(), "{cut}");
        }
        // A filter inside the header or past the protected bytes, an unknown or empty
        // features byte, no parity, a grey stream with multipliers: errors.
        let patches: [&[(usize, u8)]; 6] = [
            &[(7, 0), (8, 10)],
            &[(6, 0x10)],
            &[(5, 0x1b)],
            &[(5, 0)],
            &[(19, 0)],
            &[(4, 0x98)],
        ];
        for patch in patches {
            let mut bad = all_out.clone();
            for &(at, byte) in patch {
                bad[at] = byte;
            }
            assert!(
                matches!(Header::read(&bad), Err(Error::Setting { .. })),
                "{patch:?}: {:?}",
                Header::read(&bad)
            );
        }
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
}
