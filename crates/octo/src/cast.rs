//! A scan made ready for the tree: its rays cast, its cells discretised and put in the order the
//! tree will update them ([`ScanCaster::prepare`]), with nothing read from the tree. The tree
//! then applies a [`PreparedScan`] ([`super::tree::OcTree::apply_scan`]).
//!
//! Casting depends only on the scan and the grid, so the next scan can be cast on one thread
//! while the tree applies the previous one on another (`octo-delta build` does so), and the
//! sequence of updates, and hence the map, is the same as casting and applying in turn.
//!
//! Two orders, as [`super::tree`] explains: a plain tree takes the scan's cells in Morton order
//! (free cells less the hit ones, and the hit ones, merged), which its one recursive pass needs
//! (cast with [`super::lanes`], many rays side by side into bit tables of the scan's key box,
//! or, for a box too large for those tables, ray by ray into a [`CellSet`]);
//! a coloured tree takes them in OctoMap's `insertPointCloud` order (the free [`KeySet`] less
//! the occupied cells, then the occupied `KeySet`), which decides its colours.

use std::sync::atomic::{AtomicBool, Ordering};

use super::Scan;
use super::cellset::CellSet;
use super::firstray::FirstRay;
use super::hashorder::KeySet;
use super::lanes::{BoxBits, LaneSink, OVERSHOOT_CELLS, walk_lanes};
use super::math::{
    ColorSlot, FAN_BATCH, Fan, Grid, Key, NO_COLOR, RaySink, RayStart, RayWalk, color_slot,
    end_at_range, morton, norm_f32, slot_order, world_points,
};

/// How many points a scan's rays are cast between two looks at the stop flag.
const STOP_CHECK_POINTS: usize = 2048;

/// Points in a run of a thread's share of a scan.
const SHARE_POINTS: usize = 256;

/// Fewest points a casting thread gets.
const POINTS_PER_THREAD_MIN: usize = 4096;

/// Most threads casting one scan.
const CAST_THREADS_MAX: usize = 64;

impl RaySink for CellSet {
    #[inline(always)]
    fn add(&mut self, k: Key) {
        self.insert(k);
    }
}

/// OctoMap inserts each ray's cells into its free `KeySet` with one range insert.
impl RaySink for KeySet {
    fn begin_ray(&mut self) {
        self.begin_range();
    }
    #[inline(always)]
    fn add(&mut self, k: Key) {
        self.add_to_range(k);
    }
    fn end_ray(&mut self) {
        self.end_range();
    }
}

/// The cells of a scan's rays, ray by ray, to be inserted into a [`KeySet`] later.
#[derive(Default)]
struct RayList {
    keys: Vec<Key>,
    /// Where each ray's cells end in `keys`.
    ends: Vec<usize>,
}

impl RaySink for RayList {
    #[inline(always)]
    fn add(&mut self, k: Key) {
        self.keys.push(k);
    }
    fn end_ray(&mut self) {
        self.ends.push(self.keys.len());
    }
}

impl RayList {
    /// Inserts the rays into `set` as if they had been cast into it.
    fn insert_into(&self, set: &mut KeySet) {
        let mut start = 0;
        for &end in &self.ends {
            set.begin_ray();
            for &k in &self.keys[start..end] {
                set.add(k);
            }
            set.end_ray();
            start = end;
        }
    }
}

/// One update of a voxel: its depth-16 Morton code and whether a point ended in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Upd {
    /// Morton code of the voxel.
    pub(crate) code: u64,
    /// Hit (occupied) rather than crossed (free).
    pub(crate) hit: bool,
}

/// A scan cast and ordered, ready for [`super::tree::OcTree::apply_scan`].
#[derive(Debug, Clone, Default)]
pub struct PreparedScan {
    /// The updates, in the order the tree makes them: in Morton order; a coloured scan's in
    /// OctoMap's order ([`PreparedScan::octomap_order`]), or, cast in Morton order (with a
    /// [`PreparedScan::source`]), its free cells then its hit cells (OctoMap's two phases),
    /// each in Morton order.
    pub(crate) ups: Vec<Upd>,
    /// Each hit voxel once, in Morton order, with its brightest point's colour.
    pub(crate) hits: Vec<(u64, ColorSlot)>,
    /// Whether `ups` is in OctoMap's order (a coloured tree's) rather than Morton order.
    pub(crate) octomap_order: bool,
    /// A coloured scan cast in Morton order: its points, kept to cast it again in OctoMap's
    /// order should the tree find that the order can change its colours.
    pub(crate) source: Option<Box<ScanSource>>,
    /// Points in the scan.
    pub(crate) points: usize,
    /// Points skipped: not finite, or outside the key range.
    pub(crate) points_skipped: usize,
    /// Points beyond the maximum range.
    pub(crate) points_beyond_range: usize,
}

impl PreparedScan {
    /// Distinct voxels the scan updates as occupied.
    pub fn occupied_voxels(&self) -> usize {
        self.hits.len()
    }

    /// Distinct voxels the scan updates as free.
    pub fn free_voxels(&self) -> usize {
        self.ups.len() - self.hits.len()
    }
}

/// A coloured scan's points as cast, for [`ScanCaster::prepare_keyset_order`].
#[derive(Debug, Clone, Default)]
pub(crate) struct ScanSource {
    /// The points in the map frame.
    pts: Vec<[f32; 3]>,
    /// The sensor.
    origin: [f32; 3],
    /// The points' colours.
    colors: Option<Vec<[u8; 3]>>,
    /// Maximum range, m.
    max_range_m: Option<f64>,
    /// The scan's key box ([`key_box`]).
    window: (Key, Key),
    /// (point, Morton code) of each point's hit cell, in the order the casting threads found
    /// them.
    hit_points: Vec<(usize, u64)>,
}

impl ScanSource {
    /// The hit cells as OctoMap's occupied `KeySet` iterates them: inserted in the order of
    /// their points. `occupied` is scratch (emptied first, its memory kept from call to call:
    /// a fresh set's table of the scan's box is a few hundred kB to allocate and clear).
    pub(crate) fn hits_in_keyset_order(&self, occupied: &mut KeySet) -> Vec<Upd> {
        // One casting thread finds them in point order already: then they are not copied.
        let mut by_point = std::borrow::Cow::Borrowed(&self.hit_points[..]);
        if !by_point.is_sorted_by_key(|h| h.0) {
            by_point.to_mut().sort_unstable_by_key(|h| h.0);
        }
        occupied.set_window(self.window.0, self.window.1);
        for &(_, code) in by_point.iter() {
            occupied.insert(super::math::unmorton(code));
        }
        occupied
            .iter()
            .map(|k| Upd {
                code: morton(k),
                hit: true,
            })
            .collect()
    }
}

/// Casts scans for a tree of one resolution and kind (plain or coloured), keeping its scratch
/// sets from scan to scan.
#[derive(Clone)]
pub struct ScanCaster {
    grid: Grid,
    colored: bool,
    threads: usize,
    scratch: CellSet,
    free_keys: KeySet,
    /// The key box of the scan being cast (its sensor and points).
    window: (Key, Key),
    /// Each casting thread's free and hit cells, when the scan's box is small enough.
    boxes: Vec<(BoxBits, BoxBits)>,
    /// A coloured scan's cells and the first ray that crossed each, when the scan's box is
    /// small enough.
    first_ray: FirstRay,
    /// Most cells a scan's rays may cross ([`ScanCaster::set_max_cells`]).
    max_cells: u64,
}

