//! A synthetic underwater survey: scans of a coloured seabed to test and benchmark the octree.
//!
//! Everything is deterministic from [`SurveyParams::seed`] (randomness from
//! [`rovlink_base::rng::Rng`]): the same parameters give the same scans, bit for bit, on every
//! machine.
//!
//! # The scene
//!
//! World frame: x east, y north, z up, metres; the survey area is the square
//! `[-area_m / 2, area_m / 2]^2` around the origin, the mean seabed level is z = 0.
//!
//! - **Seabed**: a height field, the sum of four long sinusoids (wavelengths 6-16 m, 0.1-0.3 m
//!   each), six Gaussian mounds and hollows (1-3 m wide, 0.2-0.6 m high or deep) and sand
//!   ripples (0.7-1 m wavelength, 2.5 cm). It is sampled on a 5 cm grid (coarser only when the
//!   area plus twice the maximum range exceeds 51 m: at most 1024 cells a side) and is the
//!   bilinear interpolation of that grid, flat beyond it.
//! - **Rocks**: [`SurveyParams::rocks`] ellipsoids, 0.25-0.8 m, partly buried.
//! - **Debris**: three boxes ("crates", up to 1.6 m), yawed, partly buried.
//! - **A pipeline**: a chain of 1.5 m cylinders (radius 0.15-0.3 m) with a ball joint at each
//!   bend, crossing the area and lying on the seabed, open at both ends.
//!
//! Colours: sand (modulated by broad patches, ripple crests, fine speckle and green-brown algae
//! patches), rocks darker grey-brown, the pipe ochre, the crates rust. The camera sees them
//! through water, lit by the vehicle's lamps: over the light path (twice the range) each channel
//! `c` is attenuated as `exp(-beta_c * path)` with beta = (0.25, 0.07, 0.05) per metre (red goes
//! first) and mixed with a blue-green backscatter. Every albedo channel is above the
//! backscatter, so each channel gets darker with distance: a voxel's brightest observation is
//! its closest one, which is what the brightest-colour rule of the bandwidth paper
//! (`shared/papers/octomap-transmission-bandwidth.txt`, section V.B) relies on. There is no
//! shading: the light is taken as constant over the scene, as that paper assumes.
//!
//! # The sensor
//!
//! A depth camera (RGB-D or dense stereo), pinhole model, [`SurveyParams::rays_x`] x
//! [`SurveyParams::rays_y`] rays through the pixel centres over a field of view of
//! [`SurveyParams::fov_x_deg`] x [`SurveyParams::fov_y_deg`], its optical axis tilted
//! [`SurveyParams::tilt_deg`] below the horizontal (forward and down). Each ray is cast
//! analytically against the objects and by safe-step marching against the height field (steps
//! bounded by the grid's steepest slope, so it never tunnels through, then refined by
//! bisection). The measured range gets Gaussian noise ([`SurveyParams::range_noise_m`]). A ray
//! that hits nothing within [`SurveyParams::max_range_m`] (or whose noisy range falls beyond it)
//! gives **no point**: the default geometry looks at the seabed with every ray, so this happens
//! only with other parameters.
//!
//! Points are in the **sensor frame**, the camera's optical convention: x right, y down, z
//! along the optical axis; a point is its ray's unit direction times the measured range,
//! computed in `f64` and cast to `f32`. The scan's pose (translation in metres and unit
//! quaternion, computed in `f64` and cast to `f32`) places them in the world:
//! `world = R(q) * p + t`, and `t` is the camera centre, where every ray starts. Points are in
//! row-major pixel order from the top-left; every scan has colours, one per point.
//!
//! # The path
//!
//! A lawnmower at constant altitude over the seabed (terrain following, with small Gaussian
//! attitude jitter): the first part of the scans ([`SurveyParams::explore_scans`]) explores the
//! whole area with lanes along x spaced for about 25 % side overlap; the rest
//! ([`SurveyParams::revisit_fraction`]) then revisits that already mapped ground along lanes
//! crossing them (along y), lower ([`SurveyParams::revisit_altitude_m`]), hence with closer,
//! brighter views: the explore-then-revisit scenario of the bandwidth paper (section VII.C),
//! where the map first grows and then is only updated. Scans are evenly spaced along each part.

use super::{Pose, Scan};
use rovlink_base::rng::Rng;

/// What to survey and how: scene, sensor and path. Any values are accepted (non-finite or
/// out-of-range ones are clamped to something sensible); [`Default`] is the benchmark survey.
#[derive(Debug, Clone, PartialEq)]
pub struct SurveyParams {
    /// Seed of the scene, the path's jitter and the range noise.
    pub seed: u64,
    /// Number of scans, explore and revisit parts together.
    pub scans: usize,
    /// Rays (pixels) across the image.
    pub rays_x: usize,
    /// Rays (pixels) down the image.
    pub rays_y: usize,
    /// Horizontal field of view in degrees (clamped to 1-170).
    pub fov_x_deg: f64,
    /// Vertical field of view in degrees (clamped to 1-170).
    pub fov_y_deg: f64,
    /// Tilt of the optical axis below the horizontal in degrees (0: forward, 90: straight
    /// down; clamped to 0-90).
    pub tilt_deg: f64,
    /// Side of the square survey area in metres.
    pub area_m: f64,
    /// Height of the camera above the seabed while exploring, in metres.
    pub altitude_m: f64,
    /// Height of the camera above the seabed while revisiting, in metres.
    pub revisit_altitude_m: f64,
    /// Longest range the camera measures, in metres.
    pub max_range_m: f64,
    /// Fraction of the scans (0-1) that revisit already mapped ground, at the end.
    pub revisit_fraction: f64,
    /// Standard deviation of the range noise in metres (0: exact ranges).
    pub range_noise_m: f64,
    /// Standard deviation of the heading, tilt and roll jitter in degrees.
    pub attitude_jitter_deg: f64,
    /// Number of rocks on the seabed.
    pub rocks: usize,
}

impl Default for SurveyParams {
    /// The benchmark survey: 80 scans of 128 x 96 rays (983 040 points) over 20 x 20 m at 3 m,
    /// the last 30 % revisiting at 2 m.
    fn default() -> Self {
        SurveyParams {
            seed: 1,
            scans: 80,
            rays_x: 128,
            rays_y: 96,
            fov_x_deg: 60.0,
            fov_y_deg: 45.0,
            tilt_deg: 60.0,
            area_m: 20.0,
            altitude_m: 3.0,
            revisit_altitude_m: 2.0,
            max_range_m: 8.0,
            revisit_fraction: 0.3,
            range_noise_m: 0.01,
            attitude_jitter_deg: 2.0,
            rocks: 30,
        }
    }
}

