//! Plain CDR (XCDR1), the bytes of every ROS 2 message: a writer of the primitives in either
//! byte order ([`CdrWriter`], the one `rovlink_scans::ros`'s bag encoders build on too), and a
//! reader for the small messages a session takes from the graph ([`CdrReader`]).
//!
//! A message is a 4-byte encapsulation header (`00 01` little endian, `00 00` big endian, two
//! option bytes), then the fields in order, each primitive aligned to its own size counted from
//! after the header, strings as a `u32` length (with the terminating NUL) and the bytes,
//! sequences as a `u32` count and the items.

/// The byte order a writer writes (readers read both).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum ByteOrder {
    /// Little endian (encapsulation `00 01`), what ROS 2 writes on every common machine.
    #[default]
    Little,
    /// Big endian (encapsulation `00 00`).
    Big,
}

/// Writes plain CDR in either byte order.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
    big: bool,
}

impl CdrWriter {
    /// A message: its encapsulation header, no field yet.
    pub fn new(order: ByteOrder) -> Self {
        let big = order == ByteOrder::Big;
        CdrWriter {
            buf: vec![0, u8::from(!big), 0, 0],
            big,
        }
    }

    /// Whether it writes big endian.
    pub fn is_big(&self) -> bool {
        self.big
    }

    /// Pads to a multiple of `n` bytes after the header.
    pub fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    fn put<const N: usize>(&mut self, le: [u8; N]) {
        self.align(N);
        let mut a = le;
        if self.big {
            a.reverse();
        }
        self.buf.extend_from_slice(&a);
    }

    /// A `uint8`, `int8`, `bool` or `char`.
    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) {
        self.put(v.to_le_bytes());
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) {
        self.put(v.to_le_bytes());
    }

    /// A `string`.
    ///
    /// # Panics
    ///
    /// If it is over 4 GiB.
    pub fn string(&mut self, s: &str) {
        let n = u32::try_from(s.len() + 1).expect("CDR string: over 4 GiB");
        self.u32(n);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A `uint8[]` or `int8[]` sequence: its count, then the bytes.
    ///
    /// # Panics
    ///
    /// If it is over 4 GiB.
    pub fn bytes(&mut self, data: &[u8]) {
        self.u32(u32::try_from(data.len()).expect("CDR sequence: over 4 GiB"));
        self.buf.extend_from_slice(data);
    }

    /// A `builtin_interfaces/Time` of `stamp_ns` nanoseconds since the epoch.
    ///
    /// # Panics
    ///
    /// If the seconds do not fit an `int32`.
    pub fn time(&mut self, stamp_ns: i64) {
        let sec = i32::try_from(stamp_ns.div_euclid(1_000_000_000))
            .expect("Time stamp: seconds beyond i32 (builtin_interfaces/Time)");
        self.i32(sec);
        self.u32(stamp_ns.rem_euclid(1_000_000_000) as u32);
    }

    /// A `std_msgs/Header`.
    ///
    /// # Panics
    ///
    /// As [`CdrWriter::time`].
    pub fn header(&mut self, stamp_ns: i64, frame_id: &str) {
        self.time(stamp_ns);
        self.string(frame_id);
    }

    /// The bytes so far, to append unaligned data (a cloud's points) to.
    pub fn raw(&mut self) -> &mut Vec<u8> {
        &mut self.buf
    }

    /// The message.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }
}

/// Reads plain CDR in either byte order; every error names the message and field, and where.
/// Never panics, on any input.
pub struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
    big: bool,
    what: &'static str,
}

impl<'a> CdrReader<'a> {
    /// A reader of `message`, a `what` (named in errors).
    pub fn new(message: &'a [u8], what: &'static str) -> Result<Self, String> {
        let big = match message.get(..4) {
            Some([0, 0, _, _]) => true,
            Some([0, 1, _, _]) => false,
            Some(h) => {
                return Err(format!(
                    "{what}: expected a plain CDR header 00 00 or 00 01, found {:02x} {:02x}",
                    h[0], h[1]
                ));
            }
            None => {
                return Err(format!(
                    "{what}: expected 4 bytes of CDR header, found {}",
                    message.len()
                ));
            }
        };
        Ok(CdrReader {
            data: message.get(4..).unwrap_or_default(),
            pos: 0,
            big,
            what,
        })
    }

