//! The live map's transport from any bytes: each input is a run of segments (a length byte,
//! then that many bytes) handed to a view (`Viewer::on_segment`, which parses the segment,
//! reassembles records and applies them) and to the segment parser.
//!
//! Checks:
//! - `Repr::parse` never panics; a segment it takes emits the same bytes again;
//! - `Request::parse` never panics; a request it takes emits the same bytes again;
//! - the view never panics on any run of segments (a stream start is forged by the first
//!   byte's low bit, so that records, and the `.odl` messages in them, are reached), and
//!   every segment it answers with parses.

#![no_main]

use std::time::Duration;

use libfuzzer_sys::fuzz_target;
use rovlink_maplink::{Repr, Request};
use rovlink_mapper::live::viewer::Viewer;

fuzz_target!(|data: &[u8]| {
    let Some((&mode, mut rest)) = data.split_first() else {
        return;
    };
    let mut view = Viewer::new(Duration::from_millis(500), 7, 0.0, mode & 2 != 0);
    if mode & 1 != 0 {
        // A stream's start: a sync record with a valid header, so that what follows is applied.
        let header = rovlink_octo::delta::encode_header(&rovlink_octo::delta::ViewSpec {
            resolution_m: 0.1,
            coarse_depth: 13,
            roi: None,
        });
        let mut chunk = vec![1u8];
        chunk.extend_from_slice(&header);
        let start = Repr::Data {
            epoch: 1,
            seq: 0,
            first: true,
            last: true,
            chunk: &chunk,
        }
        .emit();
        view.on_segment(&start, Duration::ZERO);
    }
    let mut t = Duration::ZERO;
    while let Some((&n, tail)) = rest.split_first() {
        let n = (n as usize).min(tail.len());
        let (seg, more) = tail.split_at(n);
        rest = more;
        if let Ok(r) = Repr::parse(seg) {
            assert_eq!(r.emit(), seg);
        }
        if let Ok(r) = Request::parse(seg) {
            let mut out = Vec::new();
            r.emit(&mut out);
            assert_eq!(out, seg);
        }
        t += Duration::from_millis(10);
        view.on_segment(seg, t);
        while let Some(out) = view.poll(t) {
            assert!(Repr::parse(&out).is_ok());
        }
        view.take_outputs();
    }
});
