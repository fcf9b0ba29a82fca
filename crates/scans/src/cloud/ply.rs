//! PLY (Polygon File Format): an ASCII header of elements and their properties, then the
//! elements' rows as text or binary. Only the `vertex` element is read.

use std::fmt::Write as _;

use super::{CloudBuilder, Lines, Scalar, Tokens, capacity, err, shown, shown_names, text};
use rovlink_octo::{ParseError, Pose, Scan};

/// How a PLY file stores its rows (the header's `format` line).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlyFormat {
    /// `format ascii 1.0`: one row per line, values separated by spaces.
    Ascii,
    /// `format binary_little_endian 1.0`.
    BinaryLittleEndian,
    /// `format binary_big_endian 1.0`.
    BinaryBigEndian,
}

impl PlyFormat {
    fn keyword(self) -> &'static str {
        match self {
            PlyFormat::Ascii => "ascii",
            PlyFormat::BinaryLittleEndian => "binary_little_endian",
            PlyFormat::BinaryBigEndian => "binary_big_endian",
        }
    }
}

#[derive(Debug, Clone)]
enum Kind {
    Scalar(Scalar),
    /// A list: a count of the first type, then that many values of the second.
    List(Scalar, Scalar),
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: u64,
    offset: usize,
    properties: Vec<Property>,
}

impl Element {
    /// Bytes per row in binary, when no property is a list.
    fn fixed_size(&self) -> Option<usize> {
        self.properties
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => Some(s.size()),
                Kind::List(..) => None,
            })
            .sum()
    }

    /// The fewest bytes a row can take (binary), at least 1.
    fn min_size(&self) -> usize {
        self.properties
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) | Kind::List(s, _) => s.size(),
            })
            .sum::<usize>()
            .max(1)
    }
}

/// What the vertex rows are read for: property indices of x, y, z and the colour channels.
struct Wanted {
    xyz: [usize; 3],
    rgb: Option<[usize; 3]>,
}

fn scalar_type(name: &[u8]) -> Option<Scalar> {
    Some(match name {
        b"char" | b"int8" => Scalar::I8,
        b"uchar" | b"uint8" => Scalar::U8,
        b"short" | b"int16" => Scalar::I16,
        b"ushort" | b"uint16" => Scalar::U16,
        b"int" | b"int32" => Scalar::I32,
        b"uint" | b"uint32" => Scalar::U32,
        b"float" | b"float32" => Scalar::F32,
        b"double" | b"float64" => Scalar::F64,
        _ => return None,
    })
}

const TYPE_NAMES: &str = "char, uchar, short, ushort, int, uint, float, double, int8, uint8, \
                          int16, uint16, int32, uint32, float32, float64";

