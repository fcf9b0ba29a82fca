//! Point-cloud readers: PCD, PLY, XYZ text and MCAP (ROS 2 `PointCloud2`), into [`Scan`]s.
//!
//! Every reader is a pure function over `&[u8]`. [`read`] dispatches on a [`CloudFormat`],
//! which [`CloudFormat::from_path`] takes from a file name and [`CloudFormat::sniff`] from the
//! first bytes.
//!
//! # Formats
//!
//! - **PCD** ([`read_pcd`]), the Point Cloud Library's format, v0.7 headers and the older ones
//!   PCL still reads (`COLUMNS` for `FIELDS`; `SIZE`, `TYPE`, `COUNT`, `WIDTH`, `HEIGHT`,
//!   `VIEWPOINT` and `POINTS` optional with PCL's defaults). `DATA ascii`, `DATA binary` and
//!   `DATA binary_compressed` (LZF, decompressed here with bounds checks). Fields `x y z` of any
//!   `TYPE`/`SIZE` (I/U 1, 2, 4, 8 bytes; F 4, 8), colour from `rgb` (a 4-byte field whose bit
//!   pattern is `0x00RRGGBB`: a float in binary files and PCL's older ASCII files, an integer in
//!   newer ASCII files) or `rgba` (`0xAARRGGBB`, alpha dropped); every other field is skipped by
//!   `SIZE` x `COUNT`. `VIEWPOINT tx ty tz qw qx qy qz` becomes the scan's pose.
//! - **PLY** ([`read_ply`]): `ascii 1.0`, `binary_little_endian 1.0`, `binary_big_endian 1.0`;
//!   element `vertex` with scalar `x y z` of any PLY type (both the `float`/`uchar` and the
//!   `float32`/`uint8` names) and optional colour `red green blue` (or `diffuse_red ...`, or
//!   `r g b`); other vertex properties, list ones included, are skipped. Elements before
//!   `vertex` are skipped, elements after it (faces) are not read. The pose is the identity.
//! - **XYZ** ([`read_xyz`]): text, one point per line, `x y z` or `x y z r g b`, separated by
//!   spaces, tabs or commas; `#` starts a comment; blank lines and one leading header line of
//!   names (`x,y,z`) are skipped. Colours are integers 0..255, or, when the file writes them as
//!   fractions all within 0..1, scaled by 255. The pose is the identity.
//! - **MCAP** ([`read_mcap`]): ROS 2 recordings. Every `sensor_msgs/msg/PointCloud2` message
//!   (CDR) on the chosen topic becomes a scan whose pose is the latest
//!   `geometry_msgs/msg/PoseStamped` logged at or before it. Chunks may be uncompressed, zstd or
//!   lz4 (the records are walked by [`crate::bag`]). [`write_clouds_mcap`] writes such
//!   files.
//!
//! In every format, points with a coordinate that is not finite once converted to `f32` (the
//! NaN holes of organised clouds, infinities, doubles beyond `f32`'s range) are dropped with
//! their colours, so every accepted scan has finite points and, when it has colours, exactly one
//! colour per point.
//!
//! # The no-panic contract
//!
//! The readers never panic, on any input: every failure is a [`ParseError`] whose `offset` is
//! the byte offset, from the start of the input, where the input stopped making sense, and whose
//! message names the field and says what was expected and what was found
//! (`offset 212: PCD header field SIZE: expected 4 numbers (one per FIELDS entry), found 3`).
//! XYZ errors also give the line number. Allocations are bounded by the input: a header that
//! claims more points than the remaining bytes can hold is an error before anything is
//! allocated for them. The readers are fuzzed (`fuzz/fuzz_targets/octo_cloud.rs`) and
//! property-tested (`tests/proptest_octo_cloud.rs`).
//!
//! The writers ([`write_pcd`], [`write_ply`] / [`write_ply_as`], [`write_xyz`], [`write_clouds_mcap`]) produce
//! files the readers read back to the same points and colours (and, for PCD and MCAP, pose).

use std::fmt;
use std::path::Path;

use rovlink_octo::{ParseError, Pose, Scan};

mod mcap;
mod pcd;
mod ply;
mod xyz;

pub use self::mcap::{
    DEFAULT_CLOUD_TOPIC, DEFAULT_POSE_TOPIC, McapOptions, McapScans, POINT_CLOUD2_SCHEMA,
    POSE_STAMPED_SCHEMA, read_mcap, write_clouds_mcap,
};
pub use self::pcd::{PcdData, read_pcd, write_pcd};
pub use self::ply::{PlyFormat, read_ply, write_ply, write_ply_as};
pub use self::xyz::{read_xyz, write_xyz};

