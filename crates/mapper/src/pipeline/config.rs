//! A build's configuration and its checks: every number with its range and unit
//! ([`check_range`], [`BuildConfig::validate`]), errors that name the option, the range and
//! what was found ([`ConfigError`]), and the operator's view a configuration asks for
//! ([`view_spec`]: resolution, coarse depth, region of interest).

use super::InputFormat;
use rovlink_octo::cast::{PreparedScan, TooManyCells};
pub use rovlink_octo::checks::{ConfigError, check_range, check_scan_period, shown};
use rovlink_octo::delta::{Roi, ViewSpec};
use rovlink_octo::tree::{OcTree, TREE_DEPTH};
use rovlink_scans::cloud::McapOptions;

/// Finest voxel edge accepted, m (0.1 mm).
pub const RESOLUTION_MIN_M: f64 = 1e-4;
/// Coarsest voxel edge accepted, m (1 km: the map then spans 65 536 km a side).
pub const RESOLUTION_MAX_M: f64 = 1e3;
/// Longest `--max-range`, m (100 km, beyond any sensor).
pub const MAX_RANGE_M: f64 = 1e5;
/// Largest coordinate of an ROI corner or a sensor origin, m (10 000 km).
pub const COORDINATE_MAX_M: f64 = 1e7;
/// Most threads casting rays.
pub const THREADS_MAX: usize = 64;
/// The most cells one scan's rays may cross by default (`--max-cells`): 2^28, a few GiB of
/// cell sets and new voxels at worst. A real sensor at a sane resolution stays far below it
/// (12 288 rays of 20 m at 0.1 m: about 4 M); a resolution far too fine for the scans' range
/// (0.1 mm over metres) would exhaust any machine's memory.
pub const CELLS_PER_SCAN_DEFAULT: u64 = 1 << 28;
/// Largest `--coarse-res` as a multiple of the resolution (coarse depth 1).
pub const COARSE_FACTOR_MAX: f64 = 32768.0;

/// How coarse the voxels sent outside the ROI are.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Coarse {
    /// A tree depth, 1..=16 (16 - k: voxels 2^k times the fine edge).
    Depth(u32),
    /// An edge in metres, rounded to the nearest power-of-two multiple of the resolution.
    Edge(f64),
}

impl Default for Coarse {
    /// Depth 13: coarse voxels 8 times the fine edge.
    fn default() -> Self {
        Coarse::Depth(13)
    }
}

/// Checks an ROI: finite corners within [`COORDINATE_MAX_M`], the lower not above the upper.
pub fn check_roi(roi: &Roi) -> Result<(), ConfigError> {
    let all = roi.min_m.iter().chain(&roi.max_m);
    if all
        .clone()
        .any(|c| !(c.is_finite() && c.abs() <= COORDINATE_MAX_M))
    {
        return Err(ConfigError::new(
            "--roi",
            format!("corners within +-{COORDINATE_MAX_M} m"),
            format!("{:?}..{:?}", roi.min_m, roi.max_m),
        ));
    }
    if (0..3).any(|i| roi.min_m[i] > roi.max_m[i]) {
        return Err(ConfigError::new(
            "--roi",
            "x0,y0,z0 not above x1,y1,z1",
            format!("{:?}..{:?}", roi.min_m, roi.max_m),
        ));
    }
    Ok(())
}

/// The operator's view: `resolution_m` (checked), the coarse depth of `coarse` and the ROI.
pub fn view_spec(
    resolution_m: f64,
    coarse: Coarse,
    roi: Option<Roi>,
) -> Result<ViewSpec, ConfigError> {
    check_range(
        "--res",
        resolution_m,
        RESOLUTION_MIN_M,
        RESOLUTION_MAX_M,
        "m",
    )?;
    if let Some(r) = &roi {
        check_roi(r)?;
    }
    let coarse_depth = match coarse {
        Coarse::Depth(d) => {
            if !(1..=TREE_DEPTH).contains(&d) {
                return Err(ConfigError::new("--coarse-depth", "1 ..= 16", d));
            }
            d
        }
        Coarse::Edge(m) => {
            let max = resolution_m * COARSE_FACTOR_MAX;
            check_range("--coarse-res", m, resolution_m, max, "m")?;
            let k = (m / resolution_m).log2().round().clamp(0.0, 15.0);
            TREE_DEPTH - k as u32
        }
    };
    Ok(ViewSpec {
        resolution_m,
        coarse_depth,
        roi,
    })
}

