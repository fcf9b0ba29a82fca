//! Picture files to and from the codec's [`Image`]: the one image loader of the toolkit.
//!
//! - Reading: any format the `image` crate is built with (PNG, JPEG, PNM, BMP, TIFF, GIF, WebP,
//!   TGA, QOI), from bytes, a file, or every picture in a directory. Grey pictures stay grey
//!   (one channel), everything else becomes 8-bit RGB.
//! - Bounded memory: at most [`MAX_INPUT_BYTES`] of file are read, and the dimensions are
//!   checked from the file's header before anything is decoded: a picture wider or taller than
//!   [`MAX_PICTURE_SIDE`] (the most DEBT codes) is refused, never decoded.
//! - Writing: PNG, JPEG, binary PPM/PGM/PNM, BMP and TIFF, chosen by the file's extension
//!   ([`OutputFormat`]).
//! - Grey conversion ([`to_gray`]): BT.601 luma with one rounding (to nearest, halves up),
//!   shared by every caller.

use std::borrow::Cow;
use std::io::{Cursor, Read};
use std::path::{Path, PathBuf};

use super::{Image, MAX_SIDE, metrics};

/// Widest and tallest picture read, pixels: the most a DEBT stream holds.
pub const MAX_PICTURE_SIDE: usize = MAX_SIDE;

/// Most bytes of a picture file read (a 4096 x 4096 16-bit RGBA TIFF is 128 MiB).
pub const MAX_INPUT_BYTES: u64 = 256 << 20;

/// JPEG quality of written pictures (the image has been through a lossy codec already).
const JPEG_QUALITY: u8 = 92;

/// What can go wrong reading or writing a picture; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum PictureError {
    /// The file could not be opened or read.
    #[error("{name}: cannot read: {source}")]
    Read {
        /// The file.
        name: String,
        /// The reason.
        source: std::io::Error,
    },
    /// More bytes than any picture this loader takes.
    #[error("{name}: more than {} MiB: not a picture this tool reads", MAX_INPUT_BYTES >> 20)]
    TooManyBytes {
        /// The file.
        name: String,
    },
    /// Not a picture in a format this build reads, or a damaged one.
    #[error("{name}: not a readable image: {reason}")]
    Format {
        /// The file.
        name: String,
        /// What the decoder said.
        reason: String,
    },
    /// Larger than [`MAX_PICTURE_SIDE`] a side.
    #[error(
        "{name}: {width}x{height} pixels, larger than the {MAX_PICTURE_SIDE}x{MAX_PICTURE_SIDE} \
         this tool reads: scale it down first"
    )]
    TooLarge {
        /// The file.
        name: String,
        /// Width in pixels, from the file's header.
        width: u64,
        /// Height in pixels, from the file's header.
        height: u64,
    },
    /// More pixels than a scaled-down read decodes ([`Oversize::ScaleDown`]).
    #[error(
        "{name}: {width}x{height} pixels: pictures of at most {} megapixels are scaled down to \
         fit; scale it down first",
        max_pixels >> 20
    )]
    TooManyPixels {
        /// The file.
        name: String,
        /// Width in pixels, from the file's header.
        width: u64,
        /// Height in pixels, from the file's header.
        height: u64,
        /// The most pixels decoded.
        max_pixels: u64,
    },
    /// A directory without a single readable picture.
    #[error("{name}: no image found in the directory")]
    NoImage {
        /// The directory.
        name: String,
    },
    /// An output file whose extension names no format this build writes.
    #[error(
        "{name}: cannot write {found:?} pictures: the extension must be one of {OUTPUT_EXTENSIONS}"
    )]
    OutputExtension {
        /// The file.
        name: String,
        /// The extension found (empty: none).
        found: String,
    },
    /// The encoder failed.
    #[error("cannot encode the picture as {format:?}: {reason}")]
    Encode {
        /// The format.
        format: OutputFormat,
        /// What the encoder said.
        reason: String,
    },
}

