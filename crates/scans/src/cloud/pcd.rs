//! PCD, the Point Cloud Library's format: an ASCII header, then the points as text, as packed
//! little-endian records, or LZF-compressed field by field.

use std::fmt::Write as _;

use super::{
    CloudBuilder, Lines, Scalar, Tokens, capacity, err, shown, shown_names, text, unpack_rgb,
};
use rovlink_octo::{ParseError, Pose, Scan};

/// How a PCD file stores its points (the header's `DATA` line).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PcdData {
    /// `DATA ascii`: one point per line, values separated by spaces.
    Ascii,
    /// `DATA binary`: packed little-endian records of `SIZE` x `COUNT` bytes per field.
    Binary,
    /// `DATA binary_compressed`: sizes (`u32` compressed, `u32` uncompressed), then LZF data
    /// which decompresses to each field's values for all points, field after field.
    BinaryCompressed,
}

impl PcdData {
    fn keyword(self) -> &'static str {
        match self {
            PcdData::Ascii => "ascii",
            PcdData::Binary => "binary",
            PcdData::BinaryCompressed => "binary_compressed",
        }
    }
}

/// One `FIELDS` entry with its `SIZE`, `TYPE` and `COUNT`.
#[derive(Debug, Clone)]
struct Field {
    name: String,
    scalar: Scalar,
    count: usize,
    /// Offset in a packed (`DATA binary`) record.
    offset: usize,
}

impl Field {
    /// Bytes the field takes in one point: `SIZE` x `COUNT`.
    fn bytes(&self) -> usize {
        self.scalar.size() * self.count
    }
}

/// A header line's tokens and where it starts.
struct HeaderLine<'a> {
    offset: usize,
    values: Vec<(usize, &'a [u8])>,
}

#[derive(Debug)]
struct Header {
    fields: Vec<Field>,
    /// Bytes per point (the sum of the fields' bytes).
    point_step: usize,
    points: usize,
    points_offset: usize,
    pose: Pose,
    data: PcdData,
    /// Offset of the first byte after the `DATA` line.
    data_start: usize,
    /// Indices in `fields` of x, y, z.
    xyz: [usize; 3],
    /// Index of the colour field and whether it is `rgba`.
    color: Option<usize>,
}

/// Reads a PCD file: its points (in the sensor frame), colours from an `rgb`/`rgba` field, and
/// the `VIEWPOINT` as the pose (identity when absent). Never panics; see the
/// [module documentation](super) for what is accepted.
pub fn read_pcd(bytes: &[u8]) -> Result<Scan, ParseError> {
    let header = parse_header(bytes)?;
    let body = bytes.get(header.data_start..).unwrap_or(&[]);
    let builder = match header.data {
        PcdData::Ascii => read_ascii(&header, body, bytes.len())?,
        PcdData::Binary => {
            let need = header.points.checked_mul(header.point_step);
            if need.is_none_or(|need| need > body.len()) {
                return Err(err(
                    header.data_start,
                    format!(
                        "PCD binary data: expected {} points x {} bytes = {} bytes, found {}",
                        header.points,
                        header.point_step,
                        need.map_or("too many".to_string(), |n| n.to_string()),
                        body.len()
                    ),
                ));
            }
            let step = header.point_step;
            read_packed(&header, body, header.data_start, |field, point| {
                point * step + header.fields[field].offset
            })?
        }
        PcdData::BinaryCompressed => {
            let (data, data_offset) = decompress(&header, bytes)?;
            // Field after field, padding fields ("_") left out by PCL's writer.
            let mut starts = vec![0usize; header.fields.len()];
            let mut at = 0usize;
            for (i, f) in header.fields.iter().enumerate() {
                starts[i] = at;
                if f.name != "_" {
                    at += f.bytes() * header.points;
                }
            }
            read_packed(&header, &data, data_offset, |field, point| {
                starts[field] + point * header.fields[field].bytes()
            })?
        }
    };
    Ok(builder.finish(header.pose))
}