/// Everything [`build`] needs besides its inputs and outputs.
#[derive(Debug, Clone)]
pub struct BuildConfig {
    /// Voxel edge, m ([`RESOLUTION_MIN_M`] ..= [`RESOLUTION_MAX_M`]).
    pub resolution_m: f64,
    /// Coarse voxels outside the ROI.
    pub coarse: Coarse,
    /// The region sent at full resolution with colour; `None`: everywhere.
    pub roi: Option<Roi>,
    /// Rays longer than this mark free space up to it only, no hit, m (`None`: no limit).
    pub max_range_m: Option<f64>,
    /// The inputs' format; `None`: from each file's name, else its first bytes.
    pub format: Option<InputFormat>,
    /// Sensor origin for inputs without poses (PCD without VIEWPOINT, PLY, XYZ), m.
    pub origin_m: Option<[f64; 3]>,
    /// Bag topics (MCAP and rosbag2): the clouds' and the poses'.
    pub mcap: McapOptions,
    /// Bags posed by TF: the frame the map is built in (`None`: the root of the TF tree).
    pub fixed_frame: Option<String>,
    /// Build an `OcTree` even when the scans have colour.
    pub no_color: bool,
    /// Also resend an occupied voxel when a brighter colour is found for it.
    pub color_updates: bool,
    /// Threads casting rays (1 ..= [`THREADS_MAX`]); `None`: the machine's cores, at most 8.
    pub threads: Option<usize>,
    /// Most cells one scan's rays may cross (at least 1; counted before casting, as
    /// [`rovlink_octo::cast::ScanCaster::cells_bound`]): a scan over it fails the build
    /// ([`super::PipelineError::TooManyCells`]) rather than exhaust memory.
    pub max_cells_per_scan: u64,
    /// How `ros2:TOPIC` inputs join the graph.
    pub ros2: super::ros2_input::Ros2Input,
    /// Read bags in one pass ([`rovlink_scans::recording::one_pass`]): only for a caller that
    /// starts again without it on [`super::PipelineError::is_one_pass`] (a build whose outputs
    /// are not committed yet), never for a live mapper.
    pub one_pass_bags: bool,
}

impl Default for BuildConfig {
    fn default() -> Self {
        BuildConfig {
            resolution_m: 0.1,
            coarse: Coarse::default(),
            roi: None,
            max_range_m: None,
            format: None,
            origin_m: None,
            mcap: McapOptions::default(),
            fixed_frame: None,
            no_color: false,
            color_updates: false,
            threads: None,
            max_cells_per_scan: CELLS_PER_SCAN_DEFAULT,
            ros2: super::ros2_input::Ros2Input::default(),
            one_pass_bags: false,
        }
    }
}

