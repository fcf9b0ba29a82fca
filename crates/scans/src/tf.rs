//! Where each scan was taken: a TF buffer (the tree of frames `/tf` and `/tf_static`
//! describe) and pose tracks (a `PoseStamped`, `TransformStamped` or `Odometry` topic), looked
//! up at a cloud's stamp.
//!
//! # TF
//!
//! Each `geometry_msgs/TransformStamped` links a child frame to its parent at a stamp. The
//! frames form a forest: every frame has at most one parent. [`TfTree::lookup`] gives the
//! transform taking points in a frame into a fixed frame: up the chain from the frame to the
//! common ancestor, down to the fixed frame (inverting those links). Each dynamic link (from
//! `/tf`) is interpolated between its two samples around the stamp, the translation linearly
//! and the rotation by slerp along the shortest arc, as tf2 does; a static link (from
//! `/tf_static`) holds at all times. A stamp outside a dynamic link's samples is unavailable
//! (tf2's `ExtrapolationException`), and a link with a single sample is available only at that
//! sample's exact stamp.
//!
//! Exactness: at a stamp equal to a sample's the sample itself is used (no interpolation at
//! fraction 0 or 1), and composing with an identity link is exact, so a chain such as
//! `map -> base_link` (dynamic) `-> sensor` (static identity) gives the stored `map ->
//! base_link` numbers bit for bit, and a map built from them equals the one OctoMap builds from
//! the same numbers.
//!
//! Malformed TF is refused with a [`TfError`] naming the frames: an empty frame id, a link from
//! a frame to itself, a frame given two different parents (tf2 warns and flips between them; a
//! map built that way is wrong, so we refuse), a link published both static and dynamic, a
//! number that is not finite, a quaternion not of unit length (tf2's rule, `|norm² - 1| >
//! 0.01`), and, when the buffer is [finished](TfTree::finish), a cycle. Two samples of a link
//! at the same stamp: the one added last wins. A static link published again: the last one
//! wins (as tf2's static cache keeps one value).
//!
//! # Pose tracks
//!
//! A [`PoseTrack`] is one topic's stamped poses of the sensor (or the vehicle) in a fixed
//! frame, interpolated by the same rules.
//!
//! Nothing here panics, on any input; memory is what the added transforms take.

use std::collections::{BTreeMap, BTreeSet};

use crate::ros::{Header, Transform, TransformProblem, TransformStamped};

/// Malformed TF or pose-track input: what, naming the frames.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TfError {
    /// A transform's parent or child frame id is empty.
    #[error(
        "TF transform {parent:?} -> {child:?}: expected non-empty frame ids, found an empty one"
    )]
    EmptyFrameId {
        /// The parent frame id (`header.frame_id`).
        parent: String,
        /// The child frame id.
        child: String,
    },
    /// A transform links a frame to itself.
    #[error(
        "TF transform {frame:?} -> {frame:?}: expected two different frames, found a self-link"
    )]
    SelfLink {
        /// The frame.
        frame: String,
    },
    /// A frame was given a second, different parent.
    #[error("TF frame {child:?}: expected one parent, found two: {parent:?} and {other_parent:?}")]
    TwoParents {
        /// The frame.
        child: String,
        /// Its first parent.
        parent: String,
        /// The other parent a later transform gave it.
        other_parent: String,
    },
    /// A link was published on both `/tf_static` and `/tf`.
    #[error(
        "TF link {parent:?} -> {child:?}: expected it static (/tf_static) or dynamic (/tf), found \
         both"
    )]
    StaticAndDynamic {
        /// The parent frame.
        parent: String,
        /// The child frame.
        child: String,
    },
    /// A transform's numbers are not finite, or its quaternion is not of unit length.
    #[error("{link} at stamp {} s: {problem}", stamp(*.stamp_ns))]
    BadTransform {
        /// Which link (`TF link "map" -> "base"`) or track.
        link: String,
        /// The transform's stamp, nanoseconds.
        stamp_ns: i64,
        /// What is wrong.
        problem: TransformProblem,
    },
    /// The links form a cycle.
    #[error("TF frames form a cycle: expected a tree, found {}", cycle(.frames))]
    Cycle {
        /// The frames of the cycle, each the parent of the one before it.
        frames: Vec<String>,
    },
}

/// The most frames of a cycle an error names: a cycle of 10^5 frames is named by its first
/// few and its length, so the error stays one readable line.
const CYCLE_FRAMES_SHOWN: usize = 8;
/// The most characters of one frame's name an error shows.
const FRAME_NAME_SHOWN: usize = 64;

fn cycle(frames: &[String]) -> String {
    let name = |f: &String| {
        if f.chars().count() > FRAME_NAME_SHOWN {
            let head: String = f.chars().take(FRAME_NAME_SHOWN).collect();
            format!("{head:?}...")
        } else {
            format!("{f:?}")
        }
    };
    let mut s: Vec<String> = frames.iter().take(CYCLE_FRAMES_SHOWN).map(name).collect();
    if frames.len() > CYCLE_FRAMES_SHOWN {
        s.push(format!("... ({} frames in all)", frames.len()));
    } else if let Some(first) = frames.first() {
        s.push(name(first));
    }
    s.join(" -> ")
}