fn parse_header(bytes: &[u8]) -> Result<Header, ParseError> {
    let mut lines = Lines::new(bytes);
    let mut seen: Vec<(&'static str, HeaderLine)> = Vec::new();
    let data_line = loop {
        let Some((offset, line)) = lines.next() else {
            return Err(err(
                bytes.len(),
                "PCD header: expected a DATA line, found end of input",
            ));
        };
        let mut tokens = Tokens::new(line, offset);
        let Some((_, keyword)) = tokens.next() else {
            continue;
        };
        if keyword.starts_with(b"#") {
            continue;
        }
        let keyword: &'static str = match keyword {
            b"VERSION" => "VERSION",
            b"FIELDS" | b"COLUMNS" => "FIELDS",
            b"SIZE" => "SIZE",
            b"TYPE" => "TYPE",
            b"COUNT" => "COUNT",
            b"WIDTH" => "WIDTH",
            b"HEIGHT" => "HEIGHT",
            b"VIEWPOINT" => "VIEWPOINT",
            b"POINTS" => "POINTS",
            b"DATA" => "DATA",
            other => {
                return Err(err(
                    offset,
                    format!(
                        "PCD header: expected a field (VERSION, FIELDS, SIZE, TYPE, COUNT, \
                         WIDTH, HEIGHT, VIEWPOINT, POINTS, DATA) or a # comment, found {}",
                        shown(other)
                    ),
                ));
            }
        };
        if seen.iter().any(|(k, _)| *k == keyword) {
            return Err(err(
                offset,
                format!("PCD header field {keyword}: expected once, found again"),
            ));
        }
        let values = tokens.collect();
        let line = HeaderLine { offset, values };
        if keyword == "DATA" {
            break line;
        }
        seen.push((keyword, line));
    };
    let data_start = lines.position();
    let get = |k: &str| seen.iter().find(|(key, _)| *key == k).map(|(_, l)| l);

    // DATA
    let data = match data_line.values.as_slice() {
        [(_, b"ascii")] => PcdData::Ascii,
        [(_, b"binary")] => PcdData::Binary,
        [(_, b"binary_compressed")] => PcdData::BinaryCompressed,
        [(at, other)] => {
            return Err(err(
                *at,
                format!(
                    "PCD header field DATA: expected ascii, binary or binary_compressed, found {}",
                    shown(other)
                ),
            ));
        }
        values => {
            return Err(err(
                data_line.offset,
                format!(
                    "PCD header field DATA: expected 1 word (ascii, binary or \
                     binary_compressed), found {}",
                    values.len()
                ),
            ));
        }
    };

    // FIELDS, SIZE, TYPE, COUNT
    let Some(names) = get("FIELDS") else {
        return Err(err(
            data_line.offset,
            "PCD header: expected a FIELDS line before DATA, found none",
        ));
    };
    let n = names.values.len();
    if n == 0 {
        return Err(err(
            names.offset,
            "PCD header field FIELDS: expected field names, found none",
        ));
    }
    let per_field = |key: &'static str| -> Result<Option<&HeaderLine>, ParseError> {
        match get(key) {
            Some(line) if line.values.len() != n => Err(err(
                line.offset,
                format!(
                    "PCD header field {key}: expected {n} {} (one per FIELDS entry), found {}",
                    if key == "TYPE" { "letters" } else { "numbers" },
                    line.values.len()
                ),
            )),
            other => Ok(other),
        }
    };
    let sizes = per_field("SIZE")?;
    let types = per_field("TYPE")?;
    let counts = per_field("COUNT")?;
    let remaining = bytes.len().saturating_sub(data_start);
    // Every point takes at least one byte of data, or, compressed, an 88th of one; more points
    // than that cannot be read, and saying so early keeps every size below in range.
    let limit = match data {
        PcdData::BinaryCompressed => remaining.saturating_mul(LZF_MAX_RATIO),
        PcdData::Ascii | PcdData::Binary => remaining,
    }
    .max(1);
    let mut fields = Vec::with_capacity(n);
    let mut point_step = 0usize;
    for i in 0..n {
        // PCL's defaults for older headers: 4-byte floats, one value each.
        let (size_at, size) = match sizes {
            Some(line) => {
                let (at, tok) = line.values[i];
                let size = match tok {
                    b"1" => 1,
                    b"2" => 2,
                    b"4" => 4,
                    b"8" => 8,
                    _ => {
                        return Err(err(
                            at,
                            format!(
                                "PCD header field SIZE: expected 1, 2, 4 or 8, found {}",
                                shown(tok)
                            ),
                        ));
                    }
                };
                (at, size)
            }
            None => (names.values[i].0, 4),
        };
        let (type_at, kind) = match types {
            Some(line) => {
                let (at, tok) = line.values[i];
                match tok {
                    b"I" | b"U" | b"F" => (at, tok[0]),
                    _ => {
                        return Err(err(
                            at,
                            format!(
                                "PCD header field TYPE: expected I, U or F, found {}",
                                shown(tok)
                            ),
                        ));
                    }
                }
            }
            None => (size_at, b'F'),
        };
        let scalar = match (kind, size) {
            (b'I', 1) => Scalar::I8,
            (b'I', 2) => Scalar::I16,
            (b'I', 4) => Scalar::I32,
            (b'I', 8) => Scalar::I64,
            (b'U', 1) => Scalar::U8,
            (b'U', 2) => Scalar::U16,
            (b'U', 4) => Scalar::U32,
            (b'U', 8) => Scalar::U64,
            (b'F', 4) => Scalar::F32,
            (b'F', 8) => Scalar::F64,
            _ => {
                return Err(err(
                    type_at,
                    format!(
                        "PCD header field TYPE: expected SIZE 4 or 8 for F (float), found SIZE {size}"
                    ),
                ));
            }
        };
        let (count_at, count) = match counts {
            Some(line) => {
                let (at, tok) = line.values[i];
                match text(tok).and_then(|t| t.parse::<usize>().ok()) {
                    Some(c) if c >= 1 => (at, c),
                    _ => {
                        return Err(err(
                            at,
                            format!(
                                "PCD header field COUNT: expected a whole number from 1, found {}",
                                shown(tok)
                            ),
                        ));
                    }
                }
            }
            None => (type_at, 1),
        };
        let name = String::from_utf8_lossy(names.values[i].1).into_owned();
        point_step = count
            .checked_mul(size)
            .and_then(|bytes| point_step.checked_add(bytes))
            .ok_or_else(|| {
                err(
                    count_at,
                    format!(
                        "PCD header field COUNT: expected a count whose points fit in memory, \
                         found {count} (of {size} bytes)"
                    ),
                )
            })?;
        fields.push(Field {
            name,
            scalar,
            count,
            offset: point_step - count * size,
        });
    }
    let index = |name: &str| fields.iter().position(|f| f.name == name);
    let (Some(x), Some(y), Some(z)) = (index("x"), index("y"), index("z")) else {
        return Err(err(
            names.offset,
            format!(
                "PCD header field FIELDS: expected x, y and z among the fields, found {}",
                shown_names(fields.iter().map(|f| f.name.as_str()))
            ),
        ));
    };
    let color = index("rgb").or_else(|| index("rgba"));
    if let Some(c) = color
        && fields[c].scalar.size() != 4
    {
        let at = sizes.map_or(names.offset, |l| l.values[c].0);
        return Err(err(
            at,
            format!(
                "PCD header field SIZE: expected 4 for {} (packed colour), found {}",
                fields[c].name,
                fields[c].scalar.size()
            ),
        ));
    }

    // WIDTH, HEIGHT, POINTS
    let number = |key: &'static str| -> Result<Option<(usize, u64)>, ParseError> {
        let Some(line) = get(key) else {
            return Ok(None);
        };
        match line.values.as_slice() {
            [(at, tok)] => match text(tok).and_then(|t| t.parse::<u64>().ok()) {
                Some(v) => Ok(Some((line.offset, v))),
                None => Err(err(
                    *at,
                    format!(
                        "PCD header field {key}: expected a whole number, found {}",
                        shown(tok)
                    ),
                )),
            },
            values => Err(err(
                line.offset,
                format!(
                    "PCD header field {key}: expected 1 number, found {}",
                    values.len()
                ),
            )),
        }
    };
    let width = number("WIDTH")?;
    let height = number("HEIGHT")?;
    let points = number("POINTS")?;
    // PCL's rules for older headers: no WIDTH and HEIGHT means width = POINTS, height 1; no
    // HEIGHT means 1; a HEIGHT without WIDTH is an error. No POINTS: WIDTH x HEIGHT.
    let (width, height) = match (width, height) {
        (None, None) => (points.map(|p| p.1), 1),
        (Some(w), None) => (Some(w.1), 1),
        (Some(w), Some(h)) => (Some(w.1), h.1),
        (None, Some((at, _))) => {
            return Err(err(
                at,
                "PCD header field HEIGHT: expected a WIDTH line with it, found none",
            ));
        }
    };
    let Some(width) = width else {
        return Err(err(
            data_line.offset,
            "PCD header: expected POINTS or WIDTH before DATA, found neither",
        ));
    };
    let product = width.checked_mul(height);
    let (points_offset, points) = match points {
        Some((at, p)) => {
            if product != Some(p) {
                return Err(err(
                    at,
                    format!(
                        "PCD header field POINTS: expected WIDTH x HEIGHT = {width} x {height} = \
                         {}, found {p}",
                        product.map_or("too many".to_string(), |v| v.to_string())
                    ),
                ));
            }
            (at, p)
        }
        None => match product {
            Some(p) => (data_line.offset, p),
            None => {
                return Err(err(
                    data_line.offset,
                    format!("PCD header: WIDTH x HEIGHT = {width} x {height}: too many points"),
                ));
            }
        },
    };
    let points = usize::try_from(points)
        .ok()
        .filter(|&p| p <= limit || p == 0)
        .ok_or_else(|| {
            err(
                points_offset,
                format!(
                    "PCD header field POINTS: expected at most {limit} (what the data's \
                     {remaining} bytes can hold), found {points}"
                ),
            )
        })?;

    // VIEWPOINT
    let pose = match get("VIEWPOINT") {
        None => Pose::IDENTITY,
        Some(line) => {
            if line.values.len() != 7 {
                return Err(err(
                    line.offset,
                    format!(
                        "PCD header field VIEWPOINT: expected 7 numbers (tx ty tz qw qx qy qz), \
                         found {}",
                        line.values.len()
                    ),
                ));
            }
            let mut v = [0f32; 7];
            for (slot, (at, tok)) in v.iter_mut().zip(&line.values) {
                *slot = text(tok)
                    .and_then(|t| t.parse::<f32>().ok())
                    .filter(|f| f.is_finite())
                    .ok_or_else(|| {
                        err(
                            *at,
                            format!(
                                "PCD header field VIEWPOINT: expected a finite number, found {}",
                                shown(tok)
                            ),
                        )
                    })?;
            }
            Pose {
                translation_m: [v[0], v[1], v[2]],
                rotation: [v[3], v[4], v[5], v[6]],
            }
        }
    };

    Ok(Header {
        fields,
        point_step,
        points,
        points_offset,
        pose,
        data,
        data_start,
        xyz: [x, y, z],
        color,
    })
}

