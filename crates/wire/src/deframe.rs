//! A streaming deframer: finds link frames in a byte stream that arrives in chunks of any size,
//! with garbage and corrupted frames between them.
//!
//! The hunt, as wire.md fixes it: look for the preamble 0x55, read LEN, wait for the whole frame,
//! check the CRC. A good frame is yielded and the hunt resumes after it. On a CRC failure the
//! failure is reported with its stream offset and the hunt resumes at the byte after that
//! preamble, so a good frame that starts inside garbage or inside a corrupted frame is still
//! found. Bytes that end up in no good frame are reported as skipped runs.
//!
//! A 0x55 byte inside garbage looks like a preamble: when the bytes after it fail the CRC it is
//! reported as a CRC failure too. The format cannot tell the two apart.
//!
//! Memory is bounded: the deframer keeps at most one pushed chunk plus one maximal frame.
//!
//! No-panic contract: [`Deframer::push`], [`Deframer::next_event`] and [`Deframer::finish`]
//! never panic, on any bytes in any chunking.
//!
//! ```
//! use rovlink_wire::{Deframer, DeframeEvent, frame};
//! let mut stream = vec![0x00, 0x55, 0x99]; // garbage, including a false preamble
//! stream.extend(frame::build(1, 0, b"hello").unwrap());
//! let mut deframer = Deframer::new();
//! deframer.push(&stream);
//! deframer.finish();
//! let mut frames = Vec::new();
//! while let Some(event) = deframer.next_event() {
//!     if let DeframeEvent::Frame { offset, frame } = event {
//!         frames.push((offset, frame.payload().to_vec()));
//!     }
//! }
//! assert_eq!(frames, vec![(3, b"hello".to_vec())]);
//! assert_eq!(deframer.stats().bytes_skipped, 3);
//! ```

use super::frame::{CRC16, Frame, OVERHEAD_BYTES, PREAMBLE};

/// Bytes of the header the deframer reads before it knows a frame's length.
const HEADER_BYTES: usize = 3;

/// One thing the deframer found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeframeEvent<'a> {
    /// A frame whose CRC checks. `frame` spans exactly the frame's bytes.
    Frame {
        /// Stream offset of its preamble.
        offset: u64,
        /// The frame.
        frame: Frame<&'a [u8]>,
    },
    /// A preamble whose frame failed the CRC.
    BadCrc {
        /// Stream offset of the preamble.
        offset: u64,
        /// The LEN byte read after it.
        payload_len: usize,
        /// CRC computed over the bytes.
        computed: u16,
        /// CRC the bytes carried.
        carried: u16,
    },
    /// A run of bytes that belong to no good frame (garbage, corrupted frames).
    Skipped {
        /// Stream offset of the first byte.
        offset: u64,
        /// Number of bytes.
        len: u64,
    },
    /// A preamble whose frame never completed: the stream ended, or the caller gave up on it
    /// with [`Deframer::abandon_incomplete`] because the line went quiet.
    Truncated {
        /// Stream offset of the preamble.
        offset: u64,
        /// Bytes the frame needs.
        expected: usize,
        /// Bytes the stream still had.
        found: usize,
        /// True at the end of the stream, false when abandoned on a quiet line.
        at_end: bool,
    },
}

/// Counters over everything the deframer has seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct DeframeStats {
    /// Bytes pushed.
    pub bytes_in: u64,
    /// Good frames yielded.
    pub frames: u64,
    /// CRC failures reported.
    pub crc_failures: u64,
    /// Truncated frames at the end of the stream.
    pub truncated: u64,
    /// Bytes that belong to no good frame.
    pub bytes_skipped: u64,
}

/// The streaming deframer. Push bytes, then drain events with [`next_event`](Self::next_event)
/// until it returns `None`; call [`finish`](Self::finish) at the end of the stream and drain again.
#[derive(Debug, Clone, Default)]
pub struct Deframer {
    buf: Vec<u8>,
    /// Index in `buf` of the first byte not yet examined.
    pos: usize,
    /// Stream offset of `buf[0]`.
    buf_offset: u64,
    /// The skipped run being gathered: (stream offset, length).
    skipped: Option<(u64, u64)>,
    finished: bool,
    /// Give up on incomplete frames until the pending bytes are examined.
    abandon: bool,
    stats: DeframeStats,
}

impl Deframer {
    /// A deframer at stream offset 0.
    pub fn new() -> Deframer {
        Deframer::default()
    }