/// A stamp in seconds, exactly (`-1.500000000`).
fn stamp(ns: i64) -> String {
    let sign = if ns < 0 { "-" } else { "" };
    let abs = ns.unsigned_abs();
    format!("{sign}{}.{:09}", abs / 1_000_000_000, abs % 1_000_000_000)
}

/// Why a transform cannot be had at a stamp, naming the frames.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Unavailable {
    /// The frame is in no transform.
    #[error("frame {frame:?} is not in the TF tree")]
    UnknownFrame {
        /// The frame asked for.
        frame: String,
    },
    /// The frame and the fixed frame are in different trees.
    #[error(
        "frame {frame:?} (tree root {frame_root:?}) is not connected to the fixed frame \
         {fixed:?} (tree root {fixed_root:?})"
    )]
    NotConnected {
        /// The frame asked for.
        frame: String,
        /// The root of its tree.
        frame_root: String,
        /// The fixed frame.
        fixed: String,
        /// The root of the fixed frame's tree.
        fixed_root: String,
    },
    /// The stamp is before a link's (or track's) first sample.
    #[error(
        "stamp {} s is before the first sample of {link} (samples {} .. {} s)",
        stamp(*.stamp_ns), stamp(*.first_ns), stamp(*.last_ns)
    )]
    Before {
        /// The link (`TF link "odom" -> "base"`) or track.
        link: String,
        /// The stamp asked for, nanoseconds.
        stamp_ns: i64,
        /// The first sample's stamp.
        first_ns: i64,
        /// The last sample's stamp.
        last_ns: i64,
    },
    /// The stamp is after a link's (or track's) last sample.
    #[error(
        "stamp {} s is after the last sample of {link} (samples {} .. {} s)",
        stamp(*.stamp_ns), stamp(*.first_ns), stamp(*.last_ns)
    )]
    After {
        /// The link or track.
        link: String,
        /// The stamp asked for, nanoseconds.
        stamp_ns: i64,
        /// The first sample's stamp.
        first_ns: i64,
        /// The last sample's stamp.
        last_ns: i64,
    },
    /// A pose track has no samples.
    #[error("{link} has no poses")]
    NoSamples {
        /// The track.
        link: String,
    },
    /// Transforms were added after the last [`TfTree::finish`] / [`PoseTrack::finish`] (a
    /// mistake of the caller, not of the input).
    #[error("the TF buffer or pose track was not finished after transforms were added")]
    NotFinished,
}

/// Stamped samples of one link or track, sorted by [`Samples::finish`].
#[derive(Debug, Clone, Default, PartialEq)]
struct Samples {
    samples: Vec<(i64, Transform)>,
    /// How many of `samples` [`Samples::finish`] left sorted (the rest added since).
    sorted: usize,
}

/// Where a stamp falls outside the samples.
enum Outside {
    Empty,
    Before(i64, i64),
    After(i64, i64),
}

impl Outside {
    fn named(self, link: String, stamp_ns: i64) -> Unavailable {
        match self {
            Outside::Empty => Unavailable::NoSamples { link },
            Outside::Before(first_ns, last_ns) => Unavailable::Before {
                link,
                stamp_ns,
                first_ns,
                last_ns,
            },
            Outside::After(first_ns, last_ns) => Unavailable::After {
                link,
                stamp_ns,
                first_ns,
                last_ns,
            },
        }
    }
}

impl Samples {
    /// Drops the samples before `stamp_ns` except the last of them (a lookup at `stamp_ns` or
    /// later still interpolates from it). The samples must be sorted ([`Samples::finish`]).
    fn forget_before(&mut self, stamp_ns: i64) {
        let i = self.samples.partition_point(|s| s.0 < stamp_ns);
        if i > 1 {
            self.samples.drain(..i - 1);
            self.sorted = self.sorted.saturating_sub(i - 1);
        }
    }

    /// Sorts by stamp; of samples at the same stamp the last added is kept. Samples added in
    /// stamp order since the last call (every publisher's own) cost only their number, so a
    /// buffer finished after every message (one pass over a bag) stays linear; true when the
    /// samples had to be sorted whole (one came out of order, or at a stamp already there).
    fn finish(&mut self) -> bool {
        let last_sorted = self.sorted.saturating_sub(1);
        if self
            .samples
            .get(last_sorted..)
            .is_some_and(|tail| tail.windows(2).all(|w| w[0].0 < w[1].0))
        {
            self.sorted = self.samples.len();
            return false;
        }
        // Stable: equal stamps stay in the order they were added.
        self.samples.sort_by_key(|s| s.0);
        let mut kept: Vec<(i64, Transform)> = Vec::with_capacity(self.samples.len());
        for s in self.samples.drain(..) {
            match kept.last_mut() {
                Some(last) if last.0 == s.0 => *last = s,
                _ => kept.push(s),
            }
        }
        self.samples = kept;
        self.sorted = self.samples.len();
        true
    }