/// Points from packed values: `locate(field, point)` is the offset in `data` of the field's
/// first value for that point; `base` is `data`'s offset in the input (or of its compressed
/// form) for errors.
fn read_packed(
    header: &Header,
    data: &[u8],
    base: usize,
    locate: impl Fn(usize, usize) -> usize,
) -> Result<CloudBuilder, ParseError> {
    let mut builder = CloudBuilder::new(header.points, header.color.is_some());
    let short = || {
        err(
            base,
            "PCD data: a value lies outside the data (internal size check failed)",
        )
    };
    for i in 0..header.points {
        let mut p = [0f32; 3];
        for (slot, &f) in p.iter_mut().zip(&header.xyz) {
            let field = &header.fields[f];
            let at = locate(f, i);
            *slot = data
                .get(at..)
                .and_then(|b| field.scalar.read_f32(b, false))
                .ok_or_else(short)?;
        }
        let mut color = [0u8; 3];
        if let Some(c) = header.color {
            let at = locate(c, i);
            let packed = data
                .get(at..)
                .and_then(|b| header.fields[c].scalar.read_bits32(b, false))
                .ok_or_else(short)?;
            color = unpack_rgb(packed);
        }
        builder.push(p, color);
    }
    Ok(builder)
}

fn read_ascii(header: &Header, body: &[u8], end: usize) -> Result<CloudBuilder, ParseError> {
    // No overflow: each count times its size (at least 1) fits in the point step.
    let values_per_point: usize = header.fields.iter().map(|f| f.count).sum();
    // Each value takes at least two bytes ("0 ").
    let mut builder = CloudBuilder::new(
        capacity(
            header.points as u64,
            body.len(),
            values_per_point.saturating_mul(2),
        ),
        header.color.is_some(),
    );
    let mut n = 0usize;
    let mut lines = Lines::new(body);
    // PCL reads POINTS lines and ignores any after them.
    while n < header.points {
        let Some((line_at, line)) = lines.next() else {
            break;
        };
        let line_at = header.data_start + line_at;
        if line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let mut tokens = Tokens::new(line, line_at);
        let mut p = [0f32; 3];
        let mut color = [0u8; 3];
        let mut k = 0usize;
        for (f, field) in header.fields.iter().enumerate() {
            for c in 0..field.count {
                let Some((at, tok)) = tokens.next() else {
                    return Err(err(
                        line_at,
                        format!(
                            "PCD ascii point {n}: expected {values_per_point} values (one per \
                             FIELDS entry and COUNT), found {k}"
                        ),
                    ));
                };
                k += 1;
                if c != 0 {
                    continue;
                }
                if let Some(axis) = header.xyz.iter().position(|&x| x == f) {
                    p[axis] = parse_coordinate(field.scalar, tok).ok_or_else(|| {
                        err(
                            at,
                            format!(
                                "PCD ascii point {n} field {}: expected a number ({}), found {}",
                                field.name,
                                field.scalar.name(),
                                shown(tok)
                            ),
                        )
                    })?;
                } else if header.color == Some(f) {
                    let packed = parse_packed(field.scalar, tok).ok_or_else(|| {
                        err(
                            at,
                            format!(
                                "PCD ascii point {n} field {}: expected a packed colour ({}), \
                                 found {}",
                                field.name,
                                field.scalar.name(),
                                shown(tok)
                            ),
                        )
                    })?;
                    color = unpack_rgb(packed);
                }
            }
        }
        if let Some((at, _)) = tokens.next() {
            return Err(err(
                at,
                format!(
                    "PCD ascii point {n}: expected {values_per_point} values (one per FIELDS \
                     entry and COUNT), found more"
                ),
            ));
        }
        builder.push(p, color);
        n += 1;
    }
    if n < header.points {
        return Err(err(
            end,
            format!(
                "PCD ascii data: expected {} points (POINTS at offset {}), found {n}",
                header.points, header.points_offset
            ),
        ));
    }
    Ok(builder)
}

