//! What a build reads: the input formats ([`InputFormat`]: OctoMap's `.graph`, the point-cloud
//! formats of [`cloud`], rosbag2 bags), files read whole within a bound
//! ([`read_input`], [`MAX_INPUT_BYTES`]), and each input opened as its scans: a `.graph`
//! streamed from disk, a cloud file read whole, a robot log read cloud by cloud.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use super::{BuildConfig, PipelineError};
use rovlink_base::io::{Input, IoError, StopReader};
use rovlink_octo::{ParseError, Pose, Scan, graph};
use rovlink_scans::bag::Bag;
use rovlink_scans::cloud::{self, CloudFormat, McapOptions};
use rovlink_scans::recording::{Recording, RecordingOptions};

/// An input's format: OctoMap's `.graph`, one of the point-cloud formats of [`cloud`], or a
/// rosbag2 bag.
///
/// The point-cloud formats are [`CloudFormat`]'s, named in one place: their names, file
/// extensions, sniffing and readers, here and in octo-delta's `--format` (its values, `--help`
/// and messages), all come from [`CloudFormat::ALL`]. See [`CloudFormat`] for the files a new
/// point-cloud format touches; nothing here changes for one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InputFormat {
    /// OctoMap scan graph (`.graph`): scans with poses, streamed from disk.
    Graph,
    /// A point-cloud file of [`cloud`]; an MCAP file is a robot log, its clouds posed by TF or
    /// a pose topic ([`recording`](rovlink_scans::recording)).
    Cloud(CloudFormat),
    /// A rosbag2 bag: its directory, its `metadata.yaml` or one `.db3` (sqlite3 or mcap storage).
    Rosbag2,
}

impl InputFormat {
    /// Every format: `.graph`, the point-cloud formats in [`CloudFormat::ALL`]'s order, rosbag2.
    pub const ALL: [InputFormat; CloudFormat::ALL.len() + 2] = {
        let mut all = [InputFormat::Graph; CloudFormat::ALL.len() + 2];
        let mut i = 0;
        while i < CloudFormat::ALL.len() {
            all[i + 1] = InputFormat::Cloud(CloudFormat::ALL[i]);
            i += 1;
        }
        all[CloudFormat::ALL.len() + 1] = InputFormat::Rosbag2;
        all
    };

    /// The short name: `graph`, a point-cloud format's ([`CloudFormat::name`]), `rosbag2`.
    pub fn name(self) -> &'static str {
        match self {
            InputFormat::Graph => "graph",
            InputFormat::Cloud(f) => f.name(),
            InputFormat::Rosbag2 => "rosbag2",
        }
    }

    /// Every name, as messages and `--help` list them: `graph, pcd, ply, xyz, mcap or rosbag2`.
    pub fn names() -> String {
        let names = InputFormat::ALL.map(InputFormat::name);
        let (last, rest) = names.split_last().expect("ALL is not empty");
        format!("{} or {last}", rest.join(", "))
    }

    /// The file names [`InputFormat::from_path`] knows, as messages list them: `.graph`, then
    /// each point-cloud format's first extension (`.graph, .pcd, .ply, .xyz, .mcap`).
    pub fn extensions() -> String {
        let clouds = CloudFormat::ALL.map(|f| format!(".{}", f.extensions()[0]));
        format!(".graph, {}", clouds.join(", "))
    }

    /// The format a file name names (`.graph`, `.db3` or `metadata.yaml`, or one of
    /// [`CloudFormat::from_path`]); a directory is not looked at here (see
    /// [`build`](super::build)).
    pub fn from_path(path: &Path) -> Option<InputFormat> {
        let ext = |e: &str| path.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
        if ext("graph") {
            return Some(InputFormat::Graph);
        }
        if rovlink_scans::bag::is_rosbag2_file_name(path) {
            return Some(InputFormat::Rosbag2);
        }
        CloudFormat::from_path(path).map(InputFormat::Cloud)
    }

    /// The point-cloud reader of this format (`None` for `.graph` and rosbag2).
    pub fn cloud(self) -> Option<CloudFormat> {
        match self {
            InputFormat::Cloud(f) => Some(f),
            InputFormat::Graph | InputFormat::Rosbag2 => None,
        }
    }

    /// Whether the format carries the sensor's pose (`.graph`, bags); the others get
    /// [`BuildConfig::origin_m`] (a bag without any pose source does too).
    pub fn has_poses(self) -> bool {
        matches!(
            self,
            InputFormat::Graph | InputFormat::Cloud(CloudFormat::Mcap) | InputFormat::Rosbag2
        )
    }

    /// Whether inputs of this format are robot logs read by [`Recording`].
    pub fn is_bag(self) -> bool {
        matches!(
            self,
            InputFormat::Cloud(CloudFormat::Mcap) | InputFormat::Rosbag2
        )
    }

    /// Reads every scan of `bytes` in this format.
    pub fn read(self, bytes: &[u8], mcap: &McapOptions) -> Result<Vec<Scan>, ParseError> {
        match self {
            InputFormat::Rosbag2 => Err(ParseError::new(
                0,
                "rosbag2: expected a bag directory, its metadata.yaml or a .db3 file, found bytes",
            )),
            InputFormat::Graph => graph::read_scans(bytes),
            InputFormat::Cloud(f) => cloud::read(f, bytes, mcap),
        }
    }
}

