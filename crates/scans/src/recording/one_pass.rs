//! One pass over a bag: its clouds posed as the transforms beside them are read, and checked
//! at the end against what two passes (every transform first) would have given.
//!
//! Two passes decompress every chunk twice and read all the transforms before the first cloud,
//! which a build cannot overlap with anything. One pass reads clouds and poses together, in the
//! bag's order, and hands out a cloud once the transforms read so far settle its pose: every
//! dynamic link of its chain has a sample at or after its stamp (tf2's rule, as
//! [`live`](crate::live) applies it). A cloud that has to wait holds back the clouds after it,
//! so the order is the bag's.
//!
//! That is the two-pass pose whenever each link's samples come in stamp order and the tree does
//! not grow above the fixed frame later, which is how recorders write. It is not when a sample
//! comes out of order between two others, a static transform is sent again with another value,
//! or (no `--fixed-frame`) a frame's parent appears after the first cloud: so every cloud handed
//! out is kept as (frame, stamp, pose or why not), and at the end of the bag each is looked up
//! again in the whole tree with two passes' choice of fixed frame. Any difference, or more than
//! [`MAX_HELD_CLOUDS`] clouds (or [`MAX_HELD_POINTS`] points) waiting at once, is
//! [`RecordingError::OnePass`]: the caller reads the bag again in two passes (a build's outputs
//! are not committed before its end). So is any error two passes might report otherwise or
//! later (a cloud or a chunk that does not decode, a TF cycle before the bag's end): two passes
//! then give their own error. A malformed transform is the same error either way, the first in
//! the bag's order. A pass stopped before the bag's end (SIGTERM) keeps the
//! clouds handed out as the transforms read by then posed them: the check needs the whole bag.
//! Nothing here panics on any input.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};

use super::{Item, Poses, RecordingError, add_pose_message, add_tf_message, pose_at, pose_of};
use crate::bag::{BagError, Location, Message};
use crate::cloud::CloudBuilder;
use crate::ros::{self, Header};
use rovlink_octo::Pose;

/// The most clouds one pass holds back waiting for transforms.
pub const MAX_HELD_CLOUDS: usize = 32;
/// The most points the clouds held back have room for (8 Mi points: 96 MiB, 120 MiB with
/// colours; an organised cloud's dropped points count too).
pub const MAX_HELD_POINTS: usize = 8 << 20;

/// A cloud handed out: where and when it was, and its pose (or why it had none).
struct Given {
    /// Its frame, an index into [`State::frames`] (a bag has few).
    frame: usize,
    stamp_ns: i64,
    outcome: Result<Pose, String>,
}

/// What one pass reads besides the clouds.
pub(super) enum PoseTopics {
    /// TF topics, with whether each is static, and their names (for messages).
    Tf(Vec<(usize, bool)>, String),
    /// A pose topic and its message type.
    Track(usize, String),
}

impl PoseTopics {
    /// The topics to read.
    pub(super) fn indices(&self) -> Vec<usize> {
        match self {
            PoseTopics::Tf(topics, _) => topics.iter().map(|t| t.0).collect(),
            PoseTopics::Track(i, _) => vec![*i],
        }
    }
}

/// The one pass; an iterator of [`Item`]s in the bag's order.
pub(super) struct OnePass<'a> {
    pub(super) messages: Box<dyn Iterator<Item = Result<Message, BagError>> + 'a>,
    pub(super) cloud: usize,
    pub(super) topics: &'a PoseTopics,
    pub(super) poses: &'a mut Poses,
    pub(super) fixed: &'a mut Option<String>,
    pub(super) notes: &'a mut Vec<String>,
    pub(super) name: &'a str,
    pub(super) stop: &'a AtomicBool,
    /// The user's `--fixed-frame`, for the check at the end.
    pub(super) fixed_given: Option<String>,
    pub(super) state: State,
}

/// What one pass keeps between messages.
#[derive(Default)]
pub(super) struct State {
    /// Transforms added since the poses were last finished.
    dirty: bool,
    /// Clouds waiting for their transforms, in the bag's order, and their points.
    held: VecDeque<(Header, CloudBuilder)>,
    held_points: usize,
    given: Vec<Given>,
    /// The clouds' frames, each once, and their indices.
    frames: Vec<String>,
    frame_index: HashMap<String, usize>,
    out: VecDeque<Item>,
    ended: bool,
    /// The last pose message, for errors found when the tree is finished.
    last: Option<Location>,
}