/// Reads the vertices of a PLY file: positions and, when the vertex element has red, green and
/// blue properties, colours. The pose is the identity (PLY has none). Never panics; see the
/// [module documentation](super) for what is accepted.
pub fn read_ply(bytes: &[u8]) -> Result<Scan, ParseError> {
    let (format, elements, data_start) = parse_header(bytes)?;
    let Some(v) = elements.iter().position(|e| e.name == "vertex") else {
        return Err(err(
            data_start,
            format!(
                "PLY header: expected an element vertex, found {}",
                if elements.is_empty() {
                    "no elements".to_string()
                } else {
                    format!(
                        "elements {}",
                        elements
                            .iter()
                            .map(|e| e.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                }
            ),
        ));
    };
    let vertex = &elements[v];
    let find = |name: &str| {
        vertex
            .properties
            .iter()
            .position(|p| p.name == name && matches!(p.kind, Kind::Scalar(_)))
    };
    let xyz = match (find("x"), find("y"), find("z")) {
        (Some(x), Some(y), Some(z)) => [x, y, z],
        _ => {
            return Err(err(
                vertex.offset,
                format!(
                    "PLY element vertex: expected scalar properties x, y and z, found {}",
                    shown_names(vertex.properties.iter().map(|p| p.name.as_str()))
                ),
            ));
        }
    };
    let rgb = [
        ["red", "green", "blue"],
        ["diffuse_red", "diffuse_green", "diffuse_blue"],
        ["r", "g", "b"],
    ]
    .iter()
    .find_map(|names| Some([find(names[0])?, find(names[1])?, find(names[2])?]));
    let wanted = Wanted { xyz, rgb };
    let body = bytes.get(data_start..).unwrap_or(&[]);
    let builder = match format {
        PlyFormat::Ascii => {
            let mut tokens = Tokens::new(body, data_start);
            for e in &elements[..v] {
                skip_ascii(e, &mut tokens)?;
            }
            read_ascii(vertex, &wanted, &mut tokens, body.len())?
        }
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            let big = format == PlyFormat::BinaryBigEndian;
            let mut pos = data_start;
            for e in &elements[..v] {
                pos = skip_binary(e, bytes, pos, big)?;
            }
            read_binary(vertex, &wanted, bytes, pos, big)?
        }
    };
    Ok(builder.finish(Pose::IDENTITY))
}

fn parse_header(bytes: &[u8]) -> Result<(PlyFormat, Vec<Element>, usize), ParseError> {
    let mut lines = Lines::new(bytes);
    match lines.next() {
        Some((_, b"ply")) => {}
        other => {
            return Err(err(
                0,
                format!(
                    "PLY magic: expected \"ply\" on the first line, found {}",
                    other.map_or("end of input".to_string(), |(_, l)| shown(l))
                ),
            ));
        }
    }
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some((offset, line)) = lines.next() else {
            return Err(err(
                bytes.len(),
                "PLY header: expected end_header, found end of input",
            ));
        };
        let mut tokens = Tokens::new(line, offset);
        let Some((_, keyword)) = tokens.next() else {
            continue;
        };
        let values: Vec<(usize, &[u8])> = tokens.collect();
        let count_error = |what: &str| {
            err(
                offset,
                format!(
                    "PLY header line {}: expected {what}, found {} words",
                    shown(keyword),
                    values.len()
                ),
            )
        };
        match keyword {
            b"comment" | b"obj_info" => {}
            b"end_header" => break,
            b"format" => {
                if format.is_some() {
                    return Err(err(offset, "PLY header format: expected once, found again"));
                }
                let [(at, name), _version] = values.as_slice() else {
                    return Err(count_error("2 words (format and version)"));
                };
                format = Some(match *name {
                    b"ascii" => PlyFormat::Ascii,
                    b"binary_little_endian" => PlyFormat::BinaryLittleEndian,
                    b"binary_big_endian" => PlyFormat::BinaryBigEndian,
                    other => {
                        return Err(err(
                            *at,
                            format!(
                                "PLY header format: expected ascii, binary_little_endian or \
                                 binary_big_endian, found {}",
                                shown(other)
                            ),
                        ));
                    }
                });
            }
            b"element" => {
                let [(_, name), (at, count)] = values.as_slice() else {
                    return Err(count_error("2 words (name and count)"));
                };
                let count = text(count)
                    .and_then(|t| t.parse::<u64>().ok())
                    .ok_or_else(|| {
                        err(
                            *at,
                            format!(
                                "PLY header element count: expected a whole number, found {}",
                                shown(count)
                            ),
                        )
                    })?;
                elements.push(Element {
                    name: String::from_utf8_lossy(name).into_owned(),
                    count,
                    offset,
                    properties: Vec::new(),
                });
            }
            b"property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(err(
                        offset,
                        "PLY header property: expected an element line before it, found none",
                    ));
                };
                let ty = |(at, name): (usize, &[u8])| {
                    scalar_type(name).ok_or_else(|| {
                        err(
                            at,
                            format!(
                                "PLY header property type: expected one of {TYPE_NAMES}, found {}",
                                shown(name)
                            ),
                        )
                    })
                };
                let (kind, name) = match values.as_slice() {
                    [(_, b"list"), count, item, (_, name)] => {
                        let count_ty = ty(*count)?;
                        if count_ty.is_float() {
                            return Err(err(
                                count.0,
                                format!(
                                    "PLY header list count type: expected an integer type, \
                                     found {}",
                                    shown(count.1)
                                ),
                            ));
                        }
                        (Kind::List(count_ty, ty(*item)?), name)
                    }
                    [(_, b"list"), ..] => {
                        return Err(count_error("4 words (list, count type, item type, name)"));
                    }
                    [t, (_, name)] => (Kind::Scalar(ty(*t)?), name),
                    _ => return Err(count_error("2 words (type and name)")),
                };
                element.properties.push(Property {
                    name: String::from_utf8_lossy(name).into_owned(),
                    kind,
                });
            }
            other => {
                return Err(err(
                    offset,
                    format!(
                        "PLY header: expected format, element, property, comment, obj_info or \
                         end_header, found {}",
                        shown(other)
                    ),
                ));
            }
        }
    }
    let data_start = lines.position();
    let Some(format) = format else {
        return Err(err(
            data_start,
            "PLY header: expected a format line before end_header, found none",
        ));
    };
    Ok((format, elements, data_start))
}

