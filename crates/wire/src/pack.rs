//! The packer behind `rcp-pack`: messages as JSON Lines to link frames (raw or as hex lines),
//! and a file cut into the ROV messages that carry it as one image's trunks.

use std::io::{self, BufRead, Read};

use super::json::{self, JsonError};
use super::rov::{MAX_TRUNKS, cut_trunks};
use super::{Error, Message, MessageRepr, rov};

/// The longest input line read: far above any message's JSON.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// The most bytes one image's trunks can carry: 64 trunks of the largest size.
pub const MAX_IMAGE_BYTES: usize = MAX_TRUNKS * rov::MAX_TRUNK_BYTES;

/// Why a line gave no message.
#[derive(Debug, thiserror::Error)]
pub enum LineError {
    /// Reading failed: the input ends here.
    #[error("read failed: {0}")]
    Read(io::Error),
    /// A line too long to be a message: the input ends here.
    #[error("longer than {MAX_LINE_BYTES} bytes: not a message")]
    TooLong,
    /// Not UTF-8.
    #[error("not UTF-8 at byte {0}")]
    Utf8(usize),
    /// Not a message in wire.md's JSON form.
    #[error(transparent)]
    Json(#[from] JsonError),
}

impl LineError {
    /// True when nothing after this line can be read.
    pub fn is_fatal(&self) -> bool {
        matches!(self, LineError::Read(_) | LineError::TooLong)
    }
}

/// One input line: its message, and the counter it asks for when sealed (`"ctr"`, read only
/// by [`Lines::with_counters`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// The message.
    pub repr: MessageRepr,
    /// The line's `ctr` field ([`json::counter_field`]).
    pub ctr: Option<u64>,
}

/// The messages of a JSON Lines input, with their 1-based line numbers; blank lines are
/// skipped, each line is read up to [`MAX_LINE_BYTES`], and a fatal error ends the lines.
pub struct Lines<R: BufRead> {
    reader: R,
    number: usize,
    line: Vec<u8>,
    done: bool,
    counters: bool,
}

impl<R: BufRead> Lines<R> {
    /// The lines of `reader`; a `ctr` field is ignored, as the other fields `rcp-dump` adds
    /// are ([`json::DUMP_FIELDS`]).
    pub fn new(reader: R) -> Lines<R> {
        Lines {
            reader,
            number: 0,
            line: Vec::new(),
            done: false,
            counters: false,
        }
    }

    /// The lines of `reader`, each with its `ctr` field read and checked (frames to be
    /// sealed).
    pub fn with_counters(reader: R) -> Lines<R> {
        Lines {
            counters: true,
            ..Lines::new(reader)
        }
    }

    /// One line's text as a [`Line`].
    fn parse(&self, text: &str) -> Result<Line, LineError> {
        if self.counters {
            let (repr, ctr) = json::parse_line_with_counter(text)?;
            return Ok(Line { repr, ctr });
        }
        Ok(Line {
            repr: json::parse_line(text)?,
            ctr: None,
        })
    }
}

impl<R: BufRead> Iterator for Lines<R> {
    type Item = (usize, Result<Line, LineError>);

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            self.number += 1;
            self.line.clear();
            let read = (&mut self.reader)
                .take(MAX_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut self.line);
            let outcome = match read {
                Err(e) => Err(LineError::Read(e)),
                Ok(0) => return None,
                Ok(_) if self.line.len() > MAX_LINE_BYTES && self.line.last() != Some(&b'\n') => {
                    Err(LineError::TooLong)
                }
                Ok(_) => match std::str::from_utf8(&self.line) {
                    Err(e) => Err(LineError::Utf8(e.valid_up_to())),
                    Ok(text) if text.trim().is_empty() => continue,
                    Ok(text) => self.parse(text.trim()),
                },
            };
            self.done = outcome.as_ref().is_err_and(LineError::is_fatal);
            return Some((self.number, outcome));
        }
        None
    }
}

/// A message's frame: its bytes, or a line of lowercase hex with its newline.
pub fn frame(repr: &MessageRepr, hex: bool) -> Result<Vec<u8>, Error> {
    let mut bytes = Vec::with_capacity(repr.buffer_len());
    repr.emit_to_vec(&mut bytes)?;
    if hex {
        let mut line = json::encode_hex(&bytes);
        line.push('\n');
        return Ok(line.into_bytes());
    }
    Ok(bytes)
}