/// The extensions [`OutputFormat::for_path`] knows, for messages.
pub const OUTPUT_EXTENSIONS: &str = ".png, .jpg, .jpeg, .ppm, .pgm, .pnm, .bmp, .tif, .tiff";

/// Picture formats written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFormat {
    /// PNG, grey or RGB as the image is.
    Png,
    /// JPEG, grey or RGB as the image is.
    Jpeg,
    /// Binary PPM (P6): always RGB.
    Ppm,
    /// Binary PGM (P5): always grey (luma).
    Pgm,
    /// Binary PGM or PPM as the image is.
    Pnm,
    /// BMP.
    Bmp,
    /// TIFF.
    Tiff,
}

impl OutputFormat {
    /// The format an output path's extension asks for (case-insensitive); PNG for a path
    /// without one (and for standard output). Any other extension is an error naming the
    /// ones written, rather than a PNG under a misleading name.
    pub fn for_path(path: &Path) -> Result<OutputFormat, PictureError> {
        let Some(ext) = path.extension() else {
            return Ok(OutputFormat::Png);
        };
        let ext = ext.to_string_lossy().to_ascii_lowercase();
        Ok(match ext.as_str() {
            "png" => OutputFormat::Png,
            "jpg" | "jpeg" => OutputFormat::Jpeg,
            "ppm" => OutputFormat::Ppm,
            "pgm" => OutputFormat::Pgm,
            "pnm" => OutputFormat::Pnm,
            "bmp" => OutputFormat::Bmp,
            "tif" | "tiff" => OutputFormat::Tiff,
            _ => {
                return Err(PictureError::OutputExtension {
                    name: path.display().to_string(),
                    found: ext,
                });
            }
        })
    }
}

/// What to do with a picture larger than DEBT codes ([`MAX_PICTURE_SIDE`] a side).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Oversize {
    /// Refuse it ([`PictureError::TooLarge`]): what the codec's tools do.
    Refuse,
    /// Decode it if it has at most `max_pixels`, then scale it down, aspect kept, to fit (a
    /// camera's pictures); more pixels than that is [`PictureError::TooManyPixels`].
    ScaleDown {
        /// The most pixels decoded.
        max_pixels: u64,
    },
}

/// A picture as read: the image, and the size it had if it was scaled down to fit.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The file.
    pub path: PathBuf,
    /// The image, at most [`MAX_PICTURE_SIDE`] a side.
    pub image: Image,
    /// The picture's own width and height, when it was scaled down.
    pub scaled_from: Option<(usize, usize)>,
}

/// Decodes a picture file's bytes; `name` is what errors call it. A picture larger than DEBT
/// codes is refused.
pub fn from_bytes(name: &str, bytes: &[u8]) -> Result<Image, PictureError> {
    from_bytes_fit(name, bytes, Oversize::Refuse).map(|(image, _)| image)
}

/// Decodes a picture file's bytes, dealing with a large one as `oversize` says; the
/// dimensions are checked from the header before a pixel is decoded. Returns the image and,
/// if it was scaled down, the picture's own size.
pub fn from_bytes_fit(
    name: &str,
    bytes: &[u8],
    oversize: Oversize,
) -> Result<(Image, Option<(usize, usize)>), PictureError> {
    let format_error = |e: &dyn std::fmt::Display| PictureError::Format {
        name: name.to_string(),
        reason: e.to_string(),
    };
    let reader = || {
        image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| format_error(&e))
    };
    let (width, height) = reader()?.into_dimensions().map_err(|e| format_error(&e))?;
    if width == 0 || height == 0 {
        return Err(format_error(&format!("{width}x{height} pixels")));
    }
    let fits = width as usize <= MAX_PICTURE_SIDE && height as usize <= MAX_PICTURE_SIDE;
    let mut limits = image::Limits::default();
    match oversize {
        _ if fits => {
            limits.max_image_width = Some(MAX_PICTURE_SIDE as u32);
            limits.max_image_height = Some(MAX_PICTURE_SIDE as u32);
        }
        Oversize::Refuse => {
            return Err(PictureError::TooLarge {
                name: name.to_string(),
                width: width.into(),
                height: height.into(),
            });
        }
        Oversize::ScaleDown { max_pixels } => {
            if u64::from(width) * u64::from(height) > max_pixels {
                return Err(PictureError::TooManyPixels {
                    name: name.to_string(),
                    width: width.into(),
                    height: height.into(),
                    max_pixels,
                });
            }
            // RGBA at 16 bits a sample is the most a decoder holds per pixel.
            limits.max_alloc = Some(max_pixels.saturating_mul(8));
        }
    }
    let mut decoding = reader()?;
    decoding.limits(limits);
    let image = to_image(decoding.decode().map_err(|e| format_error(&e))?);
    if fits {
        return Ok((image, None));
    }
    let from = (image.width, image.height);
    Ok((scale_to_fit(&image, MAX_PICTURE_SIDE), Some(from)))
}