/// Most scans in a synthetic survey (it is built in memory: 10 000 default scans are about
/// 1.8 GB of points).
pub const MAX_SCANS: usize = 10_000;
/// Most rays across or down the image.
pub const MAX_RAYS: usize = 4096;
/// Most points in a whole survey (scans x rays), 2^27: about 2 GB in memory.
pub const MAX_POINTS: u64 = 1 << 27;
/// Most rocks on the seabed.
pub const MAX_ROCKS: usize = 100_000;

impl SurveyParams {
    /// Checks every number against a range no survey needs to leave (finite, the sign, a
    /// maximum); the error names the option (`--scans` for [`scans`](Self::scans)) and the
    /// range with its unit. [`survey`] itself clamps instead, so it never fails.
    pub fn validate(&self) -> Result<(), crate::checks::ConfigError> {
        use crate::checks::{ConfigError, check_range};
        let count = |option, v: usize, lo: usize, hi: usize, unit: &str| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(ConfigError {
                    option,
                    expected: format!("{lo} ..= {hi} {unit}"),
                    found: v.to_string(),
                })
            }
        };
        count("--scans", self.scans, 1, MAX_SCANS, "scans")?;
        count("rays_x", self.rays_x, 1, MAX_RAYS, "rays")?;
        count("rays_y", self.rays_y, 1, MAX_RAYS, "rays")?;
        count("rocks", self.rocks, 0, MAX_ROCKS, "rocks")?;
        let points = self.scans as u64 * self.rays_x as u64 * self.rays_y as u64;
        if points > MAX_POINTS {
            return Err(ConfigError {
                option: "--scans",
                expected: format!(
                    "at most {MAX_POINTS} points in the survey ({} scans of {} x {} rays)",
                    MAX_POINTS / (self.rays_x as u64 * self.rays_y as u64),
                    self.rays_x,
                    self.rays_y
                ),
                found: format!("{} scans, {points} points", self.scans),
            });
        }
        check_range("fov_x_deg", self.fov_x_deg, 1.0, 170.0, "deg")?;
        check_range("fov_y_deg", self.fov_y_deg, 1.0, 170.0, "deg")?;
        check_range("tilt_deg", self.tilt_deg, 0.0, 90.0, "deg")?;
        check_range("area_m", self.area_m, 0.0, 1e4, "m")?;
        check_range("altitude_m", self.altitude_m, 0.05, 1e4, "m")?;
        check_range(
            "revisit_altitude_m",
            self.revisit_altitude_m,
            0.05,
            1e4,
            "m",
        )?;
        check_range("max_range_m", self.max_range_m, 0.01, 1e4, "m")?;
        check_range("revisit_fraction", self.revisit_fraction, 0.0, 1.0, "")?;
        check_range("range_noise_m", self.range_noise_m, 0.0, 1e3, "m")?;
        check_range(
            "attitude_jitter_deg",
            self.attitude_jitter_deg,
            0.0,
            90.0,
            "deg",
        )?;
        Ok(())
    }

    /// How many of the scans (the first ones) explore; the others revisit.
    pub fn explore_scans(&self) -> usize {
        let revisit = clamp_or(self.revisit_fraction, 0.0, 1.0, 0.0);
        let explore = (self.scans as f64 * (1.0 - revisit)).round() as usize;
        explore.min(self.scans)
    }
}