/// A point-cloud file format that [`read`] understands: the one place the point-cloud formats
/// are named, with their command-line names ([`CloudFormat::name`]), file extensions
/// ([`CloudFormat::extensions`]), sniffing ([`CloudFormat::sniff`]) and readers ([`read`]).
/// `pipeline::InputFormat` wraps these (beside `.graph` and rosbag2) and octo-delta's
/// `--format` parses, lists and names them from [`CloudFormat::ALL`].
///
/// A new point-cloud format touches three files: its reader (`src/octo/cloud/<format>.rs`, a
/// `read_<format>(&[u8]) -> Result<Scan, ParseError>` declared and re-exported below), this
/// file (a variant, in [`CloudFormat::ALL`], and its arms in `name`, `extensions`, `sniff`
/// when its first bytes can tell, and [`read`]), and its tests (`tests/proptest_octo_cloud.rs`
/// or the reader's own). The README's octo-delta section and `--help`'s prose list of input
/// kinds are documentation to update with it; no code elsewhere names the formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CloudFormat {
    /// Point Cloud Library `.pcd`.
    Pcd,
    /// Polygon File Format `.ply` (vertices only).
    Ply,
    /// Text, one `x y z [r g b]` point per line (`.xyz`, `.txt`, `.csv`).
    Xyz,
    /// MCAP recording with ROS 2 `PointCloud2` (and `PoseStamped`) messages.
    Mcap,
}

impl CloudFormat {
    /// Every format, in the order messages and `--help` list them.
    pub const ALL: [CloudFormat; 4] = [
        CloudFormat::Pcd,
        CloudFormat::Ply,
        CloudFormat::Xyz,
        CloudFormat::Mcap,
    ];

    /// The file-name extensions of the format, lower case, the usual one first.
    pub fn extensions(self) -> &'static [&'static str] {
        match self {
            CloudFormat::Pcd => &["pcd"],
            CloudFormat::Ply => &["ply"],
            CloudFormat::Xyz => &["xyz", "txt", "csv"],
            CloudFormat::Mcap => &["mcap"],
        }
    }

    /// The format a file name's extension names (case-insensitive): one of
    /// [`CloudFormat::extensions`] (`.pcd`, `.ply`, `.xyz`, `.txt`, `.csv`, `.mcap`); `None` for
    /// any other extension or none.
    pub fn from_path(path: &Path) -> Option<CloudFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        CloudFormat::ALL
            .into_iter()
            .find(|f| f.extensions().contains(&ext.as_str()))
    }

    /// The format the first bytes look like: MCAP's magic, PLY's `ply` line, a PCD header
    /// keyword (or PCL's `# .PCD` comment) on the first non-comment line, or a first data line of
    /// 3 or 6 numbers (XYZ). `None` when nothing fits. Only looks at the first few kilobytes.
    pub fn sniff(bytes: &[u8]) -> Option<CloudFormat> {
        if bytes.starts_with(::mcap::MAGIC) {
            return Some(CloudFormat::Mcap);
        }
        if bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n") {
            return Some(CloudFormat::Ply);
        }
        let head = &bytes[..bytes.len().min(4096)];
        if head.starts_with(b"# .PCD") {
            return Some(CloudFormat::Pcd);
        }
        let mut first_xyz_line = true;
        for (_, line) in Lines::new(head) {
            let text = String::from_utf8_lossy(line);
            let text = text.trim();
            if text.is_empty() || text.starts_with('#') {
                continue;
            }
            let keyword = text.split_ascii_whitespace().next().unwrap_or("");
            if matches!(keyword, "VERSION" | "FIELDS" | "COLUMNS") {
                return Some(CloudFormat::Pcd);
            }
            let values = text
                .split(|c: char| c == ',' || c.is_ascii_whitespace())
                .filter(|t| !t.is_empty())
                .collect::<Vec<_>>();
            let numeric = values.iter().filter(|t| t.parse::<f64>().is_ok()).count();
            if numeric == values.len() && matches!(values.len(), 3 | 6) {
                return Some(CloudFormat::Xyz);
            }
            // One header line of column names may precede XYZ data.
            if numeric == 0 && first_xyz_line {
                first_xyz_line = false;
                continue;
            }
            return None;
        }
        None
    }

    /// The format's short name: `pcd`, `ply`, `xyz`, `mcap`.
    pub fn name(self) -> &'static str {
        match self {
            CloudFormat::Pcd => "pcd",
            CloudFormat::Ply => "ply",
            CloudFormat::Xyz => "xyz",
            CloudFormat::Mcap => "mcap",
        }
    }
}