/// `image` scaled down (triangle filter), aspect kept, to at most `max_side` a side (at least
/// one pixel); an image that fits is returned as it is.
pub fn scale_to_fit(image: &Image, max_side: usize) -> Image {
    let longest = image.width.max(image.height);
    if longest <= max_side {
        return image.clone();
    }
    let side = |n: usize| (n * max_side).div_ceil(longest).clamp(1, max_side);
    let (width, height) = (side(image.width), side(image.height));
    let filter = image::imageops::FilterType::Triangle;
    let (w, h) = (width as u32, height as u32);
    let (iw, ih) = (image.width as u32, image.height as u32);
    let data = if image.channels == 1 {
        image::GrayImage::from_raw(iw, ih, image.data.clone())
            .map(|buffer| image::imageops::resize(&buffer, w, h, filter).into_raw())
    } else {
        image::RgbImage::from_raw(iw, ih, image.data.clone())
            .map(|buffer| image::imageops::resize(&buffer, w, h, filter).into_raw())
    };
    Image {
        width,
        height,
        channels: image.channels,
        data: data.unwrap_or_else(|| vec![0; width * height * image.channels]),
    }
}

/// A decoded picture as grey (one channel) if it has no colour, else RGB.
fn to_image(decoded: image::DynamicImage) -> Image {
    let (width, height) = (decoded.width() as usize, decoded.height() as usize);
    if decoded.color().has_color() {
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
    }
}

/// Reads a picture from any reader (standard input, say), at most [`MAX_INPUT_BYTES`].
pub fn read(name: &str, reader: impl Read) -> Result<Image, PictureError> {
    let bytes = rovlink_base::io::read_bounded(reader, MAX_INPUT_BYTES)
        .map_err(|source| PictureError::Read {
            name: name.to_string(),
            source,
        })?
        .ok_or_else(|| PictureError::TooManyBytes {
            name: name.to_string(),
        })?;
    from_bytes(name, &bytes)
}

/// A binary PGM or PPM of 8-bit samples that fits ([`MAX_PICTURE_SIDE`]), has no comment and
/// is exactly as long as its header says, as an image of the file's samples, copied once
/// (the `image` crate's reader copies twice); `None` for anything else (the `image` crate
/// reads it, and names what is wrong).
fn plain_pnm(bytes: &[u8]) -> Option<Image> {
    let channels = match bytes.get(..2)? {
        b"P5" => 1,
        b"P6" => 3,
        _ => return None,
    };
    let mut at = 2;
    let mut fields = [0usize; 3];
    for field in &mut fields {
        let start = at;
        while bytes.get(at)?.is_ascii_whitespace() {
            at += 1;
        }
        if at == start {
            return None;
        }
        let digits = bytes[at..]
            .iter()
            .take_while(|b| b.is_ascii_digit())
            .count();
        if digits == 0 || digits > 5 {
            return None;
        }
        *field = std::str::from_utf8(&bytes[at..at + digits])
            .ok()?
            .parse()
            .ok()?;
        at += digits;
    }
    let [width, height, maxval] = fields;
    // One whitespace byte ends the header.
    if maxval != 255 || !bytes.get(at)?.is_ascii_whitespace() {
        return None;
    }
    let fits = (1..=MAX_PICTURE_SIDE).contains(&width) && (1..=MAX_PICTURE_SIDE).contains(&height);
    let samples = &bytes[at + 1..];
    if !fits || samples.len() != width * height * channels {
        return None;
    }
    Some(Image {
        width,
        height,
        channels,
        data: samples.to_vec(),
    })
}

