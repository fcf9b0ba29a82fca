#!/usr/bin/env python3
"""Real-time accuracy of link-sim over pseudo-terminals.

Starts `link-sim --pty` with the S100 model without jitter (so every frame's scheduled delay is
known exactly: 85 ms + size x 8 / 1900 bit/s), writes frames into side A one at a time, reads
them from side B, and reports how late each arrived against its scheduled time: p50, p99, max.
The figure includes everything a program on the far side sees (link-sim's timer, its writer
thread, the pseudo-terminal, this script's own wake-up). link-sim's own view (when it handed each
frame to the port) is read from its --stats file and printed beside it.

link-sim runs twice: with its default scheduling, and with --rt-priority (SCHED_FIFO, which
needs root or CAP_SYS_NICE). This script also asks for SCHED_FIFO for itself, so its
own wake-ups disturb the end-to-end figure as little as possible.

Usage: scripts/pty-latency.py [--count N] [--size BYTES] [--gap-ms MS] [--link-sim PATH]
"""
import argparse
import json
import os
import select
import subprocess
import sys
import tempfile
import time
import tty

from wireframe import frame


def numbered_frame(seq, size):
    """A frame of `size` bytes (header and CRC included) whose payload depends on `seq`."""
    return frame(1, 2, bytes((seq * 7 + j) & 0xFF for j in range(size - 5)))


def quantile(sorted_values, q):
    rank = max(1, min(len(sorted_values), int(-(-q * len(sorted_values) // 1))))
    return sorted_values[rank - 1]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=200, help="frames to send [200]")
    parser.add_argument("--size", type=int, default=57, help="frame size, bytes [57]")
    parser.add_argument("--gap-ms", type=float, default=20.0,
                        help="pause after each frame arrives before the next is sent [20]")
    parser.add_argument("--link-sim", default="target/release/link-sim")
    args = parser.parse_args()
    if not os.path.exists(args.link_sim):
        sys.exit(f"pty-latency: {args.link_sim} not found: run `cargo build --release` first")

    expected_ms = 85.0 + args.size * 8 / 1900 * 1000
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        me = "SCHED_FIFO"
    except (PermissionError, AttributeError, OSError):
        me = "normal scheduling"
    print(f"link-sim --pty, S100 without jitter, {args.count} frames of {args.size} bytes each "
          f"run, scheduled delay {expected_ms:.3f} ms; this script under {me}")
    print(f"{'link-sim scheduling':<22} {'measured at':<28} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8}")
    for label, extra in (("default", []), ("--rt-priority", ["--rt-priority"])):
        late_ms, stats = measure(args, expected_ms, extra)
        print(f"{label:<22} {'the far program':<28} {quantile(late_ms, 0.5):8.3f} "
              f"{quantile(late_ms, 0.99):8.3f} {late_ms[-1]:8.3f}")
        print(f"{'':<22} {'link-sim, handed to port':<28} {stats['delivery_lateness_ms_p50']:8.3f} "
              f"{stats['delivery_lateness_ms_p99']:8.3f} {stats['delivery_lateness_ms_max']:8.3f}")
        sys.stdout.flush()
    print("bar: p99 within 2 ms")


def measure(args, expected_ms, extra):
    stats_path = os.path.join(tempfile.mkdtemp(), "stats.json")
    proc = subprocess.Popen(
        [args.link_sim, "--model", "s100", "--jitter-distribution", "none", "--pty",
         "--stats", stats_path] + extra,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    side_a = proc.stdout.readline().decode().strip()
    side_b = proc.stdout.readline().decode().strip()
    fa = os.open(side_a, os.O_RDWR | os.O_NOCTTY)
    fb = os.open(side_b, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fa)
    tty.setraw(fb)
    late_ms = []
    try:
        for seq in range(args.count):
            data = numbered_frame(seq, args.size)
            sent = time.monotonic()
            os.write(fa, data)
            got = b""
            while len(got) < len(data):
                ready, _, _ = select.select([fb], [], [], 5.0)
                if not ready:
                    sys.exit(f"pty-latency: frame {seq} did not arrive within 5 s")
                got += os.read(fb, 4096)
            arrived = time.monotonic()
            if got != data:
                sys.exit(f"pty-latency: frame {seq} arrived changed")
            late_ms.append((arrived - sent) * 1000 - expected_ms)
            if (seq + 1) % 50 == 0:
                print(f"  {seq + 1}/{args.count} frames", file=sys.stderr)
            time.sleep(args.gap_ms / 1000)
    finally:
        proc.terminate()
        proc.communicate(timeout=10)
        os.close(fa)
        os.close(fb)
    with open(stats_path) as f:
        stats = json.load(f)["real_time"]
    late_ms.sort()
    return late_ms, stats


if __name__ == "__main__":
    main()