/// A vertex colour channel as 0..255: 8-bit values as they are, 16-bit ones scaled down, floats
/// taken as 0..1 and scaled up; anything else clamped.
fn channel(scalar: Scalar, v: f64) -> u8 {
    let v = match scalar {
        Scalar::U16 => v / 257.0,
        Scalar::F32 | Scalar::F64 => v * 255.0,
        _ => v,
    };
    // `as` saturates, and NaN becomes 0.
    v.round() as u8
}

/// A value of an ASCII row of type `scalar`, with what it is for error messages. A `float` is
/// parsed as `f32` directly: through `f64` it could round twice.
fn ascii_value(
    tokens: &mut Tokens,
    element: &Element,
    row: u64,
    property: &str,
    scalar: Scalar,
) -> Result<(usize, f64), ParseError> {
    let Some((at, tok)) = tokens.next() else {
        return Err(err(
            tokens.end(),
            format!(
                "PLY {} {row} property {property}: expected a number, found end of input",
                element.name
            ),
        ));
    };
    let v = text(tok)
        .and_then(|t| match scalar {
            Scalar::F32 => t.parse::<f32>().ok().map(f64::from),
            _ => t.parse::<f64>().ok(),
        })
        .ok_or_else(|| {
            err(
                at,
                format!(
                    "PLY {} {row} property {property}: expected a number, found {}",
                    element.name,
                    shown(tok)
                ),
            )
        })?;
    Ok((at, v))
}

/// A list's count from an ASCII row.
fn ascii_count(
    tokens: &mut Tokens,
    element: &Element,
    row: u64,
    property: &str,
) -> Result<u64, ParseError> {
    let (at, v) = ascii_value(tokens, element, row, property, Scalar::U32)?;
    if v < 0.0 || v.fract() != 0.0 || v > u32::MAX as f64 {
        return Err(err(
            at,
            format!(
                "PLY {} {row} list {property}: expected a count (whole number), found {v}",
                element.name
            ),
        ));
    }
    Ok(v as u64)
}

fn skip_ascii(element: &Element, tokens: &mut Tokens) -> Result<(), ParseError> {
    if element.properties.is_empty() {
        return Ok(());
    }
    for row in 0..element.count {
        for p in &element.properties {
            let (n, scalar) = match p.kind {
                Kind::Scalar(s) => (1, s),
                Kind::List(_, s) => (ascii_count(tokens, element, row, &p.name)?, s),
            };
            for _ in 0..n {
                ascii_value(tokens, element, row, &p.name, scalar)?;
            }
        }
    }
    Ok(())
}