/// A scan whose rays may cross more cells than the caster's budget
/// ([`ScanCaster::set_max_cells`]): casting it could exhaust memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("its rays may cross up to {cells} cells, more than the {max} a scan may")]
pub struct TooManyCells {
    /// The bound on the cells the scan's rays cross ([`ScanCaster::cells_bound`]).
    pub cells: u64,
    /// The budget.
    pub max: u64,
}

impl std::fmt::Debug for ScanCaster {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScanCaster")
            .field("resolution_m", &self.grid.resolution_m())
            .field("colored", &self.colored)
            .field("threads", &self.threads)
            .finish()
    }
}

/// One thread's share of a plain scan: free codes (sorted), end cells, points skipped and
/// beyond range.
type CastPart = (Vec<u64>, Vec<(u64, ColorSlot)>, usize, usize);

impl ScanCaster {
    /// A caster for a tree of voxel edge `resolution_m`, coloured or not, casting a plain scan
    /// on up to `threads` threads, a coloured one on up to two (its cells still inserted in the
    /// order of the points).
    pub fn new(resolution_m: f64, colored: bool, threads: usize) -> Self {
        ScanCaster {
            grid: Grid::new(resolution_m),
            colored,
            threads: threads.max(1),
            scratch: CellSet::new(),
            free_keys: KeySet::new(),
            window: ([0; 3], [0; 3]),
            boxes: Vec::new(),
            first_ray: FirstRay::default(),
            max_cells: u64::MAX,
        }
    }

    /// Sets the most cells one scan's rays may cross, counted before casting as
    /// [`ScanCaster::cells_bound`] does: a scan over it is refused ([`TooManyCells`]) rather
    /// than cast (its cell sets and the voxels it adds grow with that count). No limit unless
    /// set.
    pub fn set_max_cells(&mut self, max_cells: u64) {
        self.max_cells = max_cells;
    }

    /// The most cells one scan's rays may cross ([`ScanCaster::set_max_cells`]).
    pub fn max_cells(&self) -> u64 {
        self.max_cells
    }

    /// An upper bound on the cells the rays of a scan (its points in the map frame, from
    /// `origin`) cross, each ray cut at `max_range_m` as casting cuts it: a ray's walk takes at
    /// most as many steps as its end cell's key differs from its start cell's along the three
    /// axes, plus three (the walk's own bound), so it crosses at most that plus one cell, and
    /// its end cell one more. Points that get no ray (not finite, or an end outside the key
    /// range) count nothing.
    pub fn cells_bound(&self, pts: &[[f32; 3]], origin: [f32; 3], max_range_m: Option<f64>) -> u64 {
        let Some(ko) = self.grid.key_of(origin) else {
            return 0;
        };
        pts.iter()
            .filter_map(|&p| self.ray_end(p, origin, max_range_m)?.end_key)
            .map(|ke| {
                (0..3)
                    .map(|i| u64::from(ko[i].abs_diff(ke[i])))
                    .sum::<u64>()
                    + 5
            })
            .sum()
    }

    /// A looser bound than [`ScanCaster::cells_bound`], in a few operations a point: each
    /// axis' key difference is at most the point's distance along it over the voxel edge plus
    /// one, whatever the range and the key range. Not finite points count nothing.
    fn quick_cells_bound(&self, pts: &[[f32; 3]], origin: [f32; 3]) -> f64 {
        let mut extent_m = 0f64;
        let mut rays = 0u64;
        for p in pts {
            let l1 = (p[0] - origin[0]).abs() + (p[1] - origin[1]).abs() + (p[2] - origin[2]).abs();
            let finite = l1.is_finite();
            extent_m += if finite { f64::from(l1) } else { 0.0 };
            rays += u64::from(finite);
        }
        // f32 rounding of each sum: a relative error far below the 1 % added.
        extent_m * 1.01 / self.grid.resolution_m() + 8.0 * rays as f64
    }