/// Reads a picture file.
pub fn open(path: &Path) -> Result<Image, PictureError> {
    open_fit(path, Oversize::Refuse).map(|loaded| loaded.image)
}

/// Reads a picture file, dealing with a large one as `oversize` says.
pub fn open_fit(path: &Path, oversize: Oversize) -> Result<Loaded, PictureError> {
    let name = path.display().to_string();
    let bytes = match rovlink_base::io::read_file_bounded(path, MAX_INPUT_BYTES) {
        Ok(Some(bytes)) => bytes,
        Ok(None) => return Err(PictureError::TooManyBytes { name }),
        Err(source) => return Err(PictureError::Read { name, source }),
    };
    if let Some(image) = plain_pnm(&bytes) {
        return Ok(Loaded {
            path: path.to_path_buf(),
            image,
            scaled_from: None,
        });
    }
    let (image, scaled_from) = from_bytes_fit(&name, &bytes, oversize)?;
    Ok(Loaded {
        path: path.to_path_buf(),
        image,
        scaled_from,
    })
}

/// The pictures a path names: the file itself, or every readable picture in a directory
/// (sorted by name; files that are not pictures are skipped, a picture too large is an error).
pub fn load(path: &Path) -> Result<Vec<(PathBuf, Image)>, PictureError> {
    Ok(load_fit(path, Oversize::Refuse)?
        .into_iter()
        .map(|loaded| (loaded.path, loaded.image))
        .collect())
}

/// [`load`], dealing with large pictures as `oversize` says.
pub fn load_fit(path: &Path, oversize: Oversize) -> Result<Vec<Loaded>, PictureError> {
    let name = path.display().to_string();
    if !path.is_dir() {
        return Ok(vec![open_fit(path, oversize)?]);
    }
    let mut pictures = Vec::new();
    for file in files_in(path)? {
        match open_fit(&file, oversize) {
            Ok(loaded) => pictures.push(loaded),
            Err(PictureError::Format { .. }) => {}
            Err(e) => return Err(e),
        }
    }
    if pictures.is_empty() {
        return Err(PictureError::NoImage { name });
    }
    Ok(pictures)
}

/// A picture [`list`] found: its path, and its width and height in pixels when its header was
/// read.
pub type Listed = (PathBuf, Option<(usize, usize)>);

/// Checks a picture file from its header alone, without decoding it: a format this build
/// reads, at least one pixel and at most [`MAX_PICTURE_SIDE`] a side. Returns its width and
/// height in pixels. Only what [`open`] would read whole can be checked this way: call it on
/// regular files (a pipe's bytes would be spent).
pub fn probe(path: &Path) -> Result<(usize, usize), PictureError> {
    let name = path.display().to_string();
    let format_error = |e: &dyn std::fmt::Display| PictureError::Format {
        name: name.clone(),
        reason: e.to_string(),
    };
    let reader = image::ImageReader::open(path).map_err(|source| PictureError::Read {
        name: name.clone(),
        source,
    })?;
    let reader = reader.with_guessed_format().map_err(|e| format_error(&e))?;
    let (width, height) = reader.into_dimensions().map_err(|e| format_error(&e))?;
    if width == 0 || height == 0 {
        return Err(format_error(&format!("{width}x{height} pixels")));
    }
    if width as usize > MAX_PICTURE_SIDE || height as usize > MAX_PICTURE_SIDE {
        return Err(PictureError::TooLarge {
            name,
            width: width.into(),
            height: height.into(),
        });
    }
    Ok((width as usize, height as usize))
}

