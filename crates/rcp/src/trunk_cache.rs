//! The ROV's images as trunks, kept by picture and settings ([`TrunkCache`], at most
//! [`TRUNK_CACHE_BYTES`] of pictures), so that a camera cycling through a few pictures has each
//! encoded once per setting instead of at every capture.

use std::collections::VecDeque;

use crate::{ImageSettings, trunks_of};
use rovlink_debt as debt;

/// The most picture bytes a [`TrunkCache`] keeps (the four built-in 320x240 pictures take
/// 0.9 MB); a larger picture is encoded every time.
pub const TRUNK_CACHE_BYTES: usize = 8 << 20;

/// The trunks of the pictures last encoded, by picture and settings: a camera that cycles
/// through a few pictures (`--images`, the built-in ones) has each encoded once per setting
/// instead of at every capture. The encoder is a function of the picture and the settings, so
/// a hit is the same trunks [`trunks_of`] would return. Holds at most [`TRUNK_CACHE_BYTES`]
/// of pictures (by default), the least recently used dropped first.
#[derive(Debug)]
pub struct TrunkCache {
    /// Least recently used first.
    entries: VecDeque<(ImageSettings, debt::Image, Vec<Vec<u8>>)>,
    picture_bytes: usize,
    budget_bytes: usize,
}

impl Default for TrunkCache {
    fn default() -> Self {
        TrunkCache::with_budget(TRUNK_CACHE_BYTES)
    }
}

impl TrunkCache {
    /// An empty cache holding at most `budget_bytes` of pictures.
    pub fn with_budget(budget_bytes: usize) -> TrunkCache {
        TrunkCache {
            entries: VecDeque::new(),
            picture_bytes: 0,
            budget_bytes,
        }
    }

    /// [`trunks_of`] `image` with `settings`, encoded only when not already held.
    pub fn trunks(&mut self, image: &debt::Image, settings: &ImageSettings) -> Vec<Vec<u8>> {
        let held = self
            .entries
            .iter()
            .position(|(s, i, _)| s == settings && i == image);
        if let Some(entry) = held.and_then(|k| self.entries.remove(k)) {
            let trunks = entry.2.clone();
            self.entries.push_back(entry);
            return trunks;
        }
        let trunks = trunks_of(image, settings);
        let bytes = image.data.len();
        if bytes <= self.budget_bytes {
            while self.picture_bytes + bytes > self.budget_bytes {
                let Some((_, dropped, _)) = self.entries.pop_front() else {
                    break;
                };
                self.picture_bytes -= dropped.data.len();
            }
            self.picture_bytes += bytes;
            self.entries
                .push_back((*settings, image.clone(), trunks.clone()));
        }
        trunks
    }

    /// The number of (picture, settings) pairs held.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when nothing is held.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::builtin_picture;
    use crate::trunks_of;

    #[test]
    fn the_trunk_cache_gives_what_trunks_of_gives_and_stays_bounded() {
        let picture_bytes = 64 * 48 * 3;
        let mut cache = TrunkCache::with_budget(4 * picture_bytes);
        let pictures: Vec<debt::Image> = (0..3).map(|k| builtin_picture(64, 48, k)).collect();
        let small = ImageSettings {
            size_bytes: 400,
            ..ImageSettings::default()
        };
        for _ in 0..2 {
            for picture in &pictures[..2] {
                for settings in [ImageSettings::default(), small] {
                    assert_eq!(
                        cache.trunks(picture, &settings),
                        trunks_of(picture, &settings)
                    );
                }
            }
        }
        assert_eq!(cache.len(), 4);
        // A picture above the budget is encoded, not held.
        let large = builtin_picture(64, 48 * 5, 0);
        assert_eq!(cache.trunks(&large, &small), trunks_of(&large, &small));
        assert_eq!(cache.len(), 4);
        // One more pushes out the least recently used: the first picture at the default
        // settings.
        assert_eq!(
            cache.trunks(&pictures[2], &small),
            trunks_of(&pictures[2], &small)
        );
        assert_eq!(cache.len(), 4);
        assert!(cache.picture_bytes <= 4 * picture_bytes);
        let first = (ImageSettings::default(), &pictures[0]);
        assert!(!cache.entries.iter().any(|(s, i, _)| (*s, i) == first));
    }
}
