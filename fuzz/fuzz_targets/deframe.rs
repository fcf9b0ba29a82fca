//! The streaming deframer on any bytes in any chunking, with and without giving up on stalled
//! frames (`abandon_incomplete`).
//!
//! Input: byte 0 gives a count `n` (its low 4 bits); the next `n` bytes each give a chunk length
//! (low 7 bits; 0 pushes an empty chunk) and a flag (top bit), used in turn and cyclically; the
//! rest is the stream. The stream is pushed chunk by chunk with the events drained after each
//! push, then `finish` and a last drain. This runs in that chunking, then in one push, and, if
//! any flag is set, in that chunking again calling `abandon_incomplete` and draining once more
//! after each flagged chunk (as `rcp-dump --idle-ms` does when the line goes quiet).
//!
//! Checks, on every run:
//! - every `Frame` event spans a frame that passes `Frame::new_checked(..).check()`, has exactly
//!   the stream's bytes at its offset, was wholly pushed already, and frame offsets strictly
//!   increase without overlap;
//! - good frames and `Skipped` runs tile the stream exactly, and after `finish`
//!   `bytes_skipped + sum of frame lengths == stream length`; the other counters match the events;
//! - every 0x55 byte outside a good frame gets exactly one `BadCrc` or `Truncated` event and
//!   every such event is right about the bytes pushed so far (its CRCs, lengths), so no frame
//!   that was complete when it was examined is missed;
//! - `Truncated` comes with `at_end` only after `finish`, and without it only in the drain that
//!   follows `abandon_incomplete` (the flag does not outlive that drain), which examines every
//!   pending byte;
//! - without `abandon_incomplete`, the chunked run gives the same events and counters as one push.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_wire::frame::{CRC16, Frame, OVERHEAD_BYTES, PREAMBLE};
use rovlink_wire::{DeframeEvent, DeframeStats, Deframer};

/// An owned copy of a [`DeframeEvent`].
#[derive(Debug, Clone, PartialEq, Eq)]
enum Ev {
    Frame {
        offset: u64,
        bytes: Vec<u8>,
    },
    BadCrc {
        offset: u64,
        payload_len: usize,
        computed: u16,
        carried: u16,
    },
    Skipped {
        offset: u64,
        len: u64,
    },
    Truncated {
        offset: u64,
        expected: usize,
        found: usize,
        at_end: bool,
    },
}

/// When an event came out: bytes pushed so far, and what the drain followed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct When {
    pushed: usize,
    after_abandon: bool,
    finished: bool,
}

/// Drains every event; `limit` bounds the total so a deframer that loops is caught quickly.
fn drain(d: &mut Deframer, out: &mut Vec<(Ev, When)>, when: When, limit: usize) {
    while let Some(event) = d.next_event() {
        let ev = match event {
            DeframeEvent::Frame { offset, frame } => Ev::Frame {
                offset,
                bytes: frame.into_inner().to_vec(),
            },
            DeframeEvent::BadCrc {
                offset,
                payload_len,
                computed,
                carried,
            } => Ev::BadCrc {
                offset,
                payload_len,
                computed,
                carried,
            },
            DeframeEvent::Skipped { offset, len } => Ev::Skipped { offset, len },
            DeframeEvent::Truncated {
                offset,
                expected,
                found,
                at_end,
            } => Ev::Truncated {
                offset,
                expected,
                found,
                at_end,
            },
        };
        out.push((ev, when));
        assert!(
            out.len() <= limit,
            "more than {limit} events: the deframer does not make progress"
        );
    }
}