/// The pictures a list of paths names, each checked from its header ([`probe`]) before any is
/// decoded: a directory stands for the pictures in it (sorted by name; files that are not
/// pictures skipped, none at all an error), a regular file must be a picture, and anything
/// else (`-` for standard input, a pipe) is kept as it is, read when its turn comes. Each
/// picture comes with its width and height when they are known.
pub fn list(paths: &[PathBuf]) -> Result<Vec<Listed>, PictureError> {
    let mut pictures = Vec::new();
    for path in paths {
        if path.is_dir() {
            let before = pictures.len();
            for file in files_in(path)? {
                match probe(&file) {
                    Ok(size) => pictures.push((file, Some(size))),
                    Err(PictureError::Format { .. }) => {}
                    Err(e) => return Err(e),
                }
            }
            if pictures.len() == before {
                return Err(PictureError::NoImage {
                    name: path.display().to_string(),
                });
            }
        } else if path.is_file() {
            pictures.push((path.clone(), Some(probe(path)?)));
        } else {
            pictures.push((path.clone(), None));
        }
    }
    Ok(pictures)
}

/// The files of a directory (not its subdirectories), sorted by name: what [`load`] tries.
pub fn files_in(dir: &Path) -> Result<Vec<PathBuf>, PictureError> {
    let entries = std::fs::read_dir(dir).map_err(|source| PictureError::Read {
        name: dir.display().to_string(),
        source,
    })?;
    let mut files: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    Ok(files)
}

/// One 8-bit sample from a computed value: to nearest, halves up, clamped to 0..=255.
pub fn sample(value: f64) -> u8 {
    (value.clamp(0.0, 255.0) + 0.5) as u8
}

/// The luma (BT.601) of an image as a grey image; a grey image as it is.
pub fn to_gray(img: &Image) -> Image {
    if img.channels == 1 {
        return img.clone();
    }
    Image {
        width: img.width,
        height: img.height,
        channels: 1,
        data: metrics::luma(img).into_iter().map(sample).collect(),
    }
}

/// An image as RGB (a grey one with its sample in every channel).
pub fn to_rgb(img: &Image) -> Image {
    if img.channels == 3 {
        return img.clone();
    }
    Image {
        width: img.width,
        height: img.height,
        channels: 3,
        data: img.data.iter().flat_map(|&v| [v, v, v]).collect(),
    }
}

/// Encodes an image as PNG (grey or RGB, as it is).
pub fn to_png(img: &Image) -> Result<Vec<u8>, PictureError> {
    encode(img, OutputFormat::Png)
}

/// Encodes an image as JPEG at `quality` (1..=100), grey or RGB as it is: for previews,
/// where size matters more than the last detail.
pub fn to_jpeg(img: &Image, quality: u8) -> Result<Vec<u8>, PictureError> {
    use image::ImageEncoder;
    let color = if img.channels == 1 {
        image::ExtendedColorType::L8
    } else {
        image::ExtendedColorType::Rgb8
    };
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality.clamp(1, 100))
        .write_image(&img.data, img.width as u32, img.height as u32, color)
        .map_err(|e| PictureError::Encode {
            format: OutputFormat::Jpeg,
            reason: e.to_string(),
        })?;
    Ok(bytes)
}

/// Encodes an image in a format: `Ppm` always RGB, `Pgm` always grey ([`to_gray`]), the
/// others as the image is.
pub fn encode(img: &Image, format: OutputFormat) -> Result<Vec<u8>, PictureError> {
    let (mut bytes, samples) = encode_parts(img, format)?;
    bytes.extend_from_slice(&samples);
    Ok(bytes)
}

