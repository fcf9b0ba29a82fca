//! The ROV camera's pictures, through the one picture loader ([`debt::picture`]) with its
//! header checked before anything is decoded:
//! - [`Cycle`]: pictures loaded before the session ([`load`]: one image file or a directory of
//!   them; `--images`), or the built-in ones ([`builtin_picture`]), cycled;
//! - [`NewestInDir`] (`--camera DIR`): the newest picture file of a directory at capture time,
//!   for a camera program that keeps writing frames there;
//! - [`CommandCamera`] (`--camera-cmd CMD`): one picture from the standard output of `sh -c CMD`,
//!   run in a background thread so that a slow camera never holds up the ROV's answers.
//!
//! DEBT holds at most [`debt::MAX_SIDE`] pixels a side: a larger picture of at most
//! [`MAX_DECODED_PIXELS`] pixels is decoded and scaled down to fit (the caller says so, from
//! [`Pictures::scaled`]); a picture beyond that, a file over the loader's limit, or pictures
//! holding more than [`MAX_TOTAL_BYTES`] of pixels in all are refused, so a crafted header never
//! makes the camera allocate gigabytes. A picture named on its own must be a regular file (a
//! FIFO would block the session before it starts).
//!
//! No-panic, no-hang contract: a capture that finds no picture returns `Err` saying why (the ROV
//! sends status only and tries again at the next slot). A camera command's output is bounded
//! ([`MAX_COMMAND_BYTES`]), it is killed with its process group after [`COMMAND_TIMEOUT_S`], and
//! [`Camera::capture`] never waits for it in real time. In simulation
//! ([`command_camera_waiting`]) a capture waits for the command, at most the timeout once: a
//! command that ran out of time is not run again (each capture would wait as long, stretching
//! the session without end), and [`CommandCamera::stop_on`] ends a wait when a signal comes.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender, channel};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use rovlink_debt as debt;
use rovlink_debt::picture::{Oversize, PictureError};

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
    /// `--camera` names something that is not a directory.
    #[error("{}: not a directory: the camera takes the newest picture file in a directory", path.display())]
    NotADirectory {
        /// The path.
        path: PathBuf,
    },
    /// An empty camera command.
    #[error("camera command: empty: expected a shell command writing one picture to its output")]
    EmptyCommand,
    /// The camera command's thread could not be started.
    #[error("camera command: cannot start its thread: {0}")]
    Thread(std::io::Error),
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
/// 320x240 ones ([`builtin_picture`] of seeds 0 to 3).
pub fn load_or_builtin(path: Option<&Path>) -> Result<Pictures, CameraError> {
    match path {
        Some(path) => load(path),
        None => Ok(Pictures {
            images: (0..4).map(|k| builtin_picture(320, 240, k)).collect(),
            scaled: Vec::new(),
        }),
    }
}