/// Runs `stream` through a deframer in chunks of the given lengths (low 7 bits, cyclically);
/// with `abandon`, gives up on incomplete frames after each chunk whose length byte has its top
/// bit set.
fn run(stream: &[u8], lens: &[u8], abandon: bool) -> (Vec<(Ev, When)>, DeframeStats) {
    // Each BadCrc/Truncated consumes a byte, each Frame five, and a Skipped run precedes a
    // frame or ends a drain after finish or abandon_incomplete: at most 2 events per byte + 1.
    let limit = 2 * stream.len() + 1;
    let mut d = Deframer::new();
    let mut events = Vec::new();
    let mut when = When {
        pushed: 0,
        after_abandon: false,
        finished: false,
    };
    let mut push = |d: &mut Deframer, events: &mut Vec<_>, chunk: &[u8], len_byte: u8| {
        d.push(chunk);
        when.pushed += chunk.len();
        drain(d, events, when, limit);
        if abandon && len_byte & 0x80 != 0 {
            d.abandon_incomplete();
            let after = When {
                after_abandon: true,
                ..when
            };
            drain(d, events, after, limit);
            assert_eq!(
                d.pending_bytes(),
                0,
                "bytes left unexamined after abandon_incomplete and a drain"
            );
        }
    };
    if lens.iter().all(|&l| l & 0x7f == 0) {
        for &len in lens {
            push(&mut d, &mut events, &[], len);
        }
        push(&mut d, &mut events, stream, 0);
    } else {
        let mut pos = 0;
        for &len in lens.iter().cycle() {
            if pos >= stream.len() {
                break;
            }
            let end = (pos + usize::from(len & 0x7f)).min(stream.len());
            push(&mut d, &mut events, &stream[pos..end], len);
            pos = end;
        }
    }
    assert_eq!(when.pushed, stream.len());
    d.finish();
    let at_end = When {
        pushed: stream.len(),
        after_abandon: false,
        finished: true,
    };
    drain(&mut d, &mut events, at_end, limit);
    // A drained, finished deframer stays empty.
    assert!(d.next_event().is_none());
    assert_eq!(d.pending_bytes(), 0, "bytes left unexamined after finish");
    (events, d.stats())
}