/// The survey's scans, in path order: [`SurveyParams::explore_scans`] exploring, then the
/// revisit. See the module docs for the scene, the sensor and the frames.
pub fn survey(params: &SurveyParams) -> Vec<Scan> {
    let cfg = Config::new(params);
    let scene = Scene::new(&cfg);
    let cams = cameras(&cfg, &scene);
    let dirs = ray_directions(&cfg);
    let scan_one = |index: usize, cam: &Camera| scene.scan(&cfg, &dirs, cam, index);

    // Scans are independent (each has its own noise stream): spread them over a few threads;
    // the result does not depend on how many.
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, 8)
        .min(cams.len().max(1));
    if threads <= 1 {
        return cams
            .iter()
            .enumerate()
            .map(|(i, c)| scan_one(i, c))
            .collect();
    }
    let chunk = cams.len().div_ceil(threads);
    std::thread::scope(|s| {
        let handles: Vec<_> = cams
            .chunks(chunk)
            .enumerate()
            .map(|(k, part)| {
                let scan_one = &scan_one;
                s.spawn(move || {
                    part.iter()
                        .enumerate()
                        .map(|(i, c)| scan_one(k * chunk + i, c))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| match h.join() {
                Ok(scans) => scans,
                Err(panic) => std::panic::resume_unwind(panic),
            })
            .collect()
    })
}

/// The poses [`survey`] would give its scans (same parameters, same order), without casting a
/// ray.
pub fn survey_poses(params: &SurveyParams) -> Vec<Pose> {
    let cfg = Config::new(params);
    let scene = Scene::new(&cfg);
    cameras(&cfg, &scene).iter().map(|c| c.pose).collect()
}

// ---- parameters ---------------------------------------------------------------------------

/// `x` clamped to `[lo, hi]`, or `default` when it is NaN.
fn clamp_or(x: f64, lo: f64, hi: f64, default: f64) -> f64 {
    if x.is_nan() { default } else { x.clamp(lo, hi) }
}

/// The parameters made safe to compute with.
struct Config {
    seed: u64,
    scans: usize,
    explore: usize,
    rays_x: usize,
    rays_y: usize,
    fov_x_rad: f64,
    fov_y_rad: f64,
    tilt_rad: f64,
    area_m: f64,
    altitude_m: f64,
    revisit_altitude_m: f64,
    max_range_m: f64,
    range_noise_m: f64,
    jitter_rad: f64,
    rocks: usize,
}

impl Config {
    fn new(p: &SurveyParams) -> Config {
        Config {
            seed: p.seed,
            scans: p.scans,
            explore: p.explore_scans(),
            rays_x: p.rays_x,
            rays_y: p.rays_y,
            fov_x_rad: clamp_or(p.fov_x_deg, 1.0, 170.0, 60.0).to_radians(),
            fov_y_rad: clamp_or(p.fov_y_deg, 1.0, 170.0, 45.0).to_radians(),
            tilt_rad: clamp_or(p.tilt_deg, 0.0, 90.0, 60.0).to_radians(),
            area_m: clamp_or(p.area_m, 0.0, 1e4, 20.0),
            altitude_m: clamp_or(p.altitude_m, 0.05, 1e4, 3.0),
            revisit_altitude_m: clamp_or(p.revisit_altitude_m, 0.05, 1e4, 2.0),
            max_range_m: clamp_or(p.max_range_m, 0.01, 1e4, 8.0),
            range_noise_m: clamp_or(p.range_noise_m, 0.0, 1e3, 0.0),
            jitter_rad: clamp_or(p.attitude_jitter_deg, 0.0, 90.0, 0.0).to_radians(),
            rocks: p.rocks,
        }
    }
}

// ---- small vector algebra -----------------------------------------------------------------

type V3 = [f64; 3];

fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// Row-major 3 x 3 matrix.
type M3 = [[f64; 3]; 3];

fn mul(m: &M3, v: V3) -> V3 {
    [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
}

/// The unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (Shepperd's method).
fn quaternion_of(m: &M3) -> [f64; 4] {
    let trace = m[0][0] + m[1][1] + m[2][2];
    let q = if trace > 0.0 {
        let s = (trace + 1.0).sqrt() * 2.0;
        [
            s / 4.0,
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            s / 4.0,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][2] - m[2][0]) / s,
            (m[0][1] + m[1][0]) / s,
            s / 4.0,
            (m[1][2] + m[2][1]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[1][0] - m[0][1]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            s / 4.0,
        ]
    };
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
    q.map(|c| sign * c / n)
}

/// The rotation matrix of a quaternion (w, x, y, z), normalised first.
fn matrix_of(q: [f64; 4]) -> M3 {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// A uniform draw in `[lo, hi)`.
fn between(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.uniform()
}

/// A hash of a lattice cell to `[0, 1)`: texture that stays put in the world.
fn hash01(seed: u64, cell: [i64; 3]) -> f64 {
    let mut h = seed ^ 0x9e37_79b9_7f4a_7c15;
    for c in cell {
        h = (h ^ c as u64).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 29;
    }
    h = h.wrapping_mul(0x94d0_49bb_1331_11eb);
    h ^= h >> 32;
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// The cell of `p` in a lattice of `size_m`.
fn cell_of(p: V3, size_m: f64) -> [i64; 3] {
    p.map(|c| (c / size_m).floor() as i64)
}

fn smoothstep(lo: f64, hi: f64, x: f64) -> f64 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

// ---- the seabed height field --------------------------------------------------------------

/// `amplitude * sin(kx x + ky y + phase)`.
#[derive(Clone, Copy)]
struct Wave {
    kx: f64,
    ky: f64,
    phase: f64,
    amplitude_m: f64,
}

/// `amplitude * exp(-r^2 / (2 sigma^2))` around (x, y).
struct Bump {
    x_m: f64,
    y_m: f64,
    sigma_m: f64,
    amplitude_m: f64,
}

/// The seabed: a bilinear height grid, flat beyond its edges.
struct HeightGrid {
    x0_m: f64,
    y0_m: f64,
    cell_m: f64,
    nx: usize,
    ny: usize,
    /// Row-major heights (row j at y0 + j cell); `f32` halves the memory the rays walk over.
    z_m: Vec<f32>,
    /// An upper bound of the gradient's norm anywhere.
    slope: f64,
    /// The highest sample: nothing of the seabed is above.
    highest_m: f64,
}

impl HeightGrid {
    fn new(half_extent_m: f64, waves: &[Wave], bumps: &[Bump]) -> HeightGrid {
        let extent = 2.0 * half_extent_m;
        let cell_m = (extent / 1023.0).max(0.05);
        let n = ((extent / cell_m).ceil() as usize + 1).max(2);
        let (nx, ny) = (n, n);
        let x0_m = -half_extent_m;
        let y0_m = -half_extent_m;
        let xs: Vec<f64> = (0..nx).map(|i| x0_m + i as f64 * cell_m).collect();
        let ys: Vec<f64> = (0..ny).map(|j| y0_m + j as f64 * cell_m).collect();
        let mut z_m = vec![0.0; nx * ny];
        // Separable sums: sin(a + b) = sin a cos b + cos a sin b, exp(-(dx^2 + dy^2)) =
        // exp(-dx^2) exp(-dy^2): one pass of multiply-adds per component.
        for w in waves {
            let (sx, cx): (Vec<f64>, Vec<f64>) = xs.iter().map(|x| (w.kx * x).sin_cos()).unzip();
            for (j, y) in ys.iter().enumerate() {
                let (sy, cy) = (w.ky * y + w.phase).sin_cos();
                let row = &mut z_m[j * nx..(j + 1) * nx];
                for (i, z) in row.iter_mut().enumerate() {
                    *z += w.amplitude_m * (sx[i] * cy + cx[i] * sy);
                }
            }
        }
        for b in bumps {
            let g = |d: f64| (-d * d / (2.0 * b.sigma_m * b.sigma_m)).exp();
            let ex: Vec<f64> = xs.iter().map(|x| g(x - b.x_m)).collect();
            for (j, y) in ys.iter().enumerate() {
                let ey = b.amplitude_m * g(y - b.y_m);
                let row = &mut z_m[j * nx..(j + 1) * nx];
                for (z, e) in row.iter_mut().zip(&ex) {
                    *z += ey * e;
                }
            }
        }
        let z_m: Vec<f32> = z_m.into_iter().map(|z| z as f32).collect();
        let (mut gx, mut gy) = (0.0f32, 0.0f32);
        for j in 0..ny {
            for i in 0..nx {
                let z = z_m[j * nx + i];
                if i + 1 < nx {
                    gx = gx.max((z_m[j * nx + i + 1] - z).abs());
                }
                if j + 1 < ny {
                    gy = gy.max((z_m[(j + 1) * nx + i] - z).abs());
                }
            }
        }
        let highest_m = f64::from(z_m.iter().copied().fold(f32::NEG_INFINITY, f32::max));
        HeightGrid {
            x0_m,
            y0_m,
            cell_m,
            nx,
            ny,
            z_m,
            // Within a cell the bilinear gradient's components are blends of edge
            // differences: bounded by the largest ones.
            slope: f64::from(gx).hypot(f64::from(gy)) / cell_m,
            highest_m,
        }
    }

    fn height_m(&self, x: f64, y: f64) -> f64 {
        let locate = |v: f64, v0: f64, n: usize| {
            let f = ((v - v0) / self.cell_m).clamp(0.0, (n - 1) as f64);
            let i = (f as usize).min(n - 2);
            (i, f - i as f64)
        };
        let (i, tx) = locate(x, self.x0_m, self.nx);
        let (j, ty) = locate(y, self.y0_m, self.ny);
        let k = j * self.nx + i;
        let z = |k: usize| f64::from(self.z_m[k]);
        let (z00, z10) = (z(k), z(k + 1));
        let (z01, z11) = (z(k + self.nx), z(k + self.nx + 1));
        let a = z00 + (z10 - z00) * tx;
        let b = z01 + (z11 - z01) * tx;
        a + (b - a) * ty
    }

    /// Distance along the ray `o + t d` (d unit) to the seabed, if it is reached by `t_max`.
    fn cast(&self, o: V3, d: V3, t_max: f64) -> Option<f64> {
        const HIT_GAP_M: f64 = 1e-4;
        const MIN_STEP_M: f64 = 0.01;
        let gap = |t: f64| o[2] + t * d[2] - self.height_m(o[0] + t * d[0], o[1] + t * d[1]);
        // Along the ray the gap falls at most this fast: if not at all, it is never crossed.
        let closing = self.slope * d[0].hypot(d[1]) - d[2];
        if closing <= 0.0 || t_max.is_nan() || t_max <= 0.0 {
            return None;
        }
        let (mut t, mut g) = (0.0, gap(0.0));
        if g.is_nan() || g <= 0.0 {
            return None; // starts under the seabed
        }
        // Every step but the last is at least MIN_STEP_M long.
        let steps = (t_max / MIN_STEP_M).min(1e6) as usize + 2;
        for _ in 0..steps {
            if g < HIT_GAP_M {
                return Some(t);
            }
            // Also skip whole heights the ray cannot meet yet (high above the highest point).
            let above = o[2] + t * d[2] - self.highest_m;
            let safe = if above > 0.0 && d[2] < 0.0 {
                (above / -d[2]).max(g / closing)
            } else {
                g / closing
            };
            let mut t_next = t + safe.max(MIN_STEP_M);
            let at_end = t_next >= t_max;
            if at_end {
                t_next = t_max;
            }
            let g_next = gap(t_next);
            if g_next <= 0.0 {
                // Crossed within the last step, at most MIN_STEP_M long (shorter steps are
                // safe): there the surface is nearly a plane, and regula falsi converges in a
                // couple of steps.
                let (mut lo, mut hi, mut g_lo, mut g_hi) = (t, t_next, g, g_next);
                for _ in 0..3 {
                    let mid = lo + (hi - lo) * g_lo / (g_lo - g_hi);
                    let g_mid = gap(mid);
                    if g_mid.abs() < HIT_GAP_M {
                        return Some(mid);
                    }
                    if g_mid > 0.0 {
                        (lo, g_lo) = (mid, g_mid);
                    } else {
                        (hi, g_hi) = (mid, g_mid);
                    }
                }
                return Some(lo + (hi - lo) * g_lo / (g_lo - g_hi));
            }
            if at_end {
                return None;
            }
            (t, g) = (t_next, g_next);
        }
        None
    }
}

// ---- objects ------------------------------------------------------------------------------

/// What a ray hit, for its colour.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Surface {
    Sand,
    Rock(usize),
    Pipe,
    Crate,
}

/// An axis-aligned ellipsoid.
struct Rock {
    centre: V3,
    semi_axes_m: V3,
    albedo: [f64; 3],
}

impl Rock {
    fn radius_m(&self) -> f64 {
        self.semi_axes_m.iter().copied().fold(0.0, f64::max)
    }

    fn cast(&self, o: V3, d: V3) -> Option<f64> {
        let a = self.semi_axes_m;
        let os = sub(o, self.centre);
        let o1 = [os[0] / a[0], os[1] / a[1], os[2] / a[2]];
        let d1 = [d[0] / a[0], d[1] / a[1], d[2] / a[2]];
        sphere_roots(o1, d1, 1.0)
    }
}

/// The nearest t > 0 where `|o + t d| = r`.
fn sphere_roots(o: V3, d: V3, r: f64) -> Option<f64> {
    let a = dot(d, d);
    let b = dot(o, d);
    let c = dot(o, o) - r * r;
    let disc = b * b - a * c;
    if disc < 0.0 || a == 0.0 {
        return None;
    }
    let s = disc.sqrt();
    [(-b - s) / a, (-b + s) / a].into_iter().find(|&t| t > 1e-9)
}

/// An open cylinder from `start` along unit `axis` for `length_m`.
struct PipeSegment {
    start: V3,
    axis: V3,
    length_m: f64,
    radius_m: f64,
}

impl PipeSegment {
    fn cast(&self, o: V3, d: V3) -> Option<f64> {
        let w = sub(o, self.start);
        let (wa, da) = (dot(w, self.axis), dot(d, self.axis));
        let wp = sub(w, scale(self.axis, wa));
        let dp = sub(d, scale(self.axis, da));
        let a = dot(dp, dp);
        if a < 1e-12 {
            return None;
        }
        let b = dot(wp, dp);
        let c = dot(wp, wp) - self.radius_m * self.radius_m;
        let disc = b * b - a * c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        [(-b - s) / a, (-b + s) / a].into_iter().find(|&t| {
            let along = wa + t * da;
            t > 1e-9 && (0.0..=self.length_m).contains(&along)
        })
    }
}

/// A box yawed about z.
struct Crate {
    centre: V3,
    half_m: V3,
    cos_yaw: f64,
    sin_yaw: f64,
}

impl Crate {
    fn to_local(&self, v: V3) -> V3 {
        [
            self.cos_yaw * v[0] + self.sin_yaw * v[1],
            -self.sin_yaw * v[0] + self.cos_yaw * v[1],
            v[2],
        ]
    }

    fn cast(&self, o: V3, d: V3) -> Option<f64> {
        let ol = self.to_local(sub(o, self.centre));
        let dl = self.to_local(d);
        let (mut t_in, mut t_out) = (f64::NEG_INFINITY, f64::INFINITY);
        for k in 0..3 {
            let e = self.half_m[k];
            if dl[k] == 0.0 {
                if ol[k].abs() > e {
                    return None;
                }
                continue;
            }
            let (t1, t2) = ((-e - ol[k]) / dl[k], (e - ol[k]) / dl[k]);
            t_in = t_in.max(t1.min(t2));
            t_out = t_out.min(t1.max(t2));
        }
        if t_out < t_in || t_out <= 1e-9 {
            None
        } else if t_in > 1e-9 {
            Some(t_in)
        } else {
            Some(t_out)
        }
    }
}

// ---- the scene ----------------------------------------------------------------------------

const SAND: [f64; 3] = [196.0, 178.0, 132.0];
const ALGAE: [f64; 3] = [96.0, 118.0, 72.0];
const PIPE: [f64; 3] = [178.0, 136.0, 74.0];
const CRATE: [f64; 3] = [140.0, 86.0, 70.0];
/// Attenuation per metre of light path, per channel.
const BETA_PER_M: [f64; 3] = [0.25, 0.07, 0.05];
/// What the water itself scatters back towards the camera (far away, everything is this).
const BACKSCATTER: [f64; 3] = [4.0, 22.0, 30.0];

struct Scene {
    seed: u64,
    grid: HeightGrid,
    ripple: Wave,
    patches: [f64; 4],
    rocks: Vec<Rock>,
    pipe: Vec<PipeSegment>,
    joints: Vec<V3>,
    pipe_radius_m: f64,
    crates: Vec<Crate>,
}

/// One scan's camera: pose, and the same in f64 as the rays use it.
struct Camera {
    pose: Pose,
    origin: V3,
    rotation: M3,
}

impl Scene {
    fn new(cfg: &Config) -> Scene {
        let mut rng = Rng::new(cfg.seed, 0);
        let half = cfg.area_m / 2.0;
        let tau = std::f64::consts::TAU;
        let wave = |rng: &mut Rng, lambda: (f64, f64), amp: (f64, f64)| {
            let k = tau / between(rng, lambda.0, lambda.1);
            let dir = between(rng, 0.0, tau);
            Wave {
                kx: k * dir.cos(),
                ky: k * dir.sin(),
                phase: between(rng, 0.0, tau),
                amplitude_m: between(rng, amp.0, amp.1),
            }
        };
        let mut waves: Vec<Wave> = (0..4)
            .map(|_| wave(&mut rng, (6.0, 16.0), (0.1, 0.3)))
            .collect();
        let ripple = wave(&mut rng, (0.7, 1.0), (0.025, 0.025));
        let bumps: Vec<Bump> = (0..6)
            .map(|_| Bump {
                x_m: between(&mut rng, -half, half),
                y_m: between(&mut rng, -half, half),
                sigma_m: between(&mut rng, 1.0, 3.0),
                amplitude_m: between(&mut rng, 0.2, 0.6)
                    * if rng.bernoulli(0.5) { 1.0 } else { -1.0 },
            })
            .collect();
        waves.push(ripple);
        let grid = HeightGrid::new(half + cfg.max_range_m.min(50.0) + 1.0, &waves, &bumps);
        let patches = [0.0; 4].map(|_| between(&mut rng, 0.0, tau));

        let spread = half + 2.0;
        let rocks = (0..cfg.rocks)
            .map(|_| {
                let r = between(&mut rng, 0.25, 0.8);
                let semi_axes_m = [
                    r * between(&mut rng, 0.8, 1.3),
                    r * between(&mut rng, 0.8, 1.3),
                    r * between(&mut rng, 0.5, 0.9),
                ];
                let (x, y) = (
                    between(&mut rng, -spread, spread),
                    between(&mut rng, -spread, spread),
                );
                let z = grid.height_m(x, y) + semi_axes_m[2] * between(&mut rng, -0.4, 0.3);
                let grey = between(&mut rng, 75.0, 110.0);
                Rock {
                    centre: [x, y, z],
                    semi_axes_m,
                    albedo: [grey * 1.08, grey, grey * between(&mut rng, 0.78, 0.9)],
                }
            })
            .collect();

        let crates = (0..3)
            .map(|_| {
                let half_m = [
                    between(&mut rng, 0.3, 0.8),
                    between(&mut rng, 0.2, 0.5),
                    between(&mut rng, 0.15, 0.4),
                ];
                let (x, y) = (
                    between(&mut rng, -half * 0.8, half * 0.8),
                    between(&mut rng, -half * 0.8, half * 0.8),
                );
                let yaw = between(&mut rng, 0.0, tau);
                Crate {
                    centre: [x, y, grid.height_m(x, y) + 0.4 * half_m[2]],
                    half_m,
                    cos_yaw: yaw.cos(),
                    sin_yaw: yaw.sin(),
                }
            })
            .collect();

        // The pipeline: across the area at a random angle, 1.5 m segments resting on the seabed.
        let pipe_radius_m = between(&mut rng, 0.15, 0.3);
        let angle = between(&mut rng, -0.5, 0.5) + if rng.bernoulli(0.5) { 0.0 } else { 1.57 };
        let (dx, dy) = (angle.cos(), angle.sin());
        let (cx, cy) = (
            between(&mut rng, -half * 0.3, half * 0.3),
            between(&mut rng, -half * 0.3, half * 0.3),
        );
        let reach = 0.65 * cfg.area_m;
        let segments = ((2.0 * reach / 1.5).ceil() as usize).max(1);
        let joints: Vec<V3> = (0..=segments)
            .map(|k| {
                let s = -reach + 2.0 * reach * k as f64 / segments as f64;
                let (x, y) = (cx + s * dx, cy + s * dy);
                [x, y, grid.height_m(x, y) + 0.6 * pipe_radius_m]
            })
            .collect();
        let pipe = joints
            .windows(2)
            .filter_map(|w| {
                let v = sub(w[1], w[0]);
                let length_m = norm(v);
                (length_m > 0.0).then(|| PipeSegment {
                    start: w[0],
                    axis: scale(v, 1.0 / length_m),
                    length_m,
                    radius_m: pipe_radius_m,
                })
            })
            .collect();

        Scene {
            seed: cfg.seed,
            grid,
            ripple,
            patches,
            rocks,
            pipe,
            joints,
            pipe_radius_m,
            crates,
        }
    }

    /// One scan from `cam`; `index` picks its noise stream.
    fn scan(&self, cfg: &Config, dirs: &[V3], cam: &Camera, index: usize) -> Scan {
        let mut rng = Rng::new(cfg.seed, 1000 + index as u64);
        let o = cam.origin;
        let reach = cfg.max_range_m;
        // Only the objects a ray from here can reach: within range and inside the field of
        // view's four side planes (inward normals, through the camera centre).
        let (sa, ca) = (cfg.fov_x_rad / 2.0).sin_cos();
        let (sb, cb) = (cfg.fov_y_rad / 2.0).sin_cos();
        let sides = [[ca, 0.0, sa], [-ca, 0.0, sa], [0.0, cb, sb], [0.0, -cb, sb]]
            .map(|n| mul(&cam.rotation, n));
        let visible = |centre: V3, radius: f64| {
            let v = sub(centre, o);
            norm(v) <= reach + radius && sides.iter().all(|&n| dot(n, v) >= -radius)
        };
        let rocks: Vec<usize> = (0..self.rocks.len())
            .filter(|&i| visible(self.rocks[i].centre, self.rocks[i].radius_m()))
            .collect();
        let pipe: Vec<&PipeSegment> = self
            .pipe
            .iter()
            .filter(|s| {
                let half = s.length_m / 2.0;
                visible(add(s.start, scale(s.axis, half)), half + s.radius_m)
            })
            .collect();
        let joints: Vec<V3> = self
            .joints
            .iter()
            .copied()
            .filter(|&j| visible(j, self.pipe_radius_m))
            .collect();
        let crates: Vec<&Crate> = self
            .crates
            .iter()
            .filter(|c| visible(c.centre, norm(c.half_m)))
            .collect();

        let mut points = Vec::with_capacity(dirs.len());
        let mut colors = Vec::with_capacity(dirs.len());
        for &ds in dirs {
            let d = mul(&cam.rotation, ds);
            let mut best = (reach, None);
            let consider = |best: &mut (f64, Option<Surface>), t: Option<f64>, what: Surface| {
                if let Some(t) = t
                    && t <= best.0
                {
                    *best = (t, Some(what));
                }
            };
            for &i in &rocks {
                consider(&mut best, self.rocks[i].cast(o, d), Surface::Rock(i));
            }
            for s in &pipe {
                consider(&mut best, s.cast(o, d), Surface::Pipe);
            }
            for &j in &joints {
                let t = sphere_roots(sub(o, j), d, self.pipe_radius_m);
                consider(&mut best, t, Surface::Pipe);
            }
            for c in &crates {
                consider(&mut best, c.cast(o, d), Surface::Crate);
            }
            let ground = self.grid.cast(o, d, best.0);
            consider(&mut best, ground, Surface::Sand);
            let (t, Some(surface)) = best else {
                continue;
            };
            let range_m = if cfg.range_noise_m > 0.0 {
                t + cfg.range_noise_m * rng.standard_normal()
            } else {
                t
            };
            if !(range_m > 0.0 && range_m <= reach) {
                continue;
            }
            let albedo = self.albedo(surface, add(o, scale(d, t)));
            points.push(scale(ds, range_m).map(|c| c as f32));
            colors.push(through_water(albedo, range_m));
        }
        Scan {
            points,
            colors: Some(colors),
            pose: cam.pose,
        }
    }

    fn albedo(&self, surface: Surface, p: V3) -> [f64; 3] {
        let speckle = |size_m: f64| hash01(self.seed, cell_of(p, size_m));
        match surface {
            Surface::Sand => {
                let [x, y, _] = p;
                let ph = &self.patches;
                let patch = 0.5
                    + 0.5 * (0.9 * x + 0.4 * y + ph[0]).sin() * (0.5 * x - 0.8 * y + ph[1]).sin();
                let algae = 0.5
                    + 0.5
                        * (0.31 * x + 0.17 * y + ph[2]).sin()
                        * (0.23 * x - 0.37 * y + ph[3]).sin();
                let w = &self.ripple;
                let crest = 0.5 + 0.5 * (w.kx * x + w.ky * y + w.phase).sin();
                let m = 0.8 + 0.1 * patch + 0.06 * crest + 0.1 * (speckle(0.04) - 0.5);
                let g = 0.75 * smoothstep(0.72, 0.95, algae);
                [0, 1, 2].map(|c| m * (SAND[c] + (ALGAE[c] - SAND[c]) * g))
            }
            Surface::Rock(i) => {
                let m = 0.8 + 0.3 * speckle(0.05);
                self.rocks[i].albedo.map(|c| c * m)
            }
            Surface::Pipe => {
                let m = 0.85 + 0.25 * speckle(0.03);
                PIPE.map(|c| c * m)
            }
            Surface::Crate => {
                let slat = if (p[2] / 0.15).rem_euclid(1.0) < 0.12 {
                    0.75
                } else {
                    1.0
                };
                let m = slat * (0.8 + 0.3 * speckle(0.04));
                CRATE.map(|c| c * m)
            }
        }
    }
}

/// What the camera sees of `albedo` at `range_m`, lit from the vehicle (light path twice the
/// range).
fn through_water(albedo: [f64; 3], range_m: f64) -> [u8; 3] {
    [0, 1, 2].map(|c| {
        let k = (-BETA_PER_M[c] * 2.0 * range_m).exp();
        (albedo[c] * k + BACKSCATTER[c] * (1.0 - k))
            .round()
            .clamp(0.0, 255.0) as u8
    })
}

// ---- sensor and path ----------------------------------------------------------------------

/// Unit ray directions in the sensor frame (x right, y down, z forward), row-major.
fn ray_directions(cfg: &Config) -> Vec<V3> {
    let fx = cfg.rays_x as f64 / 2.0 / (cfg.fov_x_rad / 2.0).tan();
    let fy = cfg.rays_y as f64 / 2.0 / (cfg.fov_y_rad / 2.0).tan();
    let mut dirs = Vec::with_capacity(cfg.rays_x.saturating_mul(cfg.rays_y));
    for j in 0..cfg.rays_y {
        for i in 0..cfg.rays_x {
            let v = [
                (i as f64 + 0.5 - cfg.rays_x as f64 / 2.0) / fx,
                (j as f64 + 0.5 - cfg.rays_y as f64 / 2.0) / fy,
                1.0,
            ];
            dirs.push(scale(v, 1.0 / norm(v)));
        }
    }
    dirs
}

/// A polyline of lanes: `lanes` lines across the square of side `area_m`, along x (or y when
/// `along_y`), alternating direction.
fn lawnmower(area_m: f64, lanes: usize, along_y: bool) -> Vec<[f64; 2]> {
    let half = area_m / 2.0;
    let mut pts = Vec::with_capacity(2 * lanes);
    for k in 0..lanes {
        let across = -half + (k as f64 + 0.5) * area_m / lanes as f64;
        let (a, b) = if k % 2 == 0 {
            (-half, half)
        } else {
            (half, -half)
        };
        for along in [a, b] {
            pts.push(if along_y {
                [across, -along]
            } else {
                [along, across]
            });
        }
    }
    pts
}

/// `n` positions evenly spaced along a polyline, with the heading (radians from +x) of the
/// segment each lies on.
fn along(path: &[[f64; 2]], n: usize) -> Vec<([f64; 2], f64)> {
    let seg_len = |w: &[[f64; 2]]| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
    let total: f64 = path.windows(2).map(seg_len).sum();
    let start = path.first().copied().unwrap_or([0.0, 0.0]);
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut s = total * (i as f64 + 0.5) / n as f64;
        let mut at = (start, 0.0);
        for w in path.windows(2) {
            let l = seg_len(w);
            if l <= 0.0 {
                continue;
            }
            let heading = (w[1][1] - w[0][1]).atan2(w[1][0] - w[0][0]);
            let f = (s / l).min(1.0);
            at = (
                [
                    w[0][0] + f * (w[1][0] - w[0][0]),
                    w[0][1] + f * (w[1][1] - w[0][1]),
                ],
                heading,
            );
            if s <= l {
                break;
            }
            s -= l;
        }
        out.push(at);
    }
    out
}

/// Every scan's camera, in order.
fn cameras(cfg: &Config, scene: &Scene) -> Vec<Camera> {
    let mut rng = Rng::new(cfg.seed, 1);
    // Lanes spaced for ~25 % side overlap of the image footprint at the centre row.
    let slant_m = cfg.altitude_m / cfg.tilt_rad.sin().max(0.2);
    let swath_m = 2.0 * slant_m * (cfg.fov_x_rad / 2.0).tan();
    let lanes = ((cfg.area_m / (0.75 * swath_m)).ceil() as usize).clamp(1, 1000);
    let explore = lawnmower(cfg.area_m, lanes, false);
    let revisit = lawnmower(cfg.area_m, lanes.div_ceil(2), true);
    let parts = [
        (along(&explore, cfg.explore), cfg.altitude_m),
        (
            along(&revisit, cfg.scans - cfg.explore),
            cfg.revisit_altitude_m,
        ),
    ];
    let mut cams = Vec::with_capacity(cfg.scans);
    for (stations, altitude_m) in parts {
        for ([x, y], heading) in stations {
            let mut jitter = || cfg.jitter_rad * rng.standard_normal();
            let (psi, theta, roll) = (heading + jitter(), cfg.tilt_rad + jitter(), jitter());
            let forward = [psi.cos(), psi.sin(), 0.0];
            let right = [psi.sin(), -psi.cos(), 0.0];
            let z_axis = add(scale(forward, theta.cos()), [0.0, 0.0, -theta.sin()]);
            let y0 = cross(z_axis, right);
            let x_axis = add(scale(right, roll.cos()), scale(y0, roll.sin()));
            let y_axis = cross(z_axis, x_axis);
            // Columns: the sensor axes in the world.
            let m: M3 = [0, 1, 2].map(|r| [x_axis[r], y_axis[r], z_axis[r]]);
            let q = quaternion_of(&m).map(|c| c as f32);
            let t = [x, y, scene.grid.height_m(x, y) + altitude_m].map(|c| c as f32);
            cams.push(Camera {
                pose: Pose {
                    translation_m: t,
                    rotation: q,
                },
                // The rays use the pose as stored, so the points agree with it.
                origin: t.map(f64::from),
                rotation: matrix_of(q.map(f64::from)),
            });
        }
    }
    cams
}

/// `scans` in the input format of the C++ `ColorOcTree` reference (`tests/octomap/color_tree.cpp`,
/// the coloured build's anchor in `scripts/octo-bench.sh`), little-endian: `RVCS`, u32 scan
/// count, then per scan seven `f32` (tx ty tz qw qx qy qz: the sensor pose), u32 point count n,
/// n x 3 `f32` (x y z in the sensor frame), n x 3 `u8` (r g b; white for a scan without
/// colours).
pub fn reference_dump(scans: &[Scan]) -> Vec<u8> {
    let mut out = b"RVCS".to_vec();
    out.extend((scans.len() as u32).to_le_bytes());
    for scan in scans {
        let p = &scan.pose;
        for v in p.translation_m.iter().chain(&p.rotation) {
            out.extend(v.to_le_bytes());
        }
        out.extend((scan.points.len() as u32).to_le_bytes());
        for v in scan.points.iter().flatten() {
            out.extend(v.to_le_bytes());
        }
        let white = [255u8; 3];
        for i in 0..scan.points.len() {
            let c = scan
                .colors
                .as_ref()
                .and_then(|c| c.get(i))
                .unwrap_or(&white);
            out.extend(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn numbers_beyond_any_survey_are_refused_before_allocating() {
        // Issue 14: --scans 4294967296 aborted allocating 72 GB.
        let p = SurveyParams {
            scans: 4_294_967_296,
            ..SurveyParams::default()
        };
        assert_eq!(
            p.validate().unwrap_err().to_string(),
            "--scans: expected 1 ..= 10000 scans, found 4294967296"
        );
        for bad in [
            SurveyParams {
                scans: 0,
                ..SurveyParams::default()
            },
            SurveyParams {
                rays_x: 0,
                ..SurveyParams::default()
            },
            SurveyParams {
                rays_x: 4096,
                rays_y: 4096,
                ..SurveyParams::default()
            },
            SurveyParams {
                area_m: f64::NAN,
                ..SurveyParams::default()
            },
            SurveyParams {
                max_range_m: f64::INFINITY,
                ..SurveyParams::default()
            },
            SurveyParams {
                revisit_fraction: -0.5,
                ..SurveyParams::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        assert_eq!(SurveyParams::default().validate(), Ok(()));
        assert_eq!(
            SurveyParams {
                scans: MAX_SCANS,
                ..SurveyParams::default()
            }
            .validate(),
            Ok(())
        );
    }

    use super::*;
    use std::collections::HashSet;

    fn small() -> SurveyParams {
        // The default survey's geometry and path, fewer rays.
        SurveyParams {
            rays_x: 32,
            rays_y: 24,
            ..SurveyParams::default()
        }
    }

    /// `R(q) p + t` in f64, as OctoMap's pose transform does it (q p q*).
    fn to_world(pose: &Pose, p: [f32; 3]) -> V3 {
        let m = matrix_of(pose.rotation.map(f64::from));
        add(mul(&m, p.map(f64::from)), pose.translation_m.map(f64::from))
    }

    #[test]
    fn deterministic_by_seed() {
        let p = small();
        let a = survey(&p);
        assert_eq!(a, survey(&p));
        let b = survey(&SurveyParams {
            seed: 2,
            ..p.clone()
        });
        assert_ne!(a, b);
        assert_eq!(
            a.iter().map(|s| s.pose).collect::<Vec<_>>(),
            survey_poses(&p)
        );
    }

    #[test]
    fn shape_range_and_colours() {
        let p = small();
        let scans = survey(&p);
        assert_eq!(scans.len(), 80);
        assert_eq!(p.explore_scans(), 56);
        let mut distinct = HashSet::new();
        for s in &scans {
            let colors = s.colors.as_ref().expect("colours");
            assert_eq!(colors.len(), s.points.len());
            // Looking at the seabed: (nearly) every ray hits.
            assert!(s.points.len() > 32 * 24 * 9 / 10, "{}", s.points.len());
            for (pt, c) in s.points.iter().zip(colors) {
                let r = pt.iter().map(|&v| f64::from(v).powi(2)).sum::<f64>().sqrt();
                assert!(r <= p.max_range_m + 1e-4 && pt[2] > 0.0, "{pt:?}");
                distinct.insert(*c);
            }
            let q = s.pose.rotation.map(f64::from);
            assert!((q.iter().map(|c| c * c).sum::<f64>() - 1.0).abs() < 1e-6);
        }
        assert!(distinct.len() > 500, "{} colours", distinct.len());
    }

    #[test]
    fn points_lie_on_the_scene() {
        let p = SurveyParams {
            range_noise_m: 0.0,
            ..small()
        };
        let cfg = Config::new(&p);
        let scene = Scene::new(&cfg);
        let (mut on_sand, mut total) = (0, 0);
        for s in survey(&p) {
            for &pt in &s.points {
                let w = to_world(&s.pose, pt);
                let gap = w[2] - scene.grid.height_m(w[0], w[1]);
                // Nothing under the seabed, nothing floating higher than a rock or crate.
                assert!((-1e-3..1.7).contains(&gap), "{w:?} gap {gap}");
                on_sand += usize::from(gap.abs() < 2e-3);
                total += 1;
            }
        }
        assert!(on_sand * 10 > total * 7, "{on_sand} of {total} on the sand");
        assert!(on_sand < total, "some points on objects");
    }

    #[test]
    fn revisit_re_observes_explored_ground() {
        let p = small();
        let scans = survey(&p);
        let explore = p.explore_scans();
        let cell = |w: V3| [(w[0] / 0.5).floor() as i64, (w[1] / 0.5).floor() as i64];
        let seen: HashSet<[i64; 2]> = scans[..explore]
            .iter()
            .flat_map(|s| s.points.iter().map(|&pt| cell(to_world(&s.pose, pt))))
            .collect();
        let half = p.area_m / 2.0;
        let (mut again, mut total) = (0usize, 0usize);
        let brightness = |s: &Scan| {
            let c = s.colors.as_ref().unwrap();
            c.iter()
                .map(|c| c.iter().map(|&v| f64::from(v)).sum::<f64>())
                .sum::<f64>()
                / c.len() as f64
        };
        for s in &scans[explore..] {
            let [x, y, _] = s.pose.translation_m.map(f64::from);
            assert!(
                x.abs() <= half && y.abs() <= half,
                "revisit pose over the area"
            );
            for &pt in &s.points {
                again += usize::from(seen.contains(&cell(to_world(&s.pose, pt))));
                total += 1;
            }
        }
        assert!(total > 0 && again * 100 >= total * 95, "{again} of {total}");
        // Lower, hence closer, hence brighter.
        let mean = |s: &[Scan]| s.iter().map(brightness).sum::<f64>() / s.len() as f64;
        assert!(mean(&scans[explore..]) > mean(&scans[..explore]) + 10.0);
    }

    #[test]
    fn colours_fade_with_distance() {
        for albedo in [
            SAND.map(|c| c * 0.7),
            ALGAE.map(|c| c * 0.7),
            CRATE.map(|c| c * 0.6),
        ] {
            let mut last = through_water(albedo, 0.0);
            for k in 1..40 {
                let c = through_water(albedo, k as f64 * 0.25);
                assert!((0..3).all(|i| c[i] <= last[i]), "{c:?} after {last:?}");
                last = c;
            }
            assert!(last[0] < last[2], "far away is blue: {last:?}");
        }
    }

    #[test]
    fn height_field_march_meets_the_grid() {
        let cfg = Config::new(&SurveyParams::default());
        let scene = Scene::new(&cfg);
        let g = &scene.grid;
        let mut rng = Rng::new(9, 9);
        for _ in 0..2000 {
            let (x, y) = (
                between(&mut rng, -12.0, 12.0),
                between(&mut rng, -12.0, 12.0),
            );
            let o = [x, y, g.height_m(x, y) + between(&mut rng, 0.5, 4.0)];
            let d = [
                rng.standard_normal(),
                rng.standard_normal(),
                -rng.uniform() - 0.05,
            ];
            let d = scale(d, 1.0 / norm(d));
            if let Some(t) = g.cast(o, d, 30.0) {
                let w = add(o, scale(d, t));
                assert!((w[2] - g.height_m(w[0], w[1])).abs() < 2e-3);
                // No earlier crossing (sampled).
                for k in 1..100 {
                    let s = t * k as f64 / 100.0;
                    let w = add(o, scale(d, s));
                    assert!(w[2] - g.height_m(w[0], w[1]) > -1e-3, "tunnelled");
                }
            }
        }
        assert!(g.cast([0.0, 0.0, 5.0], [0.0, 0.0, 1.0], 30.0).is_none());
        let t = g.cast(
            [0.0, 0.0, g.height_m(0.0, 0.0) + 3.0],
            [0.0, 0.0, -1.0],
            30.0,
        );
        assert!((t.unwrap() - 3.0).abs() < 1e-3);
    }

    #[test]
    fn quaternions_round_trip() {
        let mut rng = Rng::new(3, 3);
        for _ in 0..200 {
            let q = [0; 4].map(|_| rng.standard_normal());
            let m = matrix_of(q);
            let back = quaternion_of(&m);
            let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
            let sign = if q[0] < 0.0 { -1.0 } else { 1.0 };
            for i in 0..4 {
                assert!((back[i] - sign * q[i] / n).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn odd_parameters_do_not_panic() {
        for p in [
            SurveyParams {
                scans: 0,
                ..small()
            },
            SurveyParams {
                rays_x: 0,
                ..small()
            },
            SurveyParams {
                area_m: 0.0,
                scans: 3,
                ..small()
            },
            SurveyParams {
                revisit_fraction: 1.0,
                scans: 3,
                ..small()
            },
            SurveyParams {
                revisit_fraction: f64::NAN,
                fov_x_deg: f64::INFINITY,
                scans: 2,
                ..small()
            },
            SurveyParams {
                tilt_deg: 0.0,
                max_range_m: 1.0,
                scans: 2,
                ..small()
            },
        ] {
            let scans = survey(&p);
            assert_eq!(scans.len(), p.scans);
        }
        // Looking forward with a short range: most rays see only water, and give no point.
        let p = SurveyParams {
            tilt_deg: 0.0,
            max_range_m: 1.0,
            scans: 2,
            ..small()
        };
        assert!(survey(&p).iter().all(|s| s.points.len() < 32 * 24 / 2));
    }
}