impl BuildConfig {
    /// The threads a build casts on: [`BuildConfig::threads`], else the machine's cores, at
    /// most 8.
    pub fn thread_count(&self) -> usize {
        self.threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get().min(8)))
    }

    /// The map a build makes of scans starting with `first`: a `ColorOcTree` when it has
    /// colours (unless [`BuildConfig::no_color`]), its caster bound to
    /// [`BuildConfig::max_cells_per_scan`].
    pub fn new_tree(&self, first: &rovlink_octo::Scan) -> OcTree {
        let mut t = OcTree::new(self.resolution_m);
        if first.colors.is_some() && !self.no_color {
            t.enable_color();
        }
        t.caster_mut().set_max_cells(self.max_cells_per_scan);
        t
    }

    /// A scan as cast ([`rovlink_octo::cast::ScanCaster::prepare`]), scan number `scan` of
    /// the build: an error naming it when it would cross too many cells.
    pub fn cells_checked(
        &self,
        scan: u32,
        cast: Result<Option<PreparedScan>, TooManyCells>,
    ) -> Result<Option<PreparedScan>, super::PipelineError> {
        cast.map_err(|source| super::PipelineError::TooManyCells {
            scan,
            resolution_m: self.resolution_m,
            source,
        })
    }

    /// Checks every number; returns the view the stream will carry.
    pub fn validate(&self) -> Result<ViewSpec, ConfigError> {
        let spec = view_spec(self.resolution_m, self.coarse, self.roi)?;
        if let Some(r) = self.max_range_m
            && !(r.is_finite() && r > 0.0 && r <= MAX_RANGE_M)
        {
            return Err(ConfigError::new(
                "--max-range",
                format!("a range > 0 m ..= {MAX_RANGE_M} m"),
                shown(r),
            ));
        }
        if let Some(o) = self.origin_m
            && o.iter()
                .any(|c| !(c.is_finite() && c.abs() <= COORDINATE_MAX_M))
        {
            return Err(ConfigError::new(
                "--origin",
                format!("coordinates within +-{COORDINATE_MAX_M} m"),
                format!("{o:?}"),
            ));
        }
        if self.max_cells_per_scan == 0 {
            return Err(ConfigError::new("--max-cells", "at least 1 cell", 0));
        }
        if let Some(t) = self.threads
            && !(1..=THREADS_MAX).contains(&t)
        {
            return Err(ConfigError::new(
                "--threads",
                format!("1 ..= {THREADS_MAX} threads"),
                t,
            ));
        }
        Ok(spec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_out_of_range_are_refused_with_units() {
        let bad = |f: fn(&mut BuildConfig)| {
            let mut c = BuildConfig::default();
            f(&mut c);
            c.validate().unwrap_err().to_string()
        };
        assert_eq!(
            bad(|c| c.resolution_m = 0.0),
            "--res: expected 0.0001 m ..= 1000 m, found 0"
        );
        assert!(bad(|c| c.resolution_m = f64::NAN).starts_with("--res: expected"));
        assert!(bad(|c| c.resolution_m = 1e300).contains("found 1e300"));
        assert!(
            bad(|c| c.max_range_m = Some(-1.0)).starts_with("--max-range: expected a range > 0 m")
        );
        assert!(bad(|c| c.max_range_m = Some(f64::INFINITY)).contains("found inf"));
        assert!(bad(|c| c.coarse = Coarse::Depth(0)).starts_with("--coarse-depth"));
        assert!(bad(|c| c.coarse = Coarse::Edge(0.05)).starts_with("--coarse-res: expected 0.1 m"));
        assert!(bad(|c| c.coarse = Coarse::Edge(1e9)).starts_with("--coarse-res"));
        assert!(bad(|c| c.origin_m = Some([0.0, 1e300, 0.0])).starts_with("--origin"));
        assert!(bad(|c| c.threads = Some(0)).starts_with("--threads"));
        assert!(
            bad(|c| {
                c.roi = Some(Roi {
                    min_m: [1.0, 0.0, 0.0],
                    max_m: [0.0, 1.0, 1.0],
                })
            })
            .starts_with("--roi")
        );
        assert!(check_scan_period(f64::NAN).is_err());
        assert!(check_scan_period(1e300).is_err());
        assert_eq!(check_scan_period(0.0), Ok(0.0));
        let ok = BuildConfig {
            coarse: Coarse::Edge(0.8),
            ..BuildConfig::default()
        };
        assert_eq!(ok.validate().map(|s| s.coarse_depth), Ok(13));
    }
}