fn check(stream: &[u8], events: &[(Ev, When)], stats: &DeframeStats, abandon: bool) {
    let n = stream.len() as u64;
    assert_eq!(stats.bytes_in, n);

    let mut frame_bytes = 0u64;
    let mut frames = 0u64;
    let mut next_free = 0u64;
    // (offset, len, is_frame) of every frame and skipped run, to check the tiling.
    let mut tiles = Vec::new();
    let mut hunted = Vec::new();
    let (mut crc_failures, mut truncated, mut skipped) = (0u64, 0u64, 0u64);
    for (ev, when) in events {
        match ev {
            Ev::Frame { offset, bytes } => {
                let frame = Frame::new_checked(&bytes[..]).expect("frame event fails new_checked");
                frame.check().expect("frame event fails check");
                assert_eq!(
                    frame.total_len(),
                    bytes.len(),
                    "frame event has extra bytes"
                );
                let (at, len) = (*offset as usize, bytes.len());
                assert!(at + len <= when.pushed, "frame past the bytes pushed");
                assert_eq!(&stream[at..at + len], &bytes[..], "frame bytes differ");
                assert!(
                    *offset >= next_free,
                    "frame at {offset} overlaps or precedes the previous one (ends at {next_free})"
                );
                next_free = offset + len as u64;
                frame_bytes += len as u64;
                frames += 1;
                tiles.push((*offset, len as u64, true));
            }
            Ev::Skipped { offset, len } => {
                assert!(*len > 0, "empty skipped run at {offset}");
                assert!(
                    offset + len <= when.pushed as u64,
                    "skipped run past the bytes pushed"
                );
                skipped += len;
                tiles.push((*offset, *len, false));
            }
            Ev::BadCrc {
                offset,
                payload_len,
                computed,
                carried,
            } => {
                crc_failures += 1;
                let at = *offset as usize;
                let end = at + payload_len + OVERHEAD_BYTES;
                assert!(
                    end <= when.pushed,
                    "BadCrc on a frame not wholly pushed yet"
                );
                assert_eq!(stream[at], PREAMBLE, "BadCrc not at a preamble");
                assert_eq!(usize::from(stream[at + 2]), *payload_len);
                assert_eq!(*computed, CRC16.checksum(&stream[at + 1..end - 2]));
                assert_eq!(
                    *carried,
                    u16::from_be_bytes([stream[end - 2], stream[end - 1]])
                );
                assert_ne!(computed, carried, "BadCrc on a good CRC");
                hunted.push(*offset);
            }
            Ev::Truncated {
                offset,
                expected,
                found,
                at_end,
            } => {
                truncated += 1;
                if *at_end {
                    assert!(when.finished, "Truncated at_end before finish");
                } else {
                    assert!(
                        when.after_abandon && !when.finished,
                        "Truncated without at_end outside the drain after abandon_incomplete: {when:?}"
                    );
                }
                let at = *offset as usize;
                assert!(at < when.pushed, "Truncated past the bytes pushed");
                assert_eq!(stream[at], PREAMBLE, "Truncated not at a preamble");
                assert_eq!(*found, when.pushed - at, "Truncated: wrong byte count");
                let want = if *found >= 3 {
                    usize::from(stream[at + 2]) + OVERHEAD_BYTES
                } else {
                    OVERHEAD_BYTES
                };
                assert_eq!(*expected, want);
                assert!(expected > found, "Truncated frame that was wholly pushed");
                hunted.push(*offset);
            }
        }
    }
    assert_eq!(stats.frames, frames);
    assert_eq!(stats.crc_failures, crc_failures);
    assert_eq!(stats.truncated, truncated);
    assert_eq!(
        stats.bytes_skipped, skipped,
        "Skipped runs do not add up to bytes_skipped"
    );
    assert_eq!(
        stats.bytes_skipped + frame_bytes,
        n,
        "bytes_skipped + frame bytes != stream length"
    );

    // Frames and skipped runs tile the stream. Without abandon_incomplete a skipped run only
    // ends at a frame or at the end, so two are never adjacent.
    tiles.sort_unstable();
    let mut at = 0u64;
    let mut last_was_skip = false;
    let mut in_good_frame = vec![false; stream.len()];
    for &(offset, len, is_frame) in &tiles {
        assert_eq!(
            offset, at,
            "gap or overlap at {at} in frames + skipped runs: {tiles:?}"
        );
        assert!(
            abandon || is_frame || !last_was_skip,
            "two adjacent skipped runs at {offset}"
        );
        if is_frame {
            in_good_frame[offset as usize..(offset + len) as usize].fill(true);
        }
        last_was_skip = !is_frame;
        at += len;
    }
    assert_eq!(
        at, n,
        "frames + skipped runs end at {at}, stream has {n} bytes"
    );

    // The hunt looks at every preamble outside good frames exactly once.
    hunted.sort_unstable();
    let preambles: Vec<u64> = (0..stream.len())
        .filter(|&i| stream[i] == PREAMBLE && !in_good_frame[i])
        .map(|i| i as u64)
        .collect();
    assert_eq!(
        hunted, preambles,
        "BadCrc/Truncated offsets differ from the skipped preambles"
    );
}

fuzz_target!(|data: &[u8]| {
    let (count, rest) = match data.split_first() {
        Some((&b, rest)) => (usize::from(b & 0x0f), rest),
        None => (0, data),
    };
    let (lens, stream) = rest.split_at(count.min(rest.len()));

    let (events, stats) = run(stream, lens, false);
    check(stream, &events, &stats, false);

    let (whole_events, whole_stats) = run(stream, &[], false);
    let strip = |evs: &[(Ev, When)]| evs.iter().map(|(e, _)| e.clone()).collect::<Vec<_>>();
    assert_eq!(
        strip(&events),
        strip(&whole_events),
        "events depend on the chunking {lens:?}"
    );
    assert_eq!(
        stats, whole_stats,
        "counters depend on the chunking {lens:?}"
    );

    if lens.iter().any(|&l| l & 0x80 != 0) {
        let (events, stats) = run(stream, lens, true);
        check(stream, &events, &stats, true);
    }
});
