//! Compression trials (`debt-encode --sweep`): encode an image at a budget, decode it back,
//! and measure quality and time, one [`Trial`] per image and budget.

use std::time::Instant;

use super::{EncodeOptions, Error, Image, decode, encode, metrics, picture};

/// The columns of a trials CSV, in [`Trial`]'s field order.
pub const COLUMNS: [&str; 11] = [
    "image",
    "width",
    "height",
    "budget_bytes",
    "bytes",
    "psnr_rgb_db",
    "psnr_y_db",
    "ssim",
    "ms_ssim",
    "encode_ms",
    "decode_ms",
];

/// One trial's figures (quality against the image as coded: its luma for a grey stream).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Trial {
    /// The image's name.
    pub image: String,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// The budget asked for.
    pub budget_bytes: u64,
    /// The stream's length (the budget, or less when the image coded completely).
    pub bytes: usize,
    /// PSNR over every sample, dB, three decimals.
    pub psnr_rgb_db: String,
    /// PSNR of luma, dB, three decimals.
    pub psnr_y_db: String,
    /// SSIM of luma, five decimals.
    pub ssim: String,
    /// MS-SSIM of luma, five decimals.
    pub ms_ssim: String,
    /// Encoding time, ms.
    pub encode_ms: String,
    /// Decoding time, ms.
    pub decode_ms: String,
}

/// Encodes `img` with `options`, decodes the stream and measures the result.
pub fn run(name: &str, img: &Image, options: &EncodeOptions) -> Result<Trial, Error> {
    let started = Instant::now();
    let stream = encode(img, options)?;
    let encode_ms = started.elapsed().as_secs_f64() * 1e3;
    measure(name, img, options, &stream, encode_ms)
}

/// Decodes `stream`, the encoding of `img` with `options` that took `encode_ms`, and measures
/// the result.
pub fn measure(
    name: &str,
    img: &Image,
    options: &EncodeOptions,
    stream: &[u8],
    encode_ms: f64,
) -> Result<Trial, Error> {
    let started = Instant::now();
    let decoded = decode(stream)?;
    let decode_ms = started.elapsed().as_secs_f64() * 1e3;
    let reference = if decoded.channels == 1 {
        picture::to_gray(img)
    } else {
        img.clone()
    };
    Ok(Trial {
        image: name.to_string(),
        width: img.width,
        height: img.height,
        budget_bytes: options.bytes as u64,
        bytes: stream.len(),
        psnr_rgb_db: format!("{:.3}", metrics::psnr(&reference, &decoded)),
        psnr_y_db: format!("{:.3}", metrics::psnr_y(&reference, &decoded)),
        ssim: format!("{:.5}", metrics::ssim(&reference, &decoded)),
        ms_ssim: format!("{:.5}", metrics::ms_ssim(&reference, &decoded)),
        encode_ms: format!("{encode_ms:.2}"),
        decode_ms: format!("{decode_ms:.2}"),
    })
}

impl Trial {
    /// The trial as JSON with its measured columns as numbers (`debt-encode --metrics`).
    pub fn figures(&self) -> serde_json::Value {
        serde_json::json!({
            "image": self.image,
            "width": self.width,
            "height": self.height,
            "budget_bytes": self.budget_bytes,
            "bytes": self.bytes,
            "psnr_rgb_db": number(&self.psnr_rgb_db),
            "psnr_y_db": number(&self.psnr_y_db),
            "ssim": number(&self.ssim),
            "ms_ssim": number(&self.ms_ssim),
            "encode_ms": number(&self.encode_ms),
            "decode_ms": number(&self.decode_ms),
        })
    }
}

/// A measured column's text as a number (NaN if it were not one).
fn number(text: &str) -> f64 {
    text.parse().unwrap_or(f64::NAN)
}

/// The figures of many trials as JSON (`debt-encode --metrics`): the number of trials and
/// images, and per budget the mean of every measured column over the images.
pub fn summary(trials: &[Trial]) -> serde_json::Value {
    let mut budgets: Vec<u64> = trials.iter().map(|t| t.budget_bytes).collect();
    budgets.sort_unstable();
    budgets.dedup();
    let mut images: Vec<&str> = trials.iter().map(|t| t.image.as_str()).collect();
    images.sort_unstable();
    images.dedup();
    let mut per_budget = serde_json::Map::new();
    for budget in budgets {
        let at: Vec<&Trial> = trials.iter().filter(|t| t.budget_bytes == budget).collect();
        let mean =
            |field: fn(&Trial) -> f64| at.iter().map(|&t| field(t)).sum::<f64>() / at.len() as f64;
        per_budget.insert(
            budget.to_string(),
            serde_json::json!({
                "images": at.len(),
                "bytes": mean(|t| t.bytes as f64),
                "psnr_rgb_db": mean(|t| number(&t.psnr_rgb_db)),
                "psnr_y_db": mean(|t| number(&t.psnr_y_db)),
                "ssim": mean(|t| number(&t.ssim)),
                "ms_ssim": mean(|t| number(&t.ms_ssim)),
                "encode_ms": mean(|t| number(&t.encode_ms)),
                "decode_ms": mean(|t| number(&t.decode_ms)),
            }),
        );
    }
    serde_json::json!({
        "trials": trials.len(),
        "images": images.len(),
        "budgets": per_budget,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trial_measures_its_stream() {
        let img = Image {
            width: 16,
            height: 8,
            channels: 3,
            data: (0..16 * 8 * 3).map(|v| (v * 5 % 251) as u8).collect(),
        };
        let options = EncodeOptions {
            bytes: 200,
            gray: true,
            ..EncodeOptions::default()
        };
        let trial = run("t.png", &img, &options).unwrap();
        assert_eq!(
            (trial.width, trial.height, trial.budget_bytes),
            (16, 8, 200)
        );
        assert!(trial.bytes <= 200);
        assert!(trial.psnr_y_db.parse::<f64>().unwrap() > 10.0, "{trial:?}");
        let row = serde_json::to_value(&trial).unwrap();
        let keys: Vec<&String> = row.as_object().unwrap().keys().collect();
        assert_eq!(keys, COLUMNS);
    }

    #[test]
    fn the_summary_averages_each_budget_over_the_images() {
        let trial = |image: &str, budget: u64, psnr: &str| Trial {
            image: image.into(),
            width: 4,
            height: 4,
            budget_bytes: budget,
            bytes: budget as usize,
            psnr_rgb_db: psnr.into(),
            psnr_y_db: psnr.into(),
            ssim: "0.5".into(),
            ms_ssim: "0.5".into(),
            encode_ms: "1".into(),
            decode_ms: "2".into(),
        };
        let s = summary(&[
            trial("a", 100, "20"),
            trial("b", 100, "22"),
            trial("a", 300, "30"),
        ]);
        assert_eq!((&s["trials"], &s["images"]), (&3.into(), &2.into()));
        assert_eq!(s["budgets"]["100"]["psnr_rgb_db"], 21.0);
        assert_eq!(s["budgets"]["300"]["images"], 1);
        assert_eq!(s["budgets"]["300"]["bytes"], 300.0);
    }
}
