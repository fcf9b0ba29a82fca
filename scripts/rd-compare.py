#!/usr/bin/env python3
"""Equal-byte rate-distortion comparison of DEBT against JPEG 2000 (OpenJPEG, 9/7), WebP and AVIF.

For every image and byte budget, each codec's quality knob is searched for the largest file
that fits the budget (DEBT hits it exactly), the file is decoded, and PSNR is measured against
the original (RGB, or grey for grey images), with SSIM and MS-SSIM of luma beside it (the
definitions of debt-encode --sweep: BT.601 luma, 11-tap Gaussian window sigma 1.5, borders
clamped; MS-SSIM over five scales by 2x2 means, Wang et al.'s weights). AVIF is also tried on the image shrunk by 2 and 4
and scaled back up (bilinear), keeping the best: at a few hundred bytes its container and
headers alone nearly fill the budget. Prints a table of mean PSNR per set and budget, writes one
CSV row per image, budget and codec, and PNG plots of PSNR, SSIM and MS-SSIM against bytes.

The last column checks issue 18's bars: DEBT at least AVIF up to 4000 B (where AVIF reaches the
budget), within 0.3 dB of AVIF above, and at least OpenJPEG + 0.5 dB everywhere.

Usage: scripts/rd-compare.sh [--budgets 300,500,...] [--out DIR] [--quick] [--sets A,B]
       [--codecs debt] [--reference OLD/rd-compare.csv]
(the .sh wrapper installs the codecs and Python packages when missing).
"""
import argparse
import csv
import math
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
from PIL import Image, ImageDraw

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(ROOT, "..", "shared", "testdata", "images")
DEBT_ENCODE = os.path.join(ROOT, "target", "release", "debt-encode")
DEBT_DECODE = os.path.join(ROOT, "target", "release", "debt-decode")


def run(cmd):
    return subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0


def decoded(ref, path, resample=Image.BICUBIC):
    """The decoded file at `path` as `ref`'s mode and size (loaded now: the file is reused)."""
    img = Image.open(path)
    img.load()
    img = img.convert(ref.mode)
    return img if img.size == ref.size else img.resize(ref.size, resample)


def psnr(ref, img):
    a = np.asarray(ref, dtype=np.float64)
    b = np.asarray(img, dtype=np.float64)
    mse = ((a - b) ** 2).mean()
    return float("inf") if mse == 0 else 10 * math.log10(255 * 255 / mse)


def luma(img):
    a = np.asarray(img, dtype=np.float64)
    return a if a.ndim == 2 else 0.299 * a[..., 0] + 0.587 * a[..., 1] + 0.114 * a[..., 2]


_K = np.exp(-np.arange(-5, 6) ** 2 / (2 * 1.5 * 1.5))
_K /= _K.sum()


def blur(v):
    """Separable 11-tap Gaussian, borders clamped (as crates/debt/src/metrics.rs)."""
    p = np.pad(v, ((0, 0), (5, 5)), mode="edge")
    rows = sum(_K[k] * p[:, k:k + v.shape[1]] for k in range(11))
    p = np.pad(rows, ((5, 5), (0, 0)), mode="edge")
    return sum(_K[k] * p[k:k + v.shape[0], :] for k in range(11))


def ssim_terms(x, y):
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    mx, my = blur(x), blur(y)
    vx, vy, cxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    lum = (2 * mx * my + c1) / (mx * mx + my * my + c1)
    cs = (2 * cxy + c2) / (vx + vy + c2)
    return float((lum * cs).mean()), float(lum.mean()), float(cs.mean())


def ssim(ref, img):
    return ssim_terms(luma(ref), luma(img))[0]


MS_SSIM_WEIGHTS = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333]


