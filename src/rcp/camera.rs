//! The ROV camera's pictures: one image file or a directory of them, checked before anything is
//! decoded.
//!
//! A picture's dimensions are read from its file header first. DEBT holds at most
//! [`debt::MAX_SIDE`] pixels a side: a larger picture of at most [`MAX_DECODED_PIXELS`] pixels is
//! decoded and scaled down to fit (the caller says so, from [`Pictures::scaled`]); a picture
//! beyond that, a file over [`MAX_FILE_BYTES`], or pictures holding more than
//! [`MAX_TOTAL_BYTES`] of pixels in all are refused before they are decoded, so a crafted header
//! never makes the camera allocate gigabytes.

use std::io::BufReader;
use std::path::{Path, PathBuf};

use crate::debt;

/// The largest picture decoded (and then scaled down), pixels: 64 megapixels, 192 MB of RGB.
pub const MAX_DECODED_PIXELS: u64 = 1 << 26;

/// The largest image file read, bytes.
pub const MAX_FILE_BYTES: u64 = 1 << 28;

/// The most pixel bytes the camera keeps for all its pictures together.
pub const MAX_TOTAL_BYTES: usize = 1 << 28;

/// What is wrong with the camera's pictures.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// A file or directory could not be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file or directory.
        path: PathBuf,
        /// The reason.
        source: std::io::Error,
    },
    /// A file given by name is not an image this crate reads.
    #[error("{path}: not an image this tool reads")]
    NotAnImage {
        /// The file.
        path: PathBuf,
    },
    /// A picture given by name that is not a regular file (a FIFO, a device).
    #[error("{path}: not a regular file: the camera reads image files")]
    NotAFile {
        /// The path.
        path: PathBuf,
    },
    /// An image file that does not decode.
    #[error("{path}: {source}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The decoder's reason.
        source: image::ImageError,
    },
    /// A file too big to read.
    #[error("{path}: more than {MAX_FILE_BYTES} bytes: too big for a camera picture")]
    FileTooBig {
        /// The file.
        path: PathBuf,
    },
    /// A picture too big to decode.
    #[error(
        "{path}: {width}x{height} pixels: the camera scales down pictures of at most {} megapixels; scale it down first",
        MAX_DECODED_PIXELS >> 20
    )]
    TooManyPixels {
        /// The file.
        path: PathBuf,
        /// Its width, pixels.
        width: u32,
        /// Its height, pixels.
        height: u32,
    },
    /// The pictures together are too big to keep.
    #[error(
        "{path}: the pictures hold more than {} MiB of pixels; use fewer or smaller ones",
        MAX_TOTAL_BYTES >> 20
    )]
    TooMuch {
        /// The directory or file.
        path: PathBuf,
    },
    /// A directory without any image.
    #[error("{path}: no image found")]
    Empty {
        /// The directory.
        path: PathBuf,
    },
}

/// A picture scaled down to fit DEBT.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scaled {
    /// The file.
    pub path: PathBuf,
    /// Its size in the file, pixels.
    pub from: (usize, usize),
    /// Its size as the camera keeps it, pixels.
    pub to: (usize, usize),
}

/// The camera's pictures, in file-name order.
#[derive(Debug, Clone)]
pub struct Pictures {
    /// The pictures, 8-bit grey or RGB, at most [`debt::MAX_SIDE`] a side.
    pub images: Vec<debt::Image>,
    /// The pictures that were scaled down, to say so.
    pub scaled: Vec<Scaled>,
}

impl Pictures {
    /// What to say once when pictures were scaled down, naming the first.
    pub fn note(&self) -> Option<String> {
        let first = self.scaled.first()?;
        let side = debt::MAX_SIDE;
        Some(format!(
            "{} picture(s) larger than DEBT's {side}x{side} scaled down to fit ({}: {}x{} to {}x{})",
            self.scaled.len(),
            first.path.display(),
            first.from.0,
            first.from.1,
            first.to.0,
            first.to.1,
        ))
    }
}