/// A coordinate written as text in a field of type `scalar`.
fn parse_coordinate(scalar: Scalar, tok: &[u8]) -> Option<f32> {
    let t = text(tok)?;
    match scalar {
        Scalar::F32 => t.parse::<f32>().ok(),
        Scalar::F64 => t.parse::<f64>().ok().map(|v| v as f32),
        Scalar::I8 => t.parse::<i8>().ok().map(f32::from),
        Scalar::I16 => t.parse::<i16>().ok().map(f32::from),
        Scalar::I32 => t.parse::<i32>().ok().map(|v| v as f32),
        Scalar::I64 => t.parse::<i64>().ok().map(|v| v as f32),
        Scalar::U8 => t.parse::<u8>().ok().map(f32::from),
        Scalar::U16 => t.parse::<u16>().ok().map(f32::from),
        Scalar::U32 => t.parse::<u32>().ok().map(|v| v as f32),
        Scalar::U64 => t.parse::<u64>().ok().map(|v| v as f32),
    }
}

/// A packed colour written as text: the float whose bits are the colour (older PCL), or the
/// integer itself (newer PCL writes `rgb` as `U` in ASCII; some writers keep `F` but print the
/// integer, which a float's bit pattern of a colour never looks like).
fn parse_packed(scalar: Scalar, tok: &[u8]) -> Option<u32> {
    let t = text(tok)?;
    match scalar {
        Scalar::F32 if t.bytes().all(|b| b.is_ascii_digit()) => t.parse::<u32>().ok(),
        Scalar::F32 => t.parse::<f32>().ok().map(f32::to_bits),
        Scalar::U32 => t.parse::<u32>().ok(),
        Scalar::I32 => t.parse::<i32>().ok().map(|v| v as u32),
        _ => None,
    }
}

/// The decompressed field-after-field data of a `binary_compressed` file, and the offset of
/// the compressed bytes (for errors).
fn decompress(header: &Header, bytes: &[u8]) -> Result<(Vec<u8>, usize), ParseError> {
    let s = header.data_start;
    let word = |at: usize, what: &str| -> Result<u32, ParseError> {
        bytes
            .get(at..at + 4)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes)
            .ok_or_else(|| {
                err(
                    at.min(bytes.len()),
                    format!(
                        "PCD binary_compressed {what}: expected 4 bytes (u32), found {}",
                        bytes.len().saturating_sub(at).min(3)
                    ),
                )
            })
    };
    let compressed = word(s, "compressed size")? as usize;
    let uncompressed = word(s + 4, "uncompressed size")? as usize;
    let start = s + 8;
    let available = bytes.len() - start;
    if compressed > available {
        return Err(err(
            s,
            format!(
                "PCD binary_compressed compressed size: expected at most the {available} bytes \
                 left, found {compressed}"
            ),
        ));
    }
    let per_point: usize = header
        .fields
        .iter()
        .filter(|f| f.name != "_")
        .map(Field::bytes)
        .sum();
    let expected = header.points.checked_mul(per_point);
    if expected != Some(uncompressed) {
        return Err(err(
            s + 4,
            format!(
                "PCD binary_compressed uncompressed size: expected {} points x {per_point} bytes \
                 = {}, found {uncompressed}",
                header.points,
                expected.map_or("too many".to_string(), |v| v.to_string())
            ),
        ));
    }
    let data = lzf_decompress(&bytes[start..start + compressed], uncompressed)
        .map_err(|(at, message)| err(start + at, format!("PCD binary_compressed {message}")))?;
    Ok((data, start))
}

/// The most one input byte of LZF can expand to: a 3-byte back reference copies 264 bytes.
const LZF_MAX_RATIO: usize = 88;

/// Decompresses LZF (liblzf's format, as PCL writes it) to exactly `out_len` bytes. Errors give
/// the offset in `input` and what was wrong. Never reads or writes out of bounds, and refuses
/// before allocating an `out_len` that `input` could not expand to.
fn lzf_decompress(input: &[u8], out_len: usize) -> Result<Vec<u8>, (usize, String)> {
    if out_len > input.len().saturating_mul(LZF_MAX_RATIO) {
        return Err((
            0,
            format!(
                "LZF data: expected at least {} bytes to expand to {out_len}, found {}",
                out_len.div_ceil(LZF_MAX_RATIO),
                input.len()
            ),
        ));
    }
    let mut out = Vec::with_capacity(out_len);
    let mut ip = 0usize;
    while ip < input.len() {
        let at = ip;
        let ctrl = usize::from(input[ip]);
        ip += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            let Some(lit) = input.get(ip..ip + len) else {
                return Err((
                    at,
                    format!(
                        "LZF literal run: expected {len} bytes, found {}",
                        input.len() - ip
                    ),
                ));
            };
            if out.len() + len > out_len {
                return Err((
                    at,
                    format!("LZF data: expands beyond the expected {out_len} bytes"),
                ));
            }
            out.extend_from_slice(lit);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                let Some(&more) = input.get(ip) else {
                    return Err((
                        at,
                        "LZF back reference: expected a length byte, found end of data".into(),
                    ));
                };
                len += usize::from(more);
                ip += 1;
            }
            len += 2;
            let Some(&low) = input.get(ip) else {
                return Err((
                    at,
                    "LZF back reference: expected an offset byte, found end of data".into(),
                ));
            };
            ip += 1;
            let distance = ((ctrl & 0x1f) << 8) + usize::from(low) + 1;
            if distance > out.len() {
                return Err((
                    at,
                    format!(
                        "LZF back reference: expected a distance within the {} bytes written, \
                         found {distance}",
                        out.len()
                    ),
                ));
            }
            if out.len() + len > out_len {
                return Err((
                    at,
                    format!("LZF data: expands beyond the expected {out_len} bytes"),
                ));
            }
            let from = out.len() - distance;
            for k in 0..len {
                let b = out[from + k];
                out.push(b);
            }
        }
    }
    if out.len() != out_len {
        return Err((
            input.len(),
            format!(
                "LZF data: expected {out_len} bytes, found {} after the last run",
                out.len()
            ),
        ));
    }
    Ok(out)
}