def ms_ssim(ref, img):
    x, y = luma(ref), luma(img)
    terms = []
    for scale in range(5):
        _, lum, cs = ssim_terms(x, y)
        terms.append((max(cs, 0.0), max(lum, 0.0)))
        h, w = x.shape
        if scale == 4 or w // 2 < 11 or h // 2 < 11:
            break
        half = lambda a: (a[0:h // 2 * 2:2, 0:w // 2 * 2:2] + a[1:h // 2 * 2:2, 0:w // 2 * 2:2]
                          + a[0:h // 2 * 2:2, 1:w // 2 * 2:2] + a[1:h // 2 * 2:2, 1:w // 2 * 2:2]) / 4
        x, y = half(x), half(y)
    weights = MS_SSIM_WEIGHTS[:len(terms)]
    total = sum(weights)
    out = 1.0
    for k, ((cs, lum), wt) in enumerate(zip(terms, weights)):
        out *= (cs * lum if k == len(terms) - 1 else cs) ** (wt / total)
    return out


def search(encode, lo, hi, budget, bigger_is_larger=True, integer=True, steps=14):
    """Largest output <= budget over a monotone knob in [lo, hi]; encode(knob) -> path or None."""
    best = None
    a, b = lo, hi
    for _ in range(steps):
        if integer and b - a < 1:
            break
        mid = (a + b) // 2 if integer else (a * b) ** 0.5
        path = encode(mid)
        size = os.path.getsize(path) if path and os.path.exists(path) else None
        fits = size is not None and size <= budget
        if fits and (best is None or size > best[0]):
            best = (size, path, mid)
            keep = path + ".best"
            shutil.copyfile(path, keep)
            best = (size, keep, mid)
        # Move towards larger files when it fits, smaller when it does not.
        if fits == bigger_is_larger:
            a = mid + (1 if integer else 0)
        else:
            b = mid - (1 if integer else 0)
        if not integer and b / a < 1.005:
            break
    if integer:
        for knob in {a, b}:
            if lo <= knob <= hi:
                path = encode(knob)
                size = os.path.getsize(path) if path and os.path.exists(path) else None
                if size is not None and size <= budget and (best is None or size > best[0]):
                    shutil.copyfile(path, path + ".best")
                    best = (size, path + ".best", knob)
    return best


def debt(src, ref, budget, tmp):
    out, dec = os.path.join(tmp, "o.debt"), os.path.join(tmp, "o.png")
    if not (run([DEBT_ENCODE, src, "--bytes", str(budget), "-o", out]) and run([DEBT_DECODE, out, "-o", dec])):
        return None
    return os.path.getsize(out), decoded(ref, dec)


def j2k(src, ref, budget, tmp):
    raw = ref.size[0] * ref.size[1] * len(ref.getbands())
    out = os.path.join(tmp, "o.j2k")

    def enc(ratio):
        if os.path.exists(out):
            os.remove(out)
        return out if run(["opj_compress", "-i", src, "-o", out, "-r", f"{ratio:.5f}", "-I"]) else None

    # Larger ratio = smaller file.
    best = search(enc, raw / budget / 1.5, raw / budget * 50, budget, bigger_is_larger=False, integer=False, steps=30)
    if not best:
        return None
    dec = os.path.join(tmp, "j.png")
    if not run(["opj_decompress", "-i", best[1], "-o", dec]):
        return None
    return best[0], decoded(ref, dec)


def webp(src, ref, budget, tmp):
    out = os.path.join(tmp, "o.webp")

    def enc(q):
        return out if run(["cwebp", "-quiet", "-m", "6", "-q", str(q), src, "-o", out]) else None

    best = search(enc, 0, 100, budget)
    if not best:
        return None
    dec = os.path.join(tmp, "w.png")
    if not run(["dwebp", "-quiet", best[1], "-o", dec]):
        return None
    return best[0], decoded(ref, dec)


def avif(src, ref, budget, tmp):
    results = []
    for shrink in (1, 2, 4):
        small = os.path.join(tmp, f"s{shrink}.png")
        w, h = ref.size
        ref.resize((max(1, w // shrink), max(1, h // shrink)), Image.LANCZOS).save(small)
        out = os.path.join(tmp, "o.avif")

        def enc(q):
            # Quantiser 0 (best) .. 63 (worst): a larger q gives a smaller file.
            return out if run(["avifenc", "-s", "4", "--min", str(q), "--max", str(q), small, out]) else None

        best = search(enc, 0, 63, budget, bigger_is_larger=False)
        if not best:
            continue
        dec = os.path.join(tmp, "a.png")
        if run(["avifdec", best[1], dec]):
            results.append((best[0], decoded(ref, dec, Image.BILINEAR)))
    return max(results, key=lambda r: psnr(ref, r[1])) if results else None


def prepare(tmp, quick, wanted):
    """The sets: underwater images resized to 640 wide (read from ../shared, never copied into
    the repository), the grey 512 x 512 images, and the Kodak photographs (768 x 512 colour) we
    keep for checking that DEBT is tuned for photographs in general, not for the first two."""
    sets = {"underwater-640": [], "grey-512": [], "kodak-768": []}
    names = ["uieb-616", "uieb-866", "uieb-880"][: 1 if quick else 3]
    for name in names:
        path = os.path.join(SHARED, name + ".png")
        if not os.path.exists(path):
            continue
        im = Image.open(path).convert("RGB")
        w, h = im.size
        small = im.resize((640, round(h * 640 / w)), Image.LANCZOS)
        dest = os.path.join(tmp, f"{name}-640.ppm")
        small.save(dest)
        sets["underwater-640"].append(dest)
    for name in ["barbara-gray", "boats-gray", "peppers-gray"][: 1 if quick else 3]:
        path = os.path.join(SHARED, name + ".png")
        if os.path.exists(path):
            dest = os.path.join(tmp, f"{name}.pgm")
            Image.open(path).convert("L").save(dest)
            sets["grey-512"].append(dest)
    for name in ["kodim03", "kodim05", "kodim13", "kodim19", "kodim23"][: 1 if quick else 5]:
        path = os.path.join(SHARED, name + ".png")
        if os.path.exists(path):
            dest = os.path.join(tmp, f"{name}.ppm")
            Image.open(path).convert("RGB").save(dest)
            sets["kodak-768"].append(dest)
    return {k: v for k, v in sets.items() if k in wanted}


METRICS = {"psnr_db": "mean PSNR (dB)", "ssim": "mean SSIM", "ms_ssim": "mean MS-SSIM"}


def plot(rows, path, key="psnr_db"):
    """`key` against bytes, one panel per set, one line per codec (log-scaled bytes)."""
    codecs = ["debt", "j2k", "webp", "avif"]
    colours = {"debt": (200, 30, 30), "j2k": (30, 90, 200), "webp": (30, 150, 60), "avif": (150, 60, 170)}
    sets = sorted({r["set"] for r in rows})
    width, height, pad = 520, 360, 50
    canvas = Image.new("RGB", (width * len(sets), height), "white")
    draw = ImageDraw.Draw(canvas)
    for k, name in enumerate(sets):
        ox = k * width
        pts = [r for r in rows if r["set"] == name and r[key] not in ("", None)]
        if not pts:
            continue
        xs = [math.log10(float(r["budget_bytes"])) for r in pts]
        ys = [float(r[key]) for r in pts if math.isfinite(float(r[key]))]
        scale = 1.0 if key == "psnr_db" else 100.0
        ys = [v * scale for v in ys]
        x0, x1, y0, y1 = min(xs), max(xs), math.floor(min(ys)), math.ceil(max(ys))
        sx = lambda v: ox + pad + (v - x0) / max(x1 - x0, 1e-9) * (width - 2 * pad)
        sy = lambda v: height - pad - (v - y0) / max(y1 - y0, 1e-9) * (height - 2 * pad)
        draw.rectangle([ox + pad, pad, ox + width - pad, height - pad], outline="black")
        label = METRICS[key] + ("" if scale == 1.0 else " x 100")
        draw.text((ox + pad, 10), f"{name}: {label} vs bytes", fill="black")
        for b in sorted({int(r["budget_bytes"]) for r in pts}):
            draw.text((sx(math.log10(b)) - 12, height - pad + 5), str(b), fill="black")
        for v in range(y0, y1 + 1, max(1, (y1 - y0) // 6)):
            draw.text((ox + 10, sy(v) - 6), str(v), fill="black")
        for i, codec in enumerate(codecs):
            line = []
            for b in sorted({int(r["budget_bytes"]) for r in pts}):
                vals = [float(r[key]) * scale for r in pts if r["codec"] == codec and int(r["budget_bytes"]) == b]
                if vals and len(vals) == len({r["image"] for r in pts}):
                    line.append((sx(math.log10(b)), sy(sum(vals) / len(vals))))
            if len(line) > 1:
                draw.line(line, fill=colours[codec], width=2)
            for p in line:
                draw.ellipse([p[0] - 3, p[1] - 3, p[0] + 3, p[1] + 3], fill=colours[codec])
            draw.text((ox + width - pad - 60, pad + 8 + 14 * i), codec, fill=colours[codec])
    canvas.save(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--budgets", default="300,500,1000,2000,4000,8000,16000")
    ap.add_argument("--out", default="rd-compare")
    ap.add_argument("--quick", action="store_true", help="one image per set")
    ap.add_argument("--sets", default="underwater-640,grey-512,kodak-768",
                    help="comma list of sets: underwater-640, grey-512, kodak-768")
    ap.add_argument("--codecs", default="debt,j2k,webp,avif", help="codecs to run now")
    ap.add_argument("--reference", metavar="CSV",
                    help="an earlier run's rd-compare.csv: rows of the codecs not run now are taken "
                         "from it (same sets, images and budgets), so a DEBT experiment reruns in seconds")
    args = ap.parse_args()
    run_now = set(args.codecs.split(","))
    if not run_now <= {"debt", "j2k", "webp", "avif"}:
        sys.exit("rd-compare: --codecs: expected names among debt,j2k,webp,avif, found " + args.codecs)
    reference = {}
    if args.reference:
        with open(args.reference, newline="") as rf:
            for r in csv.DictReader(rf):
                reference[(r["set"], r["image"], int(r["budget_bytes"]), r["codec"])] = r
    budgets = [int(b) for b in args.budgets.split(",")]
    os.makedirs(args.out, exist_ok=True)
    csv_path = os.path.join(args.out, "rd-compare.csv")
    rows = []
    with tempfile.TemporaryDirectory() as tmp, open(csv_path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["set", "image", "budget_bytes", "codec", "bytes", "psnr_db",
                                               "ssim", "ms_ssim"])
        writer.writeheader()
        for set_name, images in prepare(tmp, args.quick, set(args.sets.split(","))).items():
            for src in images:
                ref = Image.open(src)
                for budget in budgets:
                    for codec, fn in (("debt", debt), ("j2k", j2k), ("webp", webp), ("avif", avif)):
                        if codec not in run_now:
                            old = reference.get((set_name, os.path.basename(src), budget, codec))
                            if old is not None:
                                old = dict(old, budget_bytes=budget)
                                writer.writerow(old)
                                rows.append(old)
                            continue
                        r = fn(src, ref, budget, tmp)
                        row = {"set": set_name, "image": os.path.basename(src), "budget_bytes": budget, "codec": codec,
                               "bytes": r[0] if r else "", "psnr_db": f"{psnr(ref, r[1]):.3f}" if r else "",
                               "ssim": f"{ssim(ref, r[1]):.5f}" if r else "",
                               "ms_ssim": f"{ms_ssim(ref, r[1]):.5f}" if r else ""}
                        writer.writerow(row)
                        f.flush()
                        rows.append(row)
                    print(f"\r{set_name} {os.path.basename(src)} {budget} B done   ", end="", file=sys.stderr)
        print(file=sys.stderr)
    # The table: mean PSNR per set and budget; n/a where a codec cannot go that small on some image.
    print(f"{'set':<16} {'bytes':>6} {'DEBT':>7} {'J2K':>7} {'WebP':>7} {'AVIF':>7} {'DEBT-J2K':>9} {'DEBT-AVIF':>10} {'bar':>5}")
    for set_name in sorted({r["set"] for r in rows}):
        n_images = len({r["image"] for r in rows if r["set"] == set_name})
        for budget in budgets:
            means = {}
            for codec in ("debt", "j2k", "webp", "avif"):
                vals = [float(r["psnr_db"]) for r in rows
                        if r["set"] == set_name and r["budget_bytes"] == budget and r["codec"] == codec and r["psnr_db"]]
                means[codec] = sum(vals) / len(vals) if len(vals) == n_images else None
            fmt = lambda v: f"{v:7.2f}" if v is not None else "    n/a"
            diff = lambda a, b: f"{means[a] - means[b]:+.2f}" if means[a] is not None and means[b] is not None else "n/a"
            bar = "n/a"
            if means["debt"] is not None and means["j2k"] is not None:
                ok = means["debt"] - means["j2k"] >= 0.5
                if means["avif"] is not None:
                    ok &= means["debt"] - means["avif"] >= (0.0 if budget <= 4000 else -0.3)
                bar = "ok" if ok else "FAIL"
            print(f"{set_name:<16} {budget:>6} {fmt(means['debt'])} {fmt(means['j2k'])} {fmt(means['webp'])} "
                  f"{fmt(means['avif'])} {diff('debt', 'j2k'):>9} {diff('debt', 'avif'):>10} {bar:>5}")
    # Perception: mean SSIM and MS-SSIM per set and budget.
    print(f"{'set':<16} {'bytes':>6} " + " ".join(f"{c + ' SSIM':>10} {c + ' MS':>8}" for c in ("debt", "j2k", "webp", "avif")))
    for set_name in sorted({r["set"] for r in rows}):
        n_images = len({r["image"] for r in rows if r["set"] == set_name})
        for budget in budgets:
            cells = []
            for codec in ("debt", "j2k", "webp", "avif"):
                for key in ("ssim", "ms_ssim"):
                    vals = [float(r[key]) for r in rows if r["set"] == set_name and r["budget_bytes"] == budget
                            and r["codec"] == codec and r[key]]
                    width = 10 if key == "ssim" else 8
                    cells.append(f"{sum(vals) / len(vals):>{width}.4f}" if len(vals) == n_images else f"{'n/a':>{width}}")
            print(f"{set_name:<16} {budget:>6} " + " ".join(cells))
    plots = {"psnr_db": "rd-compare.png", "ssim": "rd-compare-ssim.png", "ms_ssim": "rd-compare-ms-ssim.png"}
    for key, name in plots.items():
        plot(rows, os.path.join(args.out, name), key)
    print(f"wrote {csv_path} and " + ", ".join(os.path.join(args.out, n) for n in plots.values()), file=sys.stderr)


if __name__ == "__main__":
    main()