/// [`encode`] in two parts, to be written one after the other: a PNM of the image's own
/// channels is its header and, borrowed rather than copied, the image's samples; any other
/// file is whole in the first part and the second is empty.
pub fn encode_parts(
    img: &Image,
    format: OutputFormat,
) -> Result<(Vec<u8>, Cow<'_, [u8]>), PictureError> {
    let pnm = matches!(
        format,
        OutputFormat::Ppm | OutputFormat::Pgm | OutputFormat::Pnm
    );
    let converted = match format {
        OutputFormat::Ppm if img.channels == 1 => Some(to_rgb(img)),
        OutputFormat::Pgm if img.channels == 3 => Some(to_gray(img)),
        _ => None,
    };
    if pnm {
        let shown = converted.as_ref().unwrap_or(img);
        let magic = if shown.channels == 1 { "P5" } else { "P6" };
        let head = format!("{magic}\n{} {}\n255\n", shown.width, shown.height).into_bytes();
        let samples = match converted {
            Some(other) => Cow::Owned(other.data),
            None => Cow::Borrowed(img.data.as_slice()),
        };
        return Ok((head, samples));
    }
    let img = converted.as_ref().unwrap_or(img);
    let color = if img.channels == 1 {
        image::ExtendedColorType::L8
    } else {
        image::ExtendedColorType::Rgb8
    };
    let (width, height) = (img.width as u32, img.height as u32);
    let mut bytes = Vec::new();
    let mut cursor = Cursor::new(&mut bytes);
    let written = match format {
        OutputFormat::Jpeg => {
            use image::ImageEncoder;
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut cursor, JPEG_QUALITY)
                .write_image(&img.data, width, height, color)
        }
        _ => {
            let kind = match format {
                OutputFormat::Bmp => image::ImageFormat::Bmp,
                OutputFormat::Tiff => image::ImageFormat::Tiff,
                _ => image::ImageFormat::Png,
            };
            image::write_buffer_with_format(&mut cursor, &img.data, width, height, color, kind)
        }
    };
    written.map_err(|e| PictureError::Encode {
        format,
        reason: e.to_string(),
    })?;
    Ok((bytes, Cow::Borrowed(&[])))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn picture(width: usize, height: usize, channels: usize) -> Image {
        Image {
            width,
            height,
            channels,
            data: (0..width * height * channels)
                .map(|v| (v * 7) as u8)
                .collect(),
        }
    }

    #[test]
    fn lossless_formats_round_trip_grey_and_colour() {
        for channels in [1, 3] {
            let img = picture(5, 3, channels);
            for format in [
                OutputFormat::Png,
                OutputFormat::Pnm,
                OutputFormat::Bmp,
                OutputFormat::Tiff,
            ] {
                let bytes = encode(&img, format).unwrap();
                let back = from_bytes("x", &bytes).unwrap();
                // BMP has no grey: it comes back as RGB.
                let expected = if back.channels == 3 {
                    to_rgb(&img)
                } else {
                    img.clone()
                };
                assert_eq!(back, expected, "{format:?} {channels}");
            }
            let ppm = from_bytes("x", &encode(&img, OutputFormat::Ppm).unwrap()).unwrap();
            assert_eq!(ppm, to_rgb(&img));
            let pgm = from_bytes("x", &encode(&img, OutputFormat::Pgm).unwrap()).unwrap();
            assert_eq!(pgm, to_gray(&img));
        }
        assert!(matches!(
            from_bytes("junk", b"not an image"),
            Err(PictureError::Format { .. })
        ));
    }

    #[test]
    fn plain_pnm_reads_as_the_image_crate_does() {
        for channels in [1, 3] {
            let img = picture(5, 3, channels);
            let format = if channels == 1 {
                OutputFormat::Pgm
            } else {
                OutputFormat::Ppm
            };
            let bytes = encode(&img, format).unwrap();
            assert_eq!(plain_pnm(&bytes).unwrap(), from_bytes("x", &bytes).unwrap());
            // A comment, a short or long file, another maxval: left to the image crate.
            let mut commented = b"P6 # a comment\n".to_vec();
            commented.extend_from_slice(&bytes[3..]);
            assert_eq!(plain_pnm(&commented), None);
            assert_eq!(plain_pnm(&bytes[..bytes.len() - 1]), None);
            assert_eq!(plain_pnm(&[&bytes[..], &[0]].concat()), None);
            let deep = String::from_utf8_lossy(&bytes[..12]).replace("255", "65535");
            assert_eq!(plain_pnm(deep.as_bytes()), None);
        }
    }

    #[test]
    fn jpeg_is_written_as_jpeg() {
        // debt-decode -o x.jpg wrote PNG bytes (issue 14).
        let path = Path::new("out/X.JPG");
        assert_eq!(OutputFormat::for_path(path).unwrap(), OutputFormat::Jpeg);
        let img = picture(16, 8, 3);
        let bytes = encode(&img, OutputFormat::Jpeg).unwrap();
        assert_eq!(&bytes[..2], &[0xff, 0xd8]);
        let back = from_bytes("x.jpg", &bytes).unwrap();
        assert_eq!((back.width, back.height), (16, 8));
        assert_eq!(
            OutputFormat::for_path(Path::new("-")).unwrap(),
            OutputFormat::Png
        );
        let err = OutputFormat::for_path(Path::new("x.gif")).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "x.gif: cannot write \"gif\" pictures: the extension must be one of {OUTPUT_EXTENSIONS}"
            )
        );
    }

    #[test]
    fn pictures_too_large_are_refused_from_their_header() {
        // A 20000 x 20000 PNG header: refused without decoding (or allocating) 1.2 GB.
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut chunk = |kind: &[u8], data: &[u8]| {
            png.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let body = [kind, data].concat();
            png.extend_from_slice(&body);
            let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&body);
            png.extend_from_slice(&crc.to_be_bytes());
        };
        let side = 20000u32.to_be_bytes();
        chunk(b"IHDR", &[&side[..], &side, &[8, 2, 0, 0, 0]].concat());
        chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
        chunk(b"IEND", &[]);
        let err = from_bytes("huge.png", &png).unwrap_err();
        assert_eq!(
            err.to_string(),
            "huge.png: 20000x20000 pixels, larger than the 4096x4096 this tool reads: scale it down first"
        );
        let pnm = b"P5\n5000 10\n255\n";
        assert!(matches!(
            from_bytes("tall.pgm", pnm),
            Err(PictureError::TooLarge { width: 5000, .. })
        ));
    }

    #[test]
    fn grey_conversion_rounds_once_to_nearest() {
        let img = Image {
            width: 3,
            height: 1,
            channels: 3,
            data: vec![255, 255, 255, 0, 0, 0, 10, 20, 30],
        };
        // 0.299 * 10 + 0.587 * 20 + 0.114 * 30 = 18.15
        assert_eq!(to_gray(&img).data, vec![255, 0, 18]);
        assert_eq!(sample(2.5), 3);
        assert_eq!(sample(-4.0), 0);
        assert_eq!(sample(300.0), 255);
    }

    #[test]
    fn directories_give_their_pictures_in_order() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("b.png"), to_png(&picture(4, 4, 3)).unwrap()).unwrap();
        std::fs::write(
            dir.path().join("a.pgm"),
            encode(&picture(2, 2, 1), OutputFormat::Pgm).unwrap(),
        )
        .unwrap();
        std::fs::write(dir.path().join("notes.txt"), "not a picture").unwrap();
        let found = load(dir.path()).unwrap();
        let names: Vec<_> = found
            .iter()
            .map(|(p, img)| (p.file_name().unwrap().to_owned(), img.channels))
            .collect();
        assert_eq!(names, [("a.pgm".into(), 1), ("b.png".into(), 3)]);
        let empty = tempfile::tempdir().unwrap();
        assert!(matches!(
            load(empty.path()),
            Err(PictureError::NoImage { .. })
        ));
        assert!(matches!(
            load(&dir.path().join("missing.png")),
            Err(PictureError::Read { .. })
        ));
    }
}
