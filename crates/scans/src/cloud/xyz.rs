//! XYZ text: one point per line, `x y z` or `x y z r g b`.

use std::fmt::Write as _;

use super::{CloudBuilder, Lines, err, shown};
use rovlink_octo::{ParseError, Pose, Scan};

/// A colour value as read, for deciding the file's colour scale once all are known.
struct Channel {
    value: f64,
    /// Written with a decimal point or exponent (`0.5`, `1e0`), not as an integer.
    fraction: bool,
    line: usize,
    offset: usize,
}

const CHANNEL_NAMES: [&str; 3] = ["r", "g", "b"];
const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

/// Splits a line at commas and runs of spaces or tabs: the values and their offsets in the line.
/// `Err` names the offset of an empty value between commas.
fn split<'a>(line: &'a str, values: &mut Vec<(usize, &'a str)>) -> Result<(), usize> {
    values.clear();
    let mut start = 0;
    for piece in line.split(',') {
        let mut any = false;
        for token in piece.split([' ', '\t']) {
            if !token.is_empty() {
                let at = token.as_ptr() as usize - line.as_ptr() as usize;
                values.push((at, token));
                any = true;
            }
        }
        if !any && line.contains(',') {
            return Err(start);
        }
        start += piece.len() + 1;
    }
    Ok(())
}

/// Reads XYZ text: `x y z` or `x y z r g b` per line (every line the same), separated by spaces,
/// tabs or commas; `#` to the end of a line is a comment; blank lines are skipped, and so is a
/// first line of column names (`x,y,z,r,g,b`). Colours are integers 0..255, or, if the file
/// writes them as fractions (`0.5`) and all lie within 0..1, scaled by 255. The pose is the
/// identity. Errors name the line (`line 3: ...`) and carry the offset of the value or line.
/// Never panics.
pub fn read_xyz(bytes: &[u8]) -> Result<Scan, ParseError> {
    let mut points: Vec<[f32; 3]> = Vec::new();
    let mut channels: Vec<[Channel; 3]> = Vec::new();
    let mut columns: Option<(usize, usize)> = None; // (count, line that set it)
    let mut values = Vec::new();
    let mut seen_content = false;
    for (number, (offset, line)) in Lines::new(bytes).enumerate() {
        let number = number + 1;
        let line = std::str::from_utf8(line).map_err(|e| {
            err(
                offset + e.valid_up_to(),
                format!(
                    "line {number}: expected UTF-8 text, found byte 0x{:02x}",
                    line.get(e.valid_up_to()).copied().unwrap_or(0)
                ),
            )
        })?;
        let content = line.split('#').next().unwrap_or("");
        if content.trim().is_empty() {
            continue;
        }
        split(content, &mut values).map_err(|at| {
            err(
                offset + at,
                format!("line {number}: expected a value between commas, found none"),
            )
        })?;
        let first_content = !seen_content;
        seen_content = true;
        // A header of column names on the first line.
        if first_content && values.iter().all(|(_, v)| v.parse::<f64>().is_err()) {
            continue;
        }
        let n = values.len();
        match columns {
            None if n == 3 || n == 6 => columns = Some((n, number)),
            None => {
                return Err(err(
                    offset,
                    format!(
                        "line {number}: expected 3 values (x y z) or 6 (x y z r g b), found {n}"
                    ),
                ));
            }
            Some((want, first)) if want != n => {
                return Err(err(
                    offset,
                    format!("line {number}: expected {want} values like line {first}, found {n}"),
                ));
            }
            Some(_) => {}
        }
        let mut p = [0f32; 3];
        for (axis, (slot, (at, v))) in p.iter_mut().zip(&values).enumerate() {
            *slot = v.parse::<f32>().map_err(|_| {
                err(
                    offset + at,
                    format!(
                        "line {number}: {}: expected a number, found {}",
                        AXIS_NAMES[axis],
                        shown(v.as_bytes())
                    ),
                )
            })?;
        }
        points.push(p);
        if n == 6 {
            let mut c = [0usize; 3].map(|_| Channel {
                value: 0.0,
                fraction: false,
                line: number,
                offset,
            });
            for (k, (slot, (at, v))) in c.iter_mut().zip(&values[3..]).enumerate() {
                let value = v.parse::<f64>().ok().filter(|v| v.is_finite());
                let Some(value) = value.filter(|v| (0.0..=255.0).contains(v)) else {
                    return Err(err(
                        offset + at,
                        format!(
                            "line {number}: colour {}: expected 0..255 (or 0..1), found {}",
                            CHANNEL_NAMES[k],
                            shown(v.as_bytes())
                        ),
                    ));
                };
                *slot = Channel {
                    value,
                    fraction: v.contains(['.', 'e', 'E']),
                    line: number,
                    offset: offset + at,
                };
            }
            channels.push(c);
        }
    }
    let colors = if channels.is_empty() {
        None
    } else {
        let all = || channels.iter().flatten();
        let unit = all().any(|c| c.fraction) && all().all(|c| c.value <= 1.0);
        let mut colors = Vec::with_capacity(channels.len());
        for c in &channels {
            let mut rgb = [0u8; 3];
            for (k, (slot, ch)) in rgb.iter_mut().zip(c).enumerate() {
                *slot = if unit {
                    (ch.value * 255.0).round() as u8
                } else if ch.value.fract() == 0.0 {
                    ch.value as u8
                } else {
                    return Err(err(
                        ch.offset,
                        format!(
                            "line {}: colour {}: expected a whole number 0..255 (the file's \
                             colours are not all fractions within 0..1), found {}",
                            ch.line, CHANNEL_NAMES[k], ch.value
                        ),
                    ));
                };
            }
            colors.push(rgb);
        }
        Some(colors)
    };
    let mut builder = CloudBuilder::new(points.len(), colors.is_some());
    for (i, p) in points.iter().enumerate() {
        builder.push(*p, colors.as_ref().map_or([0; 3], |c| c[i]));
    }
    Ok(builder.finish(Pose::IDENTITY))
}