    /// Threads a scan is cast on, at most.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Sets the threads a scan is cast on, at most (at least 1).
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
    }

    /// Whether the scans are cast for a coloured tree.
    pub fn is_colored(&self) -> bool {
        self.colored
    }

    /// Casts `scan` as `graph2tree` does (`insertPointCloud` with the scan's pose, no lazy
    /// evaluation, no discretisation), with an optional maximum range; `Ok(None)` when `stop`
    /// is set before its rays are cast (checked every few thousand points); [`TooManyCells`],
    /// before any is cast, when its rays may cross more cells than the budget
    /// ([`ScanCaster::set_max_cells`]).
    pub fn prepare(
        &mut self,
        scan: &Scan,
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Result<Option<PreparedScan>, TooManyCells> {
        let (pts, origin) = world_points(scan);
        // The exact bound only when a quicker, looser one is over the budget.
        if self.max_cells < u64::MAX && self.quick_cells_bound(&pts, origin) > self.max_cells as f64
        {
            let cells = self.cells_bound(&pts, origin, max_range_m);
            if cells > self.max_cells {
                return Err(TooManyCells {
                    cells,
                    max: self.max_cells,
                });
            }
        }
        Ok(self.prepare_points(scan, pts, origin, max_range_m, stop))
    }

    /// [`ScanCaster::prepare`]'s casting, of the scan's points in the map frame.
    fn prepare_points(
        &mut self,
        scan: &Scan,
        pts: Vec<[f32; 3]>,
        origin: [f32; 3],
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Option<PreparedScan> {
        self.window = key_box(&self.grid, origin, &pts);
        let colors = if self.colored {
            scan.colors.as_deref()
        } else {
            None
        };
        let points = pts.len();
        let mut p = if self.colored {
            // In Morton order with the lanes, the points kept for the tree to cast the scan
            // again in OctoMap's order only if that order can change its colours
            // ([`super::order`]); in OctoMap's order at once when the box does not suit the
            // lanes.
            match self.prepare_lanes(&pts, origin, Some(colors), max_range_m, stop) {
                Lanes::Done(mut p) => {
                    if let Some(src) = &mut p.source {
                        src.pts = pts;
                        src.origin = origin;
                        src.colors = colors.map(<[_]>::to_vec);
                        src.max_range_m = max_range_m;
                        src.window = self.window;
                    }
                    p
                }
                Lanes::Stopped => return None,
                Lanes::Unfit => self.prepare_octomap(&pts, origin, colors, max_range_m, stop)?,
            }
        } else {
            self.prepare_sorted(&pts, origin, max_range_m, stop)?
        };
        p.points = points;
        Some(p)
    }

    /// A coloured scan cast in Morton order ([`ScanCaster::prepare`]) cast again, its updates
    /// in the order OctoMap's `insertPointCloud` makes them.
    pub(crate) fn prepare_keyset_order(&mut self, src: &ScanSource) -> PreparedScan {
        self.window = key_box(&self.grid, src.origin, &src.pts);
        let never = AtomicBool::new(false);
        let colors = src.colors.as_deref();
        let mut p = self
            .prepare_octomap(&src.pts, src.origin, colors, src.max_range_m, &never)
            .unwrap_or_default();
        p.points = src.pts.len();
        p
    }

    /// The hit cells of a coloured scan cast in Morton order, in OctoMap's occupied `KeySet`'s
    /// order ([`ScanSource::hits_in_keyset_order`]), with this caster's scratch set.
    pub(crate) fn hits_in_keyset_order(&mut self, src: &ScanSource) -> Vec<Upd> {
        src.hits_in_keyset_order(&mut self.free_keys)
    }

    /// A coloured scan in OctoMap's order: with the lanes and a first-ray table, or the general
    /// way when its box does not suit them; `None` when `stop` is set.
    fn prepare_octomap(
        &mut self,
        pts: &[[f32; 3]],
        origin: [f32; 3],
        colors: Option<&[[u8; 3]]>,
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Option<PreparedScan> {
        self.prepare_octomap_lanes(pts, origin, colors, max_range_m, stop)
            .or_general(|| self.prepare_octomap_order(pts, origin, colors, max_range_m, stop))
    }

    /// The rays of `pts` (the points from index `first` of the scan): free cells into `free`,
    /// end cells (with colour) into `occ`; points skipped and beyond range.
    #[allow(clippy::too_many_arguments)]
    fn cast(
        &self,
        pts: &[[f32; 3]],
        first: usize,
        origin: [f32; 3],
        colors: Option<&[[u8; 3]]>,
        max_range_m: Option<f64>,
        free: &mut impl RaySink,
        occ: &mut Vec<(u64, ColorSlot)>,
        stop: &AtomicBool,
    ) -> Option<(usize, usize)> {
        let (mut skipped, mut beyond) = (0, 0);
        let origin_key = self.grid.key_of(origin);
        for (j, &p) in pts.iter().enumerate() {
            if j % STOP_CHECK_POINTS == 0 && stop.load(Ordering::Relaxed) {
                return None;
            }
            let Some(ray) = self.ray_end(p, origin, max_range_m) else {
                skipped += 1;
                continue;
            };
            free.begin_ray();
            self.grid
                .ray_start_keyed(origin_key, ray.end_key, origin, ray.end)
                .walk_into(free);
            free.end_ray();
            if let Some(k) = ray.hit_cell(&mut skipped, &mut beyond) {
                let color = color_slot(colors.and_then(|c| c.get(first + j)).copied());
                occ.push((morton(k), color));
            }
        }
        Some((skipped, beyond))
    }

    /// Where the ray of point `p` (in the map frame) ends, as `insertPointCloud` decides: at
    /// the point, a hit; or, beyond `max_range_m` (a negative one is none), cut at that range
    /// and no hit. `None` for a point that is not finite (no ray; OctoMap casts none either,
    /// its key being out of range).
    #[inline(always)]
    fn ray_end(&self, p: [f32; 3], origin: [f32; 3], max_range_m: Option<f64>) -> Option<RayEnd> {
        if !(p[0].is_finite() && p[1].is_finite() && p[2].is_finite()) {
            return None;
        }
        let diff = [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]];
        let within = max_range_m.is_none_or(|r| r < 0.0 || norm_f32(diff) <= r);
        let end = if within {
            p
        } else {
            end_at_range(origin, diff, max_range_m.unwrap_or(0.0))
        };
        Some(RayEnd {
            end,
            end_key: self.grid.key_of(end),
            hit: within,
        })
    }

    /// A plain scan: free and hit cells merged in Morton order (a voxel hit by a point is
    /// updated as occupied only), cast on up to `threads` threads.
    fn prepare_sorted(
        &mut self,
        pts: &[[f32; 3]],
        origin: [f32; 3],
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Option<PreparedScan> {
        self.prepare_lanes(pts, origin, None, max_range_m, stop)
            .or_general(|| self.prepare_cellset(pts, origin, max_range_m, stop))
    }

    /// A plain scan cast ray by ray into [`CellSet`]s, for any key box.
    fn prepare_cellset(
        &mut self,
        pts: &[[f32; 3]],
        origin: [f32; 3],
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Option<PreparedScan> {
        let mut p = PreparedScan::default();
        let mut free: Vec<u64> = Vec::new();
        let mut occ: Vec<(u64, ColorSlot)> = Vec::with_capacity(pts.len());
        let threads = self
            .threads
            .min(pts.len() / POINTS_PER_THREAD_MIN)
            .clamp(1, CAST_THREADS_MAX);
        if threads <= 1 {
            let mut set = std::mem::take(&mut self.scratch);
            set.set_window(self.window.0, self.window.1);
            let cast = self.cast(pts, 0, origin, None, max_range_m, &mut set, &mut occ, stop);
            let Some((s, b)) = cast else {
                set.clear();
                self.scratch = set;
                return None;
            };
            set.drain_sorted(&mut free);
            self.scratch = set;
            p.points_skipped = s;
            p.points_beyond_range = b;
        } else {
            let chunk = pts.len().div_ceil(threads);
            let this = &*self;
            let parts: Vec<Option<CastPart>> = std::thread::scope(|sc| {
                let handles: Vec<_> = pts
                    .chunks(chunk)
                    .enumerate()
                    .map(|(n, part)| {
                        sc.spawn(move || {
                            let mut set = CellSet::new();
                            set.set_window(this.window.0, this.window.1);
                            let mut o = Vec::with_capacity(part.len());
                            let (s, b) = this.cast(
                                part,
                                n * chunk,
                                origin,
                                None,
                                max_range_m,
                                &mut set,
                                &mut o,
                                stop,
                            )?;
                            let mut f = Vec::new();
                            set.drain_sorted(&mut f);
                            Some((f, o, s, b))
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|_| Some(CastPart::default())))
                    .collect()
            });
            let parts: Vec<CastPart> = parts.into_iter().collect::<Option<_>>()?;
            let mut lists = Vec::with_capacity(parts.len());
            for (f, o, s, b) in parts {
                lists.push(f);
                occ.extend(o);
                p.points_skipped += s;
                p.points_beyond_range += b;
            }
            free = merge_sorted(lists);
        }
        brightest_per_voxel(&mut occ);
        // Merge: a voxel hit by a point is updated as occupied only.
        let mut ups = Vec::with_capacity(free.len() + occ.len());
        let (mut i, mut j) = (0, 0);
        while i < free.len() || j < occ.len() {
            if j >= occ.len() || (i < free.len() && free[i] < occ[j].0) {
                ups.push(Upd {
                    code: free[i],
                    hit: false,
                });
                i += 1;
            } else {
                if i < free.len() && free[i] == occ[j].0 {
                    i += 1;
                }
                ups.push(Upd {
                    code: occ[j].0,
                    hit: true,
                });
                j += 1;
            }
        }
        p.ups = ups;
        p.hits = occ;
        Some(p)
    }

    /// The scan's key box padded by the cells a walk may overshoot its end by
    /// ([`OVERSHOOT_CELLS`]), the lanes' tables' box; `None` at the key range's edge.
    fn padded_window(&self) -> Option<(Key, Key)> {
        let (low, high) = self.window;
        let pad = OVERSHOOT_CELLS;
        if low.iter().any(|&k| k < pad) || high.iter().any(|&k| k > u16::MAX - pad) {
            return None;
        }
        Some((low.map(|k| k - pad), high.map(|k| k + pad)))
    }

    /// A scan cast with [`walk_lanes`] into bit tables of its key box, on up to `threads`
    /// threads, its updates in Morton order; [`Lanes::Unfit`] when the box is too large or at
    /// the key range's edge, or a ray left it (the caller then casts the scan the general way).
    /// `colors` is `Some` for a coloured scan (its colours, if it has any): each hit voxel then
    /// takes its brightest point's colour.
    fn prepare_lanes(
        &mut self,
        pts: &[[f32; 3]],
        origin: [f32; 3],
        colors: Option<Option<&[[u8; 3]]>>,
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Lanes {
        let Some((low, high)) = self.padded_window() else {
            return Lanes::Unfit;
        };
        let threads = self
            .threads
            .min(pts.len() / POINTS_PER_THREAD_MIN)
            .clamp(1, CAST_THREADS_MAX);
        let mut boxes = std::mem::take(&mut self.boxes);
        boxes.resize_with(threads, Default::default);
        for (f, h) in &mut boxes {
            if !(f.reset(low, high) && h.reset(low, high)) {
                self.boxes = boxes;
                return Lanes::Unfit;
            }
        }
        let this = &*self;
        let share = |n| LaneShare {
            pts,
            part: (n, threads),
            origin,
            max_range_m,
            stop,
        };
        // One share: its counts, and a coloured scan's hits with their colours and points.
        let cast = move |n: usize, f: &mut BoxBits, h: &mut BoxBits| match colors {
            None => (this.cast_lanes(share(n), f, h), ColorHits::default()),
            Some(_) => {
                // A hit a point at most: the share's points, room made once.
                let mut hits = ColorHits {
                    bits: Some(h),
                    points: Vec::with_capacity(pts.len().div_ceil(threads)),
                };
                let counts = this.cast_lanes(share(n), f, &mut hits);
                (counts, ColorHits { bits: None, ..hits })
            }
        };
        let (counts, parts): (Vec<_>, Vec<_>) = std::thread::scope(|sc| {
            let mut parts = boxes.iter_mut().enumerate();
            let first = parts.next();
            let handles: Vec<_> = parts
                .map(|(n, (f, h))| sc.spawn(move || cast(n, f, h)))
                .collect();
            let mut parts = vec![
                first.map_or((Some((0, 0)), ColorHits::default()), |(_, (f, h))| {
                    cast(0, f, h)
                }),
            ];
            parts.extend(
                handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or((None, ColorHits::default()))),
            );
            parts.into_iter().unzip()
        });
        let result = match counts.into_iter().collect::<Option<Vec<_>>>() {
            None => Lanes::Stopped,
            Some(_) if boxes.iter().any(|(f, h)| f.missed() || h.missed()) => Lanes::Unfit,
            Some(counts) => {
                let (first, rest) = boxes.split_at_mut(1);
                let (free, hits) = &mut first[0];
                for (f, h) in rest.iter() {
                    free.union_with(f);
                    hits.union_with(h);
                }
                // Room for the cells once, as many as the tables hold.
                let (free_n, hit_n) = (free.len(), hits.len());
                let mut ups = Vec::with_capacity(free_n + hit_n);
                let mut hit_cells = Vec::with_capacity(hit_n);
                let mut source = None;
                if colors.is_none() {
                    free.merged_codes(hits, |code, hit| {
                        ups.push(Upd { code, hit });
                        if hit {
                            hit_cells.push((code, NO_COLOR));
                        }
                    });
                } else {
                    // The free cells, then the hit cells (OctoMap's two phases), each in
                    // Morton order.
                    free.merged_codes(hits, |code, hit| {
                        if hit {
                            hit_cells.push((code, NO_COLOR));
                        } else {
                            ups.push(Upd { code, hit });
                        }
                    });
                    ups.extend(hit_cells.iter().map(|&(code, _)| Upd { code, hit: true }));
                    let mut src = ScanSource::default();
                    let mut index = VoxelIndex::new(&hit_cells);
                    let color_of = |point: usize| {
                        color_slot(colors.flatten().and_then(|c| c.get(point)).copied())
                    };
                    for part in parts {
                        let occ = part.points.iter().map(|&(p, code)| (code, color_of(p)));
                        index.keep_brightest(&mut hit_cells, occ);
                        // One share (a scan cast on one thread): its points, not a copy.
                        if src.hit_points.is_empty() {
                            src.hit_points = part.points;
                        } else {
                            src.hit_points.extend(part.points);
                        }
                    }
                    source = Some(Box::new(src));
                }
                Lanes::Done(PreparedScan {
                    ups,
                    hits: hit_cells,
                    source,
                    points_skipped: counts.iter().map(|c| c.0).sum(),
                    points_beyond_range: counts.iter().map(|c| c.1).sum(),
                    ..PreparedScan::default()
                })
            }
        };
        self.boxes = boxes;
        result
    }

    /// The rays of one share of a scan ([`LaneShare`]), [`walk_lanes`] at a time: free cells
    /// into `free`, end cells into `hits`; points skipped and beyond range, or `None` when the
    /// stop flag was set.
    ///
    /// On a processor with AVX-512 or AVX2 the same code runs compiled for it (the lanes'
    /// arithmetic in wider registers): the same operations on the same `f64`s, hence the same
    /// cells (the compiler fuses no multiply-add unless told to).
    fn cast_lanes<F: LaneSink, H: RayEnds>(
        &self,
        share: LaneShare<'_>,
        free: &mut F,
        hits: &mut H,
    ) -> Option<(usize, usize)> {
        #[cfg(target_arch = "x86_64")]
        if has_avx512() {
            // SAFETY: `cast_lanes_avx512` only needs the processor to have AVX-512's four
            // parts it names, checked above.
            #[allow(unsafe_code)]
            return unsafe { self.cast_lanes_avx512(share, free, hits) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: `cast_lanes_avx2` only needs the processor to have AVX2, checked above.
            #[allow(unsafe_code)]
            return unsafe { self.cast_lanes_avx2(share, free, hits) };
        }
        self.cast_lanes_body(share, free, hits)
    }

    /// [`ScanCaster::cast_lanes`]'s work, inlined into each of its compilations.
    #[inline(always)]
    fn cast_lanes_body<F: LaneSink, H: RayEnds>(
        &self,
        share: LaneShare<'_>,
        free: &mut F,
        hits: &mut H,
    ) -> Option<(usize, usize)> {
        let LaneShare {
            pts,
            part,
            origin,
            max_range_m,
            stop,
        } = share;
        let (share, shares) = part;
        let mut rays = ShareRays {
            caster: self,
            fan: Fan::new(&self.grid, origin, max_range_m),
            pts,
            origin,
            max_range_m,
            stop,
            next: share * SHARE_POINTS,
            shares,
            hits,
            batch: [RayWalk::default(); FAN_BATCH],
            plain: 0,
            base: 0,
            pos: 0,
            len: 0,
            skipped: 0,
            beyond: 0,
            stopped: false,
        };
        walk_lanes(&mut rays, free);
        (!rays.stopped).then_some((rays.skipped, rays.beyond))
    }

    /// A coloured scan, cell by cell in the order OctoMap's `insertPointCloud` updates them:
    /// its free `KeySet` less the occupied cells, then the occupied `KeySet` (see [`KeySet`]).
    /// With more than one thread, half the rays are cast on a second thread and inserted after
    /// the first half's: the sets' order is still that of the points.
    fn prepare_octomap_order(
        &mut self,
        pts: &[[f32; 3]],
        origin: [f32; 3],
        colors: Option<&[[u8; 3]]>,
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Option<PreparedScan> {
        let mut p = PreparedScan::default();
        let mut free = std::mem::take(&mut self.free_keys);
        free.set_window(self.window.0, self.window.1);
        let mut occ: Vec<(u64, ColorSlot)> = Vec::with_capacity(pts.len());
        // With a second thread, it casts the second half of the rays while this one casts the
        // first into the set; then the second half's rays go in, in order.
        let split = if self.threads > 1 && pts.len() >= 2 * POINTS_PER_THREAD_MIN {
            pts.len() / 2
        } else {
            pts.len()
        };
        let this = &*self;
        let (first, second) = std::thread::scope(|sc| {
            let second = (split < pts.len()).then(|| {
                sc.spawn(move || {
                    let mut rays = RayList::default();
                    let mut o = Vec::with_capacity(pts.len() - split);
                    let (s, b) = this.cast(
                        &pts[split..],
                        split,
                        origin,
                        colors,
                        max_range_m,
                        &mut rays,
                        &mut o,
                        stop,
                    )?;
                    Some((rays, o, s, b))
                })
            });
            let first = this.cast(
                &pts[..split],
                0,
                origin,
                colors,
                max_range_m,
                &mut free,
                &mut occ,
                stop,
            );
            let second = match second {
                Some(h) => h.join().ok().flatten(),
                None => Some((RayList::default(), Vec::new(), 0, 0)),
            };
            (first, second)
        });
        let (Some((mut skipped, mut beyond)), Some((rays, o, s, b))) = (first, second) else {
            self.free_keys = free;
            return None;
        };
        rays.insert_into(&mut free);
        occ.extend(o);
        skipped += s;
        beyond += b;
        p.points_skipped = skipped;
        p.points_beyond_range = beyond;
        self.octomap_ups(&mut p, free, occ);
        Some(p)
    }

    /// A coloured scan's updates in OctoMap's order from its free `KeySet` and its end cells
    /// in point order (with colours): the free cells less the occupied ones, then the occupied
    /// `KeySet`; the free set is kept for the next scan.
    fn octomap_ups(&mut self, p: &mut PreparedScan, free: KeySet, mut occ: Vec<(u64, ColorSlot)>) {
        let mut occupied = KeySet::new();
        occupied.set_window(self.window.0, self.window.1);
        for &(code, _) in &occ {
            occupied.insert(super::math::unmorton(code));
        }
        let mut ups = Vec::with_capacity(free.len() + occupied.len());
        ups.extend(free.iter().filter(|k| !occupied.contains(*k)).map(|k| Upd {
            code: morton(k),
            hit: false,
        }));
        ups.extend(occupied.iter().map(|k| Upd {
            code: morton(k),
            hit: true,
        }));
        self.free_keys = free;
        brightest_per_voxel(&mut occ);
        p.octomap_order = true;
        p.ups = ups;
        p.hits = occ;
    }

    /// A coloured scan as [`ScanCaster::prepare_octomap_order`] casts it, its rays walked with
    /// [`walk_lanes`] on one thread and each cell's first ray kept in a [`FirstRay`] table of
    /// the scan's key box; [`Lanes::Unfit`] when the box is too large or at the key range's
    /// edge, or a ray left it (the caller then casts the scan the general way).
    fn prepare_octomap_lanes(
        &mut self,
        pts: &[[f32; 3]],
        origin: [f32; 3],
        colors: Option<&[[u8; 3]]>,
        max_range_m: Option<f64>,
        stop: &AtomicBool,
    ) -> Lanes {
        let Some((low, high)) = self.padded_window() else {
            return Lanes::Unfit;
        };
        let mut table = std::mem::take(&mut self.first_ray);
        if !table.reset(low, high) {
            self.first_ray = table;
            return Lanes::Unfit;
        }
        let mut ends = ColorEnds {
            colors,
            occ: Vec::with_capacity(pts.len()),
        };
        let share = LaneShare {
            pts,
            part: (0, 1),
            origin,
            max_range_m,
            stop,
        };
        let cast = self.cast_lanes(share, &mut table, &mut ends);
        table.finish();
        let result = match cast {
            None => Lanes::Stopped,
            Some(_) if table.missed() => Lanes::Unfit,
            Some((skipped, beyond)) => {
                let mut free = std::mem::take(&mut self.free_keys);
                free.set_window(self.window.0, self.window.1);
                // No ray when the sensor is outside the key range: no cell either.
                table.insert_into(self.grid.key_of(origin).unwrap_or([0; 3]), &mut free);
                let mut p = PreparedScan {
                    points_skipped: skipped,
                    points_beyond_range: beyond,
                    ..PreparedScan::default()
                };
                self.octomap_ups(&mut p, free, ends.occ);
                Lanes::Done(p)
            }
        };
        self.first_ray = table;
        result
    }
}

/// Compilations of [`ScanCaster::cast_lanes`]'s work for wider vector registers, which only a
/// processor with `$features` may run (the callers check).
macro_rules! compiled_for {
    ($($name:ident: $features:literal),*) => {
        impl ScanCaster {
            $(
                #[doc = concat!("[`ScanCaster::cast_lanes`] compiled for ", $features, ".")]
                #[cfg(target_arch = "x86_64")]
                #[target_feature(enable = $features)]
                fn $name<F: LaneSink, H: RayEnds>(
                    &self,
                    share: LaneShare<'_>,
                    free: &mut F,
                    hits: &mut H,
                ) -> Option<(usize, usize)> {
                    self.cast_lanes_body(share, free, hits)
                }
            )*
        }
    };
}

compiled_for!(cast_lanes_avx2: "avx2", cast_lanes_avx512: "avx512f,avx512vl,avx512bw,avx512dq");

/// Where a share's rays tell the cells their points end in (a hit).
trait RayEnds {
    /// Point `point` of the scan ends in cell `k`.
    fn hit(&mut self, point: usize, k: Key);
}

/// A plain scan's hit cells: a set.
impl RayEnds for BoxBits {
    #[inline(always)]
    fn hit(&mut self, _point: usize, k: Key) {
        self.insert(k);
    }
}

/// A coloured scan's hit cells cast in Morton order: the set, and each hit with its point (its
/// colour, and the order OctoMap's occupied `KeySet` takes the hits in).
#[derive(Default)]
struct ColorHits<'b> {
    bits: Option<&'b mut BoxBits>,
    /// (point, Morton code) of each hit.
    points: Vec<(usize, u64)>,
}

impl RayEnds for ColorHits<'_> {
    #[inline(always)]
    fn hit(&mut self, point: usize, k: Key) {
        if let Some(bits) = &mut self.bits {
            bits.insert(k);
        }
        self.points.push((point, morton(k)));
    }
}

/// A coloured scan's hit cells, in point order, each with its point's colour.
struct ColorEnds<'a> {
    /// The scan's colours, by point.
    colors: Option<&'a [[u8; 3]]>,
    /// (Morton code, colour) of each hit.
    occ: Vec<(u64, ColorSlot)>,
}

impl RayEnds for ColorEnds<'_> {
    #[inline(always)]
    fn hit(&mut self, point: usize, k: Key) {
        let color = color_slot(self.colors.and_then(|c| c.get(point)).copied());
        self.occ.push((morton(k), color));
    }
}

/// One thread's share of a plain scan's rays, cast with the lanes
/// ([`ScanCaster::cast_lanes`]): runs of [`SHARE_POINTS`] points dealt to the shares in turn,
/// so that each share spans the whole image.
#[derive(Clone, Copy)]
struct LaneShare<'a> {
    /// The scan's points in the map frame.
    pts: &'a [[f32; 3]],
    /// This share's number and the number of shares.
    part: (usize, usize),
    /// The sensor, where every ray starts.
    origin: [f32; 3],
    /// Maximum range, m (`None` or negative: none).
    max_range_m: Option<f64>,
    /// Set to stop casting.
    stop: &'a AtomicBool,
}

/// The walks of one share of a scan's rays ([`LaneShare`]), in order, set up [`FAN_BATCH`] at
/// a time by [`Fan::starts`]; a ray that is not plain goes the one-ray way
/// ([`ScanCaster::ray_end`], [`Grid::ray_start_keyed`]). Each hit's cell goes into `hits` as its
/// ray is set up.
struct ShareRays<'a, H: RayEnds> {
    caster: &'a ScanCaster,
    /// The rays' shared set-up (`None`: the origin is outside the key range).
    fan: Option<Fan>,
    pts: &'a [[f32; 3]],
    origin: [f32; 3],
    max_range_m: Option<f64>,
    stop: &'a AtomicBool,
    /// The next point to set up.
    next: usize,
    /// Shares the scan is cut into.
    shares: usize,
    hits: &'a mut H,
    /// The batch's walks, and which are plain (bit per walk).
    batch: [RayWalk; FAN_BATCH],
    plain: u64,
    /// The batch's first point, the next of its rays to hand out, and its length.
    base: usize,
    pos: usize,
    len: usize,
    /// Points with no ray, and rays cut at the maximum range.
    skipped: usize,
    beyond: usize,
    /// Whether the stop flag ended the share.
    stopped: bool,
}

impl<H: RayEnds> ShareRays<'_, H> {
    /// Sets up the next batch of the share's points; false when there is none (or the stop
    /// flag is set, checked at the start of every [`SHARE_POINTS`]).
    #[inline(always)]
    fn refill(&mut self) -> bool {
        if self.next >= self.pts.len() || self.stopped {
            return false;
        }
        if self.next.is_multiple_of(SHARE_POINTS) && self.stop.load(Ordering::Relaxed) {
            self.stopped = true;
            return false;
        }
        let chunk_end = (self.next / SHARE_POINTS + 1) * SHARE_POINTS;
        let end = (self.next + FAN_BATCH).min(chunk_end).min(self.pts.len());
        let pts = &self.pts[self.next..end];
        self.plain = match &self.fan {
            Some(fan) => fan.starts(pts, &mut self.batch),
            None => 0,
        };
        self.base = self.next;
        self.pos = 0;
        self.len = pts.len();
        self.next = end;
        if end == chunk_end {
            self.next += (self.shares - 1) * SHARE_POINTS;
        }
        true
    }
}