    fn take<const N: usize>(&mut self, field: &str) -> Result<[u8; N], String> {
        let at = self.pos.div_ceil(N) * N;
        match self.data.get(at..at + N) {
            Some(b) => {
                self.pos = at + N;
                let mut a = [0u8; N];
                a.copy_from_slice(b);
                if self.big {
                    a.reverse();
                }
                Ok(a)
            }
            None => Err(format!(
                "{}: {field} at byte {}: expected {N} bytes, found {}",
                self.what,
                at + 4,
                self.data.len().saturating_sub(at)
            )),
        }
    }

    /// A `uint8`, `bool` or `char`.
    pub fn u8(&mut self, field: &str) -> Result<u8, String> {
        self.take::<1>(field).map(|b| b[0])
    }

    /// A `uint8[]` sequence of at most `max` bytes (a count beyond what is left, or beyond
    /// `max`, is refused before anything is copied).
    pub fn bytes(&mut self, field: &str, max: usize) -> Result<&'a [u8], String> {
        let n = self.u32(field)? as usize;
        let left = self.data.len().saturating_sub(self.pos);
        if n > left || n > max {
            return Err(format!(
                "{}: {field}: {n} bytes claimed, {left} left (at most {max} taken)",
                self.what
            ));
        }
        let b = self.data.get(self.pos..self.pos + n).unwrap_or_default();
        self.pos += n;
        Ok(b)
    }

    /// A `uint32`.
    pub fn u32(&mut self, field: &str) -> Result<u32, String> {
        self.take::<4>(field).map(u32::from_le_bytes)
    }

    /// A `float64` that must be finite.
    pub fn f64(&mut self, field: &str) -> Result<f64, String> {
        let v = self.take::<8>(field).map(f64::from_le_bytes)?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(format!(
                "{}: {field}: expected a finite number, found {v}",
                self.what
            ))
        }
    }

    /// A `string` (UTF-8, its NUL dropped).
    pub fn string(&mut self, field: &str) -> Result<String, String> {
        let n = self.u32(field)? as usize;
        let bytes = self
            .data
            .get(self.pos..self.pos.saturating_add(n))
            .filter(|b| n > 0 && b.last() == Some(&0))
            .ok_or_else(|| format!("{}: {field}: a string of {n} bytes does not fit", self.what))?;
        self.pos += n;
        String::from_utf8(bytes[..n - 1].to_vec())
            .map_err(|_| format!("{}: {field}: expected UTF-8", self.what))
    }

    /// A `std_msgs/Header`: the stamp in nanoseconds and the frame id.
    pub fn header(&mut self) -> Result<(i64, String), String> {
        let sec = i64::from(self.take::<4>("header.stamp.sec").map(i32::from_le_bytes)?);
        let nsec = i64::from(self.u32("header.stamp.nanosec")?);
        let frame = self.string("header.frame_id")?;
        Ok((sec * 1_000_000_000 + nsec, frame))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_aligned_after_the_header_in_either_order() {
        let mut w = CdrWriter::new(ByteOrder::Little);
        w.u8(7);
        w.f64(1.5);
        w.string("ab");
        let m = w.into_bytes();
        assert_eq!(
            m,
            [
                0, 1, 0, 0, // header
                7, 0, 0, 0, 0, 0, 0, 0, // u8, padded to 8
                0, 0, 0, 0, 0, 0, 0xf8, 0x3f, // 1.5
                3, 0, 0, 0, b'a', b'b', 0
            ]
        );
        let mut w = CdrWriter::new(ByteOrder::Big);
        w.header(1_500_000_000, "map");
        let m = w.into_bytes();
        let mut r = CdrReader::new(&m, "Header").unwrap();
        assert_eq!(r.header().unwrap(), (1_500_000_000, "map".to_string()));
    }

    #[test]
    fn the_reader_refuses_what_does_not_fit_naming_the_field() {
        let e = CdrReader::new(&[0, 1, 0, 0, 1], "Twist")
            .unwrap()
            .f64("linear.x")
            .unwrap_err();
        assert!(
            e.contains("linear.x") && e.contains("expected 8 bytes"),
            "{e}"
        );
        assert!(CdrReader::new(&[1, 2, 0, 0], "Twist").is_err());
        let mut nan = CdrWriter::new(ByteOrder::Little);
        nan.f64(f64::NAN);
        let m = nan.into_bytes();
        assert!(CdrReader::new(&m, "Twist").unwrap().f64("x").is_err());
        let huge = [0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff];
        assert!(CdrReader::new(&huge, "S").unwrap().string("s").is_err());
    }
}