/// Compresses with LZF (greedy matching over a hash of 3-byte prefixes), readable by
/// [`lzf_decompress`] and liblzf.
fn lzf_compress(input: &[u8]) -> Vec<u8> {
    const HLOG: u32 = 14;
    const MAX_DISTANCE: usize = 1 << 13;
    const MAX_MATCH: usize = 264;
    fn flush(out: &mut Vec<u8>, literals: &[u8]) {
        for run in literals.chunks(32) {
            out.push((run.len() - 1) as u8);
            out.extend_from_slice(run);
        }
    }
    let mut out = Vec::with_capacity(input.len() + input.len() / 32 + 1);
    let mut table = vec![0usize; 1 << HLOG];
    let mut literal_start = 0;
    let mut i = 0;
    while i + 3 <= input.len() {
        let key = u32::from_be_bytes([0, input[i], input[i + 1], input[i + 2]]);
        let h = (key.wrapping_mul(2_654_435_761) >> (32 - HLOG)) as usize;
        let candidate = table[h];
        table[h] = i + 1;
        if candidate > 0 {
            let r = candidate - 1;
            if i - r <= MAX_DISTANCE && input[r..r + 3] == input[i..i + 3] {
                let max = MAX_MATCH.min(input.len() - i);
                let mut len = 3;
                while len < max && input[r + len] == input[i + len] {
                    len += 1;
                }
                flush(&mut out, &input[literal_start..i]);
                let offset = i - r - 1;
                let l = len - 2;
                if l < 7 {
                    out.push(((l as u8) << 5) | (offset >> 8) as u8);
                } else {
                    out.push((7 << 5) | (offset >> 8) as u8);
                    out.push((l - 7) as u8);
                }
                out.push(offset as u8);
                i += len;
                literal_start = i;
                continue;
            }
        }
        i += 1;
    }
    flush(&mut out, &input[literal_start..]);
    out
}