/// A picture of the built-in camera (no `--images`, [`load_or_builtin`]): `width` x `height`
/// RGB, a seabed-like texture with a pipe and a rock, different for each `seed`. Tests use it
/// too, as a picture like the ones sessions send.
pub fn builtin_picture(width: usize, height: usize, seed: u64) -> debt::Image {
    let mut data = Vec::with_capacity(width * height * 3);
    let s = seed as f64;
    for y in 0..height {
        for x in 0..width {
            let (fx, fy) = (x as f64 / width as f64, y as f64 / height as f64);
            let sand = 0.5
                + 0.15 * ((fx * 23.0 + s).sin() * (fy * 17.0 - s).cos())
                + 0.1 * ((fx * 71.0 + fy * 43.0 + s * 3.0).sin());
            let rock = ((fx - 0.3 - 0.05 * s.sin()).powi(2) + (fy - 0.6).powi(2)).sqrt() < 0.15;
            let pipe = (fy - 0.35 - 0.1 * fx).abs() < 0.03;
            let (r, g, b) = if rock {
                (0.25, 0.3, 0.3)
            } else if pipe {
                (0.8, 0.6, 0.1)
            } else {
                (0.3 * sand, 0.6 * sand, 0.7 * sand + 0.1)
            };
            for c in [r, g, b] {
                data.push((c * 255.0).clamp(0.0, 255.0) as u8);
            }
        }
    }
    debt::Image {
        width,
        height,
        channels: 3,
        data,
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

/// How [`NewestInDir`] and [`CommandCamera`] decode: large pictures scaled down to fit.
const CAMERA_OVERSIZE: Oversize = Oversize::ScaleDown {
    max_pixels: MAX_DECODED_PIXELS,
};

/// The most files [`NewestInDir`] tries at one capture, newest first.
pub const DIR_CANDIDATES: usize = 8;

/// `--camera DIR`: at each capture, the newest picture file of the directory (by modification
/// time, the name breaking ties). A file that does not decode (being written, not a picture) is
/// passed over for the next newest, up to [`DIR_CANDIDATES`] files. Names starting with `.`
/// (temporary files of writers that rename into place) are not looked at. The directory is
/// listed each time, holding only the candidates, so it may grow without bound.
pub struct NewestInDir {
    dir: PathBuf,
}

/// A camera reading the newest picture file of `dir` at each capture; `dir` must be a
/// directory (it may be empty until the camera program writes its first frame).
pub fn newest_in_dir(dir: &Path) -> Result<NewestInDir, CameraError> {
    let read_error = |source| {
        CameraError::Picture(PictureError::Read {
            name: dir.display().to_string(),
            source,
        })
    };
    let meta = std::fs::metadata(dir).map_err(read_error)?;
    if !meta.is_dir() {
        return Err(CameraError::NotADirectory {
            path: dir.to_path_buf(),
        });
    }
    std::fs::read_dir(dir).map_err(read_error)?;
    Ok(NewestInDir {
        dir: dir.to_path_buf(),
    })
}

impl NewestInDir {
    /// The newest files, newest first, at most [`DIR_CANDIDATES`].
    fn candidates(&self) -> Result<Vec<PathBuf>, String> {
        let entries = std::fs::read_dir(&self.dir)
            .map_err(|e| format!("{}: cannot list: {e}", self.dir.display()))?;
        let mut newest: Vec<(SystemTime, PathBuf)> = Vec::with_capacity(DIR_CANDIDATES + 1);
        for entry in entries.flatten() {
            if entry.file_name().as_encoded_bytes().starts_with(b".") {
                continue;
            }
            let path = entry.path();
            let Some(modified) = std::fs::metadata(&path)
                .ok()
                .filter(std::fs::Metadata::is_file)
                .and_then(|m| m.modified().ok())
            else {
                continue;
            };
            let key = (modified, path);
            let at = newest.partition_point(|k| *k > key);
            if at < DIR_CANDIDATES {
                newest.insert(at, key);
                newest.truncate(DIR_CANDIDATES);
            }
        }
        Ok(newest.into_iter().map(|(_, path)| path).collect())
    }
}

/// A picture from a camera's bytes, `name` naming them: a JPEG must be whole (end with its EOI
/// marker), since the JPEG decoder makes a picture of any prefix, grey where bytes are missing
/// (a frame still being written, a command cut short). Other formats' decoders refuse a prefix.
pub fn camera_picture(name: &str, bytes: &[u8]) -> Result<debt::Image, String> {
    let jpeg = bytes.starts_with(&[0xFF, 0xD8]);
    if jpeg && !bytes.trim_ascii_end().ends_with(&[0xFF, 0xD9]) {
        return Err(format!(
            "{name}: a JPEG without its end (EOI) marker: not whole yet"
        ));
    }
    debt::picture::from_bytes_fit(name, bytes, CAMERA_OVERSIZE)
        .map(|(image, _)| image)
        .map_err(|e| e.to_string())
}

/// A picture file through [`camera_picture`].
fn camera_file(path: &Path) -> Result<debt::Image, String> {
    let name = path.display().to_string();
    match rovlink_base::io::read_file_bounded(path, debt::picture::MAX_INPUT_BYTES) {
        Ok(Some(bytes)) => camera_picture(&name, &bytes),
        Ok(None) => Err(PictureError::TooManyBytes { name }.to_string()),
        Err(source) => Err(PictureError::Read { name, source }.to_string()),
    }
}

impl Camera for NewestInDir {
    fn capture(&mut self) -> Result<debt::Image, String> {
        let mut first_error = None;
        for path in self.candidates()? {
            match camera_file(&path) {
                Ok(image) => return Ok(image),
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
        Err(first_error.unwrap_or_else(|| format!("{}: no picture file yet", self.dir.display())))
    }
}

/// How long a camera command may run before it is killed, s.
pub const COMMAND_TIMEOUT_S: f64 = 10.0;

/// The most bytes read from a camera command's standard output.
pub const MAX_COMMAND_BYTES: u64 = 64 << 20;

/// What a capture says while the command's first picture is not ready.
pub const WAITING: &str = "waiting for the camera command";

/// The tail of a command's standard error kept for its last line, bytes.
const STDERR_TAIL_BYTES: usize = 4096;

/// A capture's outcome from the worker.
type Shot = Result<debt::Image, String>;

/// `--camera-cmd CMD`: runs `sh -c CMD` (standard input closed) and reads one picture, in any
/// format the loader reads (PNG, JPEG, PNM, ...), from its standard output, e.g.
/// `ffmpeg -loglevel error -f v4l2 -i /dev/video0 -frames:v 1 -f image2pipe -c:v png -`.
///
/// In real time ([`command_camera`]) runs happen in a background thread, one at a time: the
/// first starts when the camera is made; each [`Camera::capture`] returns the picture finished since the
/// previous capture (or why the run failed: its exit status and the last line of its standard
/// error), and starts the next run. While a run is under way a capture returns
/// `Err(`[`WAITING`]`)` at once. In simulation ([`command_camera_waiting`]) a capture runs the
/// command and waits for it:
/// virtual time does not pass meanwhile, so the session is the same however long it takes. A
/// run that takes longer than its timeout is killed with its whole process group; so is a run
/// in progress when the camera is dropped.
pub struct CommandCamera {
    cmd: String,
    timeout: Duration,
    /// The background runs, in real time.
    worker: Option<Worker>,
    group: Arc<Mutex<Option<nix::unistd::Pid>>>,
    /// Set when the run is asked to stop: a waiting capture then kills its command at once.
    stop: Option<&'static AtomicBool>,
    /// Waiting captures: why the command is not run any more (one run took the whole timeout,
    /// and each capture waiting as long would stretch a simulation without end).
    gave_up: Option<String>,
}

struct Worker {
    requests: Sender<()>,
    shots: Receiver<Shot>,
    running: bool,
}

/// A camera running `cmd` in the background (real time), with the [`COMMAND_TIMEOUT_S`]
/// timeout; its first run starts now.
pub fn command_camera(cmd: &str) -> Result<CommandCamera, CameraError> {
    command_camera_timed(cmd, true, Duration::from_secs_f64(COMMAND_TIMEOUT_S))
}

/// A camera running `cmd` at each capture and waiting for it (simulation: virtual time stands
/// still meanwhile), with the [`COMMAND_TIMEOUT_S`] timeout.
pub fn command_camera_waiting(cmd: &str) -> Result<CommandCamera, CameraError> {
    command_camera_timed(cmd, false, Duration::from_secs_f64(COMMAND_TIMEOUT_S))
}

/// [`command_camera`] (`live`) or [`command_camera_waiting`] with another timeout.
pub fn command_camera_timed(
    cmd: &str,
    live: bool,
    timeout: Duration,
) -> Result<CommandCamera, CameraError> {
    if cmd.trim().is_empty() {
        return Err(CameraError::EmptyCommand);
    }
    let group = Arc::new(Mutex::new(None));
    let worker = live
        .then(|| {
            let (requests, wanted) = channel::<()>();
            let (done, shots) = channel();
            let (cmd, group) = (cmd.to_string(), Arc::clone(&group));
            std::thread::Builder::new()
                .name("camera-cmd".into())
                .spawn(move || {
                    while wanted.recv().is_ok() {
                        if done.send(run_once(&cmd, timeout, &group, None)).is_err() {
                            return;
                        }
                    }
                })
                .map_err(CameraError::Thread)?;
            let running = requests.send(()).is_ok();
            Ok::<_, CameraError>(Worker {
                requests,
                shots,
                running,
            })
        })
        .transpose()?;
    Ok(CommandCamera {
        cmd: cmd.to_string(),
        timeout,
        worker,
        group,
        stop: None,
        gave_up: None,
    })
}

impl CommandCamera {
    /// The same camera, a waiting capture of which ends (killing the command) as soon as
    /// `stop` is set, rather than at the timeout: a SIGTERM ends a simulation promptly.
    pub fn stop_on(mut self, stop: &'static AtomicBool) -> Self {
        self.stop = Some(stop);
        self
    }
}

impl Camera for CommandCamera {
    fn capture(&mut self) -> Result<debt::Image, String> {
        let Some(worker) = self.worker.as_mut() else {
            if let Some(reason) = &self.gave_up {
                return Err(reason.clone());
            }
            let started = Instant::now();
            let shot = run_once(&self.cmd, self.timeout, &self.group, self.stop);
            if let Err(reason) = &shot
                && started.elapsed() >= self.timeout
            {
                self.gave_up = Some(format!("{reason}; not run again"));
            }
            return shot;
        };
        let mut shot = None;
        while let Ok(finished) = worker.shots.try_recv() {
            shot = Some(finished);
            worker.running = false;
        }
        if !worker.running {
            if worker.requests.send(()).is_err() {
                return Err("camera command: its thread has ended".into());
            }
            worker.running = true;
        }
        shot.unwrap_or_else(|| Err(WAITING.into()))
    }
}

impl Drop for CommandCamera {
    fn drop(&mut self) {
        // The worker ends at its next request; a run in progress is killed now.
        self.worker = None;
        let group = self.group.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(pid) = *group {
            let _ = nix::sys::signal::killpg(pid, nix::sys::signal::Signal::SIGKILL);
        }
    }
}

/// The last non-empty line of a stream, reading it all (so the writer never blocks) but
/// keeping only its tail.
fn last_line(mut reader: impl std::io::Read) -> String {
    let mut tail = Vec::with_capacity(2 * STDERR_TAIL_BYTES);
    let mut chunk = [0u8; 4096];
    loop {
        match reader.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => {
                tail.extend_from_slice(chunk.get(..n).unwrap_or_default());
                if tail.len() > STDERR_TAIL_BYTES {
                    tail.drain(..tail.len() - STDERR_TAIL_BYTES);
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(_) => break,
        }
    }
    String::from_utf8_lossy(&tail)
        .lines()
        .map(str::trim)
        .rfind(|l| !l.is_empty())
        .unwrap_or_default()
        .to_string()
}

/// Runs the command once: its picture, or why there is none.
fn run_once(
    cmd: &str,
    timeout: Duration,
    group: &Mutex<Option<nix::unistd::Pid>>,
    stop: Option<&AtomicBool>,
) -> Shot {
    use std::os::unix::process::CommandExt;
    use std::process::{Command, Stdio};
    let deadline = Instant::now() + timeout;
    let lock = || group.lock().unwrap_or_else(|e| e.into_inner());
    let mut child = {
        let mut held = lock();
        let child = Command::new("sh")
            .arg("-c")
            .arg(cmd)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn()
            .map_err(|e| format!("camera command: cannot start sh: {e}"))?;
        *held = i32::try_from(child.id())
            .ok()
            .map(nix::unistd::Pid::from_raw);
        child
    };
    let (out_tx, out_rx) = channel();
    if let Some(stdout) = child.stdout.take() {
        std::thread::spawn(move || {
            let _ = out_tx.send(rovlink_base::io::read_bounded(stdout, MAX_COMMAND_BYTES));
        });
    }
    let (err_tx, err_rx) = channel();
    if let Some(stderr) = child.stderr.take() {
        std::thread::spawn(move || {
            let _ = err_tx.send(last_line(stderr));
        });
    }
    let stopped = || stop.is_some_and(|flag| flag.load(Ordering::SeqCst));
    // Waited for in slices, so a stop asked for meanwhile is seen within one.
    let output = loop {
        let slice = deadline
            .saturating_duration_since(Instant::now())
            .min(Duration::from_millis(50));
        match out_rx.recv_timeout(slice) {
            Err(RecvTimeoutError::Timeout) if !stopped() && Instant::now() < deadline => {}
            other => break other,
        }
    };
    // The command has closed its output (or overrun it, or run out of time): reap it, killing
    // its group if it is still there at the deadline.
    let status = loop {
        let mut held = lock();
        match child.try_wait() {
            Ok(Some(status)) => {
                *held = None;
                break Ok(status);
            }
            Ok(None) if Instant::now() < deadline && output.is_ok() && !stopped() => {}
            Ok(None) | Err(_) => {
                if let Some(pid) = *held {
                    let _ = nix::sys::signal::killpg(pid, nix::sys::signal::Signal::SIGKILL);
                }
                let _ = child.wait();
                *held = None;
                if stopped() {
                    break Err("camera command: killed: the run was asked to stop".into());
                }
                break Err(format!(
                    "camera command: killed after {:.1} s without finishing",
                    timeout.as_secs_f64()
                ));
            }
        }
        drop(held);
        std::thread::sleep(Duration::from_millis(5));
    };
    let said = || {
        let line = err_rx
            .recv_timeout(Duration::from_millis(200))
            .unwrap_or_default();
        if line.is_empty() {
            String::new()
        } else {
            format!(": {line}")
        }
    };
    let status = status.map_err(|e| format!("{e}{}", said()))?;
    if !status.success() {
        let code = status.code().map_or_else(
            || "killed by a signal".to_string(),
            |c| format!("exit status {c}"),
        );
        return Err(format!("camera command: {code}{}", said()));
    }
    let bytes = match output {
        Ok(Ok(Some(bytes))) => bytes,
        Ok(Ok(None)) => {
            return Err(format!(
                "camera command: more than {} MiB on its output: not one picture",
                MAX_COMMAND_BYTES >> 20
            ));
        }
        Ok(Err(e)) => return Err(format!("camera command: cannot read its output: {e}")),
        Err(_) => return Err("camera command: its output did not close".into()),
    };
    if bytes.is_empty() {
        return Err(format!(
            "camera command: no picture on its output{}",
            said()
        ));
    }
    camera_picture("camera command output", &bytes)
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

    fn set_mtime(path: &Path, secs_ago: u64) {
        let when = SystemTime::now() - Duration::from_secs(secs_ago);
        std::fs::File::options()
            .write(true)
            .open(path)
            .unwrap()
            .set_modified(when)
            .unwrap();
    }

    #[test]
    fn the_directory_camera_takes_the_newest_picture_and_passes_over_one_being_written() {
        let dir = tempfile::tempdir().unwrap();
        let mut camera = newest_in_dir(dir.path()).unwrap();
        let error = camera.capture().unwrap_err();
        assert!(error.ends_with("no picture file yet"), "{error}");
        std::fs::write(dir.path().join("b.png"), png(8, 6)).unwrap();
        std::fs::write(dir.path().join("a.png"), png(4, 3)).unwrap();
        set_mtime(&dir.path().join("b.png"), 20);
        set_mtime(&dir.path().join("a.png"), 10);
        assert_eq!(camera.capture().unwrap().width, 4);
        // A newer file appears; then one half written, and a hidden one: both passed over.
        std::fs::write(dir.path().join("c.png"), png(16, 2)).unwrap();
        set_mtime(&dir.path().join("c.png"), 5);
        assert_eq!(camera.capture().unwrap().width, 16);
        let whole = png(32, 2);
        std::fs::write(dir.path().join("d.png"), &whole[..whole.len() / 2]).unwrap();
        std::fs::write(dir.path().join(".e.png"), png(64, 2)).unwrap();
        assert_eq!(camera.capture().unwrap().width, 16);
        // Same time: the name decides.
        std::fs::write(dir.path().join("d.png"), &whole).unwrap();
        set_mtime(&dir.path().join("d.png"), 5);
        assert_eq!(camera.capture().unwrap().width, 32);
    }

    #[test]
    fn the_directory_camera_needs_a_directory_and_says_why_a_capture_fails() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("x.png");
        std::fs::write(&file, png(2, 2)).unwrap();
        assert!(matches!(
            newest_in_dir(&file),
            Err(CameraError::NotADirectory { .. })
        ));
        assert!(newest_in_dir(&dir.path().join("none")).is_err());
        std::fs::write(&file, b"not a picture").unwrap();
        let error = newest_in_dir(dir.path()).unwrap().capture().unwrap_err();
        assert!(error.contains("x.png: not a readable image"), "{error}");
    }

    /// Captures until the command camera gives something other than [`WAITING`], or 5 s.
    fn shot(camera: &mut CommandCamera) -> Result<debt::Image, String> {
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            match camera.capture() {
                Err(e) if e == WAITING && Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(10));
                }
                other => return other,
            }
        }
    }

    #[test]
    fn the_command_camera_reads_a_picture_from_its_output_without_holding_up_a_capture() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("frame.png");
        std::fs::write(&file, png(12, 7)).unwrap();
        let cmd = format!("sleep 0.5; cat '{}'", file.display());
        let started = Instant::now();
        let mut camera = command_camera(&cmd).unwrap();
        assert_eq!(camera.capture().unwrap_err(), WAITING);
        assert!(
            started.elapsed() < Duration::from_millis(300),
            "a capture waited"
        );
        let image = shot(&mut camera).unwrap();
        assert_eq!((image.width, image.height, image.channels), (12, 7, 3));
        assert!(started.elapsed() >= Duration::from_millis(500));
        // The capture started the next run: it is not ready at once, then it is.
        assert_eq!(camera.capture().unwrap_err(), WAITING);
        assert_eq!(shot(&mut camera).unwrap().width, 12);
        assert!(matches!(
            command_camera("  "),
            Err(CameraError::EmptyCommand)
        ));
    }

    #[test]
    fn a_failing_command_says_its_exit_status_and_last_line() {
        let mut camera =
            command_camera("echo starting >&2; echo 'no such device /dev/video9' >&2; exit 3")
                .unwrap();
        assert_eq!(
            shot(&mut camera).unwrap_err(),
            "camera command: exit status 3: no such device /dev/video9"
        );
        let mut camera = command_camera("echo 'device busy' >&2").unwrap();
        assert_eq!(
            shot(&mut camera).unwrap_err(),
            "camera command: no picture on its output: device busy"
        );
        let mut camera = command_camera("printf 'P5 2 2 255 j'").unwrap();
        let error = shot(&mut camera).unwrap_err();
        assert!(
            error.starts_with("camera command output: not a readable image"),
            "{error}"
        );
    }

    #[test]
    fn a_command_past_its_timeout_is_killed_with_its_children() {
        let dir = tempfile::tempdir().unwrap();
        let marker = dir.path().join("late");
        // The child of the shell would write the marker if it survived.
        let cmd = format!("(sleep 1; touch '{}') & sleep 5", marker.display());
        let started = Instant::now();
        let mut camera = command_camera_timed(&cmd, true, Duration::from_millis(300)).unwrap();
        let error = shot(&mut camera).unwrap_err();
        assert_eq!(
            error,
            "camera command: killed after 0.3 s without finishing"
        );
        assert!(
            started.elapsed() < Duration::from_secs(2),
            "{:?}",
            started.elapsed()
        );
        std::thread::sleep(Duration::from_millis(1200));
        assert!(!marker.exists(), "a child of the command outlived the kill");
    }

    #[test]
    fn a_jpeg_cut_short_is_not_taken() {
        let image = debt::Image {
            width: 64,
            height: 48,
            channels: 3,
            data: (0..64 * 48 * 3).map(|k| (k % 251) as u8).collect(),
        };
        let jpeg = debt::picture::encode(&image, debt::picture::OutputFormat::Jpeg).unwrap();
        // The decoder alone makes a picture of a prefix; the camera does not take it.
        assert!(
            debt::picture::from_bytes_fit("h", &jpeg[..jpeg.len() / 2], CAMERA_OVERSIZE).is_ok()
        );
        for cut in [jpeg.len() / 4, jpeg.len() / 2, jpeg.len() - 1] {
            let error = camera_picture("half.jpg", &jpeg[..cut]).unwrap_err();
            assert_eq!(
                error,
                "half.jpg: a JPEG without its end (EOI) marker: not whole yet"
            );
        }
        assert_eq!(camera_picture("whole.jpg", &jpeg).unwrap().width, 64);
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("a.jpg"), &jpeg).unwrap();
        set_mtime(&dir.path().join("a.jpg"), 10);
        std::fs::write(dir.path().join("b.jpg"), &jpeg[..jpeg.len() / 2]).unwrap();
        let mut camera = newest_in_dir(dir.path()).unwrap();
        assert_eq!(camera.capture().unwrap().width, 64);
    }

    #[test]
    fn in_simulation_the_command_camera_waits_for_its_picture() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("frame.png");
        std::fs::write(&file, png(10, 4)).unwrap();
        let mut camera =
            command_camera_waiting(&format!("sleep 0.2; cat '{}'", file.display())).unwrap();
        for _ in 0..2 {
            let started = Instant::now();
            assert_eq!(camera.capture().unwrap().width, 10);
            assert!(started.elapsed() >= Duration::from_millis(200));
        }
        let mut camera = command_camera_waiting("exit 1").unwrap();
        assert_eq!(
            camera.capture().unwrap_err(),
            "camera command: exit status 1"
        );
    }

    #[test]
    fn a_waiting_command_that_runs_out_of_time_is_not_run_again_and_a_stop_ends_a_wait() {
        let mut camera =
            command_camera_timed("sleep 30", false, Duration::from_millis(300)).unwrap();
        let first = camera.capture().unwrap_err();
        assert!(first.contains("killed after 0.3 s"), "{first}");
        let started = Instant::now();
        let again = camera.capture().unwrap_err();
        assert!(again.ends_with("not run again"), "{again}");
        assert!(started.elapsed() < Duration::from_millis(100));

        static STOP: AtomicBool = AtomicBool::new(false);
        let mut camera = command_camera_timed("sleep 30", false, Duration::from_secs(20))
            .unwrap()
            .stop_on(&STOP);
        let setter = std::thread::spawn(|| {
            std::thread::sleep(Duration::from_millis(200));
            STOP.store(true, Ordering::SeqCst);
        });
        let started = Instant::now();
        let stopped = camera.capture().unwrap_err();
        assert!(stopped.contains("asked to stop"), "{stopped}");
        assert!(started.elapsed() < Duration::from_secs(2));
        setter.join().unwrap();
    }
}