impl fmt::Display for CloudFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The format `bytes` look like: [`CloudFormat::sniff`].
pub fn sniff(bytes: &[u8]) -> Option<CloudFormat> {
    CloudFormat::sniff(bytes)
}

/// Reads `bytes` as `format`: one scan for PCD, PLY and XYZ, one per `PointCloud2` message for
/// MCAP (chosen and posed as `options` say; [`read_mcap`] also returns the topics, log times and
/// notes). Never panics; see the [module documentation](self) for what each format accepts.
pub fn read(
    format: CloudFormat,
    bytes: &[u8],
    options: &McapOptions,
) -> Result<Vec<Scan>, ParseError> {
    match format {
        CloudFormat::Pcd => read_pcd(bytes).map(|scan| vec![scan]),
        CloudFormat::Ply => read_ply(bytes).map(|scan| vec![scan]),
        CloudFormat::Xyz => read_xyz(bytes).map(|scan| vec![scan]),
        CloudFormat::Mcap => read_mcap(bytes, options).map(|read| read.scans),
    }
}

// ---- shared by the readers ----------------------------------------------------------------

/// An error at byte `offset`.
pub(crate) fn err(offset: usize, message: impl Into<String>) -> ParseError {
    ParseError::new(offset as u64, message)
}

/// `text` quoted for an error message, cut to a readable length.
pub(crate) fn shown(text: &[u8]) -> String {
    const MAX: usize = 40;
    let cut = &text[..text.len().min(MAX)];
    let mut s = format!("{:?}", String::from_utf8_lossy(cut));
    if text.len() > MAX {
        s.push_str("...");
    }
    s
}

/// Field or property names, space-separated, as [`shown`] shows text (for "expected x, y and z,
/// found ..." messages).
pub(crate) fn shown_names<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    shown(names.into_iter().collect::<Vec<_>>().join(" ").as_bytes())
}

/// How many items to reserve room for: what the input claims, but no more than the remaining
/// bytes could hold at `min_bytes` each (so a lying header cannot make us allocate).
fn capacity(claimed: u64, remaining: usize, min_bytes: usize) -> usize {
    let fit = remaining / min_bytes.max(1);
    usize::try_from(claimed).map_or(fit, |c| c.min(fit))
}

/// A numeric type as the binary formats store it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    /// Bytes per value.
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// A name for error messages.
    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "int8",
            Scalar::U8 => "uint8",
            Scalar::I16 => "int16",
            Scalar::U16 => "uint16",
            Scalar::I32 => "int32",
            Scalar::U32 => "uint32",
            Scalar::I64 => "int64",
            Scalar::U64 => "uint64",
            Scalar::F32 => "float32",
            Scalar::F64 => "float64",
        }
    }

    /// The value at the start of `bytes`, `None` when `bytes` is shorter than [`Self::size`].
    fn read(self, bytes: &[u8], big_endian: bool) -> Option<f64> {
        fn get<const N: usize>(bytes: &[u8], big_endian: bool) -> Option<[u8; N]> {
            let mut a: [u8; N] = bytes.get(..N)?.try_into().ok()?;
            if big_endian {
                a.reverse();
            }
            Some(a)
        }
        let be = big_endian;
        Some(match self {
            Scalar::I8 => f64::from(i8::from_le_bytes(get(bytes, be)?)),
            Scalar::U8 => f64::from(*bytes.first()?),
            Scalar::I16 => f64::from(i16::from_le_bytes(get(bytes, be)?)),
            Scalar::U16 => f64::from(u16::from_le_bytes(get(bytes, be)?)),
            Scalar::I32 => f64::from(i32::from_le_bytes(get(bytes, be)?)),
            Scalar::U32 => f64::from(u32::from_le_bytes(get(bytes, be)?)),
            Scalar::I64 => i64::from_le_bytes(get(bytes, be)?) as f64,
            Scalar::U64 => u64::from_le_bytes(get(bytes, be)?) as f64,
            Scalar::F32 => f64::from(f32::from_le_bytes(get(bytes, be)?)),
            Scalar::F64 => f64::from_le_bytes(get(bytes, be)?),
        })
    }

    /// A coordinate at the start of `bytes` as `f32`: floats exactly (`f64` rounded), integers
    /// converted.
    pub(crate) fn read_f32(self, bytes: &[u8], big_endian: bool) -> Option<f32> {
        match self {
            // Read f32 directly: going through f64 and back is exact too, but this is clearer.
            Scalar::F32 => {
                let mut a: [u8; 4] = bytes.get(..4)?.try_into().ok()?;
                if big_endian {
                    a.reverse();
                }
                Some(f32::from_le_bytes(a))
            }
            _ => self.read(bytes, big_endian).map(|v| v as f32),
        }
    }

    /// The 32-bit pattern at the start of `bytes` (a packed colour); `None` unless the type is
    /// 4 bytes wide.
    pub(crate) fn read_bits32(self, bytes: &[u8], big_endian: bool) -> Option<u32> {
        if self.size() != 4 {
            return None;
        }
        let a: [u8; 4] = bytes.get(..4)?.try_into().ok()?;
        Some(if big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }
}