/// Writes `scan` as a PCD v0.7 file: fields `x y z` (4-byte floats) and, with colours, `rgb`
/// (`0x00RRGGBB`: a float's bits in binary data, an integer of `TYPE U` in ASCII, as PCL writes
/// them); `VIEWPOINT` from the pose. [`read_pcd`] reads it back exactly (non-finite points are
/// written but dropped on reading).
///
/// # Panics
///
/// If `scan.colors` is `Some` with a length other than `scan.points.len()`, or, for
/// [`PcdData::BinaryCompressed`], if the data exceeds 4 GiB (its sizes are `u32`).
pub fn write_pcd(scan: &Scan, data: PcdData) -> Vec<u8> {
    let colors = scan.colors.as_deref();
    if let Some(c) = colors {
        assert_eq!(c.len(), scan.points.len(), "one colour per point");
    }
    let n = scan.points.len();
    let rgb = colors.is_some();
    let t = scan.pose.translation_m;
    let q = scan.pose.rotation;
    let mut out = format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z{}\nSIZE 4 4 4{}\n\
         TYPE F F F{}\nCOUNT 1 1 1{}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT {} {} {} {} {} {} {}\n\
         POINTS {n}\nDATA {}\n",
        if rgb { " rgb" } else { "" },
        if rgb { " 4" } else { "" },
        match (rgb, data) {
            (false, _) => "",
            (true, PcdData::Ascii) => " U",
            (true, _) => " F",
        },
        if rgb { " 1" } else { "" },
        t[0],
        t[1],
        t[2],
        q[0],
        q[1],
        q[2],
        q[3],
        data.keyword()
    )
    .into_bytes();
    let packed = |i: usize| colors.map(|c| u32::from_be_bytes([0, c[i][0], c[i][1], c[i][2]]));
    match data {
        PcdData::Ascii => {
            for (i, p) in scan.points.iter().enumerate() {
                let mut line = format!("{} {} {}", p[0], p[1], p[2]);
                if let Some(v) = packed(i) {
                    let _ = write!(line, " {v}");
                }
                line.push('\n');
                out.extend_from_slice(line.as_bytes());
            }
        }
        PcdData::Binary => {
            for (i, p) in scan.points.iter().enumerate() {
                for c in p {
                    out.extend_from_slice(&c.to_le_bytes());
                }
                if let Some(v) = packed(i) {
                    out.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        PcdData::BinaryCompressed => {
            let mut soa = Vec::with_capacity(n * if rgb { 16 } else { 12 });
            for axis in 0..3 {
                for p in &scan.points {
                    soa.extend_from_slice(&p[axis].to_le_bytes());
                }
            }
            if rgb {
                for i in 0..n {
                    soa.extend_from_slice(&packed(i).unwrap_or(0).to_le_bytes());
                }
            }
            let compressed = lzf_compress(&soa);
            let size = |len: usize| u32::try_from(len).expect("PCD binary_compressed: over 4 GiB");
            out.extend_from_slice(&size(compressed.len()).to_le_bytes());
            out.extend_from_slice(&size(soa.len()).to_le_bytes());
            out.extend_from_slice(&compressed);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const APPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../testdata/maps/apple.pcd");

    fn scan(points: &[[f32; 3]], colors: Option<&[[u8; 3]]>, pose: Pose) -> Scan {
        Scan {
            points: points.to_vec(),
            colors: colors.map(<[_]>::to_vec),
            pose,
        }
    }

    fn pose() -> Pose {
        Pose {
            translation_m: [1.5, -2.25, 0.1],
            rotation: [0.5, 0.5, -0.5, 0.5],
        }
    }

    fn sample() -> Scan {
        scan(
            &[[0.0, 1.0, 2.0], [-1.5, 0.25, 1e-7], [3.0e5, -0.0, 7.0]],
            Some(&[[255, 0, 10], [1, 2, 3], [0, 0, 0]]),
            pose(),
        )
    }

    /// A header for hand-built data.
    fn header(fields: &str, size: &str, ty: &str, count: &str, n: usize, data: &str) -> Vec<u8> {
        format!(
            "VERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\nCOUNT {count}\nWIDTH {n}\n\
             HEIGHT 1\nVIEWPOINT 1.5 -2.25 0.1 0.5 0.5 -0.5 0.5\nPOINTS {n}\nDATA {data}\n"
        )
        .into_bytes()
    }

    fn message(r: Result<Scan, ParseError>) -> (u64, String) {
        let e = r.unwrap_err();
        (e.offset, e.message)
    }

    #[test]
    fn reads_apple_pcd() {
        let Ok(bytes) = std::fs::read(APPLE) else {
            eprintln!("skipping: {APPLE} not found");
            return;
        };
        let scan = read_pcd(&bytes).unwrap();
        assert_eq!(scan.points.len(), 3161);
        let colors = scan.colors.as_ref().unwrap();
        assert_eq!(colors.len(), 3161);
        assert!(colors.iter().all(|c| *c != [0, 0, 0]));
        assert_eq!(scan.pose, Pose::IDENTITY);
        let first: Vec<f32> = ["-0.0077637597", "0.73799998", "0.028467119"]
            .iter()
            .map(|t| t.parse().unwrap())
            .collect();
        assert_eq!(scan.points[0].to_vec(), first);
        // The first point's rgb is written as the float 4.5107335e-39: its bits are the colour.
        assert_eq!(
            colors[0],
            unpack_rgb("4.5107335e-39".parse::<f32>().unwrap().to_bits())
        );
        // The same cloud through the binary forms reads back the same.
        for data in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            assert_eq!(read_pcd(&write_pcd(&scan, data)).unwrap(), scan, "{data:?}");
        }
        let compressed = write_pcd(&scan, PcdData::BinaryCompressed);
        assert!(compressed.len() < write_pcd(&scan, PcdData::Binary).len());
    }

    #[test]
    fn round_trips_every_data_kind() {
        let s = sample();
        for data in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            assert_eq!(read_pcd(&write_pcd(&s, data)).unwrap(), s, "{data:?}");
            let plain = scan(&s.points, None, Pose::IDENTITY);
            assert_eq!(read_pcd(&write_pcd(&plain, data)).unwrap(), plain);
            let empty = scan(&[], Some(&[]), pose());
            assert_eq!(read_pcd(&write_pcd(&empty, data)).unwrap(), empty);
        }
    }

    #[test]
    fn binary_with_skipped_fields_and_types() {
        // x as F8, y as I2, z as U1, normals (F4 x 3) skipped, rgba as U4, padding.
        let mut b = header(
            "x normal y z rgba _",
            "8 4 2 1 4 1",
            "F F I U U U",
            "1 3 1 1 1 3",
            2,
            "binary",
        );
        for (x, y, z, rgba) in [
            (1.5f64, -3i16, 7u8, 0xff102030u32),
            (-2.0, 300, 0, 0x00aabbcc),
        ] {
            b.extend_from_slice(&x.to_le_bytes());
            b.extend_from_slice(&[0xee; 12]);
            b.extend_from_slice(&y.to_le_bytes());
            b.push(z);
            b.extend_from_slice(&rgba.to_le_bytes());
            b.extend_from_slice(&[0xdd; 3]);
        }
        let s = read_pcd(&b).unwrap();
        assert_eq!(s.points, vec![[1.5, -3.0, 7.0], [-2.0, 300.0, 0.0]]);
        assert_eq!(s.colors, Some(vec![[0x10, 0x20, 0x30], [0xaa, 0xbb, 0xcc]]));
        assert_eq!(s.pose, pose());
        // One byte short.
        let (at, msg) = message(read_pcd(&b[..b.len() - 1]));
        let data_start = b.len() - 2 * 30;
        assert_eq!(at, data_start as u64);
        assert!(
            msg.contains("expected 2 points x 30 bytes = 60 bytes, found 59"),
            "{msg}"
        );
    }

    #[test]
    fn organised_cloud_drops_nan_points() {
        let mut b = b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n\
                      WIDTH 2\nHEIGHT 2\nPOINTS 4\nDATA binary\n"
            .to_vec();
        for p in [
            [1.0f32, 2.0, 3.0],
            [f32::NAN, f32::NAN, f32::NAN],
            [4.0, f32::INFINITY, 5.0],
            [6.0, 7.0, 8.0],
        ] {
            for c in p {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        let s = read_pcd(&b).unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0], [6.0, 7.0, 8.0]]);
        assert_eq!(s.colors, None);
        assert_eq!(s.pose, Pose::IDENTITY);
        // ASCII nan too, with colours dropped alongside.
        let a = b"FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nWIDTH 3\nPOINTS 3\nDATA ascii\n\
                  1 2 3 16711680\nnan nan nan 255\n4 5 6 65280\n";
        let s = read_pcd(a).unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(s.colors, Some(vec![[255, 0, 0], [0, 255, 0]]));
    }

    #[test]
    fn binary_compressed_hand_built() {
        // Two points x y z rgb, field after field, compressed by hand with literal runs and a
        // back reference.
        let mut soa = Vec::new();
        for v in [1.0f32, 1.0, 2.0, 2.0, 3.0, 3.0] {
            soa.extend_from_slice(&v.to_le_bytes());
        }
        soa.extend_from_slice(&0x00112233u32.to_le_bytes());
        soa.extend_from_slice(&0x00445566u32.to_le_bytes());
        // Literal 4 bytes (x0), then a back reference of 4 bytes at distance 4 (x1).
        let mut lzf = vec![3];
        lzf.extend_from_slice(&soa[..4]);
        lzf.push(2 << 5); // length 2 + 2 = 4, distance high bits 0
        lzf.push(3); // distance 3 + 1 = 4
        let rest = &soa[8..];
        lzf.push((rest.len() - 1) as u8);
        lzf.extend_from_slice(rest);
        assert_eq!(lzf_decompress(&lzf, soa.len()).unwrap(), soa);
        let mut b = header(
            "x y z rgb",
            "4 4 4 4",
            "F F F F",
            "1 1 1 1",
            2,
            "binary_compressed",
        );
        let data_start = b.len();
        b.extend_from_slice(&(lzf.len() as u32).to_le_bytes());
        b.extend_from_slice(&(soa.len() as u32).to_le_bytes());
        b.extend_from_slice(&lzf);
        let s = read_pcd(&b).unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0], [1.0, 2.0, 3.0]]);
        assert_eq!(s.colors, Some(vec![[0x11, 0x22, 0x33], [0x44, 0x55, 0x66]]));
        // A wrong uncompressed size is reported at its field.
        let mut bad = b.clone();
        bad[data_start + 4] += 1;
        let (at, msg) = message(read_pcd(&bad));
        assert_eq!(at, data_start as u64 + 4);
        assert!(
            msg.contains("expected 2 points x 16 bytes = 32, found 33"),
            "{msg}"
        );
        // A compressed size past the end.
        let mut bad = b.clone();
        bad[data_start] = 200;
        let (at, msg) = message(read_pcd(&bad));
        assert_eq!(at, data_start as u64);
        assert!(msg.contains("found 200"), "{msg}");
        // A back reference before the start of the output.
        let mut bad = b.clone();
        bad[data_start + 8 + 6] = 9;
        let (at, msg) = message(read_pcd(&bad));
        assert_eq!(at, data_start as u64 + 8 + 5);
        assert!(
            msg.contains("distance within the 4 bytes written, found 10"),
            "{msg}"
        );
        // Truncated in the last literal run.
        let (at, msg) = message(read_pcd(&b[..b.len() - 1]));
        assert_eq!(at, data_start as u64);
        assert!(msg.contains("compressed size"), "{msg}");
    }

    #[test]
    fn lzf_round_trips_and_rejects() {
        let mut data: Vec<u8> = (0..5000u32).map(|i| (i * 7 % 13) as u8).collect();
        data.extend(std::iter::repeat_n(9u8, 1000));
        data.extend((0..3000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8));
        let c = lzf_compress(&data);
        assert!(c.len() < data.len());
        assert_eq!(lzf_decompress(&c, data.len()).unwrap(), data);
        assert_eq!(
            lzf_decompress(&lzf_compress(&[]), 0).unwrap(),
            Vec::<u8>::new()
        );
        assert_eq!(lzf_decompress(&lzf_compress(b"ab"), 2).unwrap(), b"ab");
        // Asking for more than the input can expand to errors before allocating.
        let (at, msg) = lzf_decompress(&[0, 1], usize::MAX).unwrap_err();
        assert_eq!(at, 0);
        assert!(msg.contains("expected at least"), "{msg}");
        // A back reference with no length byte; expanding past the expected size.
        assert_eq!(lzf_decompress(&[0, 1, 0xe0], 10).unwrap_err().0, 2);
        assert_eq!(lzf_decompress(&[1, 1, 2], 1).unwrap_err().0, 0);
        assert_eq!(lzf_decompress(&[0, 1, 0x20, 0], 3).unwrap_err().0, 2);
        assert_eq!(lzf_decompress(&[0, 1], 2).unwrap_err().0, 2);
    }

    #[test]
    fn header_errors_name_field_and_offset() {
        let cases: &[(&[u8], u64, &str)] = &[
            (
                b"FIELDS x y z\nSIZE 4 4\nDATA ascii\n",
                13,
                "PCD header field SIZE: expected 3 numbers (one per FIELDS entry), found 2",
            ),
            (
                b"FIELDS x y z\nTYPE F F\nDATA ascii\n",
                13,
                "PCD header field TYPE: expected 3 letters (one per FIELDS entry), found 2",
            ),
            (
                b"FIELDS x y z\nSIZE 4 4 3\nDATA ascii\n",
                22,
                "PCD header field SIZE: expected 1, 2, 4 or 8, found \"3\"",
            ),
            (
                b"FIELDS x y z\nSIZE 4 4 2\nTYPE F F F\nDATA ascii\n",
                33,
                "expected SIZE 4 or 8 for F (float), found SIZE 2",
            ),
            (
                b"FIELDS x y z\nCOUNT 1 0 1\nDATA ascii\n",
                21,
                "PCD header field COUNT: expected a whole number",
            ),
            (
                b"FIELDS x y w\nPOINTS 0\nDATA ascii\n",
                0,
                "expected x, y and z among the fields, found \"x y w\"",
            ),
            (
                b"FIELDS x y z\nWIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n",
                30,
                "PCD header field POINTS: expected WIDTH x HEIGHT = 2 x 2 = 4, found 3",
            ),
            (
                b"FIELDS x y z\nWIDTH 4294967296\nHEIGHT 4294967296\nPOINTS 1\nDATA ascii\n",
                48,
                "= too many, found 1",
            ),
            (
                b"FIELDS x y z\nPOINTS 4000000000\nDATA binary\n",
                13,
                "expected at most 1 (what the data's 0 bytes can hold), found 4000000000",
            ),
            (
                b"FIELDS x y z\nVIEWPOINT 0 0 0 1 0 0\nPOINTS 0\nDATA ascii\n",
                13,
                "PCD header field VIEWPOINT: expected 7 numbers (tx ty tz qw qx qy qz), found 6",
            ),
            (
                b"FIELDS x y z\nVIEWPOINT 0 0 nan 1 0 0 0\nPOINTS 0\nDATA ascii\n",
                27,
                "expected a finite number, found \"nan\"",
            ),
            (
                b"FIELDS x y z\nPOINTS 0\nDATA text\n",
                27,
                "expected ascii, binary or binary_compressed, found \"text\"",
            ),
            (
                b"FIELDS x y z\nPOINTS 0\n",
                22,
                "expected a DATA line, found end of input",
            ),
            (
                b"FIELDS x y z\nFIELDS x y z\n",
                13,
                "FIELDS: expected once, found again",
            ),
            (b"POINTS 0\nDATA ascii\n", 9, "expected a FIELDS line"),
            (
                b"FIELDS x y z\nHEIGHT 1\nDATA ascii\n",
                13,
                "HEIGHT: expected a WIDTH line",
            ),
            (
                b"FIELDS x y z\nDATA ascii\n",
                13,
                "expected POINTS or WIDTH",
            ),
            (b"FIELDS x y z\nBOGUS 1\n", 13, "found \"BOGUS\""),
            (
                b"FIELDS x y z rgb\nSIZE 4 4 4 2\nTYPE F F F U\nPOINTS 0\nDATA ascii\n",
                28,
                "expected 4 for rgb (packed colour), found 2",
            ),
            (
                b"FIELDS x y z\nPOINTS -1\nDATA ascii\n",
                20,
                "expected a whole number",
            ),
        ];
        for (input, offset, want) in cases {
            let (at, msg) = message(read_pcd(input));
            assert!(msg.contains(want), "{msg:?} lacks {want:?}");
            assert_eq!(at, *offset, "{msg}");
        }
    }

    #[test]
    fn ascii_errors_name_point_and_offset() {
        let h = b"FIELDS x y z n\nCOUNT 1 1 1 2\nPOINTS 2\nDATA ascii\n";
        let at = h.len() as u64;
        let mut b = h.to_vec();
        b.extend_from_slice(b"1 2 3 4\n");
        let (o, msg) = message(read_pcd(&b));
        assert_eq!(o, at);
        assert!(
            msg.contains("PCD ascii point 0: expected 5 values"),
            "{msg}"
        );
        let mut b = h.to_vec();
        b.extend_from_slice(b"1 2 3 4 5\n1 y 3 4 5\n");
        let (o, msg) = message(read_pcd(&b));
        assert_eq!(o, at + 12);
        assert!(
            msg.contains("point 1 field y: expected a number (float32), found \"y\""),
            "{msg}"
        );
        let mut b = h.to_vec();
        b.extend_from_slice(b"1 2 3 4 5 6\n");
        let (o, msg) = message(read_pcd(&b));
        assert_eq!(o, at + 10);
        assert!(msg.contains("found more"), "{msg}");
        let mut b = h.to_vec();
        b.extend_from_slice(b"1 2 3 4 5\n\n");
        let (o, msg) = message(read_pcd(&b));
        assert_eq!(o, b.len() as u64);
        assert!(
            msg.contains("expected 2 points (POINTS at offset 29), found 1"),
            "{msg}"
        );
        // Unused fields are not parsed; lines after POINTS points are ignored, as PCL does.
        let mut b = h.to_vec();
        b.extend_from_slice(b"1 2 3 a b\n\n4 5 6 c d\n7 8 9\n");
        assert_eq!(
            read_pcd(&b).unwrap().points,
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
        );
    }

    #[test]
    fn older_headers_use_pcl_defaults() {
        // v0.5: COLUMNS, no SIZE/TYPE/COUNT (4-byte floats), no WIDTH/HEIGHT/VIEWPOINT.
        let mut b = b"# .PCD v.5\nCOLUMNS x y z\nPOINTS 1\nDATA binary\n".to_vec();
        for v in [1.0f32, 2.0, 3.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let s = read_pcd(&b).unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(s.pose, Pose::IDENTITY);
        // CRLF line ends and a comment; no POINTS: WIDTH x HEIGHT.
        let b = b"# c\r\nVERSION .7\r\nFIELDS x y z\r\nWIDTH 1\r\nHEIGHT 1\r\nDATA ascii\r\n\
                  1 2 3\r\n";
        assert_eq!(read_pcd(b).unwrap().points, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn empty_clouds_with_wide_fields() {
        // No points: any COUNT is fine (a proptest once found this rejected), but one that
        // overflows the point size is not.
        for data in ["ascii", "binary", "binary_compressed"] {
            let mut b = header("n x y z", "4 4 4 4", "F F F F", "3 1 1 1", 0, data);
            if data == "binary_compressed" {
                b.extend_from_slice(&[0; 8]);
            }
            let s = read_pcd(&b).unwrap();
            assert_eq!(s.points, Vec::<[f32; 3]>::new());
            assert_eq!(s.pose, pose());
        }
        let b = header(
            "n x y z",
            "8 4 4 4",
            "F F F F",
            "4611686018427387904 1 1 1",
            0,
            "binary",
        );
        let (at, msg) = message(read_pcd(&b));
        assert_eq!(at, 59); // the COUNT token
        assert!(
            msg.contains("COUNT: expected a count whose points fit"),
            "{msg}"
        );
    }

    #[test]
    fn ascii_packed_colour_forms() {
        assert_eq!(parse_packed(Scalar::F32, b"16711680"), Some(0x00ff0000));
        assert_eq!(
            parse_packed(Scalar::F32, b"4.5107335e-39"),
            Some("4.5107335e-39".parse::<f32>().unwrap().to_bits())
        );
        assert_eq!(parse_packed(Scalar::U32, b"255"), Some(255));
        assert_eq!(parse_packed(Scalar::I32, b"-1"), Some(u32::MAX));
        assert_eq!(parse_packed(Scalar::U32, b"x"), None);
    }

    #[test]
    fn every_prefix_of_valid_files_is_handled() {
        let s = sample();
        for data in [PcdData::Ascii, PcdData::Binary, PcdData::BinaryCompressed] {
            let b = write_pcd(&s, data);
            for cut in 0..b.len() {
                // Must not panic; ascii prefixes that end inside the last number may even parse.
                let _ = read_pcd(&b[..cut]);
            }
        }
    }
}