impl From<CloudFormat> for InputFormat {
    fn from(f: CloudFormat) -> Self {
        InputFormat::Cloud(f)
    }
}

impl std::str::FromStr for InputFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        InputFormat::ALL
            .into_iter()
            .find(|f| f.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown format {s:?} ({})", InputFormat::names()))
    }
}

impl std::fmt::Display for InputFormat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Largest cloud, stream or map file read whole, bytes (1 GiB; a `.graph` streams, unbounded).
pub const MAX_INPUT_BYTES: u64 = 1 << 30;

/// Reads all of `input` up to `max_bytes`: a longer one (an endless one such as `/dev/zero`)
/// is an error naming `name`, after reading `max_bytes + 1` bytes at most.
pub fn read_limited(input: &mut dyn Read, name: &str, max_bytes: u64) -> Result<Vec<u8>, IoError> {
    let read_err = |source| IoError::Read {
        name: name.to_string(),
        source,
    };
    rovlink_base::io::read_bounded(input, max_bytes)
        .map_err(read_err)?
        .ok_or_else(|| {
            read_err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("more than {max_bytes} bytes: not a file octo-delta reads whole"),
            ))
        })
}

/// An input file (`-`: standard input) read whole, at most [`MAX_INPUT_BYTES`], and the name
/// its errors carry.
pub fn read_input(path: &Path) -> Result<(Vec<u8>, String), PipelineError> {
    let mut input = Input::open(Some(path))?;
    let name = input.name.clone();
    let bytes = read_limited(input.reader(), &name, MAX_INPUT_BYTES)?;
    Ok((bytes, name))
}

/// The files a build of `inputs` reads: the inputs, then the bags' own files (a rosbag2
/// directory's `.db3` files and `metadata.yaml`) of every input that is a bag by its path or
/// by `format`.
pub fn input_files(inputs: &[PathBuf], format: Option<InputFormat>) -> Vec<PathBuf> {
    let bags = inputs
        .iter()
        .filter(|p| Bag::is_bag_path(p) || format.is_some_and(InputFormat::is_bag));
    let bag_files = bags.flat_map(|p| Bag::files(p));
    inputs.iter().cloned().chain(bag_files).collect()
}

/// The scans of one input: a stream of scans (a `.graph` file is streamed from disk, so a large
/// survey never sits in memory whole; cloud files are read whole), or a robot log read cloud by
/// cloud ([`Recording`]).
pub(crate) enum ScanSource<'a> {
    /// Scans, how many there will be, and the format.
    Scans(
        Box<dyn Iterator<Item = Result<Scan, ParseError>> + 'a>,
        usize,
        InputFormat,
    ),
    /// A bag, its poses read.
    Bag(Box<Recording>),
    /// A live topic (`ros2:TOPIC`), read until stopped.
    Live(Box<super::ros2_input::Ros2Scans<'a>>),
}