impl<H: RayEnds> Iterator for ShareRays<'_, H> {
    type Item = RayWalk;

    #[inline(always)]
    fn next(&mut self) -> Option<RayWalk> {
        loop {
            if self.pos == self.len && !self.refill() {
                return None;
            }
            let i = self.pos;
            self.pos += 1;
            if self.plain >> i & 1 == 1 {
                let w = self.batch[i];
                self.hits.hit(self.base + i, w.end);
                return Some(w);
            }
            let p = self.pts[self.base + i];
            let Some(ray) = self.caster.ray_end(p, self.origin, self.max_range_m) else {
                self.skipped += 1;
                continue;
            };
            if let Some(k) = ray.hit_cell(&mut self.skipped, &mut self.beyond) {
                self.hits.hit(self.base + i, k);
            }
            let start = self.caster.grid.ray_start_keyed(
                self.fan.map(|f| f.origin_key()),
                ray.end_key,
                self.origin,
                ray.end,
            );
            if let RayStart::Walk(w) = start {
                return Some(w);
            }
        }
    }
}

/// Whether the processor has the parts of AVX-512 the ray walk is compiled for.
#[cfg(target_arch = "x86_64")]
fn has_avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx512bw")
        && std::arch::is_x86_feature_detected!("avx512dq")
}