/// `0x??RRGGBB` to (r, g, b).
pub(crate) fn unpack_rgb(packed: u32) -> [u8; 3] {
    let [_, r, g, b] = packed.to_be_bytes();
    [r, g, b]
}

/// Collects points and colours, dropping points that are not finite.
#[derive(Debug)]
pub struct CloudBuilder {
    points: Vec<[f32; 3]>,
    colors: Option<Vec<[u8; 3]>>,
    /// Points dropped because a coordinate was not finite.
    pub dropped: usize,
}

impl CloudBuilder {
    pub(crate) fn new(capacity: usize, with_colors: bool) -> Self {
        CloudBuilder {
            points: Vec::with_capacity(capacity),
            colors: with_colors.then(|| Vec::with_capacity(capacity)),
            dropped: 0,
        }
    }

    /// Adds a point (and its colour, when the cloud has colours) unless it is not finite.
    pub(crate) fn push(&mut self, point: [f32; 3], color: [u8; 3]) {
        if !point.iter().all(|c| c.is_finite()) {
            self.dropped += 1;
            return;
        }
        self.points.push(point);
        if let Some(colors) = &mut self.colors {
            colors.push(color);
        }
    }

    /// How many points the builder has room for (a cloud's width x height, dropped points
    /// included): what it holds in memory.
    pub(crate) fn reserved(&self) -> usize {
        self.points.capacity()
    }

    /// The scan of the points kept, with `pose`.
    pub fn finish(self, pose: Pose) -> Scan {
        Scan {
            points: self.points,
            colors: self.colors,
            pose,
        }
    }
}

/// Lines of `bytes` with their byte offsets; the `\n` (and a `\r` before it) removed.
struct Lines<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Lines<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Lines { bytes, pos: 0 }
    }

    /// Offset of the first byte after the lines returned so far.
    fn position(&self) -> usize {
        self.pos
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a [u8]);

    fn next(&mut self) -> Option<Self::Item> {
        let rest = self.bytes.get(self.pos..).filter(|r| !r.is_empty())?;
        let start = self.pos;
        let (line, used) = match rest.iter().position(|&b| b == b'\n') {
            Some(n) => (&rest[..n], n + 1),
            None => (rest, rest.len()),
        };
        self.pos += used;
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        Some((start, line))
    }
}

/// Whitespace-separated tokens of `bytes` with their offsets (plus `base`).
#[derive(Clone)]
struct Tokens<'a> {
    bytes: &'a [u8],
    pos: usize,
    base: usize,
}

impl<'a> Tokens<'a> {
    fn new(bytes: &'a [u8], base: usize) -> Self {
        Tokens {
            bytes,
            pos: 0,
            base,
        }
    }