fn read_ascii(
    vertex: &Element,
    wanted: &Wanted,
    tokens: &mut Tokens,
    body_len: usize,
) -> Result<CloudBuilder, ParseError> {
    // Each value takes at least two bytes ("0 ").
    let mut builder = CloudBuilder::new(
        capacity(vertex.count, body_len, 2 * vertex.properties.len()),
        wanted.rgb.is_some(),
    );
    let mut values = vec![0f64; vertex.properties.len()];
    for row in 0..vertex.count {
        for (i, p) in vertex.properties.iter().enumerate() {
            match p.kind {
                Kind::Scalar(s) => {
                    values[i] = ascii_value(tokens, vertex, row, &p.name, s)?.1;
                }
                Kind::List(_, s) => {
                    let n = ascii_count(tokens, vertex, row, &p.name)?;
                    for _ in 0..n {
                        ascii_value(tokens, vertex, row, &p.name, s)?;
                    }
                }
            }
        }
        push(&mut builder, vertex, wanted, &values);
    }
    Ok(builder)
}

fn push(builder: &mut CloudBuilder, vertex: &Element, wanted: &Wanted, values: &[f64]) {
    let [x, y, z] = wanted.xyz;
    let point = [values[x] as f32, values[y] as f32, values[z] as f32];
    let mut color = [0u8; 3];
    if let Some(rgb) = wanted.rgb {
        for (c, &i) in color.iter_mut().zip(&rgb) {
            if let Kind::Scalar(s) = vertex.properties[i].kind {
                *c = channel(s, values[i]);
            }
        }
    }
    builder.push(point, color);
}

/// A binary value at `pos`, or an error naming the row and property.
fn binary_value(
    bytes: &[u8],
    pos: usize,
    scalar: Scalar,
    big: bool,
    element: &Element,
    row: u64,
    property: &str,
) -> Result<f64, ParseError> {
    bytes
        .get(pos..)
        .and_then(|b| scalar.read(b, big))
        .ok_or_else(|| {
            err(
                pos.min(bytes.len()),
                format!(
                    "PLY {} {row} property {property}: expected {} bytes ({}), found {}",
                    element.name,
                    scalar.size(),
                    scalar.name(),
                    bytes.len().saturating_sub(pos)
                ),
            )
        })
}

/// Skips a list's items at `pos` after reading its count; returns the position after them.
fn skip_list(
    bytes: &[u8],
    pos: usize,
    (count_ty, item_ty): (Scalar, Scalar),
    big: bool,
    element: &Element,
    row: u64,
    property: &str,
) -> Result<usize, ParseError> {
    let n = binary_value(bytes, pos, count_ty, big, element, row, property)?;
    let start = pos + count_ty.size();
    let left = bytes.len() - start;
    let need = if n < 0.0 {
        None
    } else {
        (n as usize).checked_mul(item_ty.size())
    };
    match need {
        Some(need) if need <= left => Ok(start + need),
        _ => Err(err(
            pos,
            format!(
                "PLY {} {row} list {property}: expected {n} items of {} bytes, found {left} bytes \
                 left",
                element.name,
                item_ty.size()
            ),
        )),
    }
}

fn skip_binary(
    element: &Element,
    bytes: &[u8],
    pos: usize,
    big: bool,
) -> Result<usize, ParseError> {
    let left = bytes.len().saturating_sub(pos);
    if let Some(size) = element.fixed_size() {
        return match usize::try_from(element.count)
            .ok()
            .and_then(|n| n.checked_mul(size))
        {
            Some(need) if need <= left => Ok(pos + need),
            _ => Err(err(
                pos,
                format!(
                    "PLY element {}: expected {} rows x {size} bytes, found {left} bytes left",
                    element.name, element.count
                ),
            )),
        };
    }
    let mut pos = pos;
    for row in 0..element.count {
        for p in &element.properties {
            pos = match p.kind {
                Kind::Scalar(s) => {
                    binary_value(bytes, pos, s, big, element, row, &p.name)?;
                    pos + s.size()
                }
                Kind::List(c, i) => skip_list(bytes, pos, (c, i), big, element, row, &p.name)?,
            };
        }
    }
    Ok(pos)
}

