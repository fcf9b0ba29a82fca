//! Process-level tests of debt-encode and debt-decode: the built binaries through files and pipes.

use crate::common::{run, testdata};

const ENCODE: &str = env!("TOOL_EXE_debt-encode");
const DECODE: &str = env!("TOOL_EXE_debt-decode");

fn load(bytes: &[u8]) -> image::DynamicImage {
    image::load_from_memory(bytes).expect("decoder output is an image")
}

fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (255.0 * 255.0 / mse).log10()
    }
}

#[test]
fn streams_are_exactly_the_budget_and_better_with_more_bytes() {
    let input = testdata("kodim23-64x48.png");
    let reference = image::open(&input).unwrap().into_rgb8().into_raw();
    let mut last = 0.0;
    for bytes in [30usize, 100, 300, 1000, 3000] {
        let enc = run(
            ENCODE,
            &[input.to_str().unwrap(), "--bytes", &bytes.to_string()],
            b"",
        );
        assert_eq!(enc.code, 0, "{}", enc.stderr);
        assert_eq!(enc.stdout.len(), bytes);
        let dec = run(DECODE, &[], &enc.stdout);
        assert_eq!(dec.code, 0, "{}", dec.stderr);
        let img = load(&dec.stdout);
        assert_eq!((img.width(), img.height()), (64, 48));
        let q = psnr(&reference, &img.into_rgb8().into_raw());
        assert!(
            q > last,
            "{bytes} bytes: {q:.2} dB, fewer bytes gave {last:.2} dB"
        );
        last = q;
    }
}

#[test]
fn any_prefix_decodes() {
    let input = testdata("peppers-gray-64.png");
    let enc = run(ENCODE, &[input.to_str().unwrap(), "-b", "1500"], b"");
    assert_eq!(enc.code, 0, "{}", enc.stderr);
    let dir = tempfile::tempdir().unwrap();
    let stream = dir.path().join("p.debt");
    std::fs::write(&stream, &enc.stdout).unwrap();
    for cut in ["5", "6", "50", "700", "1500", "99999"] {
        let out = dir.path().join(format!("p{cut}.pgm"));
        let dec = run(
            DECODE,
            &[
                stream.to_str().unwrap(),
                "--bytes",
                cut,
                "-o",
                out.to_str().unwrap(),
            ],
            b"",
        );
        assert_eq!(dec.code, 0, "cut {cut}: {}", dec.stderr);
        let img = image::open(&out).unwrap();
        assert_eq!(
            (img.width(), img.height(), img.color()),
            (64, 64, image::ColorType::L8)
        );
    }
}

#[test]
fn lossless_round_trip_through_files() {
    let input = testdata("kodim23-64x48.png");
    let enc = run(
        ENCODE,
        &[input.to_str().unwrap(), "--lossless", "--bytes", "1000000"],
        b"",
    );
    assert_eq!(enc.code, 0, "{}", enc.stderr);
    assert!(enc.stdout.len() < 64 * 48 * 3, "{} bytes", enc.stdout.len());
    let dec = run(DECODE, &[], &enc.stdout);
    let reference = image::open(&input).unwrap().into_rgb8().into_raw();
    assert_eq!(load(&dec.stdout).into_rgb8().into_raw(), reference);
}