impl OnePass<'_> {
    fn redo(&self, why: String) -> RecordingError {
        RecordingError::OnePass {
            file: self.name.to_string(),
            why,
        }
    }

    /// An error two passes might report differently, or not first (they read every transform
    /// before any cloud): a refusal, so that the caller's two passes report theirs.
    fn refuse_error(&self, e: impl std::fmt::Display) -> RecordingError {
        self.redo(format!(
            "it met an error two passes may report otherwise ({e})"
        ))
    }

    /// Sorts what was added since the last lookup. A cycle in the TF is an error at the end of
    /// the bag (where two passes find it, every transform added); before, a refusal.
    fn finish_poses(&mut self, at_end: bool) -> Result<(), RecordingError> {
        if !std::mem::take(&mut self.state.dirty) {
            return Ok(());
        }
        let resorted = match self.poses {
            Poses::Tf(tree) => match tree.finish() {
                Ok(()) => tree.resorted(),
                Err(e) if !at_end => return Err(self.refuse_error(e)),
                Err(e) => {
                    let file = self.state.last.as_ref().map_or(self.name, |l| &l.file);
                    return Err(BagError::new(Location::file(file), e.to_string()).into());
                }
            },
            Poses::Track(track, _) => {
                track.finish();
                track.resorted()
            }
        };
        // Sorting a link whole at every cloud would make one pass quadratic; two passes sort
        // once.
        if resorted && !at_end {
            return Err(self.redo(
                "a transform came out of stamp order, or again at a stamp its link already had"
                    .into(),
            ));
        }
        Ok(())
    }

    fn message(&mut self, m: Message) -> Result<(), RecordingError> {
        if m.topic == self.cloud {
            let decoded = ros::decode_point_cloud2(&m.data, 0).map_err(|e| m.error(e));
            let (header, builder, note) = decoded.map_err(|e| self.refuse_error(e))?;
            if let Some(note) = note
                && !self.notes.contains(&note)
            {
                self.notes.push(note);
            }
            self.state.held_points += builder.reserved();
            self.state.held.push_back((header, builder));
            self.release()?;
            let s = &self.state;
            if s.held.len() > MAX_HELD_CLOUDS || s.held_points > MAX_HELD_POINTS {
                let first = s.held.front().map(|(h, _)| h);
                return Err(self.redo(format!(
                    "{} clouds ({} points) waited for their transforms at once (the first \
                     stamped {} ns in frame {:?}), more than one pass holds ({MAX_HELD_CLOUDS} \
                     clouds, {MAX_HELD_POINTS} points)",
                    s.held.len(),
                    s.held_points,
                    first.map_or(0, |h| h.stamp_ns),
                    first.map_or("", |h| h.frame_id.as_str()),
                )));
            }
            return Ok(());
        }
        match (&mut *self.poses, self.topics) {
            (Poses::Tf(tree), PoseTopics::Tf(topics, _)) => add_tf_message(tree, topics, &m)?,
            (Poses::Track(track, _), PoseTopics::Track(_, schema)) => {
                add_pose_message(track, schema, &m)?
            }
            _ => {
                let internal = "pose source and topics disagree (internal error)";
                return Err(BagError::new(m.at, internal).into());
            }
        }
        self.state.dirty = true;
        self.state.last = Some(m.at);
        Ok(())
    }

    /// Hands out the clouds at the front whose pose the transforms read so far settle.
    fn release(&mut self) -> Result<(), RecordingError> {
        self.finish_poses(false)?;
        while let Some((header, _)) = self.state.held.front() {
            let outcome = pose_at(
                self.poses,
                self.fixed,
                &header.frame_id,
                header.stamp_ns,
                true,
            );
            if outcome.as_ref().is_err_and(|w| w.may_come) {
                break;
            }
            self.hand_out(outcome.map_err(|w| w.reason));
        }
        Ok(())
    }

    /// Hands out the front cloud with `outcome`, and keeps it for the check at the end.
    fn hand_out(&mut self, outcome: Result<Pose, String>) {
        let Some((header, builder)) = self.state.held.pop_front() else {
            return;
        };
        self.state.held_points -= builder.reserved();
        self.state.out.push_back(match &outcome {
            Ok(pose) => Item::Scan(builder.finish(*pose)),
            Err(reason) => Item::Skipped(reason.clone()),
        });
        let s = &mut self.state;
        let frame = match s.frame_index.get(&header.frame_id) {
            Some(&i) => i,
            None => {
                s.frame_index
                    .insert(header.frame_id.clone(), s.frames.len());
                s.frames.push(header.frame_id);
                s.frames.len() - 1
            }
        };
        self.state.given.push(Given {
            frame,
            stamp_ns: header.stamp_ns,
            outcome,
        });
    }

    /// The end of the bag: the whole tree checked, what was handed out looked up again in it
    /// as two passes would, and the clouds still waiting posed (or skipped) by it.
    fn end(&mut self) -> Result<(), RecordingError> {
        self.state.ended = true;
        if self.stop.load(Ordering::Relaxed) {
            return Ok(());
        }
        self.finish_poses(true)?;
        if let (Poses::Tf(tree), PoseTopics::Tf(_, names)) = (&*self.poses, self.topics)
            && let Some(fixed) = &self.fixed_given
            && !tree.frames().any(|f| f == fixed)
        {
            return Err(RecordingError::Unusable {
                file: self.name.to_string(),
                message: super::unknown_fixed_frame(fixed, tree, names),
            });
        }
        let mut fixed = self.fixed_given.clone();
        for g in &self.state.given {
            let frame = self.state.frames.get(g.frame).map_or("", String::as_str);
            let again = pose_of(self.poses, &mut fixed, frame, g.stamp_ns);
            if again != g.outcome {
                let said = |o: &Result<Pose, String>| match o {
                    Ok(p) => format!("at {:?}", p.translation_m),
                    Err(why) => format!("not posed ({why})"),
                };
                return Err(self.redo(format!(
                    "the cloud stamped {} ns in frame {:?} was {} by the transforms read before \
                     it, {} by all of them (transforms out of stamp order, a static transform \
                     sent again, or a parent frame that comes later)",
                    g.stamp_ns,
                    frame,
                    said(&g.outcome),
                    said(&again)
                )));
            }
        }
        while let Some((header, _)) = self.state.held.front() {
            let outcome = pose_of(self.poses, &mut fixed, &header.frame_id, header.stamp_ns);
            self.hand_out(outcome);
        }
        *self.fixed = fixed;
        Ok(())
    }
}

impl Iterator for OnePass<'_> {
    type Item = Result<Item, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(item) = self.state.out.pop_front() {
                return Some(Ok(item));
            }
            if self.state.ended {
                return None;
            }
            let step = match self.messages.next() {
                Some(Ok(m)) => self.message(m),
                Some(Err(e)) => Err(self.refuse_error(e)),
                None => self.end(),
            };
            if let Err(e) = step {
                self.state.ended = true;
                self.state.out.clear();
                return Some(Err(e));
            }
        }
    }
}