    fn span(&self) -> Option<(i64, i64)> {
        Some((self.samples.first()?.0, self.samples.last()?.0))
    }

    /// The transform at `stamp_ns`: a sample's own at its stamp, else interpolated between the
    /// two around it.
    fn at(&self, stamp_ns: i64) -> Result<Transform, Outside> {
        let Some((first, last)) = self.span() else {
            return Err(Outside::Empty);
        };
        let i = self.samples.partition_point(|s| s.0 < stamp_ns);
        if let Some(&(t, x)) = self.samples.get(i)
            && t == stamp_ns
        {
            return Ok(x);
        }
        if i == 0 {
            return Err(Outside::Before(first, last));
        }
        let (Some(&(t0, a)), Some(&(t1, b))) = (self.samples.get(i - 1), self.samples.get(i))
        else {
            return Err(Outside::After(first, last));
        };
        let f = (i128::from(stamp_ns) - i128::from(t0)) as f64
            / (i128::from(t1) - i128::from(t0)) as f64;
        Ok(a.interpolate(&b, f))
    }
}

#[derive(Debug, Clone, PartialEq)]
enum LinkKind {
    Static(Transform),
    Dynamic(Samples),
}

#[derive(Debug, Clone, PartialEq)]
struct Link {
    parent: String,
    kind: LinkKind,
}

fn link_name(parent: &str, child: &str) -> String {
    format!("TF link {parent:?} -> {child:?}")
}

/// A TF buffer: every link's transforms from `/tf` (dynamic) and `/tf_static`, looked up at a
/// stamp through the chain of frames. See the [module documentation](self).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TfTree {
    /// Links by child frame.
    links: BTreeMap<String, Link>,
    /// Every frame named by a link, as child or parent.
    frames: BTreeSet<String>,
    /// No transform added since the last `finish`.
    finished: bool,
    /// Whether a `finish` had to sort a link's samples whole (see [`TfTree::resorted`]).
    resorted: bool,
}

impl TfTree {
    /// An empty buffer (finished: lookups of its no frames answer).
    pub fn new() -> TfTree {
        TfTree {
            finished: true,
            ..TfTree::default()
        }
    }

    /// Adds one transform, from `/tf_static` when `is_static`. Refuses (and leaves the buffer
    /// as it was) an empty frame id, a self-link, a frame's second parent, a link both static
    /// and dynamic, and numbers not finite or a quaternion not of unit length. Call
    /// [`TfTree::finish`] before looking up.
    pub fn add(&mut self, t: &TransformStamped, is_static: bool) -> Result<(), TfError> {
        let parent = &t.header.frame_id;
        let child = &t.child_frame_id;
        if parent.is_empty() || child.is_empty() {
            return Err(TfError::EmptyFrameId {
                parent: parent.clone(),
                child: child.clone(),
            });
        }
        if parent == child {
            return Err(TfError::SelfLink {
                frame: parent.clone(),
            });
        }
        t.transform
            .check()
            .map_err(|problem| TfError::BadTransform {
                link: link_name(parent, child),
                stamp_ns: t.header.stamp_ns,
                problem,
            })?;
        let sample = (t.header.stamp_ns, t.transform);
        match self.links.get_mut(child) {
            Some(link) => {
                if link.parent != *parent {
                    return Err(TfError::TwoParents {
                        child: child.clone(),
                        parent: link.parent.clone(),
                        other_parent: parent.clone(),
                    });
                }
                match (&mut link.kind, is_static) {
                    (LinkKind::Static(x), true) => *x = t.transform,
                    (LinkKind::Dynamic(s), false) => s.samples.push(sample),
                    _ => {
                        return Err(TfError::StaticAndDynamic {
                            parent: parent.clone(),
                            child: child.clone(),
                        });
                    }
                }
            }
            None => {
                let kind = if is_static {
                    LinkKind::Static(t.transform)
                } else {
                    LinkKind::Dynamic(Samples {
                        samples: vec![sample],
                        sorted: 0,
                    })
                };
                self.links.insert(
                    child.clone(),
                    Link {
                        parent: parent.clone(),
                        kind,
                    },
                );
                self.frames.insert(parent.clone());
                self.frames.insert(child.clone());
            }
        }
        self.finished = false;
        Ok(())
    }