/// The scans of one input, read through a [`StopReader`]: a read waiting on a silent pipe
/// gives up once `stop` is set.
pub(crate) fn open_scans<'a>(
    path: &Path,
    cfg: &BuildConfig,
    stop: &'a AtomicBool,
) -> Result<ScanSource<'a>, PipelineError> {
    if let Some(topic) = super::ros2_input::topic_of(path) {
        let scans = super::ros2_input::Ros2Scans::open(
            topic,
            &cfg.ros2,
            cfg.mcap.pose_topic.as_deref(),
            cfg.fixed_frame.clone(),
            stop,
        )?;
        return Ok(ScanSource::Live(Box::new(scans)));
    }
    let name = path.display().to_string();
    let bad = |source| PipelineError::Input {
        name: name.clone(),
        source,
    };
    let by_name = InputFormat::from_path(path);
    // Looked up, not opened (a named pipe would wait for a writer): a missing file is named.
    let meta = match rovlink_base::io::is_std(Some(path)) {
        true => None,
        false => Some(std::fs::metadata(path).map_err(|source| IoError::Open {
            path: path.to_path_buf(),
            source,
        })?),
    };
    let options = RecordingOptions {
        cloud_topic: cfg.mcap.cloud_topic.clone(),
        pose_topic: cfg.mcap.pose_topic.clone(),
        fixed_frame: cfg.fixed_frame.clone(),
        origin_given: cfg.origin_m.is_some(),
        one_pass: cfg.one_pass_bags,
    };
    let is_dir = meta.as_ref().is_some_and(|m| m.is_dir());
    let format = cfg
        .format
        .or(by_name)
        .or(is_dir.then_some(InputFormat::Rosbag2));
    if let Some(meta) = &meta {
        if format == Some(InputFormat::Graph) {
            let len = if meta.is_file() { meta.len() } else { u64::MAX };
            let stream = graph::ScanStream::new(StopReader::open(Some(path), stop), len);
            let stream = stream.map_err(bad)?;
            let n = stream.node_count() as usize;
            return Ok(ScanSource::Scans(Box::new(stream), n, InputFormat::Graph));
        }
        // A rosbag2 file is read in place (SQLite, or its directory's metadata), never as a
        // stream: a FIFO or a device there is refused at once, not waited on.
        if format == Some(InputFormat::Rosbag2) && !(meta.is_file() || is_dir) {
            rovlink_base::io::open_regular(path).map_err(|source| IoError::Open {
                path: path.to_path_buf(),
                source,
            })?;
        }
        if format.is_some_and(InputFormat::is_bag) && (meta.is_file() || is_dir) {
            let rec = Recording::open(path, &options, stop)?;
            return Ok(ScanSource::Bag(Box::new(rec)));
        }
    }
    let bytes = read_limited(
        &mut StopReader::open(Some(path), stop),
        &name,
        MAX_INPUT_BYTES,
    )?;
    let format = format
        .or_else(|| cloud::sniff(&bytes).map(InputFormat::from))
        .ok_or_else(|| PipelineError::UnknownFormat { name: name.clone() })?;
    if format == InputFormat::Cloud(CloudFormat::Mcap) {
        let rec = Recording::from_mcap_bytes(&name, bytes, &options, stop)?;
        return Ok(ScanSource::Bag(Box::new(rec)));
    }
    let scans = format.read(&bytes, &cfg.mcap).map_err(bad)?;
    let n = scans.len();
    Ok(ScanSource::Scans(
        Box::new(scans.into_iter().map(Ok)),
        n,
        format,
    ))
}

/// Inputs without a pose get the sensor origin of `--origin`: the points stay where they are in
/// the map frame, shifted into the sensor frame.
pub(crate) fn with_origin(mut scan: Scan, origin: Option<[f32; 3]>) -> Scan {
    if let Some(o) = origin
        && scan.pose == Pose::IDENTITY
    {
        scan.pose.translation_m = o;
        for p in &mut scan.points {
            *p = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        }
    }
    scan
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endless_inputs_are_cut_at_the_limit() {
        let mut zeros = std::io::repeat(0);
        let err = read_limited(&mut zeros, "/dev/zero", 1000).unwrap_err();
        assert_eq!(
            err.to_string(),
            "/dev/zero: read failed: more than 1000 bytes: not a file octo-delta reads whole"
        );
        let mut short: &[u8] = b"1 2 3\n";
        assert_eq!(read_limited(&mut short, "x", 6).unwrap(), b"1 2 3\n");
    }

    #[test]
    fn formats_by_name_and_extension() {
        for f in InputFormat::ALL {
            assert_eq!(f.name().parse::<InputFormat>(), Ok(f));
        }
        assert_eq!(
            InputFormat::from_path(Path::new("x.GRAPH")),
            Some(InputFormat::Graph)
        );
        assert_eq!(
            InputFormat::from_path(Path::new("x.txt")),
            Some(InputFormat::Cloud(CloudFormat::Xyz))
        );
        assert!("obj".parse::<InputFormat>().is_err());
        // The lists messages and --help give, made from CloudFormat::ALL.
        assert_eq!(
            InputFormat::names(),
            "graph, pcd, ply, xyz, mcap or rosbag2"
        );
        assert_eq!(InputFormat::extensions(), ".graph, .pcd, .ply, .xyz, .mcap");
        assert_eq!(
            "PLY".parse::<InputFormat>(),
            Ok(InputFormat::Cloud(CloudFormat::Ply))
        );
    }
}