/// Where a point's ray ends ([`ScanCaster::ray_end`]).
struct RayEnd {
    /// The end: the point, or where the maximum range cuts the ray.
    end: [f32; 3],
    /// The end's key (`None`: outside the key range).
    end_key: Option<Key>,
    /// Whether the ray ends at the point (a hit) rather than at the maximum range.
    hit: bool,
}

impl RayEnd {
    /// The cell of the ray's point when it is a hit inside the key range; otherwise the point
    /// is counted in `skipped` (a hit outside the key range) or `beyond` (a ray cut at the
    /// maximum range).
    #[inline(always)]
    fn hit_cell(&self, skipped: &mut usize, beyond: &mut usize) -> Option<Key> {
        match (self.hit, self.end_key) {
            (true, Some(k)) => Some(k),
            (true, None) => {
                *skipped += 1;
                None
            }
            (false, _) => {
                *beyond += 1;
                None
            }
        }
    }
}

/// How [`ScanCaster::prepare_lanes`] went.
enum Lanes {
    /// The scan, cast.
    Done(PreparedScan),
    /// The stop flag was set.
    Stopped,
    /// The scan does not suit the bit tables: cast it the general way.
    Unfit,
}

impl Lanes {
    /// The scan cast (`None`: stopped), cast by `general` when it did not suit the lanes.
    fn or_general(self, general: impl FnOnce() -> Option<PreparedScan>) -> Option<PreparedScan> {
        match self {
            Lanes::Done(p) => Some(p),
            Lanes::Stopped => None,
            Lanes::Unfit => general(),
        }
    }
}