fn read_binary(
    vertex: &Element,
    wanted: &Wanted,
    bytes: &[u8],
    start: usize,
    big: bool,
) -> Result<CloudBuilder, ParseError> {
    let left = bytes.len().saturating_sub(start);
    if let Some(size) = vertex.fixed_size() {
        let fits = usize::try_from(vertex.count)
            .ok()
            .and_then(|n| n.checked_mul(size))
            .is_some_and(|need| need <= left);
        if !fits {
            return Err(err(
                start,
                format!(
                    "PLY element vertex: expected {} rows x {size} bytes, found {left} bytes left",
                    vertex.count
                ),
            ));
        }
    }
    let mut builder = CloudBuilder::new(
        capacity(vertex.count, left, vertex.min_size()),
        wanted.rgb.is_some(),
    );
    let mut values = vec![0f64; vertex.properties.len()];
    let mut pos = start;
    for row in 0..vertex.count {
        for (i, p) in vertex.properties.iter().enumerate() {
            pos = match p.kind {
                Kind::Scalar(s) => {
                    values[i] = binary_value(bytes, pos, s, big, vertex, row, &p.name)?;
                    pos + s.size()
                }
                Kind::List(c, it) => skip_list(bytes, pos, (c, it), big, vertex, row, &p.name)?,
            };
        }
        push(&mut builder, vertex, wanted, &values);
    }
    Ok(builder)
}

/// Writes `scan`'s points as a binary little-endian PLY file; see [`write_ply_as`].
///
/// # Panics
///
/// If `scan.colors` is `Some` with a length other than `scan.points.len()`.
pub fn write_ply(scan: &Scan) -> Vec<u8> {
    write_ply_as(scan, PlyFormat::BinaryLittleEndian)
}

