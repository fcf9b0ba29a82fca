//! Sending the map's messages over a link model in virtual time, reliably, shaped to 85% of the
//! link rate (the DexROV satellite scheme of the second paper: reliable DDS streams whose burst
//! budget is about 85% of the bandwidth, the rest left for resends).
//!
//! Each message is cut into segments as the live transport cuts it (`rovlink_maplink`,
//! `octo-delta map`): wire.md link frames of at most [`SEGMENT_BYTES`] on the link, of which
//! [`SEGMENT_HEADER_BYTES`] are the frame's and the data segment's headers, and acknowledgements
//! of [`ACK_BYTES`]; so the simulated figures predict the live ones. The sender paces segments at 85% of
//! the model's bit rate, resends a segment when its acknowledgement has not come back within
//! a timeout (twice the expected round trip), resends first, and acknowledges nothing out of
//! band: every acknowledgement is a small frame over the reverse link. The receiver applies
//! messages in order, so a scan's changes are shown once it and every earlier one are complete.

use rovlink_link::{Distance, Link, Model, ModelError, Side, SimTime};

/// Largest segment on the link, bytes: a link frame of the live transport's largest data
/// segment (260).
pub const SEGMENT_BYTES: usize =
    rovlink_maplink::segment::MAX_SEGMENT_BYTES + rovlink_wire::frame::OVERHEAD_BYTES;
/// Bytes of a segment that are not the message's: the frame's and the data segment's headers
/// (15).
pub const SEGMENT_HEADER_BYTES: usize =
    rovlink_maplink::segment::DATA_HEADER_BYTES + rovlink_wire::frame::OVERHEAD_BYTES;
/// Acknowledgement frame bytes (22).
pub const ACK_BYTES: usize =
    rovlink_maplink::segment::ACK_BYTES + rovlink_wire::frame::OVERHEAD_BYTES;
/// Longest time between scans a transfer accepts, s (a day).
pub const MAX_PERIOD_S: f64 = 86_400.0;
/// Share of the link rate the reliable stream may use.
pub const SHAPING: f64 = 0.85;

/// A link model by preset name or model file path; the reverse direction (acknowledgements)
/// uses the paired satellite preset, or the same model.
pub fn model_by_name(name: &str) -> Result<Model, ModelError> {
    if std::path::Path::new(name).is_file() {
        Model::from_file(std::path::Path::new(name))
    } else {
        Model::preset(name)
    }
}

fn reverse_of(model: &Model) -> Model {
    match model.name.as_str() {
        "satellite-up" => Model::preset("satellite-down").unwrap_or_else(|_| model.clone()),
        "satellite-down" => Model::preset("satellite-up").unwrap_or_else(|_| model.clone()),
        _ => model.clone(),
    }
}

/// When one message reached the operator.
#[derive(Debug, Clone, PartialEq)]
pub struct Arrival {
    /// Scan number.
    pub scan: u32,
    /// Message bytes.
    pub bytes: usize,
    /// When the scan's message was ready to send, s.
    pub t_ready_s: f64,
    /// When its last segment arrived, s.
    pub t_complete_s: f64,
    /// When it could be applied (it and every earlier message complete), s.
    pub t_applied_s: f64,
}

/// The outcome of a transfer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TransferReport {
    /// Model name.
    pub model: String,
    /// Per message, in order.
    pub arrivals: Vec<Arrival>,
    /// Segments sent, first copies.
    pub segments: u64,
    /// Segments sent again.
    pub resends: u64,
    /// Bytes put on the link (segments, resends and acknowledgements included).
    pub link_bytes: u64,
    /// Messages never shown: never completed (the link lost everything for too long), or after
    /// one that never completed (messages are applied in order).
    pub undelivered: usize,
}

impl TransferReport {
    /// Scan ready -> shown latencies, s: (median, p90, max), zero without messages.
    fn latency_quantiles_s(&self) -> (f64, f64, f64) {
        let mut sorted: Vec<f64> = self
            .arrivals
            .iter()
            .map(|a| a.t_applied_s - a.t_ready_s)
            .collect();
        sorted.sort_by(f64::total_cmp);
        let q = |p: f64| match sorted.len() {
            0 => 0.0,
            n => sorted[((n - 1) as f64 * p).round() as usize],
        };
        (q(0.5), q(0.9), q(1.0))
    }

    /// The figures of the transfer as JSON (`octo-delta build --metrics`).
    pub fn figures(&self) -> serde_json::Value {
        let (median, p90, max) = self.latency_quantiles_s();
        serde_json::json!({
            "model": self.model,
            "messages": self.arrivals.len(),
            "segments": self.segments,
            "resends": self.resends,
            "link_bytes": self.link_bytes,
            "undelivered": self.undelivered,
            "latency_median_s": median,
            "latency_p90_s": p90,
            "latency_max_s": max,
            "last_shown_s": self.arrivals.last().map_or(0.0, |a| a.t_applied_s),
        })
    }