    /// Appends bytes of the stream.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.pos > 0 {
            self.buf.drain(..self.pos);
            self.buf_offset += self.pos as u64;
            self.pos = 0;
        }
        self.buf.extend_from_slice(bytes);
        self.stats.bytes_in += bytes.len() as u64;
    }

    /// Marks the end of the stream: frames still incomplete are reported as truncated and the
    /// last skipped run is flushed.
    pub fn finish(&mut self) {
        self.finished = true;
    }

    /// Gives up on an incomplete frame waiting at the head of the pending bytes: call it when
    /// the line has been quiet for longer than any frame takes to arrive. A false preamble in
    /// garbage can announce up to 255 payload bytes; without this, the frames after it are
    /// only yielded once that many bytes have arrived. Then drain events as usual.
    pub fn abandon_incomplete(&mut self) {
        self.abandon = true;
    }

    /// The counters so far.
    pub fn stats(&self) -> DeframeStats {
        self.stats
    }

    /// Bytes pushed but not yet examined (waiting for the rest of a frame).
    pub fn pending_bytes(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn skip(&mut self, at: usize, len: usize) {
        let offset = self.buf_offset + at as u64;
        match &mut self.skipped {
            Some((_, run)) => *run += len as u64,
            None => self.skipped = Some((offset, len as u64)),
        }
        self.stats.bytes_skipped += len as u64;
    }

    fn take_skipped(&mut self) -> Option<DeframeEvent<'static>> {
        self.skipped
            .take()
            .map(|(offset, len)| DeframeEvent::Skipped { offset, len })
    }

    /// The next event, or `None` when more bytes are needed (or, after
    /// [`finish`](Self::finish), when the stream is exhausted).
    pub fn next_event(&mut self) -> Option<DeframeEvent<'_>> {
        loop {
            let start = self.pos;
            let data = &self.buf[start..];
            if data.is_empty() {
                if self.finished || std::mem::take(&mut self.abandon) {
                    return self.take_skipped();
                }
                return None;
            }
            if data[0] != PREAMBLE {
                let garbage = data
                    .iter()
                    .position(|&b| b == PREAMBLE)
                    .unwrap_or(data.len());
                self.skip(start, garbage);
                self.pos += garbage;
                continue;
            }
            let total = match data.get(2) {
                Some(&len) => usize::from(len) + OVERHEAD_BYTES,
                None => HEADER_BYTES,
            };
            if data.len() < total {
                if !(self.finished || self.abandon) {
                    return None;
                }
                let found = data.len();
                self.skip(start, 1);
                self.pos += 1;
                self.stats.truncated += 1;
                let offset = self.buf_offset + start as u64;
                return Some(DeframeEvent::Truncated {
                    offset,
                    expected: total.max(OVERHEAD_BYTES),
                    found,
                    at_end: self.finished,
                });
            }
            let end = total - 2;
            let computed = CRC16.checksum(&data[1..end]);
            let carried = u16::from_be_bytes([data[end], data[end + 1]]);
            if computed != carried {
                self.skip(start, 1);
                self.pos += 1;
                self.stats.crc_failures += 1;
                return Some(DeframeEvent::BadCrc {
                    offset: self.buf_offset + start as u64,
                    payload_len: total - OVERHEAD_BYTES,
                    computed,
                    carried,
                });
            }
            if let Some(skipped) = self.take_skipped() {
                // Report the run before the frame; the frame is checked again on the next call.
                return Some(skipped);
            }
            self.pos += total;
            self.stats.frames += 1;
            return Some(DeframeEvent::Frame {
                offset: self.buf_offset + start as u64,
                frame: Frame::new_unchecked(&self.buf[start..start + total]),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::build;

    /// Good frames with their offsets.
    type Frames = Vec<(u64, Vec<u8>)>;

    /// Runs a whole stream through a deframer in chunks of `chunk` bytes; returns the good
    /// frames with offsets, the other events in a compact form, and the stats.
    fn run(stream: &[u8], chunk: usize) -> (Frames, Vec<String>, DeframeStats) {
        let mut d = Deframer::new();
        let (mut frames, mut other) = (Vec::new(), Vec::new());
        let mut drain = |d: &mut Deframer| {
            while let Some(ev) = d.next_event() {
                match ev {
                    DeframeEvent::Frame { offset, frame } => {
                        frames.push((offset, frame.into_inner().to_vec()))
                    }
                    DeframeEvent::BadCrc { offset, .. } => other.push(format!("crc@{offset}")),
                    DeframeEvent::Skipped { offset, len } => {
                        other.push(format!("skip@{offset}+{len}"))
                    }
                    DeframeEvent::Truncated { offset, .. } => other.push(format!("trunc@{offset}")),
                }
            }
        };
        for piece in stream.chunks(chunk.max(1)) {
            d.push(piece);
            drain(&mut d);
        }
        d.finish();
        drain(&mut d);
        (frames, other, d.stats())
    }

    #[test]
    fn back_to_back_frames_in_every_chunking() {
        let a = build(1, 0, &[1, 2, 3]).unwrap();
        let b = build(0, 1, &[0x55; 11]).unwrap();
        let stream = [a.clone(), b.clone()].concat();
        for chunk in 1..=stream.len() {
            let (frames, other, stats) = run(&stream, chunk);
            assert_eq!(
                frames,
                vec![(0, a.clone()), (a.len() as u64, b.clone())],
                "chunk {chunk}"
            );
            assert!(other.is_empty(), "chunk {chunk}: {other:?}");
            assert_eq!(stats.bytes_skipped, 0);
        }
    }

    #[test]
    fn corrupted_frame_is_reported_and_the_next_one_found() {
        let a = build(1, 0, &[9; 20]).unwrap();
        let mut bad = build(1, 0, &[7; 20]).unwrap();
        bad[10] ^= 0x04;
        let c = build(2, 0, &[]).unwrap();
        let stream = [vec![0xff, 0x00], a.clone(), bad.clone(), c.clone()].concat();
        let (frames, other, stats) = run(&stream, 7);
        let c_at = (2 + a.len() + bad.len()) as u64;
        assert_eq!(frames, vec![(2, a.clone()), (c_at, c)]);
        let bad_at = 2 + a.len() as u64;
        assert_eq!(
            other,
            vec![
                "skip@0+2".to_string(),
                format!("crc@{bad_at}"),
                format!("skip@{bad_at}+{}", bad.len())
            ]
        );
        assert_eq!(stats.crc_failures, 1);
        assert_eq!(stats.bytes_skipped, 2 + bad.len() as u64);
    }

    #[test]
    fn frame_hidden_inside_a_false_preamble_is_found() {
        // A false preamble whose LEN swallows the real frame that follows.
        let real = build(3, 0, &[1, 2]).unwrap();
        let mut stream = vec![0x55, 0x00, 0x08];
        stream.extend(&real);
        stream.extend([0u8; 6]);
        let (frames, _, stats) = run(&stream, 4);
        assert_eq!(frames, vec![(3, real)]);
        assert_eq!(stats.crc_failures, 1);
    }

    #[test]
    fn truncated_tail() {
        let a = build(1, 0, &[1; 30]).unwrap();
        let stream = [a.clone(), a[..10].to_vec()].concat();
        let (frames, other, stats) = run(&stream, 64);
        assert_eq!(frames.len(), 1);
        assert_eq!(
            other,
            vec!["trunc@35".to_string(), "skip@35+10".to_string()]
        );
        assert_eq!(stats.truncated, 1);
        assert_eq!(stats.bytes_skipped, 10);
    }

    #[test]
    fn abandoning_a_stalled_false_preamble_releases_the_frames_behind_it() {
        let real = build(1, 0, &[4; 10]).unwrap();
        let mut d = Deframer::new();
        d.push(&[0x55, 0x02, 0xff]);
        d.push(&real);
        assert_eq!(
            d.next_event(),
            None,
            "waits for the 260 bytes LEN announces"
        );
        d.abandon_incomplete();
        assert_eq!(
            d.next_event(),
            Some(DeframeEvent::Truncated {
                offset: 0,
                expected: 260,
                found: 18,
                at_end: false
            })
        );
        assert_eq!(
            d.next_event(),
            Some(DeframeEvent::Skipped { offset: 0, len: 3 })
        );
        match d.next_event() {
            Some(DeframeEvent::Frame { offset: 3, frame }) => {
                assert_eq!(frame.into_inner(), &real[..])
            }
            other => panic!("expected the frame, got {other:?}"),
        }
        assert_eq!(d.next_event(), None);
        // The flag is spent: a new incomplete frame waits again.
        d.push(&real[..5]);
        assert_eq!(d.next_event(), None);
        d.push(&real[5..]);
        assert!(matches!(
            d.next_event(),
            Some(DeframeEvent::Frame { offset: 18, .. })
        ));
    }

    #[test]
    fn lone_preamble_at_end() {
        let (frames, other, stats) = run(&[0x55], 1);
        assert!(frames.is_empty());
        assert_eq!(other, vec!["trunc@0".to_string(), "skip@0+1".to_string()]);
        assert_eq!(stats.bytes_skipped, 1);
    }
}