    /// Offset (plus `base`) of the end of the bytes.
    fn end(&self) -> usize {
        self.base + self.bytes.len()
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = (usize, &'a [u8]);

    fn next(&mut self) -> Option<Self::Item> {
        let rest = self.bytes.get(self.pos..)?;
        let skip = rest.iter().position(|b| !b.is_ascii_whitespace())?;
        let start = self.pos + skip;
        let len = self.bytes[start..]
            .iter()
            .position(|b| b.is_ascii_whitespace())
            .unwrap_or(self.bytes.len() - start);
        self.pos = start + len;
        Some((self.base + start, &self.bytes[start..start + len]))
    }
}

/// A token as text, `None` unless it is UTF-8.
fn text(token: &[u8]) -> Option<&str> {
    std::str::from_utf8(token).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_path_by_extension() {
        let f = |p: &str| CloudFormat::from_path(Path::new(p));
        assert_eq!(f("a/apple.pcd"), Some(CloudFormat::Pcd));
        assert_eq!(f("B.PLY"), Some(CloudFormat::Ply));
        assert_eq!(f("x.xyz"), Some(CloudFormat::Xyz));
        assert_eq!(f("x.txt"), Some(CloudFormat::Xyz));
        assert_eq!(f("x.csv"), Some(CloudFormat::Xyz));
        assert_eq!(f("run.mcap"), Some(CloudFormat::Mcap));
        assert_eq!(f("run.bag"), None);
        assert_eq!(f("noext"), None);
    }

    #[test]
    fn sniff_each_format() {
        assert_eq!(
            CloudFormat::sniff(&write_clouds_mcap(&[])),
            Some(CloudFormat::Mcap)
        );
        let scan = Scan {
            points: vec![[1.0, 2.0, 3.0]],
            colors: None,
            pose: Pose::IDENTITY,
        };
        for format in [
            PlyFormat::Ascii,
            PlyFormat::BinaryLittleEndian,
            PlyFormat::BinaryBigEndian,
        ] {
            assert_eq!(
                CloudFormat::sniff(&write_ply_as(&scan, format)),
                Some(CloudFormat::Ply)
            );
        }
        for data in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            assert_eq!(
                CloudFormat::sniff(&write_pcd(&scan, data)),
                Some(CloudFormat::Pcd)
            );
        }
        assert_eq!(
            CloudFormat::sniff(b"VERSION .7\nFIELDS x y z\n"),
            Some(CloudFormat::Pcd)
        );
        assert_eq!(
            CloudFormat::sniff(&write_xyz(&scan)),
            Some(CloudFormat::Xyz)
        );
        assert_eq!(
            CloudFormat::sniff(b"# c\nx,y,z,r,g,b\n1,2,3,4,5,6\n"),
            Some(CloudFormat::Xyz)
        );
        assert_eq!(CloudFormat::sniff(b"hello world\n"), None);
        assert_eq!(CloudFormat::sniff(b"1 2\n"), None);
        assert_eq!(CloudFormat::sniff(b""), None);
        assert_eq!(CloudFormat::sniff(&[0xff; 10]), None);
    }

    #[test]
    fn read_dispatches() {
        let scan = Scan {
            points: vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
            colors: Some(vec![[1, 2, 3], [4, 5, 6]]),
            pose: Pose::IDENTITY,
        };
        let opts = McapOptions::default();
        let files = [
            (CloudFormat::Pcd, write_pcd(&scan, PcdData::Binary)),
            (CloudFormat::Ply, write_ply(&scan)),
            (CloudFormat::Xyz, write_xyz(&scan)),
            (
                CloudFormat::Mcap,
                write_clouds_mcap(std::slice::from_ref(&scan)),
            ),
        ];
        for (format, bytes) in files {
            assert_eq!(CloudFormat::sniff(&bytes), Some(format));
            assert_eq!(
                read(format, &bytes, &opts).unwrap(),
                vec![scan.clone()],
                "{format}"
            );
        }
    }

    #[test]
    fn scalar_reads_both_orders() {
        assert_eq!(Scalar::I16.read(&[0xff, 0xfe], false), Some(-257.0));
        assert_eq!(Scalar::I16.read(&[0xfe, 0xff], true), Some(-257.0));
        assert_eq!(Scalar::F64.read(&1.5f64.to_be_bytes(), true), Some(1.5));
        assert_eq!(Scalar::U32.read(&[1, 2, 3], false), None);
        assert_eq!(Scalar::F32.read_f32(&2.5f32.to_be_bytes(), true), Some(2.5));
        assert_eq!(
            Scalar::U32.read_bits32(&[1, 2, 3, 4], true),
            Some(0x0102_0304)
        );
        assert_eq!(Scalar::U16.read_bits32(&[1, 2, 3, 4], true), None);
    }

    #[test]
    fn lines_and_tokens_carry_offsets() {
        let lines: Vec<_> = Lines::new(b"a b\r\n\nc").collect();
        assert_eq!(lines, vec![(0, &b"a b"[..]), (5, &b""[..]), (6, &b"c"[..])]);
        let tokens: Vec<_> = Tokens::new(b"  ab\tc \n d", 10).collect();
        assert_eq!(
            tokens,
            vec![(12, &b"ab"[..]), (15, &b"c"[..]), (19, &b"d"[..])]
        );
    }

    #[test]
    fn capacity_is_bounded_by_input() {
        assert_eq!(capacity(u64::MAX, 100, 12), 8);
        assert_eq!(capacity(3, 100, 12), 3);
        assert_eq!(capacity(3, 100, 0), 3);
    }
}
