#!/usr/bin/env python3
"""DEBT speed and ROI figures against the anchors measured in the same run.

Speed: a 1280x720 colour image (UIEB 616, read from ../shared and written as PPM to a temporary
directory so that no PNG decoding is timed) is encoded to 6000 bytes by debt-encode and by
opj_compress (9/7, -I, rate set for about 6000 bytes), and both streams are decoded, runs
interleaved; the table gives the median wall time of each and the ratio to OpenJPEG.

ROI: each underwater image resized to 640 wide is coded at 1000 bytes without and with a centred
ROI (a quarter and a sixteenth of the area, shift 3 and 5); the table gives the ROI's PSNR.

On a shared machine, --quiet-gate waits before each interleaved round until the CPUs were at
least 90 % idle for a quarter of a second (giving up on a round after --gate-timeout seconds,
when the round runs anyway and is counted as loaded), so that other work does not land in the
medians; the line above the table says how many rounds ran quiet.

Usage: scripts/debt-bench.sh [--runs N] [--restore] [--no-roi] [--quiet-gate]
"""
import argparse
import math
import os
import statistics
import subprocess
import tempfile
import time

import numpy as np
from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "testdata", "images")
ENC = os.path.join(ROOT, "target", "release", "debt-encode")
DEC = os.path.join(ROOT, "target", "release", "debt-decode")


def timed(cmd):
    start = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def idle_fraction(seconds=0.25):
    """The fraction of the machine's CPU time spent idle over the next `seconds`."""
    def read():
        with open("/proc/stat") as f:
            values = [int(v) for v in f.readline().split()[1:]]
        return values[3] + values[4], sum(values)
    idle0, total0 = read()
    time.sleep(seconds)
    idle1, total1 = read()
    return (idle1 - idle0) / max(1, total1 - total0)


def wait_quiet(timeout_s):
    """Waits until the machine was at least 90 % idle for a quarter of a second; False if it
    never was within `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if idle_fraction() >= 0.9:
            return True
    return False


def speed(tmp, runs, restore, gate_timeout_s=None):
    src = os.path.join(tmp, "u616.ppm")
    Image.open(os.path.join(SHARED, "uieb-616.png")).convert("RGB").save(src)
    w, h = Image.open(src).size
    ratio = w * h * 3 / 6000
    keys = ["debt-encode", "opj_compress", "debt-decode", "opj_decompress"]
    if restore:
        keys += ["debt-encode --restore", "debt-decode (v3)"]
    times = {k: [] for k in keys}
    debt, j2k = os.path.join(tmp, "s.debt"), os.path.join(tmp, "s.j2k")
    debt3 = os.path.join(tmp, "s3.debt")
    quiet = 0
    for _ in range(runs):
        if gate_timeout_s is not None:
            quiet += wait_quiet(gate_timeout_s)
        times["debt-encode"].append(timed([ENC, src, "--bytes", "6000", "-o", debt]))
        times["opj_compress"].append(timed(["opj_compress", "-i", src, "-o", j2k, "-r", f"{ratio:.3f}", "-I"]))
        times["debt-decode"].append(timed([DEC, debt, "-o", os.path.join(tmp, "d.ppm")]))
        times["opj_decompress"].append(timed(["opj_decompress", "-i", j2k, "-o", os.path.join(tmp, "j.ppm")]))
        if restore:
            times["debt-encode --restore"].append(timed([ENC, src, "--bytes", "6000", "--restore", "-o", debt3]))
            times["debt-decode (v3)"].append(timed([DEC, debt3, "-o", os.path.join(tmp, "d3.ppm")]))
    med = {k: statistics.median(v) * 1e3 for k, v in times.items()}
    print(f"speed: {w}x{h} RGB, DEBT {os.path.getsize(debt)} B, J2K {os.path.getsize(j2k)} B, {runs} runs, median ms")
    if gate_timeout_s is not None:
        print(f"  quiet gate: {quiet} of {runs} rounds started on a quiet machine")
    print(f"  {'encode':<8} DEBT {med['debt-encode']:7.1f}  OpenJPEG {med['opj_compress']:7.1f}  "
          f"ratio {med['debt-encode'] / med['opj_compress']:.2f} (bar <= 0.25)")
    print(f"  {'decode':<8} DEBT {med['debt-decode']:7.1f}  OpenJPEG {med['opj_decompress']:7.1f}  "
          f"ratio {med['debt-decode'] / med['opj_decompress']:.2f} (bar <= 0.7)")
    if restore:
        print(f"  {'encode':<8} DEBT --restore {med['debt-encode --restore']:7.1f}  "
              f"ratio {med['debt-encode --restore'] / med['opj_compress']:.2f} (bar <= 0.25)")
        print(f"  {'decode':<8} DEBT v3 {med['debt-decode (v3)']:7.1f}  "
              f"ratio {med['debt-decode (v3)'] / med['opj_decompress']:.2f} (bar <= 0.7)")


def psnr(a, b):
    mse = ((a - b) ** 2).mean()
    return float("inf") if mse == 0 else 10 * math.log10(255 * 255 / mse)


def roi(tmp):
    print("ROI at 1000 bytes: PSNR of the region (dB), mean over the underwater images")
    cases = [("quarter", 4), ("sixteenth", 16)]
    results = {}
    for name in ("uieb-616", "uieb-866", "uieb-880"):
        im = Image.open(os.path.join(SHARED, name + ".png")).convert("RGB")
        w, h = im.size
        im = im.resize((640, round(h * 640 / w)), Image.LANCZOS)
        src = os.path.join(tmp, name + ".ppm")
        im.save(src)
        ref = np.asarray(im, dtype=np.float64)
        W, H = im.size
        for label, area in cases:
            side = math.sqrt(area)
            x0, y0 = int(W / 2 - W / side / 2), int(H / 2 - H / side / 2)
            x1, y1 = int(W / 2 + W / side / 2), int(H / 2 + H / side / 2)
            for shift in (None, 3, 5):
                extra = [] if shift is None else ["--roi", f"{x0},{y0},{x1},{y1}", "--roi-shift", str(shift)]
                out, dec = os.path.join(tmp, "r.debt"), os.path.join(tmp, "r.ppm")
                subprocess.run([ENC, src, "--bytes", "1000", "-o", out] + extra, check=True)
                subprocess.run([DEC, out, "-o", dec], check=True)
                got = np.asarray(Image.open(dec), dtype=np.float64)
                results.setdefault((label, shift), []).append(psnr(ref[y0:y1, x0:x1], got[y0:y1, x0:x1]))
    for label, _ in cases:
        base = statistics.mean(results[(label, None)])
        row = "  ".join(f"shift {s}: {statistics.mean(results[(label, s)]):.2f} ({statistics.mean(results[(label, s)]) - base:+.2f})"
                        for s in (3, 5))
        print(f"  {label:<9} no ROI: {base:.2f}  {row}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=15)
    ap.add_argument("--restore", action="store_true",
                    help="also time debt-encode --restore (version 3) and its decode in the same runs")
    ap.add_argument("--no-roi", action="store_true", help="skip the ROI table")
    ap.add_argument("--quiet-gate", action="store_true",
                    help="start each round only once the machine is quiet (see above)")
    ap.add_argument("--gate-timeout", type=float, default=30.0, metavar="SECONDS",
                    help="how long a round waits for quiet before it runs anyway (default 30)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        speed(tmp, args.runs, args.restore, args.gate_timeout if args.quiet_gate else None)
        if not args.no_roi:
            roi(tmp)


if __name__ == "__main__":
    main()