    /// Sorts every dynamic link's samples by stamp (of two at the same stamp, the one added
    /// last is kept) and checks that the links form trees: a cycle is an error naming its
    /// frames.
    pub fn finish(&mut self) -> Result<(), TfError> {
        for link in self.links.values_mut() {
            if let LinkKind::Dynamic(s) = &mut link.kind {
                self.resorted |= s.finish();
            }
        }
        // Walk up from every frame; a frame met twice on one walk closes a cycle. Frames known
        // to reach a root are not walked again, and a walk's frames are also kept in a set, so
        // this is n log n in the frames (a chain of 100 000 frames too).
        let mut reach_root: BTreeSet<&str> = BTreeSet::new();
        for start in self.links.keys() {
            let mut path: Vec<&str> = Vec::new();
            let mut on_path: BTreeSet<&str> = BTreeSet::new();
            let mut frame = start.as_str();
            while !reach_root.contains(frame) {
                if !on_path.insert(frame)
                    && let Some(k) = path.iter().position(|&f| f == frame)
                {
                    return Err(TfError::Cycle {
                        frames: path
                            .get(k..)
                            .unwrap_or_default()
                            .iter()
                            .map(|f| f.to_string())
                            .collect(),
                    });
                }
                path.push(frame);
                match self.links.get(frame) {
                    Some(link) => frame = &link.parent,
                    None => break,
                }
            }
            reach_root.extend(path);
        }
        self.finished = true;
        Ok(())
    }

    /// Whether a [`TfTree::finish`] had to sort a link's samples whole: one came out of stamp
    /// order, or at a stamp the link already had. Finishing after every message (one pass over
    /// a bag) is then no longer linear, and a pose looked up before may have changed.
    pub(crate) fn resorted(&self) -> bool {
        self.resorted
    }

    /// Every frame a transform named, in name order.
    pub fn frames(&self) -> impl Iterator<Item = &str> {
        self.frames.iter().map(String::as_str)
    }

    /// Whether no transform was added.
    pub fn is_empty(&self) -> bool {
        self.links.is_empty()
    }

    /// [`TfTree::add`] then [`TfTree::finish`], for transforms arriving live: a transform
    /// whose new link would close a cycle is refused ([`TfError::Cycle`]) and leaves the buffer
    /// as it was, so one bad transform on a live topic does not stop the others.
    pub fn add_live(&mut self, t: &TransformStamped, is_static: bool) -> Result<(), TfError> {
        let child = t.child_frame_id.as_str();
        if !self.links.contains_key(child) && !child.is_empty() {
            let up = self.path_up(&t.header.frame_id);
            if let Some(k) = up.iter().position(|&f| f == child) {
                // child, its new parent, that one's parent, ..., back to child.
                let frames = std::iter::once(child)
                    .chain(up.get(..k).unwrap_or_default().iter().copied())
                    .map(str::to_string)
                    .collect();
                return Err(TfError::Cycle { frames });
            }
        }
        self.add(t, is_static)?;
        self.finish()
    }

    /// Drops every dynamic link's samples older than `stamp_ns`, but the last one before it:
    /// lookups at `stamp_ns` and later answer as before. A live buffer calls this to keep its
    /// memory bounded (tf2 keeps 10 s).
    pub fn forget_before(&mut self, stamp_ns: i64) {
        if !self.finished {
            let _ = self.finish();
        }
        for link in self.links.values_mut() {
            if let LinkKind::Dynamic(s) = &mut link.kind {
                s.forget_before(stamp_ns);
            }
        }
    }

    /// How many samples the buffer holds (static links count one).
    pub fn sample_count(&self) -> usize {
        self.links
            .values()
            .map(|l| match &l.kind {
                LinkKind::Static(_) => 1,
                LinkKind::Dynamic(s) => s.samples.len(),
            })
            .sum()
    }

    /// The parent of `frame` and whether that link is static; `None` for a root or an unknown
    /// frame.
    pub fn parent_of(&self, frame: &str) -> Option<(&str, bool)> {
        self.links
            .get(frame)
            .map(|l| (l.parent.as_str(), matches!(l.kind, LinkKind::Static(_))))
    }

    /// The frames from `frame` up to its root (both included); bounded by the number of
    /// links, so it ends even on a cycle (which [`TfTree::finish`] refuses).
    fn path_up<'a>(&'a self, frame: &'a str) -> Vec<&'a str> {
        let mut path = vec![frame];
        let mut f = frame;
        while let Some(link) = self.links.get(f) {
            if path.len() > self.links.len() {
                break;
            }
            f = &link.parent;
            path.push(f);
        }
        path
    }

    /// The root of the tree `frame` is in (`frame` itself when it has no parent); `None` when
    /// no transform names `frame`.
    pub fn root_of(&self, frame: &str) -> Option<&str> {
        let known = self.frames.get(frame)?;
        self.path_up(known).last().copied()
    }

    /// The default fixed frame for clouds in `cloud_frame`: the root of its tree.
    pub fn default_fixed_frame(&self, cloud_frame: &str) -> Result<&str, Unavailable> {
        self.root_of(cloud_frame)
            .ok_or_else(|| Unavailable::UnknownFrame {
                frame: cloud_frame.to_string(),
            })
    }