    /// Summary lines for people.
    pub fn lines(&self) -> Vec<String> {
        let (median, p90, max) = self.latency_quantiles_s();
        let end = self.arrivals.last().map_or(0.0, |a| a.t_applied_s);
        vec![
            format!(
                "link {}: {} messages, {} segments + {} resends, {} bytes on the link",
                self.model,
                self.arrivals.len(),
                self.segments,
                self.resends,
                self.link_bytes
            ),
            format!(
                "scan ready -> shown at the operator: median {:.3} s, p90 {:.3} s, max {:.3} s; last shown at {:.3} s{}",
                median,
                p90,
                max,
                end,
                if self.undelivered > 0 {
                    format!("; {} messages never completed", self.undelivered)
                } else {
                    String::new()
                }
            ),
        ]
    }
}

struct Seg {
    msg: usize,
    idx: u32,
    len: usize,
    acked: bool,
    sent_at: Option<SimTime>,
}

/// Sends `messages` (scan number, bytes), the k-th ready at `k * period_s`, over `model`.
pub fn send_over(
    model: &Model,
    messages: &[(u32, usize)],
    period_s: f64,
    seed: u64,
) -> TransferReport {
    let mut report = TransferReport {
        model: model.name.clone(),
        ..TransferReport::default()
    };
    let link = Link::new(model.clone(), reverse_of(model), seed, Distance::Fixed(0.0));
    let (Ok(mut link), true) = (
        link,
        period_s.is_finite() && (0.0..=MAX_PERIOD_S).contains(&period_s),
    ) else {
        report.undelivered = messages.len();
        return report;
    };
    let per_seg = SEGMENT_BYTES - SEGMENT_HEADER_BYTES;
    let mut segs: Vec<Seg> = Vec::new();
    let mut first_seg = Vec::with_capacity(messages.len());
    for (m, &(_, bytes)) in messages.iter().enumerate() {
        first_seg.push(segs.len());
        let n = bytes.div_ceil(per_seg).max(1);
        for i in 0..n {
            let len = (bytes - i * per_seg).min(per_seg) + SEGMENT_HEADER_BYTES;
            segs.push(Seg {
                msg: m,
                idx: i as u32,
                len,
                acked: false,
                sent_at: None,
            });
        }
    }
    let rate_bps = model.bitrate_bps * SHAPING;
    let rtt_s = 2.0 * (model.intrinsic_delay_ms + 3.0 * model.jitter_ms) / 1e3
        + (SEGMENT_BYTES + ACK_BYTES) as f64 * 8.0 / model.bitrate_bps;
    let rto = 2.0 * rtt_s + 0.05;
    let mut remaining: Vec<usize> = messages
        .iter()
        .enumerate()
        .map(|(m, _)| {
            let end = first_seg.get(m + 1).copied().unwrap_or(segs.len());
            end - first_seg[m]
        })
        .collect();
    let mut complete: Vec<Option<f64>> = vec![None; messages.len()];
    let mut received = vec![false; segs.len()];
    let mut next_new = 0usize;
    let mut next_slot = SimTime::ZERO;
    let mut resend_queue: std::collections::VecDeque<usize> = Default::default();
    let mut inflight: std::collections::VecDeque<(SimTime, usize)> = Default::default();
    let ready_at = |m: usize| SimTime::from_secs_f64(m as f64 * period_s.max(0.0));
    // Give up on a dead link: nothing can take longer than this.
    let horizon = SimTime::from_secs_f64(messages.len() as f64 * period_s.max(0.0) + 3600.0);
    let mut stalls = 0u32;
    loop {
        let now = link.now();
        while let Some(r) = link.pop_report() {
            if r.duplicate || r.fate != rovlink_link::Fate::Delivered || r.bytes.len() < 4 {
                continue;
            }
            let id = u32::from_le_bytes([r.bytes[0], r.bytes[1], r.bytes[2], r.bytes[3]]) as usize;
            let (Some(t_rx), Some(seg)) = (r.t_rx, segs.get_mut(id)) else {
                continue;
            };
            match r.from {
                Side::A => {
                    // The operator acknowledges every copy it gets.
                    let mut ack = vec![0u8; ACK_BYTES];
                    ack[..4].copy_from_slice(&(id as u32).to_le_bytes());
                    report.link_bytes += ACK_BYTES as u64;
                    link.offer(Side::B, ack);
                    if !received[id] {
                        received[id] = true;
                        remaining[seg.msg] -= 1;
                        if remaining[seg.msg] == 0 {
                            complete[seg.msg] = Some(t_rx.as_secs_f64());
                        }
                    }
                }
                Side::B => seg.acked = true,
            }
        }
        if complete.iter().all(Option::is_some) {
            break;
        }
        // Timeouts: unacknowledged segments sent rto ago or earlier are queued again. Sends
        // are in time order, so the oldest copy in flight is at the front; entries whose
        // segment was acknowledged or sent again since are dropped as they come up.
        while let Some(&(t, i)) = inflight.front() {
            let s = &mut segs[i];
            if s.acked || s.sent_at != Some(t) {
                inflight.pop_front();
            } else if now >= t.after_secs(rto) {
                inflight.pop_front();
                s.sent_at = None;
                resend_queue.push_back(i);
            } else {
                break;
            }
        }
        resend_queue.retain(|&i| !segs[i].acked);
        // Send one segment when the shaper allows: resends first, then new segments in order.
        if now >= next_slot {
            let pick = match resend_queue.pop_front() {
                Some(i) => Some((i, true)),
                None if next_new < segs.len() && ready_at(segs[next_new].msg) <= now => {
                    next_new += 1;
                    Some((next_new - 1, false))
                }
                None => None,
            };
            if let Some((i, again)) = pick {
                let s = &mut segs[i];
                let mut bytes = vec![0u8; s.len];
                bytes[..4].copy_from_slice(&(i as u32).to_le_bytes());
                bytes[4..8].copy_from_slice(&s.idx.to_le_bytes());
                s.sent_at = Some(now);
                inflight.push_back((now, i));
                report.link_bytes += s.len as u64;
                if again {
                    report.resends += 1;
                } else {
                    report.segments += 1;
                }
                next_slot = now.after_secs(s.len as f64 * 8.0 / rate_bps);
                link.offer(Side::A, bytes);
                continue;
            }
        }
        // The next moment anything can happen.
        let mut next: Option<SimTime> = link.next_event_time();
        let mut consider = |t: SimTime| next = Some(next.map_or(t, |n| n.min(t)));
        if !resend_queue.is_empty() {
            consider(next_slot.max(now));
        } else if next_new < segs.len() {
            consider(next_slot.max(ready_at(segs[next_new].msg)).max(now));
        }
        if let Some(&(t, _)) = inflight.front() {
            consider(t.after_secs(rto));
        }
        match next {
            Some(t) if t <= horizon => {
                // Time must move: a loop that stands still would never end.
                if t <= now && link.next_event_time().is_none_or(|e| e > now) {
                    stalls += 1;
                    if stalls > 1000 {
                        break;
                    }
                } else {
                    stalls = 0;
                }
                link.advance(t.max(now))
            }
            _ => break,
        }
    }
    let mut applied = 0.0f64;
    for (m, &(scan, bytes)) in messages.iter().enumerate() {
        // Delivery is in order: after a message that never completed, nothing can be shown.
        match complete[m].filter(|_| report.undelivered == 0) {
            Some(t) => {
                applied = applied.max(t);
                report.arrivals.push(Arrival {
                    scan,
                    bytes,
                    t_ready_s: m as f64 * period_s,
                    t_complete_s: t,
                    t_applied_s: applied,
                });
            }
            None => report.undelivered += 1,
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn satellite_transfer_takes_air_time_and_delay() {
        let model = Model::preset("satellite-up").unwrap();
        let msgs: Vec<(u32, usize)> = (0..10).map(|i| (i, 100_000)).collect();
        let r = send_over(&model, &msgs, 1.0, 1);
        assert_eq!(r.arrivals.len(), 10);
        assert_eq!(r.undelivered, 0);
        // 100 kB at 85% of 768 kbit/s is about 1.23 s of air time, plus 310 ms of delay.
        let first = &r.arrivals[0];
        let lat = first.t_complete_s - first.t_ready_s;
        assert!(lat > 1.2 && lat < 1.8, "latency {lat}");
        assert_eq!(r.resends, 0);
    }

    #[test]
    fn big_lossy_transfers_finish_in_order() {
        let mut model = Model::preset("satellite-up").unwrap();
        model.loss_percent = 5.0;
        let msgs: Vec<(u32, usize)> = (0..40).map(|i| (i, 200_000)).collect();
        let r = send_over(&model, &msgs, 0.5, 2);
        assert_eq!(r.undelivered, 0);
        assert_eq!(r.arrivals.len(), 40);
        // Every segment is sent once, plus its resends; about 5% (data) to 10% (acks) again.
        let segs = 40 * 200_000usize.div_ceil(SEGMENT_BYTES - SEGMENT_HEADER_BYTES);
        assert_eq!(r.segments as usize, segs);
        assert!(
            r.resends as usize > segs / 40 && (r.resends as usize) < segs / 4,
            "{}",
            r.resends
        );
        for w in r.arrivals.windows(2) {
            assert!(w[1].t_applied_s >= w[0].t_applied_s);
        }
    }

    #[test]
    fn losses_are_resent() {
        let mut model = Model::preset("satellite-up").unwrap();
        model.loss_percent = 10.0;
        let msgs: Vec<(u32, usize)> = (0..5).map(|i| (i, 20_000)).collect();
        let r = send_over(&model, &msgs, 1.0, 3);
        assert_eq!(r.undelivered, 0);
        assert!(r.resends > 0);
        for w in r.arrivals.windows(2) {
            assert!(w[1].t_applied_s >= w[0].t_applied_s);
        }
    }
}