#[test]
fn bad_inputs_are_clear_errors_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"this is not an image").unwrap();
    let out = dir.path().join("out.debt");
    let enc = run(
        ENCODE,
        &[
            junk.to_str().unwrap(),
            "--bytes",
            "100",
            "-o",
            out.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(enc.code, 2);
    assert!(
        enc.stderr.contains("junk.png: not a readable image"),
        "{}",
        enc.stderr
    );
    assert!(!out.exists());

    let picture = dir.path().join("out.png");
    let dec = run(
        DECODE,
        &["-o", picture.to_str().unwrap()],
        b"\x55\x10\x11 not debt",
    );
    assert_eq!(dec.code, 2);
    assert!(
        dec.stderr.contains("not a DEBT stream: first byte 0x55"),
        "{}",
        dec.stderr
    );
    assert!(!picture.exists());
    let version = run(DECODE, &[], b"\xd9\x00\x00\x00\x00");
    assert!(
        version.stderr.contains("DEBT version 9 is not supported"),
        "{}",
        version.stderr
    );

    let input = testdata("kodim23-64x48.png");
    let roi = run(
        ENCODE,
        &[input.to_str().unwrap(), "-b", "100", "--roi", "0,0,65,10"],
        b"",
    );
    assert_eq!(roi.code, 2);
    assert!(
        roi.stderr.contains("reaches outside the 64x48 image"),
        "{}",
        roi.stderr
    );
    let tiny = run(ENCODE, &[input.to_str().unwrap(), "-b", "4"], b"");
    assert_eq!(tiny.code, 2);
    assert!(
        tiny.stderr.contains("bytes: expected at least the header"),
        "{}",
        tiny.stderr
    );
    assert_eq!(
        run(
            ENCODE,
            &[input.to_str().unwrap(), "-b", "100", "--roi", "5,5,2,9"],
            b""
        )
        .code,
        2
    );
}

#[test]
fn roi_raises_quality_inside_the_region() {
    let input = testdata("kodim23-64x48.png");
    let reference = image::open(&input).unwrap().into_rgb8();
    let region = |img: &image::RgbImage| -> Vec<u8> {
        let mut v = Vec::new();
        for y in 16..32 {
            for x in 16..40 {
                v.extend_from_slice(&img.get_pixel(x, y).0);
            }
        }
        v
    };
    let decode = |extra: &[&str]| {
        let mut args = vec![input.to_str().unwrap(), "-b", "200"];
        args.extend_from_slice(extra);
        let enc = run(ENCODE, &args, b"");
        assert_eq!(enc.code, 0, "{}", enc.stderr);
        load(&run(DECODE, &[], &enc.stdout).stdout).into_rgb8()
    };
    let plain = psnr(&region(&reference), &region(&decode(&[])));
    let roi = psnr(
        &region(&reference),
        &region(&decode(&["--roi", "16,16,40,32", "--roi-shift", "4"])),
    );
    assert!(roi > plain + 1.0, "ROI {roi:.2} dB, plain {plain:.2} dB");
}

#[test]
fn sweep_writes_one_row_per_image_and_budget_and_keeps_rows_on_failure() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("trials.csv");
    let rgb = testdata("kodim23-64x48.png");
    let gray = testdata("peppers-gray-64.png");
    let out = run(
        ENCODE,
        &[
            "--sweep",
            "60,200,800",
            "--csv",
            csv.to_str().unwrap(),
            rgb.to_str().unwrap(),
            gray.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 0, "{}", out.stderr);
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(
        rows[0].join(","),
        "image,width,height,budget_bytes,bytes,psnr_rgb_db,psnr_y_db,ssim,ms_ssim,encode_ms,decode_ms"
    );
    assert_eq!(rows.len(), 1 + 6);
    for image_rows in rows[1..].chunks(3) {
        let psnrs: Vec<f64> = image_rows.iter().map(|r| r[5].parse().unwrap()).collect();
        assert!(psnrs.windows(2).all(|w| w[1] > w[0]), "{psnrs:?}");
        for r in image_rows {
            assert_eq!(r[3], r[4], "bytes equal the budget");
            let ssim: f64 = r[7].parse().unwrap();
            assert!(ssim > 0.0 && ssim <= 1.0);
            let ms_ssim: f64 = r[8].parse().unwrap();
            assert!(ms_ssim > 0.0 && ms_ssim <= 1.0);
        }
    }
    // A bad image after a good one: exit 2, found from its header before any trial, so the
    // CSV is not touched (the earlier run's rows stay) and a new one is not made.
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"junk").unwrap();
    let out = run(
        ENCODE,
        &[
            "--sweep",
            "60,200",
            "--csv",
            csv.to_str().unwrap(),
            rgb.to_str().unwrap(),
            junk.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 2);
    assert!(
        out.stderr.contains("junk.png: not a readable image"),
        "{}",
        out.stderr
    );
    assert_eq!(
        std::fs::read_to_string(&csv).unwrap().lines().count(),
        1 + 6
    );
    let fresh = dir.path().join("fresh.csv");
    let out = run(
        ENCODE,
        &[
            "--sweep",
            "60",
            "--csv",
            fresh.to_str().unwrap(),
            rgb.to_str().unwrap(),
            junk.to_str().unwrap(),
        ],
        b"",
    );
    assert_eq!(out.code, 2);
    assert!(!fresh.exists(), "no output file on exit 2");
    // --bytes or --sweep, not neither.
    assert_eq!(run(ENCODE, &[rgb.to_str().unwrap()], b"").code, 2);
}

#[test]
fn erased_trunks_decode_the_prefix_before_the_first_loss() {
    let input = testdata("peppers-gray-64.png");
    let enc = run(ENCODE, &[input.to_str().unwrap(), "-b", "400"], b"");
    let dir = tempfile::tempdir().unwrap();
    let stream = dir.path().join("p.debt");
    std::fs::write(&stream, &enc.stdout).unwrap();
    let s = stream.to_str().unwrap();
    let erased = run(DECODE, &[s, "--trunk-size", "39", "--erase", "7,3"], b"");
    let prefix = run(DECODE, &[s, "--bytes", "117"], b"");
    assert_eq!(erased.code, 0, "{}", erased.stderr);
    assert_eq!(
        erased.stdout, prefix.stdout,
        "trunks 3.. lost = the first 3 x 39 bytes"
    );
    let header_lost = run(DECODE, &[s, "--trunk-size", "39", "--erase", "0"], b"");
    assert_eq!(header_lost.code, 2);
    assert!(
        header_lost
            .stderr
            .contains("trunk 0 (the header) was lost and no parity brought it back"),
        "{}",
        header_lost.stderr
    );
    assert_eq!(
        run(DECODE, &[s, "--erase", "3"], b"").code,
        2,
        "--erase needs --trunk-size"
    );
}

#[test]
fn parity_trunks_bring_back_lost_trunks_and_the_header() {
    let input = testdata("kodim23-64x48.png");
    let dir = tempfile::tempdir().unwrap();
    let stream = dir.path().join("p.debt");
    let s = stream.to_str().unwrap();
    let enc = run(
        ENCODE,
        &[
            input.to_str().unwrap(),
            "-b",
            "1000",
            "--fec",
            "20",
            "-o",
            s,
        ],
        b"",
    );
    assert_eq!(enc.code, 0, "{}", enc.stderr);
    // 25 whole 39-byte trunks (975 bytes), 5 of them parity.
    let bytes = std::fs::read(&stream).unwrap();
    assert_eq!((bytes[0], bytes.len()), (0xd5, 975));
    let whole = run(DECODE, &[s], b"");
    assert_eq!(whole.code, 0, "{}", whole.stderr);
    for erase in ["0", "3,7", "0,1,2,3,4", "19,20,21,22,23"] {
        let erased = run(DECODE, &[s, "--trunk-size", "39", "--erase", erase], b"");
        assert_eq!(erased.code, 0, "{erase}: {}", erased.stderr);
        assert_eq!(erased.stdout, whole.stdout, "{erase}: recovered");
    }
    // One more than the parity: the prefix before the first gap.
    let erased = run(
        DECODE,
        &[s, "--trunk-size", "39", "--erase", "3,4,5,6,7,8"],
        b"",
    );
    let prefix = run(DECODE, &[s, "--bytes", "117"], b"");
    assert_eq!(erased.code, 0, "{}", erased.stderr);
    assert_eq!(erased.stdout, prefix.stdout);
    // Bad settings: one line, exit 2, no output.
    for bad in [
        &["--fec", "0"][..],
        &["--fec", "51"],
        &["--fec", "10", "--lossless"],
        &["--fec", "10", "--segments", "2"],
        &["--fec", "10", "-b", "60"],
        &["--trunk-size", "39"],
    ] {
        let out = dir.path().join("bad.debt");
        let mut args = vec![input.to_str().unwrap(), "-o", out.to_str().unwrap()];
        args.extend_from_slice(bad);
        if !bad.contains(&"-b") {
            args.extend_from_slice(&["-b", "1000"]);
        }
        let r = run(ENCODE, &args, b"");
        assert_eq!(r.code, 2, "{bad:?}: {}", r.stderr);
        assert_eq!(r.stderr.trim().lines().count().min(1), 1, "{bad:?}");
        assert!(!out.exists(), "{bad:?}");
    }
}

#[test]
fn segmented_streams_lose_one_segment_per_lost_trunk() {
    let input = testdata("kodim23-64x48.png");
    let reference = image::open(&input).unwrap().into_rgb8().into_raw();
    let i = input.to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let quality = |args: &[&str], erase: Option<&str>| -> f64 {
        let enc = run(ENCODE, args, b"");
        assert_eq!(enc.code, 0, "{}", enc.stderr);
        assert_eq!(enc.stdout.len(), 800);
        let stream = dir.path().join("s.debt");
        std::fs::write(&stream, &enc.stdout).unwrap();
        let s = stream.to_str().unwrap();
        let mut dec_args = vec![s];
        if let Some(e) = erase {
            dec_args.extend(["--trunk-size", "20", "--erase", e]);
        }
        let dec = run(DECODE, &dec_args, b"");
        assert_eq!(dec.code, 0, "{}", dec.stderr);
        psnr(&reference, &load(&dec.stdout).into_rgb8().into_raw())
    };
    let plain = [i, "-b", "800"];
    let segmented = [i, "-b", "800", "--segments", "3", "--trunk-size", "20"];
    let (plain_whole, seg_whole) = (quality(&plain, None), quality(&segmented, None));
    let (plain_lost, seg_lost) = (quality(&plain, Some("4")), quality(&segmented, Some("4")));
    assert!(
        seg_whole > plain_whole - 1.0,
        "{seg_whole:.2} vs {plain_whole:.2}"
    );
    assert!(
        seg_lost > plain_lost + 1.0,
        "trunk 4 lost: segmented {seg_lost:.2} dB, plain {plain_lost:.2} dB"
    );
    let lone_trunk_size = run(ENCODE, &[i, "-b", "800", "--trunk-size", "20"], b"");
    assert_eq!(lone_trunk_size.code, 2, "--trunk-size needs --segments");
    let tiny_trunk = run(
        ENCODE,
        &[i, "-b", "800", "--segments", "3", "--trunk-size", "8"],
        b"",
    );
    assert_eq!(tiny_trunk.code, 2);
}
