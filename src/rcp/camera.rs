//! The ROV camera's pictures: one image file or a directory of them, read through the one
//! picture loader ([`debt::picture`]) with its header checked before anything is decoded.
//!
//! DEBT holds at most [`debt::MAX_SIDE`] pixels a side: a larger picture of at most
//! [`MAX_DECODED_PIXELS`] pixels is decoded and scaled down to fit (the caller says so, from
//! [`Pictures::scaled`]); a picture beyond that, a file over the loader's limit, or pictures
//! holding more than [`MAX_TOTAL_BYTES`] of pixels in all are refused, so a crafted header never
//! makes the camera allocate gigabytes. A picture named on its own must be a regular file (a
//! FIFO would block the session before it starts).

use std::path::{Path, PathBuf};

use crate::debt;
use crate::debt::picture::{Oversize, PictureError};

/// The largest picture decoded (and then scaled down), pixels: 64 megapixels, 192 MB of RGB.
pub const MAX_DECODED_PIXELS: u64 = 1 << 26;

/// The most pixel bytes the camera keeps for all its pictures together.
pub const MAX_TOTAL_BYTES: usize = 1 << 28;

/// What is wrong with the camera's pictures.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// A picture that cannot be read, is not a picture, or is too large even to scale down.
    #[error(transparent)]
    Picture(#[from] PictureError),
    /// A picture given by name that is not a regular file (a FIFO, a device).
    #[error("{path}: not a regular file: the camera reads image files")]
    NotAFile {
        /// The path.
        path: PathBuf,
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
}

/// A picture scaled down to fit DEBT.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Scaled {
    /// The file.
    pub path: PathBuf,
    /// Its own width and height, pixels.
    pub from: (usize, usize),
    /// The width and height it was scaled to, pixels.
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

/// The camera's pictures: the files at `path` ([`load`]), or with no path the four built-in
/// 320x240 ones ([`super::test_image`]).
pub fn load_or_builtin(path: Option<&Path>) -> Result<Pictures, CameraError> {
    match path {
        Some(path) => load(path),
        None => Ok(Pictures {
            images: (0..4).map(|k| super::test_image(320, 240, k)).collect(),
            scaled: Vec::new(),
        }),
    }
}

/// Reads one image file, or every image file of a directory (other files are skipped).
pub fn load(path: &Path) -> Result<Pictures, CameraError> {
    let meta = std::fs::metadata(path).map_err(|source| PictureError::Read {
        name: path.display().to_string(),
        source,
    })?;
    if !meta.is_dir() && !meta.is_file() {
        return Err(CameraError::NotAFile {
            path: path.to_path_buf(),
        });
    }
    let oversize = Oversize::ScaleDown {
        max_pixels: MAX_DECODED_PIXELS,
    };
    let mut pictures = Pictures {
        images: Vec::new(),
        scaled: Vec::new(),
    };
    let mut total_bytes = 0usize;
    for loaded in debt::picture::load_fit(path, oversize)? {
        total_bytes = total_bytes.saturating_add(loaded.image.data.len());
        if total_bytes > MAX_TOTAL_BYTES {
            return Err(CameraError::TooMuch {
                path: path.to_path_buf(),
            });
        }
        if let Some(from) = loaded.scaled_from {
            pictures.scaled.push(Scaled {
                path: loaded.path,
                from,
                to: (loaded.image.width, loaded.image.height),
            });
        }
        pictures.images.push(loaded.image);
    }
    Ok(pictures)
}

/// The ROV's camera: one picture each time the ROV starts a new image.
pub trait Camera: Send {
    /// A picture now; `Err` says why there is none (the ROV sends status only and tries again
    /// at the next slot).
    fn capture(&mut self) -> Result<debt::Image, String>;
}

/// Pictures loaded before the session, cycled (`--images`, or the built-in ones).
pub struct Cycle {
    images: Vec<debt::Image>,
    next: usize,
}

impl Cycle {
    /// A camera yielding `images` in turn, forever (none: every capture fails).
    pub fn new(images: Vec<debt::Image>) -> Cycle {
        Cycle { images, next: 0 }
    }
}

impl Camera for Cycle {
    fn capture(&mut self) -> Result<debt::Image, String> {
        if self.images.is_empty() {
            return Err("no pictures".into());
        }
        let picture = self.images[self.next % self.images.len()].clone();
        self.next = self.next.wrapping_add(1);
        Ok(picture)
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
                CameraError::Picture(PictureError::TooManyPixels {
                    width: 20000,
                    height: 20000,
                    ..
                })
            ),
            "{error}"
        );
    }

    #[test]
    fn a_directory_skips_other_files_and_an_empty_one_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("notes.txt"), "not a picture").unwrap();
        assert!(matches!(
            load(dir.path()),
            Err(CameraError::Picture(PictureError::NoImage { .. }))
        ));
        std::fs::write(dir.path().join("a.png"), png(8, 6)).unwrap();
        let pictures = load(dir.path()).unwrap();
        assert_eq!(pictures.images.len(), 1);
        assert!(pictures.scaled.is_empty());
        assert!(matches!(
            load(&dir.path().join("notes.txt")),
            Err(CameraError::Picture(PictureError::Format { .. }))
        ));
    }
}