/// Why a file cannot be one image's trunks.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ImageError {
    /// Nothing to cut.
    #[error("empty file, nothing to cut into trunks")]
    Empty,
    /// More trunks than ITSN numbers.
    #[error(
        "{bytes} bytes need {trunks} trunks of {trunk_bytes} bytes, at most {MAX_TRUNKS} fit \
         (ITSN is 6 bits); use --trunk {smallest} or more"
    )]
    TooManyTrunks {
        /// The file's length.
        bytes: usize,
        /// Trunks it needs.
        trunks: usize,
        /// The trunk size asked.
        trunk_bytes: usize,
        /// The smallest trunk size that fits.
        smallest: usize,
    },
    /// More than any trunk size can carry.
    #[error(
        "more than {MAX_IMAGE_BYTES} bytes: not even {MAX_TRUNKS} trunks of {} bytes hold it",
        rov::MAX_TRUNK_BYTES
    )]
    TooLarge,
}

/// The ROV messages (basic status) carrying `data` as image `isn`'s trunks of `trunk_bytes`,
/// cut as the ROV cuts an encoded image ([`cut_trunks`]): FT on the first, LT on the last.
pub fn image_messages(
    data: &[u8],
    trunk_bytes: usize,
    src: u8,
    dst: u8,
    isn: bool,
) -> Result<Vec<MessageRepr>, ImageError> {
    if data.is_empty() {
        return Err(ImageError::Empty);
    }
    if data.len() > MAX_IMAGE_BYTES {
        return Err(ImageError::TooLarge);
    }
    let trunks = cut_trunks(data, trunk_bytes).map_err(|smallest| ImageError::TooManyTrunks {
        bytes: data.len(),
        trunks: data.len().div_ceil(trunk_bytes.max(1)),
        trunk_bytes,
        smallest,
    })?;
    let last = trunks.len() - 1;
    Ok(trunks
        .into_iter()
        .enumerate()
        .map(|(itsn, piece)| MessageRepr {
            src,
            dst,
            message: Message::Rov(rov::Repr {
                ft: itsn == 0,
                lt: itsn == last,
                isn,
                ci: false,
                itsn: itsn as u8,
                status: rov::Status::Basic(rov::BasicStatus::default()),
                trunk: piece.to_vec(),
            }),
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_give_messages_and_errors_by_number() {
        let good = r#"{"type":"raw","src":1,"dst":0,"payload":"00"}"#;
        let text = format!(
            "{good}\n\n{{oops\n\u{0}{}\n{good}",
            "x".repeat(MAX_LINE_BYTES + 5)
        );
        let lines: Vec<_> = Lines::new(text.as_bytes()).collect();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!(matches!(lines[0], (1, Ok(_))));
        assert!(matches!(lines[1], (3, Err(LineError::Json(_)))));
        assert!(matches!(lines[2], (4, Err(LineError::TooLong))));
        let frame_line = frame(&lines[0].1.as_ref().unwrap().repr, true).unwrap();
        assert!(frame_line.ends_with(b"\n") && frame_line.starts_with(b"55"));
    }

    #[test]
    fn counters_are_read_only_when_asked_and_checked() {
        let good = r#"{"type":"raw","src":1,"dst":0,"payload":"00","ctr":16385}"#;
        let text = format!(
            "{good}\n{}\n{}\n{}\n",
            good.replace("16385", "0"),
            good.replace("16385", "281474976710656"),
            good.replace(r#","ctr":16385"#, "")
        );
        let plain: Vec<_> = Lines::new(text.as_bytes()).collect();
        assert!(plain.iter().all(|(_, l)| l.as_ref().unwrap().ctr.is_none()));
        let lines: Vec<_> = Lines::with_counters(text.as_bytes()).collect();
        assert_eq!(lines[0].1.as_ref().unwrap().ctr, Some(16385));
        for bad in &lines[1..3] {
            let err = bad.1.as_ref().unwrap_err().to_string();
            assert!(
                err.starts_with("field ctr: expected an integer 1..=281474976710655, found"),
                "{err}"
            );
        }
        assert_eq!(lines[3].1.as_ref().unwrap().ctr, None);
    }

    #[test]
    fn images_are_cut_into_at_most_64_trunks() {
        let messages = image_messages(&[7; 100], 39, 1, 0, true).unwrap();
        assert_eq!(messages.len(), 3);
        let Message::Rov(last) = &messages[2].message else {
            panic!("not a ROV message")
        };
        assert!(last.lt && !last.ft && last.isn && last.itsn == 2 && last.trunk.len() == 22);
        assert_eq!(
            image_messages(&[0; 3000], 39, 1, 0, false)
                .unwrap_err()
                .to_string(),
            "3000 bytes need 77 trunks of 39 bytes, at most 64 fit (ITSN is 6 bits); use --trunk 47 or more"
        );
        assert_eq!(image_messages(&[], 39, 1, 0, false), Err(ImageError::Empty));
        assert_eq!(
            image_messages(&vec![0; MAX_IMAGE_BYTES + 1], 242, 1, 0, false),
            Err(ImageError::TooLarge)
        );
    }
}
