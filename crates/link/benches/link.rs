//! The link model's bars: statistics against the S100 model, and virtual-time speed.
//!
//! Run: `cargo bench -p rovlink-link --bench link` (add `-- --quick` for fewer frames and repetitions).
//!
//! 1. Statistics (issue 4's bars): 57-byte frames back to back through the S100 preset; mean
//!    delay against 85 + 240 = 325.0 ms (within 1 %), jitter (standard deviation of the delay)
//!    against 13.2 ms (within 7 %), and at BER 7e-4 the delivered fraction against
//!    (1 - 7e-4)^456 = 72.7 % with its binomial 99 % interval.
//! 2. Speed on one core: frames and events per second of the virtual-time pipe, median over the
//!    repetitions, with the anchor measured in the same run: a bare scheduler that pushes and
//!    pops the same number of events (the floor any discrete-event link costs). The bar is one
//!    million frame events per second.

use std::hint::black_box;
use std::time::Instant;

use rovlink_base::stats::Running;
use rovlink_link::pipe::{self, Pace};
use rovlink_link::{Distance, Link, Model, Scheduler, SimTime};

fn model(ber: f64) -> Model {
    let mut model = Model::preset("s100").expect("preset");
    model.ber = ber;
    model
}

/// Runs `count` 57-byte frames back to back; returns (delay stats ms, delivered, events, seconds).
fn run(model: Model, seed: u64, count: u64) -> (Running, u64, u64, f64) {
    let mut link = Link::symmetric(model, seed, Distance::Fixed(1.0)).expect("valid model");
    let frame = vec![0x55u8; 57];
    let mut sent = 0;
    let mut delay = Running::new();
    let mut delivered = 0;
    let start = Instant::now();
    pipe::run::<()>(
        &mut link,
        Pace::BackToBack,
        &std::sync::atomic::AtomicBool::new(false),
        |_| {
            sent += 1;
            Ok((sent <= count).then(|| frame.clone()))
        },
        |report| {
            if let Some(t_rx) = report.t_rx {
                delivered += 1;
                delay.push((t_rx.0 - report.t_offered.0) as f64 * 1e-6);
            }
            black_box(&report);
            Ok(())
        },
    )
    .expect("no errors");
    let seconds = start.elapsed().as_secs_f64();
    (delay, delivered, link.events_scheduled(), seconds)
}

/// The anchor: the same number of events through a bare scheduler, three per frame in flight.
fn anchor(events: u64) -> f64 {
    let start = Instant::now();
    let mut sched: Scheduler<u64> = Scheduler::new();
    let mut t = 0u64;
    for k in 0..events {
        t += 1000 + (k * 7919) % 5000;
        sched.schedule(SimTime(t), k);
        if sched.len() > 3 {
            black_box(sched.pop());
        }
    }
    while let Some(e) = sched.pop() {
        black_box(e);
    }
    start.elapsed().as_secs_f64()
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(|a, b| a.total_cmp(b));
    values[values.len() / 2]
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let (stat_frames, speed_frames, reps) = if quick {
        (20_000, 200_000, 3)
    } else {
        (200_000, 1_000_000, 7)
    };

    println!("Statistics, S100 preset, {stat_frames} frames of 57 bytes back to back (seed 1):");
    let (delay, delivered, _, _) = run(model(0.0), 1, stat_frames);
    let mean_err = delay.mean() / 325.0 - 1.0;
    let std_err = delay.std() / 13.2 - 1.0;
    println!(
        "  BER 0     mean delay {:.3} ms (model 325.0, {:+.3} %, bar 1 %)  jitter {:.3} ms (model 13.2, {:+.2} %, bar 7 %)  delivered {delivered}",
        delay.mean(),
        100.0 * mean_err,
        delay.std(),
        100.0 * std_err
    );
    let (_, delivered, _, _) = run(model(7e-4), 1, stat_frames);
    let p = (1.0f64 - 7e-4).powi(456);
    let half = 2.576 * (p * (1.0 - p) / stat_frames as f64).sqrt();
    let ratio = delivered as f64 / stat_frames as f64;
    println!(
        "  BER 7e-4  delivered {:.3} % (model {:.3} %, 99 % interval {:.3} .. {:.3} %): {}",
        100.0 * ratio,
        100.0 * p,
        100.0 * (p - half),
        100.0 * (p + half),
        if (ratio - p).abs() <= half {
            "inside"
        } else {
            "OUTSIDE"
        }
    );

    println!("\nSpeed, one core, {speed_frames} frames per run, median of {reps}:");
    let mut rates = Vec::new();
    let mut event_rates = Vec::new();
    let mut anchor_rates = Vec::new();
    for rep in 0..reps {
        let (_, _, events, seconds) = run(model(7e-4), rep + 1, speed_frames);
        rates.push(speed_frames as f64 / seconds);
        event_rates.push(events as f64 / seconds);
        anchor_rates.push(events as f64 / anchor(events));
    }
    let (frames_s, events_s, anchor_s) = (median(rates), median(event_rates), median(anchor_rates));
    println!(
        "  link pipe (S100, BER 7e-4)   {:>7.2} M frames/s   {:>7.2} M events/s",
        frames_s * 1e-6,
        events_s * 1e-6
    );
    println!(
        "  anchor: bare scheduler                              {:>7.2} M events/s",
        anchor_s * 1e-6
    );
    println!(
        "  link events/s = {:.2} x anchor; bar: >= 1 M frame events/s ({})",
        events_s / anchor_s,
        if frames_s >= 1e6 {
            "met, counting frames"
        } else if events_s >= 1e6 {
            "met, counting events"
        } else {
            "NOT met"
        }
    );
}
