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
    let started = Instant::now();
    let decoded = decode(&stream)?;
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
}