/// The box of keys (lowest, highest on each axis) holding `origin` and the finite `pts`, the
/// range's ends where they are outside it: where a scan's rays run.
fn key_box(grid: &Grid, origin: [f32; 3], pts: &[[f32; 3]]) -> (Key, Key) {
    let (mut low, mut high) = (origin, origin);
    for p in pts {
        if p.iter().all(|c| c.is_finite()) {
            for i in 0..3 {
                low[i] = low[i].min(p[i]);
                high[i] = high[i].max(p[i]);
            }
        }
    }
    let key = |c: f32, outside: u16| grid.coord_to_key(c).unwrap_or(outside);
    (
        [0, 1, 2].map(|i| key(low[i], 0)),
        [0, 1, 2].map(|i| key(high[i], u16::MAX)),
    )
}

/// Sorts end cells by voxel and keeps each voxel once, with its brightest colour (set before
/// unset): `brightness_key` is a total order, so equal keys are equal colours and the unstable
/// sort decides nothing.
fn brightest_per_voxel(occ: &mut Vec<(u64, ColorSlot)>) {
    // Sorted by voxel alone (a plain integer key), then each voxel's run kept as its
    // brightest colour: cheaper than comparing colours in the sort.
    occ.sort_unstable_by_key(|e| e.0);
    let mut kept = 0usize;
    for i in 0..occ.len() {
        let e = occ[i];
        match kept.checked_sub(1).and_then(|k| occ.get_mut(k)) {
            Some(last) if last.0 == e.0 => {
                if slot_order(e.1) > slot_order(last.1) {
                    last.1 = e.1;
                }
            }
            _ => {
                occ[kept] = e;
                kept += 1;
            }
        }
    }
    occ.truncate(kept);
}