/// Reads one image file, or every image file of a directory (other files are skipped).
pub fn load(path: &Path) -> Result<Pictures, CameraError> {
    let read_error = |source| CameraError::Read {
        path: path.to_path_buf(),
        source,
    };
    let directory = std::fs::metadata(path).map_err(read_error)?.is_dir();
    let files = if directory {
        let mut files = Vec::new();
        for entry in std::fs::read_dir(path).map_err(read_error)? {
            let entry = entry.map_err(read_error)?;
            if entry
                .file_type()
                .is_ok_and(|t| t.is_file() || t.is_symlink())
            {
                files.push(entry.path());
            }
        }
        files.sort();
        files
    } else {
        vec![path.to_path_buf()]
    };
    let mut pictures = Pictures {
        images: Vec::new(),
        scaled: Vec::new(),
    };
    let mut total_bytes = 0usize;
    for file in files {
        let Some((image, scaled)) = picture(&file, !directory)? else {
            continue;
        };
        total_bytes = total_bytes.saturating_add(image.data.len());
        if total_bytes > MAX_TOTAL_BYTES {
            return Err(CameraError::TooMuch {
                path: path.to_path_buf(),
            });
        }
        pictures.images.push(image);
        pictures.scaled.extend(scaled);
    }
    if pictures.images.is_empty() {
        return Err(CameraError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(pictures)
}

/// One file's picture; `None` for a file of a directory that is not an image (`named` false).
fn picture(path: &Path, named: bool) -> Result<Option<(debt::Image, Option<Scaled>)>, CameraError> {
    let read_error = |source| CameraError::Read {
        path: path.to_path_buf(),
        source,
    };
    // Only regular files: a FIFO would block, a device such as /dev/zero never ends.
    if !std::fs::metadata(path).map_err(read_error)?.is_file() {
        if named {
            return Err(CameraError::NotAFile {
                path: path.to_path_buf(),
            });
        }
        return Ok(None);
    }
    // The header first, read from the file as far as the decoder needs: nothing else is read
    // from a file that is not an image or too big a picture.
    let file = std::fs::File::open(path).map_err(read_error)?;
    let reader = image::ImageReader::new(BufReader::new(file))
        .with_guessed_format()
        .map_err(read_error)?;
    if reader.format().is_none() {
        if named {
            return Err(CameraError::NotAnImage {
                path: path.to_path_buf(),
            });
        }
        return Ok(None);
    }
    let decode_error = |source| CameraError::Decode {
        path: path.to_path_buf(),
        source,
    };
    let (width, height) = reader.into_dimensions().map_err(decode_error)?;
    if u64::from(width) * u64::from(height) > MAX_DECODED_PIXELS {
        return Err(CameraError::TooManyPixels {
            path: path.to_path_buf(),
            width,
            height,
        });
    }
    let Some(data) = super::read_at_most(path, MAX_FILE_BYTES).map_err(read_error)? else {
        return Err(CameraError::FileTooBig {
            path: path.to_path_buf(),
        });
    };
    let image = debt::picture::from_file_bytes(&data).map_err(decode_error)?;
    let from = (image.width, image.height);
    if from.0 <= debt::MAX_SIDE && from.1 <= debt::MAX_SIDE {
        return Ok(Some((image, None)));
    }
    let image = fit(&image);
    let scaled = Scaled {
        path: path.to_path_buf(),
        from,
        to: (image.width, image.height),
    };
    Ok(Some((image, Some(scaled))))
}

/// `image` scaled down, aspect kept, to at most [`debt::MAX_SIDE`] a side (at least 1).
fn fit(image: &debt::Image) -> debt::Image {
    let longest = image.width.max(image.height);
    let side = |n: usize| {
        (n * debt::MAX_SIDE)
            .div_ceil(longest)
            .clamp(1, debt::MAX_SIDE)
    };
    let (width, height) = (side(image.width), side(image.height));
    let filter = image::imageops::FilterType::Triangle;
    let (w, h) = (width as u32, height as u32);
    let data = if image.channels == 1 {
        image::GrayImage::from_raw(image.width as u32, image.height as u32, image.data.clone())
            .map(|buffer| image::imageops::resize(&buffer, w, h, filter).into_raw())
    } else {
        image::RgbImage::from_raw(image.width as u32, image.height as u32, image.data.clone())
            .map(|buffer| image::imageops::resize(&buffer, w, h, filter).into_raw())
    };
    debt::Image {
        width,
        height,
        channels: image.channels,
        data: data.unwrap_or_else(|| vec![0; width * height * image.channels]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn png(width: usize, height: usize) -> Vec<u8> {
        debt::picture::to_png(&debt::Image {
            width,
            height,
            channels: 3,
            data: vec![100; width * height * 3],
        })
        .unwrap()
    }

    #[test]
    fn a_picture_wider_than_debt_holds_is_scaled_down() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("wide.png");
        std::fs::write(&path, png(5000, 10)).unwrap();
        let pictures = load(&path).unwrap();
        assert_eq!(pictures.images.len(), 1);
        let image = &pictures.images[0];
        assert_eq!((image.width, image.height), (4096, 9));
        assert_eq!(image.data.len(), 4096 * 9 * 3);
        assert_eq!(pictures.scaled[0].from, (5000, 10));
    }

    #[test]
    fn a_huge_header_is_refused_before_decoding() {
        // A PNG whose header says 20000x20000 (its data would be 1.2 GB of RGB).
        let mut bytes = png(1, 1);
        bytes[16..20].copy_from_slice(&20000u32.to_be_bytes());
        bytes[20..24].copy_from_slice(&20000u32.to_be_bytes());
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&bytes[12..29]);
        bytes[29..33].copy_from_slice(&crc.to_be_bytes());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("huge.png");
        std::fs::write(&path, &bytes).unwrap();
        let error = load(&path).unwrap_err();
        assert!(
            matches!(
                error,
                CameraError::TooManyPixels {
                    width: 20000,
                    height: 20000,
                    ..
                }
            ),
            "{error}"
        );
    }

    #[test]
    fn a_directory_skips_other_files_and_an_empty_one_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("notes.txt"), "not a picture").unwrap();
        assert!(matches!(load(dir.path()), Err(CameraError::Empty { .. })));
        std::fs::write(dir.path().join("a.png"), png(8, 6)).unwrap();
        let pictures = load(dir.path()).unwrap();
        assert_eq!(pictures.images.len(), 1);
        assert!(pictures.scaled.is_empty());
        assert!(matches!(
            load(&dir.path().join("notes.txt")),
            Err(CameraError::NotAnImage { .. })
        ));
    }
}