/// Writes `scan`'s points as a PLY file in `format`: one `vertex` element with `float x y z`
/// and, when the scan has colours, `uchar red green blue`. The pose is not written (PLY has
/// none). [`read_ply`] reads it back exactly (non-finite points are written but dropped on
/// reading).
///
/// # Panics
///
/// If `scan.colors` is `Some` with a length other than `scan.points.len()`.
pub fn write_ply_as(scan: &Scan, format: PlyFormat) -> Vec<u8> {
    let colors = scan.colors.as_deref();
    if let Some(c) = colors {
        assert_eq!(c.len(), scan.points.len(), "one colour per point");
    }
    let mut out = format!(
        "ply\nformat {} 1.0\ncomment written by rovlink\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\n{}end_header\n",
        format.keyword(),
        scan.points.len(),
        if colors.is_some() {
            "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        } else {
            ""
        }
    )
    .into_bytes();
    for (i, p) in scan.points.iter().enumerate() {
        let c = colors.map(|c| c[i]);
        match format {
            PlyFormat::Ascii => {
                let mut line = format!("{} {} {}", p[0], p[1], p[2]);
                if let Some([r, g, b]) = c {
                    let _ = write!(line, " {r} {g} {b}");
                }
                line.push('\n');
                out.extend_from_slice(line.as_bytes());
            }
            PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
                for v in p {
                    out.extend_from_slice(&if format == PlyFormat::BinaryBigEndian {
                        v.to_be_bytes()
                    } else {
                        v.to_le_bytes()
                    });
                }
                if let Some(c) = c {
                    out.extend_from_slice(&c);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORMATS: [PlyFormat; 3] = [
        PlyFormat::Ascii,
        PlyFormat::BinaryLittleEndian,
        PlyFormat::BinaryBigEndian,
    ];

    fn sample(colors: bool) -> Scan {
        Scan {
            points: vec![[0.0, 1.0, 2.0], [-1.5, 0.25, 1e-7], [3.0e5, -0.0, 7.0]],
            colors: colors.then(|| vec![[255, 0, 10], [1, 2, 3], [0, 0, 0]]),
            pose: Pose::IDENTITY,
        }
    }

    fn message(r: Result<Scan, ParseError>) -> (u64, String) {
        let e = r.unwrap_err();
        (e.offset, e.message)
    }

    #[test]
    fn round_trips_every_format() {
        for format in FORMATS {
            for colors in [false, true] {
                let s = sample(colors);
                assert_eq!(
                    read_ply(&write_ply_as(&s, format)).unwrap(),
                    s,
                    "{format:?}"
                );
            }
            let empty = Scan::default();
            assert_eq!(read_ply(&write_ply_as(&empty, format)).unwrap(), empty);
        }
    }

    #[test]
    fn ascii_with_faces_lists_and_other_types() {
        let b = b"ply\r\nformat ascii 1.0\r\ncomment hi\r\nelement camera 1\r\n\
                  property float view\r\nproperty list uchar int stuff\r\n\
                  element vertex 2\r\nproperty double x\r\nproperty list uint8 float32 \
                  extras\r\nproperty int16 y\r\nproperty uint8 z\r\nproperty float diffuse_red\r\n\
                  property float diffuse_green\r\nproperty float diffuse_blue\r\n\
                  element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n\
                  9 2 1 2\r\n\
                  1.5 2 0.5 0.25 -3 7 1 0.5 0\r\n\
                  -2 0 300 255 0 0 1\r\n\
                  3 0 1 2\r\n";
        let s = read_ply(b).unwrap();
        assert_eq!(s.points, vec![[1.5, -3.0, 7.0], [-2.0, 300.0, 255.0]]);
        assert_eq!(s.colors, Some(vec![[255, 128, 0], [0, 0, 255]]));
    }

    #[test]
    fn binary_big_endian_with_list_in_vertex() {
        let mut b = b"ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty float x\n\
                      property list uchar ushort idx\nproperty float y\nproperty float z\n\
                      property uchar r\nproperty uchar g\nproperty uchar b\nend_header\n"
            .to_vec();
        let start = b.len();
        for (p, list, c) in [
            ([1.0f32, 2.0, 3.0], &[7u16, 8][..], [9u8, 8, 7]),
            ([4.0, 5.0, 6.0], &[][..], [1, 2, 3]),
        ] {
            b.extend_from_slice(&p[0].to_be_bytes());
            b.push(list.len() as u8);
            for v in list {
                b.extend_from_slice(&v.to_be_bytes());
            }
            b.extend_from_slice(&p[1].to_be_bytes());
            b.extend_from_slice(&p[2].to_be_bytes());
            b.extend_from_slice(&c);
        }
        let s = read_ply(&b).unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(s.colors, Some(vec![[9, 8, 7], [1, 2, 3]]));
        // A list count beyond the data.
        let mut bad = b.clone();
        bad[start + 4] = 200;
        let (at, msg) = message(read_ply(&bad));
        assert_eq!(at, start as u64 + 4);
        assert!(
            msg.contains("PLY vertex 0 list idx: expected 200 items of 2 bytes"),
            "{msg}"
        );
        // Truncated in the second vertex's z.
        let (at, msg) = message(read_ply(&b[..b.len() - 5]));
        assert_eq!(at, b.len() as u64 - 7);
        assert!(
            msg.contains("PLY vertex 1 property z: expected 4 bytes (float32), found 2"),
            "{msg}"
        );
    }

    #[test]
    fn fixed_size_vertices_beyond_the_data_fail_before_reading() {
        let b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\n\
                  property float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0";
        let (at, msg) = message(read_ply(b));
        assert_eq!(at, b.len() as u64 - 4);
        assert!(
            msg.contains("expected 4000000000 rows x 12 bytes, found 4 bytes left"),
            "{msg}"
        );
        // An element before the vertices claiming too much.
        let b = b"ply\nformat binary_little_endian 1.0\nelement foo 99\nproperty int a\n\
                  element vertex 0\nproperty float x\nproperty float y\nproperty float z\n\
                  end_header\n";
        let (_, msg) = message(read_ply(b));
        assert!(
            msg.contains("PLY element foo: expected 99 rows x 4 bytes"),
            "{msg}"
        );
        // Many empty rows cost nothing.
        let b = b"ply\nformat ascii 1.0\nelement nothing 18446744073709551615\n\
                  element vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                  end_header\n1 2 3\n";
        assert_eq!(read_ply(b).unwrap().points, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn header_errors_name_field_and_offset() {
        let cases: &[(&[u8], u64, &str)] = &[
            (
                b"plyx\n",
                0,
                "PLY magic: expected \"ply\" on the first line, found \"plyx\"",
            ),
            (b"", 0, "found end of input"),
            (
                b"ply\nformat ascii 1.0\n",
                21,
                "expected end_header, found end of input",
            ),
            (
                b"ply\nformat text 1.0\nend_header\n",
                11,
                "expected ascii, binary_little_endian or binary_big_endian, found \"text\"",
            ),
            (
                b"ply\nformat ascii\nend_header\n",
                4,
                "expected 2 words (format and version)",
            ),
            (
                b"ply\nend_header\n",
                15,
                "expected a format line before end_header",
            ),
            (
                b"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
                21,
                "expected an element line before it",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float3 x\nend_header\n",
                47,
                "PLY header property type: expected one of char",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n",
                52,
                "list count type: expected an integer type, found \"float\"",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n",
                36,
                "element count: expected a whole number, found \"-1\"",
            ),
            (
                b"ply\nformat ascii 1.0\nelement face 0\nend_header\n",
                47,
                "expected an element vertex, found elements face",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
                  property list uchar float z\nend_header\n",
                21,
                "expected scalar properties x, y and z, found \"x y z\"",
            ),
            (b"ply\nformat ascii 1.0\nfoo\n", 21, "found \"foo\""),
        ];
        for (input, offset, want) in cases {
            let (at, msg) = message(read_ply(input));
            assert!(msg.contains(want), "{msg:?} lacks {want:?}");
            assert_eq!(at, *offset, "{msg}");
        }
    }

    #[test]
    fn ascii_errors_name_row_and_offset() {
        let h = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                  property float z\nend_header\n";
        let at = h.len() as u64;
        let mut b = h.to_vec();
        b.extend_from_slice(b"1 2 3\n4 five 6\n");
        let (o, msg) = message(read_ply(&b));
        assert_eq!(o, at + 8);
        assert!(
            msg.contains("PLY vertex 1 property y: expected a number, found \"five\""),
            "{msg}"
        );
        let mut b = h.to_vec();
        b.extend_from_slice(b"1 2 3\n4 5\n");
        let (o, msg) = message(read_ply(&b));
        assert_eq!(o, b.len() as u64);
        assert!(
            msg.contains("PLY vertex 1 property z: expected a number, found end"),
            "{msg}"
        );
    }

    #[test]
    fn colour_channels_convert_by_type() {
        assert_eq!(channel(Scalar::U8, 200.0), 200);
        assert_eq!(channel(Scalar::U16, 65535.0), 255);
        assert_eq!(channel(Scalar::F32, 0.5), 128);
        assert_eq!(channel(Scalar::F32, 7.0), 255);
        assert_eq!(channel(Scalar::I8, -5.0), 0);
        assert_eq!(channel(Scalar::F64, f64::NAN), 0);
        assert_eq!(channel(Scalar::I32, 1000.0), 255);
    }

    #[test]
    fn every_prefix_of_valid_files_is_handled() {
        for format in FORMATS {
            let b = write_ply_as(&sample(true), format);
            for cut in 0..b.len() {
                let _ = read_ply(&b[..cut]);
            }
        }
    }
}