/// Where each voxel of a list of distinct voxels is in it: an open-addressing table of
/// positions, keyed by Morton code.
struct VoxelIndex {
    /// Positions in the list, plus one (0: empty), at each code's hash and the slots after it.
    slots: Vec<u32>,
    /// The table's size less one (a power of two less one).
    mask: usize,
}

impl VoxelIndex {
    /// The index of `cells` (distinct codes; fewer than `u32::MAX`).
    fn new(cells: &[(u64, ColorSlot)]) -> Self {
        let size = (2 * cells.len()).next_power_of_two().max(16);
        let mut index = VoxelIndex {
            slots: vec![0; size],
            mask: size - 1,
        };
        for (i, &(code, _)) in cells.iter().enumerate() {
            let mut h = index.hash(code);
            while index.slots[h] != 0 {
                h = (h + 1) & index.mask;
            }
            index.slots[h] = i as u32 + 1;
        }
        index
    }

    /// The table slot a code's search starts at.
    #[inline(always)]
    fn hash(&self, code: u64) -> usize {
        (code.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 32) as usize & self.mask
    }

    /// Each hit of `occ` (a voxel of `cells`, and its point's colour) gives its voxel its
    /// colour if it is brighter ([`slot_order`]) than the voxel's so far: the brightest colour
    /// per voxel whatever the hits' order (as [`brightest_per_voxel`], without sorting them).
    /// A hit whose voxel is not in `cells` (none is) is left out.
    fn keep_brightest(
        &mut self,
        cells: &mut [(u64, ColorSlot)],
        occ: impl IntoIterator<Item = (u64, ColorSlot)>,
    ) {
        for (code, color) in occ {
            let mut h = self.hash(code);
            while let Some(i) = (self.slots[h] as usize).checked_sub(1) {
                if let Some(cell) = cells.get_mut(i).filter(|c| c.0 == code) {
                    if slot_order(color) > slot_order(cell.1) {
                        cell.1 = color;
                    }
                    break;
                }
                h = (h + 1) & self.mask;
            }
        }
    }
}