    /// The transform of the link from `child` to its parent at `stamp_ns`.
    fn link_at(&self, child: &str, stamp_ns: i64) -> Result<Transform, Unavailable> {
        let Some(link) = self.links.get(child) else {
            return Ok(Transform::IDENTITY);
        };
        match &link.kind {
            LinkKind::Static(t) => Ok(*t),
            LinkKind::Dynamic(s) => s
                .at(stamp_ns)
                .map_err(|o| o.named(link_name(&link.parent, child), stamp_ns)),
        }
    }

    /// The transform from `path[0]` to the last frame of `path`, at `stamp_ns`.
    fn chain(&self, path: &[&str], stamp_ns: i64) -> Result<Transform, Unavailable> {
        let mut acc = Transform::IDENTITY;
        for child in path.iter().take(path.len().saturating_sub(1)) {
            acc = self.link_at(child, stamp_ns)?.compose(&acc);
        }
        Ok(acc)
    }

    /// The transform taking points in `frame` into `fixed` at `stamp_ns`: up from `frame` to
    /// the common ancestor, down to `fixed`, each dynamic link interpolated at the stamp.
    pub fn lookup(
        &self,
        fixed: &str,
        frame: &str,
        stamp_ns: i64,
    ) -> Result<Transform, Unavailable> {
        if !self.finished {
            return Err(Unavailable::NotFinished);
        }
        for f in [frame, fixed] {
            if !self.frames.contains(f) {
                return Err(Unavailable::UnknownFrame {
                    frame: f.to_string(),
                });
            }
        }
        let up = self.path_up(frame);
        let down = self.path_up(fixed);
        // Indexed, so a deep chain costs its length, not its length squared.
        let down_at: BTreeMap<&str, usize> = down
            .iter()
            .enumerate()
            .rev()
            .map(|(j, f)| (*f, j))
            .collect();
        let common = up
            .iter()
            .enumerate()
            .find_map(|(i, f)| down_at.get(f).map(|&j| (i, j)));
        let Some((i, j)) = common else {
            return Err(Unavailable::NotConnected {
                frame: frame.to_string(),
                frame_root: up.last().copied().unwrap_or(frame).to_string(),
                fixed: fixed.to_string(),
                fixed_root: down.last().copied().unwrap_or(fixed).to_string(),
            });
        };
        let from_frame = self.chain(up.get(..=i).unwrap_or_default(), stamp_ns)?;
        if j == 0 {
            return Ok(from_frame);
        }
        let from_fixed = self.chain(down.get(..=j).unwrap_or_default(), stamp_ns)?;
        Ok(from_fixed.inverse().compose(&from_frame))
    }
}

/// One topic's stamped poses (`PoseStamped`, `TransformStamped` or `Odometry`), looked up by
/// stamp with the same interpolation as a TF link.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PoseTrack {
    samples: Samples,
    /// The distinct `header.frame_id`s, in the order first seen.
    frame_ids: Vec<String>,
    finished: bool,
    /// Whether a `finish` had to sort the poses whole (see [`TfTree::resorted`]).
    resorted: bool,
}

impl PoseTrack {
    /// An empty track.
    pub fn new() -> PoseTrack {
        PoseTrack {
            finished: true,
            ..PoseTrack::default()
        }
    }

    /// Adds the pose `transform` stamped by `header` (whose frame id is recorded). Numbers not
    /// finite or a quaternion not of unit length are refused. Call [`PoseTrack::finish`]
    /// before looking up.
    pub fn add(&mut self, header: &Header, transform: &Transform) -> Result<(), TfError> {
        transform.check().map_err(|problem| TfError::BadTransform {
            link: format!("pose in frame {:?}", header.frame_id),
            stamp_ns: header.stamp_ns,
            problem,
        })?;
        if !self.frame_ids.contains(&header.frame_id) {
            self.frame_ids.push(header.frame_id.clone());
        }
        self.samples.samples.push((header.stamp_ns, *transform));
        self.finished = false;
        Ok(())
    }

    /// Sorts the poses by stamp; of two at the same stamp, the one added last is kept.
    pub fn finish(&mut self) {
        self.resorted |= self.samples.finish();
        self.finished = true;
    }

    /// Whether a [`PoseTrack::finish`] had to sort the poses whole (see [`TfTree::resorted`]).
    pub(crate) fn resorted(&self) -> bool {
        self.resorted
    }

    /// Drops the poses older than `stamp_ns` but the last one before it (see
    /// [`TfTree::forget_before`]).
    pub fn forget_before(&mut self, stamp_ns: i64) {
        if !self.finished {
            self.finish();
        }
        self.samples.forget_before(stamp_ns);
    }

    /// The distinct frame ids of the poses added, in the order first seen (more than one is
    /// worth a warning: the poses are not all in one frame).
    pub fn frame_ids(&self) -> &[String] {
        &self.frame_ids
    }

    /// How many poses (after [`PoseTrack::finish`], distinct stamps).
    pub fn len(&self) -> usize {
        self.samples.samples.len()
    }

    /// Whether the track has no poses.
    pub fn is_empty(&self) -> bool {
        self.samples.samples.is_empty()
    }

