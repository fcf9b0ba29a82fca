#!/usr/bin/env python3
"""The loss trade-off of DEBT streams cut into trunks: mean PSNR with nothing lost, and with a
share of the 39-byte trunks lost at random (seeded: the same patterns for every layout), for
plain streams, segmented streams (`--segments K`: segK) and streams with parity trunks
(`--fec P`: fecP). Trunk 0 (the header) is spared unless --lose-header; a picture that cannot
be decoded at all counts as a flat mid-grey one. Prints a table; --csv writes the rows too."""
import argparse, csv, os, random, subprocess, sys, tempfile
import numpy as np
from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.join(ROOT, "target", "release")
SHARED = os.path.join(ROOT, "..", "shared", "testdata", "images")


def psnr(ref, path):
    out = Image.open(path)
    a = np.asarray(ref.convert(out.mode), dtype=np.float64)
    b = np.asarray(out, dtype=np.float64)
    mse = ((a - b) ** 2).mean()
    return 99.0 if mse == 0 else 10 * np.log10(255 * 255 / mse)


def images(tmp):
    """Underwater images at 640 wide (read from ../shared, never copied into the repository)
    and the grey 512 x 512 images."""
    out = []
    for name in ["uieb-616", "uieb-866", "uieb-880"]:
        path = os.path.join(SHARED, name + ".png")
        if os.path.exists(path):
            im = Image.open(path).convert("RGB")
            w, h = im.size
            dest = os.path.join(tmp, f"{name}-640.ppm")
            im.resize((640, round(h * 640 / w)), Image.LANCZOS).save(dest)
            out.append(dest)
    for name in ["barbara-gray", "peppers-gray"]:
        path = os.path.join(SHARED, name + ".png")
        if os.path.exists(path):
            out.append(path)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--bytes", default="500,1000,2000,4000,8000")
    ap.add_argument("--layouts", default="plain,seg2,seg4,fec10,fec15,fec20",
                    help="comma list of plain, segK (--segments K), fecP (--fec P)")
    ap.add_argument("--lose-header", action="store_true",
                    help="trunk 0 may be lost too (a plain or segmented stream then shows nothing)")
    ap.add_argument("--loss", default="0,0.05,0.2", help="shares of trunks lost")
    ap.add_argument("--patterns", type=int, default=8, help="loss patterns per image")
    ap.add_argument("--trunk-size", type=int, default=39)
    ap.add_argument("--csv")
    args = ap.parse_args()
    budgets = [int(b) for b in args.bytes.split(",")]
    layouts = args.layouts.split(",")
    for k in layouts:
        if not (k == "plain" or (k[:3] in ("seg", "fec") and k[3:].isdigit())):
            sys.exit(f"debt-loss: --layouts: expected plain, segK or fecP, found {k!r}")
    losses = [float(x) for x in args.loss.split(",")]
    t = args.trunk_size
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        files = images(tmp)
        if not files:
            sys.exit("debt-loss: no test images found in " + SHARED)
        refs = {f: Image.open(f) for f in files}
        stream, decoded = os.path.join(tmp, "s.debt"), os.path.join(tmp, "s.png")
        print(f"{len(files)} images, {t}-byte trunks; mean PSNR in dB", flush=True)
        print(f"{'bytes':>6} {'loss':>5} " + " ".join(f"{k:>7}" for k in layouts))
        for b in budgets:
            trunks = -(-b // t)
            for loss in losses:
                line = []
                for k in layouts:
                    scores = []
                    for f in files:
                        enc = [f"{BIN}/debt-encode", f, "--bytes", str(b), "-o", stream]
                        if k.startswith("seg"):
                            enc += ["--segments", k[3:], "--trunk-size", str(t)]
                        elif k.startswith("fec"):
                            enc += ["--fec", k[3:], "--trunk-size", str(t)]
                        subprocess.run(enc, check=True)
                        rng = random.Random(f"{f}-{b}")
                        first = 0 if args.lose_header else 1
                        for _ in range(args.patterns if loss > 0 else 1):
                            # The same draws for every layout: trunk i is lost or not by the
                            # same number whatever the stream's length.
                            draws = [rng.random() for _ in range(trunks)]
                            n = -(-os.path.getsize(stream) // t)
                            lost = [i for i in range(first, n) if draws[i] < loss]
                            dec = [f"{BIN}/debt-decode", stream, "-o", decoded]
                            if lost:
                                dec += ["--trunk-size", str(t), "--erase", ",".join(map(str, lost))]
                            if subprocess.run(dec, stderr=subprocess.DEVNULL).returncode == 0:
                                scores.append(psnr(refs[f], decoded))
                            else:
                                flat = Image.new(refs[f].mode, refs[f].size, (128,) * len(refs[f].getbands()))
                                flat.save(decoded)
                                scores.append(psnr(refs[f], decoded))
                    mean = float(np.mean(scores))
                    line.append(mean)
                    rows.append({"bytes": b, "loss": loss, "layout": k, "psnr_db": round(mean, 3)})
                print(f"{b:>6} {loss:>5} " + " ".join(f"{v:>7.2f}" for v in line), flush=True)
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=["bytes", "loss", "layout", "psnr_db"])
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