/// Merges ascending lists into one ascending list without duplicates.
fn merge_sorted(mut lists: Vec<Vec<u64>>) -> Vec<u64> {
    while lists.len() > 1 {
        let b = lists.pop().unwrap_or_default();
        let a = lists.pop().unwrap_or_default();
        let mut m = Vec::with_capacity(a.len() + b.len());
        let (mut i, mut j) = (0, 0);
        while i < a.len() && j < b.len() {
            if a[i] < b[j] {
                m.push(a[i]);
                i += 1;
            } else if b[j] < a[i] {
                m.push(b[j]);
                j += 1;
            } else {
                m.push(a[i]);
                i += 1;
                j += 1;
            }
        }
        m.extend_from_slice(&a[i..]);
        m.extend_from_slice(&b[j..]);
        lists.push(m);
    }
    lists.pop().unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::{SurveyParams, survey};

    /// `n` (at least 3) scans of the synthetic survey, two points of the second not finite,
    /// and a copy of the third with a point outside the key range (the scan at `n`).
    fn odd_scans(n: usize) -> Vec<Scan> {
        let params = SurveyParams {
            scans: n,
            ..SurveyParams::default()
        };
        let mut scans = survey(&params);
        scans[1].points[17] = [f32::NAN, 0.0, 1.0];
        scans[1].points[18] = [0.0, f32::INFINITY, 1.0];
        let mut outside = scans[2].clone();
        outside.points[5] = [1e6, 0.0, 1.0];
        scans.push(outside);
        scans
    }

    /// A coloured scan cast with the lanes and a first-ray table gives the updates of the
    /// general cast (every cell inserted into the `KeySet`), in the same order, with a maximum
    /// range or not, with points that are not finite, with few rays; a scan with a point
    /// outside the key range goes the general way.
    #[test]
    fn coloured_lanes_give_octomaps_order_as_the_keyset_of_every_cell_does() {
        let mut scans = odd_scans(4);
        // A few rays only: the table grows bucket by bucket, ray by ray.
        let mut few = scans[3].clone();
        few.points.truncate(40);
        few.colors.as_mut().expect("coloured").truncate(40);
        scans.push(few);
        let stop = AtomicBool::new(false);
        for (n, scan) in scans.iter().enumerate() {
            for range in [None, Some(2.5)] {
                let mut c = ScanCaster::new(0.1, true, 1);
                let (pts, origin) = world_points(scan);
                c.window = key_box(&c.grid, origin, &pts);
                let colors = scan.colors.as_deref();
                let want = c
                    .prepare_octomap_order(&pts, origin, colors, range, &stop)
                    .expect("not stopped");
                let got = match c.prepare_octomap_lanes(&pts, origin, colors, range, &stop) {
                    Lanes::Done(p) => p,
                    Lanes::Stopped => panic!("stopped"),
                    Lanes::Unfit => {
                        // The point far away makes the box too large: the general way.
                        assert_eq!(n, 4, "scan {n} unfit");
                        continue;
                    }
                };
                assert!(
                    c.first_ray.len() > 30,
                    "scan {n}: {} cells",
                    c.first_ray.len()
                );
                assert!(got.octomap_order && want.octomap_order);
                assert_eq!(got.ups, want.ups, "scan {n}, range {range:?}");
                assert_eq!(got.hits, want.hits);
                assert_eq!(got.points_skipped, want.points_skipped);
                assert_eq!(got.points_beyond_range, want.points_beyond_range);
            }
        }
    }

    proptest::proptest! {
        /// The cell bound is at least the cells a scan's rays cross (with and without a
        /// maximum range, whatever the resolution), and the budget refuses a scan exactly when
        /// the bound is over it, before casting.
        #[test]
        fn the_cell_bound_holds_and_the_budget_refuses_over_it(
            pts in proptest::collection::vec(
                proptest::array::uniform3(-30.0f32..30.0), 1..60),
            origin in proptest::array::uniform3(-2.0f32..2.0),
            res in proptest::sample::select(vec![0.05, 0.1, 0.37, 1.0]),
            range in proptest::option::of(0.5f64..20.0),
            colored in proptest::bool::ANY,
        ) {
            let scan = Scan {
                colors: colored.then(|| vec![[10, 20, 30]; pts.len()]),
                points: pts,
                pose: crate::Pose {
                    translation_m: origin,
                    ..crate::Pose::IDENTITY
                },
            };
            let stop = AtomicBool::new(false);
            let mut c = ScanCaster::new(res, colored, 1);
            let (world, o) = world_points(&scan);
            let bound = c.cells_bound(&world, o, range);
            proptest::prop_assert!(c.quick_cells_bound(&world, o) >= bound as f64);
            let cast = c.prepare(&scan, range, &stop).ok().flatten().expect("cast");
            proptest::prop_assert!(cast.ups.len() as u64 <= bound, "{} > {bound}", cast.ups.len());
            c.set_max_cells(bound);
            proptest::prop_assert!(c.prepare(&scan, range, &stop).is_ok());
            c.set_max_cells(bound - 1);
            proptest::prop_assert_eq!(
                c.prepare(&scan, range, &stop).err(),
                Some(TooManyCells { cells: bound, max: bound - 1 })
            );
        }

        /// The index keeps each voxel's brightest colour as sorting the hits does, whatever
        /// the hits' order and split, with colliding codes, unset and tied colours.
        #[test]
        fn the_voxel_index_keeps_the_brightest_colour_as_sorting_does(
            hits in proptest::collection::vec((0u64..300, 0usize..5), 1..600),
            cut in 0usize..600,
        ) {
            let palette = [[10, 20, 30], [255, 255, 255], [200, 0, 0], [0, 200, 0], [10, 20, 30]];
            let occ: Vec<(u64, ColorSlot)> = hits
                .iter()
                .map(|&(v, c)| (v << 9, color_slot(Some(palette[c]))))
                .collect();
            let mut want = occ.clone();
            brightest_per_voxel(&mut want);
            let mut cells: Vec<(u64, ColorSlot)> = want.iter().map(|&(c, _)| (c, NO_COLOR)).collect();
            let (a, b) = occ.split_at(cut.min(occ.len()));
            let mut index = VoxelIndex::new(&cells);
            index.keep_brightest(&mut cells, b.iter().copied());
            index.keep_brightest(&mut cells, a.iter().copied());
            proptest::prop_assert_eq!(cells, want);
        }
    }

    /// A coloured scan cast in Morton order (on one and on three threads) holds the same
    /// updates and brightest colours as the scan cast in OctoMap's order, and its source casts
    /// it again in that order exactly; the hit cells in OctoMap's order are the occupied
    /// `KeySet`'s.
    #[test]
    fn a_coloured_scan_in_morton_order_keeps_what_octomaps_order_needs() {
        let stop = AtomicBool::new(false);
        for (n, scan) in odd_scans(4).iter().enumerate() {
            for (range, threads) in [(None, 1), (Some(2.5), 1), (None, 3)] {
                let mut c = ScanCaster::new(0.1, true, threads);
                let Ok(Some(fast)) = c.prepare(scan, range, &stop) else {
                    panic!("stopped")
                };
                let (pts, origin) = world_points(scan);
                c.window = key_box(&c.grid, origin, &pts);
                let colors = scan.colors.as_deref();
                let want = c
                    .prepare_octomap_order(&pts, origin, colors, range, &stop)
                    .expect("not stopped");
                let Some(src) = &fast.source else {
                    // The point far away makes the box too large: OctoMap's order at once.
                    assert_eq!(n, 4, "scan {n} unfit");
                    assert!(fast.octomap_order);
                    continue;
                };
                assert!(!fast.octomap_order);
                // The free cells, then the hit cells, each in Morton order.
                let mut ups = want.ups.clone();
                ups.sort_unstable_by_key(|u| (u.hit, u.code));
                assert_eq!(fast.ups, ups, "scan {n}, range {range:?}");
                assert_eq!(fast.free_voxels(), ups.iter().filter(|u| !u.hit).count());
                assert_eq!(fast.hits, want.hits);
                assert_eq!(fast.points_skipped, want.points_skipped);
                assert_eq!(fast.points_beyond_range, want.points_beyond_range);
                let again = c.prepare_keyset_order(src);
                assert_eq!(again.ups, want.ups, "scan {n}, range {range:?}");
                assert_eq!(again.hits, want.hits);
                let hits: Vec<Upd> = want.ups.iter().filter(|u| u.hit).copied().collect();
                let mut scratch = KeySet::new();
                assert_eq!(src.hits_in_keyset_order(&mut scratch), hits);
                // The scratch set again, holding the last scan's cells: the same order.
                assert_eq!(src.hits_in_keyset_order(&mut scratch), hits);
            }
        }
    }

    /// A plain scan cast with the lanes (on one and on three threads) gives the updates of the
    /// general cast, with a maximum range or not, with points that are not finite; a scan with
    /// a point outside the key range goes the general way.
    #[test]
    fn lanes_cast_the_scan_the_general_way_casts_it() {
        let scans = odd_scans(3);
        let stop = AtomicBool::new(false);
        for scan in &scans {
            for range in [None, Some(2.5)] {
                let mut general = ScanCaster::new(0.1, false, 1);
                let (pts, origin) = world_points(scan);
                general.window = key_box(&general.grid, origin, &pts);
                let want = general
                    .prepare_cellset(&pts, origin, range, &stop)
                    .expect("not stopped");
                assert!(want.ups.len() > 1000);
                for threads in [1, 3] {
                    let mut lanes = ScanCaster::new(0.1, false, threads);
                    let got = lanes
                        .prepare(scan, range, &stop)
                        .ok()
                        .flatten()
                        .expect("not stopped");
                    assert_eq!(got.ups, want.ups, "{threads} threads, range {range:?}");
                    assert_eq!(got.hits, want.hits);
                    assert_eq!(got.points_skipped, want.points_skipped);
                    assert_eq!(got.points_beyond_range, want.points_beyond_range);
                }
            }
        }
        // Each compilation of the lanes this processor can run gives the same cells.
        let c = ScanCaster::new(0.1, false, 1);
        let (pts, origin) = world_points(&scans[1]);
        let (low, high) = key_box(&c.grid, origin, &pts);
        let (low, high) = (low.map(|k| k - 4), high.map(|k| k + 4));
        let share = LaneShare {
            pts: &pts,
            part: (0, 1),
            origin,
            max_range_m: Some(2.5),
            stop: &stop,
        };
        type Compiled = fn(&ScanCaster, LaneShare<'_>, &mut BoxBits, &mut BoxBits);
        let mut compiled: Vec<(&str, Compiled)> = vec![("plain", |c, share, f, h| {
            c.cast_lanes_body(share, f, h);
        })];
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            compiled.push(("avx2", |c, share, f, h| {
                // SAFETY: the processor has AVX2 (checked above).
                #[allow(unsafe_code)]
                unsafe {
                    c.cast_lanes_avx2(share, f, h);
                }
            }));
        }
        #[cfg(target_arch = "x86_64")]
        if has_avx512() {
            compiled.push(("avx512", |c, share, f, h| {
                // SAFETY: the processor has the parts of AVX-512 (checked above).
                #[allow(unsafe_code)]
                unsafe {
                    c.cast_lanes_avx512(share, f, h);
                }
            }));
        }
        let mut first: Option<Vec<(u64, bool)>> = None;
        for (name, cast) in compiled {
            let mut free = BoxBits::new(low, high).expect("small box");
            let mut hits = BoxBits::new(low, high).expect("small box");
            cast(&c, share, &mut free, &mut hits);
            let mut cells = Vec::new();
            free.merged_codes(&hits, |c, hit| cells.push((c, hit)));
            assert!(cells.len() > 1000);
            match &first {
                None => first = Some(cells),
                Some(want) => assert_eq!(&cells, want, "{name}"),
            }
        }
        let mut c = ScanCaster::new(0.1, false, 1);
        let (pts, origin) = world_points(&scans[3]);
        c.window = key_box(&c.grid, origin, &pts);
        assert!(matches!(
            c.prepare_lanes(&pts, origin, None, None, &stop),
            Lanes::Unfit
        ));
        let (pts, origin) = world_points(&scans[2]);
        c.window = key_box(&c.grid, origin, &pts);
        assert!(matches!(
            c.prepare_lanes(&pts, origin, None, None, &stop),
            Lanes::Done(_)
        ));
        stop.store(true, Ordering::Relaxed);
        assert!(matches!(
            c.prepare_lanes(&pts, origin, None, None, &stop),
            Lanes::Stopped
        ));
    }
}
