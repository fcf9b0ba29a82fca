//! `--preview`'s writer thread: the image in progress, decoded and written as the file it will
//! be, off the session's thread.

use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex};

use super::write_whole;

/// `--preview`'s writer: decodes and writes the image in progress in a thread of its own, so
/// a large picture (a 1920x1080 one takes ~0.1 s to decode and compress) never holds up the
/// session. Only the latest prefix waits: one the thread had no time for is replaced by the
/// next. A preview of an image already completed is never written over its whole file.
pub(super) struct Previewer {
    shared: Arc<(Mutex<PreviewState>, Condvar)>,
    worker: Option<std::thread::JoinHandle<()>>,
}

#[derive(Default)]
struct PreviewState {
    /// The latest image in progress to write: its number, its file, its bytes so far.
    pending: Option<(u64, PathBuf, Vec<u8>)>,
    /// Images completed so far: their previews are not written any more.
    completed: u64,
    /// The first write error.
    error: Option<anyhow::Error>,
    /// No more previews: the thread writes what is pending and ends.
    closing: bool,
}

impl Previewer {
    pub(super) fn start() -> anyhow::Result<Previewer> {
        let shared = Arc::new((Mutex::new(PreviewState::default()), Condvar::new()));
        let theirs = Arc::clone(&shared);
        let worker = std::thread::Builder::new()
            .name("preview".into())
            .spawn(move || preview_worker(&theirs))
            .map_err(|e| anyhow::anyhow!("--preview: cannot start its thread: {e}"))?;
        Ok(Previewer {
            shared,
            worker: Some(worker),
        })
    }

    fn state(&self) -> std::sync::MutexGuard<'_, PreviewState> {
        self.shared.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Image `number` so far (`prefix`) is to be written to `path`.
    pub(super) fn show(&self, number: u64, path: PathBuf, prefix: &[u8]) {
        self.state().pending = Some((number, path, prefix.to_vec()));
        self.shared.1.notify_one();
    }

    /// Image `number` is complete (its whole file is written next): waits for a preview being
    /// written, and writes none of it after.
    pub(super) fn completed(&self, number: u64) {
        let mut state = self.state();
        state.completed = state.completed.max(number);
        if state.pending.as_ref().is_some_and(|(n, _, _)| *n <= number) {
            state.pending = None;
        }
    }

    pub(super) fn failed(&self) -> bool {
        self.state().error.is_some()
    }

    /// Writes what is pending, ends the thread; the first write error.
    pub(super) fn finish(mut self) -> anyhow::Result<()> {
        self.close();
        if let Some(worker) = self.worker.take() {
            let _ = worker.join();
        }
        self.state().error.take().map_or(Ok(()), Err)
    }

    fn close(&self) {
        self.state().closing = true;
        self.shared.1.notify_one();
    }
}

impl Drop for Previewer {
    fn drop(&mut self) {
        self.close();
    }
}

fn preview_worker(shared: &(Mutex<PreviewState>, Condvar)) {
    let (lock, wake) = shared;
    let state = || lock.lock().unwrap_or_else(|e| e.into_inner());
    loop {
        let (number, path, prefix) = {
            let mut held = state();
            while held.pending.is_none() && !held.closing {
                held = wake.wait(held).unwrap_or_else(|e| e.into_inner());
            }
            match held.pending.take() {
                Some(job) => job,
                None => return,
            }
        };
        // A prefix short of the stream's header is no picture yet.
        let Some(png) = rovlink_debt::decode(&prefix)
            .ok()
            .and_then(|image| rovlink_debt::picture::to_png(&image).ok())
        else {
            continue;
        };
        let mut held = state();
        if number > held.completed
            && held.error.is_none()
            && let Err(error) = write_whole(&path, &png)
        {
            held.error = Some(error);
        }
    }
}