    /// The first and last stamps, nanoseconds.
    pub fn span_ns(&self) -> Option<(i64, i64)> {
        self.samples.span()
    }

    /// The pose at `stamp_ns`: a pose's own at its stamp, else interpolated between the two
    /// around it; unavailable outside them.
    pub fn lookup(&self, stamp_ns: i64) -> Result<Transform, Unavailable> {
        self.lookup_named(stamp_ns, || "the pose track".into())
    }

    /// [`PoseTrack::lookup`], the track called `name` in what it says (`pose topic /odom`).
    pub fn lookup_named(
        &self,
        stamp_ns: i64,
        name: impl FnOnce() -> String,
    ) -> Result<Transform, Unavailable> {
        if !self.finished {
            return Err(Unavailable::NotFinished);
        }
        self.samples
            .at(stamp_ns)
            .map_err(|o| o.named(name(), stamp_ns))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: f64 = std::f64::consts::FRAC_1_SQRT_2;

    fn tr(t: [f64; 3], q: [f64; 4]) -> Transform {
        Transform {
            translation_m: t,
            rotation: q,
        }
    }

    fn ts(ns: i64, parent: &str, child: &str, t: Transform) -> TransformStamped {
        TransformStamped {
            header: Header {
                stamp_ns: ns,
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            transform: t,
        }
    }

    fn close(a: &Transform, b: &Transform) -> bool {
        let p = [0.3, -1.7, 2.5];
        let (x, y) = (a.apply(p), b.apply(p));
        x.iter().zip(y).all(|(u, v)| (u - v).abs() < 1e-9)
    }

    /// map -> odom (static), odom -> base (dynamic, at 1 s and 3 s), base -> sensor (static
    /// identity); map -> camera (static).
    fn tree() -> TfTree {
        let mut t = TfTree::new();
        t.add(
            &ts(0, "map", "odom", tr([10.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])),
            true,
        )
        .unwrap();
        t.add(
            &ts(
                1_000_000_000,
                "odom",
                "base",
                tr([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
            ),
            false,
        )
        .unwrap();
        t.add(
            &ts(
                3_000_000_000,
                "odom",
                "base",
                tr([2.0, -4.0, 6.0], [H, 0.0, 0.0, H]),
            ),
            false,
        )
        .unwrap();
        t.add(&ts(0, "base", "sensor", Transform::IDENTITY), true)
            .unwrap();
        t.add(
            &ts(
                0,
                "map",
                "camera",
                tr([0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0]),
            ),
            true,
        )
        .unwrap();
        t.finish().unwrap();
        t
    }

    #[test]
    fn interpolates_each_dynamic_link() {
        let t = tree();
        let mid = t.lookup("odom", "sensor", 2_000_000_000).unwrap();
        assert_eq!(mid.translation_m, [1.0, -2.0, 3.0]);
        let (c, s) = (
            std::f64::consts::FRAC_PI_8.cos(),
            std::f64::consts::FRAC_PI_8.sin(),
        );
        for (g, w) in mid.rotation.iter().zip([c, 0.0, 0.0, s]) {
            assert!((g - w).abs() < 1e-12, "{:?}", mid.rotation);
        }
        // A quarter of the way.
        let q = t.lookup("odom", "base", 1_500_000_000).unwrap();
        assert_eq!(q.translation_m, [0.5, -1.0, 1.5]);
    }

    #[test]
    fn sample_stamps_are_bit_exact_through_identity_links() {
        let mut t = tree();
        let odd = tr(
            [0.1, -0.2, 0.30000000000000004],
            [0.9238795325112867, 0.0, 0.3826834323650898, 0.0],
        );
        t.add(&ts(2_000_000_000, "odom", "base", odd), false)
            .unwrap();
        // An identity root link too: world -> map.
        t.add(&ts(0, "world", "map", Transform::IDENTITY), true)
            .unwrap();
        t.finish().unwrap();
        assert_eq!(t.lookup("odom", "sensor", 2_000_000_000).unwrap(), odd);
        assert_eq!(
            t.lookup("odom", "base", 3_000_000_000).unwrap().rotation,
            [H, 0.0, 0.0, H]
        );
        // Through map -> odom and world -> map the translation moves, the rotation is exact.
        let w = t.lookup("world", "sensor", 2_000_000_000).unwrap();
        assert_eq!(w.rotation, odd.rotation);
        assert_eq!(w.translation_m, [10.1, -0.2, 0.30000000000000004]);
        assert_eq!(t.lookup("map", "map", 5).unwrap(), Transform::IDENTITY);
    }

    #[test]
    fn chain_with_an_inverted_link() {
        let t = tree();
        // sensor -> base -> odom -> map, then map -> camera inverted.
        let got = t.lookup("camera", "sensor", 3_000_000_000).unwrap();
        let map_odom = tr([10.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        let odom_base = tr([2.0, -4.0, 6.0], [H, 0.0, 0.0, H]);
        let map_camera = tr([0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0]);
        let want = map_camera.inverse().compose(&map_odom.compose(&odom_base));
        assert!(close(&got, &want), "{got:?} {want:?}");
        // Point check by hand: p in sensor -> base (same) -> odom -> map -> camera.
        let p = [1.0, 0.0, 0.0];
        let in_map = [10.0 + 2.0, -4.0 + 1.0, 6.0]; // rotated 90 degrees about z: (0, 1, 0)
        let in_camera = map_camera.inverse().apply(in_map);
        let g = got.apply(p);
        for (a, b) in g.iter().zip(in_camera) {
            assert!((a - b).abs() < 1e-12, "{g:?} {in_camera:?}");
        }
        // And the other way round is the inverse.
        let back = t.lookup("sensor", "camera", 3_000_000_000).unwrap();
        assert!(close(&back.compose(&got), &Transform::IDENTITY));
    }

    #[test]
    fn unavailable_says_why() {
        let mut t = tree();
        let e = t.lookup("map", "lidar", 0).unwrap_err();
        assert_eq!(e.to_string(), "frame \"lidar\" is not in the TF tree");
        let e = t.lookup("mars", "sensor", 0).unwrap_err();
        assert_eq!(
            e,
            Unavailable::UnknownFrame {
                frame: "mars".into()
            }
        );
        let e = t.lookup("map", "sensor", 999_999_999).unwrap_err();
        assert_eq!(
            e.to_string(),
            "stamp 0.999999999 s is before the first sample of TF link \"odom\" -> \"base\" \
             (samples 1.000000000 .. 3.000000000 s)"
        );
        let e = t.lookup("map", "sensor", 3_000_000_001).unwrap_err();
        assert!(
            matches!(
                e,
                Unavailable::After {
                    stamp_ns: 3_000_000_001,
                    first_ns: 1_000_000_000,
                    last_ns: 3_000_000_000,
                    ..
                }
            ),
            "{e}"
        );
        // Static links hold at any stamp.
        assert!(t.lookup("map", "camera", -5).is_ok());
        // Another tree.
        t.add(&ts(7, "boat", "gps", Transform::IDENTITY), false)
            .unwrap();
        assert_eq!(
            t.lookup("map", "gps", 7).unwrap_err(),
            Unavailable::NotFinished
        );
        t.finish().unwrap();
        let e = t.lookup("map", "gps", 7).unwrap_err();
        assert_eq!(
            e.to_string(),
            "frame \"gps\" (tree root \"boat\") is not connected to the fixed frame \"map\" (tree \
             root \"map\")"
        );
        // A single sample: only at its stamp.
        assert_eq!(t.lookup("boat", "gps", 7).unwrap(), Transform::IDENTITY);
        assert!(matches!(
            t.lookup("boat", "gps", 6),
            Err(Unavailable::Before { .. })
        ));
        assert!(matches!(
            t.lookup("boat", "gps", 8),
            Err(Unavailable::After { .. })
        ));
        assert_eq!(t.root_of("sensor"), Some("map"));
        assert_eq!(t.root_of("gps"), Some("boat"));
        assert_eq!(t.root_of("boat"), Some("boat"));
        assert_eq!(t.root_of("x"), None);
        assert_eq!(t.default_fixed_frame("sensor"), Ok("map"));
        assert!(t.default_fixed_frame("x").is_err());
        assert_eq!(
            t.frames().collect::<Vec<_>>(),
            ["base", "boat", "camera", "gps", "map", "odom", "sensor"]
        );
        assert_eq!(t.parent_of("base"), Some(("odom", false)));
        assert_eq!(t.parent_of("odom"), Some(("map", true)));
        assert_eq!(t.parent_of("map"), None);
    }

    #[test]
    fn duplicate_stamps_last_wins_and_order_does_not_matter() {
        let mut t = TfTree::new();
        let a = tr([1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        let b = tr([2.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        let c = tr([4.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        t.add(&ts(20, "p", "c", c), false).unwrap();
        t.add(&ts(10, "p", "c", a), false).unwrap();
        t.add(&ts(10, "p", "c", b), false).unwrap();
        t.finish().unwrap();
        assert_eq!(t.lookup("p", "c", 10).unwrap(), b);
        assert_eq!(
            t.lookup("p", "c", 15).unwrap().translation_m,
            [3.0, 0.0, 0.0]
        );
        // A static link republished: the last value.
        t.add(&ts(0, "p", "s", a), true).unwrap();
        t.add(&ts(0, "p", "s", c), true).unwrap();
        t.finish().unwrap();
        assert_eq!(t.lookup("p", "s", 99).unwrap(), c);
    }

    #[test]
    fn malformed_tf_is_refused_naming_frames() {
        let mut t = tree();
        let before = t.clone();
        let id = Transform::IDENTITY;
        let e = t.add(&ts(0, "", "x", id), false).unwrap_err();
        assert!(matches!(e, TfError::EmptyFrameId { .. }), "{e}");
        let e = t.add(&ts(0, "x", "", id), true).unwrap_err();
        assert!(
            e.to_string().contains("expected non-empty frame ids"),
            "{e}"
        );
        let e = t.add(&ts(0, "x", "x", id), false).unwrap_err();
        assert_eq!(
            e.to_string(),
            "TF transform \"x\" -> \"x\": expected two different frames, found a self-link"
        );
        let e = t.add(&ts(0, "camera", "base", id), false).unwrap_err();
        assert_eq!(
            e.to_string(),
            "TF frame \"base\": expected one parent, found two: \"odom\" and \"camera\""
        );
        let e = t.add(&ts(0, "odom", "base", id), true).unwrap_err();
        assert!(matches!(e, TfError::StaticAndDynamic { .. }), "{e}");
        let nan = tr([0.0; 3], [f64::NAN, 0.0, 0.0, 0.0]);
        let e = t
            .add(&ts(1_500_000_000, "odom", "base", nan), false)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "TF link \"odom\" -> \"base\" at stamp 1.500000000 s: rotation.w: expected a finite \
             number, found NaN"
        );
        let inf = tr([f64::INFINITY, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]);
        assert!(t.add(&ts(0, "a", "b", inf), true).is_err());
        let long = tr([0.0; 3], [1.0, 0.1, 0.0, 0.0]);
        let e = t.add(&ts(0, "a", "b", long), true).unwrap_err();
        assert!(e.to_string().contains("expected a unit quaternion"), "{e}");
        // Nothing of the refused transforms was kept.
        assert_eq!(t, before);
        // A cycle: refused by finish, naming it.
        t.add(&ts(0, "sensor", "map", id), true).unwrap();
        let e = t.finish().unwrap_err();
        assert_eq!(
            e.to_string(),
            "TF frames form a cycle: expected a tree, found \"base\" -> \"odom\" -> \"map\" -> \
             \"sensor\" -> \"base\""
        );
        assert_eq!(
            t.lookup("map", "odom", 0).unwrap_err(),
            Unavailable::NotFinished
        );
        // A long cycle is named by its first frames and its length, in one short line.
        let mut long_cycle = TfTree::new();
        for i in 0..100_000 {
            let child = format!("f{}", (i + 1) % 100_000);
            long_cycle
                .add(&ts(0, &format!("f{i}"), &child, id), true)
                .unwrap();
        }
        let e = long_cycle.finish().unwrap_err().to_string();
        assert!(e.len() < 300, "{} bytes: {e}", e.len());
        assert!(e.ends_with("-> ... (100000 frames in all)"), "{e}");
        let mut two = TfTree::new();
        two.add(&ts(0, "a", "b", id), false).unwrap();
        two.add(&ts(0, "b", "a", id), false).unwrap();
        assert_eq!(
            two.finish().unwrap_err(),
            TfError::Cycle {
                frames: vec!["a".into(), "b".into()]
            }
        );
    }

    #[test]
    fn pose_tracks_and_sources() {
        let mut track = PoseTrack::new();
        let h = |ns, f: &str| Header {
            stamp_ns: ns,
            frame_id: f.into(),
        };
        assert_eq!(
            track.lookup(0).unwrap_err().to_string(),
            "the pose track has no poses"
        );
        let a = tr([0.0; 3], [1.0, 0.0, 0.0, 0.0]);
        let b = tr([2.0, 4.0, 6.0], [0.0, 0.0, 0.0, 1.0]);
        track.add(&h(100, "map"), &b).unwrap();
        track.add(&h(0, "map"), &a).unwrap();
        assert_eq!(track.lookup(50), Err(Unavailable::NotFinished));
        track.finish();
        assert_eq!(track.len(), 2);
        assert_eq!(track.span_ns(), Some((0, 100)));
        assert_eq!(track.lookup(0).unwrap(), a);
        assert_eq!(track.lookup(100).unwrap(), b);
        let m = track.lookup(50).unwrap();
        assert_eq!(m.translation_m, [1.0, 2.0, 3.0]);
        assert!(matches!(track.lookup(101), Err(Unavailable::After { .. })));
        let e = track
            .add(&h(5, "odom"), &tr([0.0; 3], [0.0; 4]))
            .unwrap_err();
        assert!(
            e.to_string()
                .starts_with("pose in frame \"odom\" at stamp 0.000000005 s: rotation"),
            "{e}"
        );
        track.add(&h(5, "odom"), &a).unwrap();
        track.finish();
        assert_eq!(track.frame_ids(), ["map", "odom"]);

        assert_eq!(track.lookup(0).unwrap(), a);
        assert_eq!(
            track
                .lookup_named(-1, || "pose topic /nav/pose".into())
                .unwrap_err()
                .to_string(),
            "stamp -0.000000001 s is before the first sample of pose topic /nav/pose (samples \
             0.000000000 .. 0.000000100 s)"
        );
    }
}
