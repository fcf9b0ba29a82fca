//! Image files to and from the codec's [`Image`]: any format the `image` crate reads, PNG out.
//!
//! Reading keeps grey pictures grey (one channel) and turns everything else into 8-bit RGB.

use super::Image;

/// Decodes an image file's bytes (PNG, JPEG, PNM, ...) into 8-bit grey or RGB.
pub fn from_file_bytes(bytes: &[u8]) -> Result<Image, image::ImageError> {
    let decoded = image::load_from_memory(bytes)?;
    let (width, height) = (decoded.width() as usize, decoded.height() as usize);
    Ok(if decoded.color().has_color() {
        Image {
            width,
            height,
            channels: 3,
            data: decoded.into_rgb8().into_raw(),
        }
    } else {
        Image {
            width,
            height,
            channels: 1,
            data: decoded.into_luma8().into_raw(),
        }
    })
}

/// Encodes an image as PNG (grey or RGB, as it is).
pub fn to_png(img: &Image) -> Result<Vec<u8>, image::ImageError> {
    let color = if img.channels == 1 {
        image::ExtendedColorType::L8
    } else {
        image::ExtendedColorType::Rgb8
    };
    let mut bytes = Vec::new();
    image::write_buffer_with_format(
        &mut std::io::Cursor::new(&mut bytes),
        &img.data,
        img.width as u32,
        img.height as u32,
        color,
        image::ImageFormat::Png,
    )?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips_grey_and_colour() {
        for channels in [1, 3] {
            let img = Image {
                width: 5,
                height: 3,
                channels,
                data: (0..15 * channels).map(|v| (v * 7) as u8).collect(),
            };
            assert_eq!(from_file_bytes(&to_png(&img).unwrap()).unwrap(), img);
        }
        assert!(from_file_bytes(b"not an image").is_err());
    }
}