/// Writes `scan`'s points as XYZ text, `x y z` or (with colours) `x y z r g b` per line, numbers
/// written so that [`read_xyz`] reads them back exactly. The pose is not written.
///
/// # Panics
///
/// If `scan.colors` is `Some` with a length other than `scan.points.len()`.
pub fn write_xyz(scan: &Scan) -> Vec<u8> {
    let colors = scan.colors.as_deref();
    if let Some(c) = colors {
        assert_eq!(c.len(), scan.points.len(), "one colour per point");
    }
    let mut out = String::new();
    for (i, p) in scan.points.iter().enumerate() {
        let _ = write!(out, "{} {} {}", p[0], p[1], p[2]);
        if let Some(c) = colors {
            let [r, g, b] = c[i];
            let _ = write!(out, " {r} {g} {b}");
        }
        out.push('\n');
    }
    out.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(r: Result<Scan, ParseError>) -> (u64, String) {
        let e = r.unwrap_err();
        (e.offset, e.message)
    }

    #[test]
    fn reads_plain_and_coloured_lines() {
        let s = read_xyz(b"# survey\n1 2 3\n\n  4\t5 6  # trailing\r\n-7e-1,8,9\n").unwrap();
        assert_eq!(
            s.points,
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [-0.7, 8.0, 9.0]]
        );
        assert_eq!(s.colors, None);
        assert_eq!(s.pose, Pose::IDENTITY);
        let s = read_xyz(b"x,y,z,r,g,b\n1, 2, 3, 255, 0, 7\n4,5,6,1,1,1\n").unwrap();
        assert_eq!(s.colors, Some(vec![[255, 0, 7], [1, 1, 1]]));
        let s = read_xyz(b"1 2 3 0.5 1.0 0\n4 5 6 1 0 0.25\n").unwrap();
        assert_eq!(s.colors, Some(vec![[128, 255, 0], [255, 0, 64]]));
        // Fractions above 1 mean the 0..255 scale, where they must be whole.
        let s = read_xyz(b"1 2 3 2.0 1.0 0\n").unwrap();
        assert_eq!(s.colors, Some(vec![[2, 1, 0]]));
        assert_eq!(read_xyz(b"").unwrap(), Scan::default());
        assert_eq!(read_xyz(b"# nothing\n\n").unwrap(), Scan::default());
    }

    #[test]
    fn drops_non_finite_points_with_their_colours() {
        let s =
            read_xyz(b"1 2 3 1 2 3\nnan 0 0 4 5 6\n0 inf 0 7 8 9\n1e39 0 0 1 1 1\n4 5 6 7 8 9\n")
                .unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(s.colors, Some(vec![[1, 2, 3], [7, 8, 9]]));
    }

    #[test]
    fn errors_give_line_and_offset() {
        let cases: &[(&[u8], u64, &str)] = &[
            (
                b"1 2 3\n1 2\n",
                6,
                "line 2: expected 3 values like line 1, found 2",
            ),
            (
                b"1 2 3 4\n",
                0,
                "line 1: expected 3 values (x y z) or 6 (x y z r g b), found 4",
            ),
            (
                b"1 2 3\n4 y 6\n",
                8,
                "line 2: y: expected a number, found \"y\"",
            ),
            (
                b"x y z\nx y z\n",
                6,
                "line 2: x: expected a number, found \"x\"",
            ),
            (
                b"1,,2,3\n",
                2,
                "line 1: expected a value between commas, found none",
            ),
            (
                b"1 2 3 0 256 0\n",
                8,
                "line 1: colour g: expected 0..255 (or 0..1), found \"256\"",
            ),
            (b"1 2 3 0 -1 0\n", 8, "colour g"),
            (
                b"1 2 3 0 1 0\n1 2 3 0 1.5 0\n",
                20,
                "line 2: colour g: expected a whole number",
            ),
            (
                b"1 2 3\n\xff\n",
                6,
                "line 2: expected UTF-8 text, found byte 0xff",
            ),
        ];
        for (input, offset, want) in cases {
            let (at, msg) = message(read_xyz(input));
            assert!(msg.contains(want), "{msg:?} lacks {want:?}");
            assert_eq!(at, *offset, "{msg}");
        }
    }

    #[test]
    fn round_trips() {
        let s = Scan {
            points: vec![[0.1, -2.5e-8, 3.4e38], [-0.0, 1.0, 2.0]],
            colors: Some(vec![[0, 128, 255], [1, 1, 1]]),
            pose: Pose::IDENTITY,
        };
        assert_eq!(read_xyz(&write_xyz(&s)).unwrap(), s);
        let plain = Scan {
            colors: None,
            ..s.clone()
        };
        assert_eq!(read_xyz(&write_xyz(&plain)).unwrap(), plain);
    }
}
