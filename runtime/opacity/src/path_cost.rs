//! [`PathCostScan`]: the region sizes the automatic λ needs, `V(λ)` for
//! every candidate, from **one** search instead of one growth per λ.
//!
//! # Why one search answers every λ
//!
//! In real arithmetic the converged opacity is `o_v = o_max − D_v / (λ σ_s)`
//! (clamped below at `o_min`), where the **path cost** `D_v` does not depend
//! on λ:
//!
//! ```text
//! D_seed = 0,   D_v = max(0, min_n D_n + c_v),   c_v = min(|d_s − d_v|, cap) − σ_s
//! ```
//!
//! (value units; `n` over the neighbours that are *reached*). Substituting
//! `o = o_max − D/(λσ_s)` into the update `o_v = min(o_max, max_n o_n − E_v)`
//! with `E_v = c_v / (λσ_s)` gives exactly this recurrence: the clamp at
//! `o_max` is the `max(0, ·)`. λ enters in two places only:
//!
//! - **reached** (`o > o_min`, the rule that opacity flows only out of
//!   reached voxels) is `D < R(λ) = (o_max − o_min) λ σ_s`;
//! - the region, opacity ≥ ½ (fixed point ≥ 32768), is `D ≤ T(λ) = (o_max
//!   − 32768/65535) λ σ_s`.
//!
//! So the costs for λ₂ > λ₁ are the costs for λ₁ relaxed further from the
//! voxels whose cost lies in `[R(λ₁), R(λ₂))`: the search runs in
//! **phases**, one per candidate, each continuing the last, and `V(λ_k)` is
//! the number of voxels with `D ≤ T(λ_k)` when phase `k` ends. The whole
//! scan costs about one growth to the largest λ it reaches; the trial
//! growths it replaces cost one growth each (on `phantom:abdomen` at 1.5 mm,
//! ten of them: docs/BENCHMARKS.md, "ROI maps").
//!
//! # The search
//!
//! Costs can be negative (a voxel within σ_s of `d_s`), so this is a
//! label-correcting search, not Dijkstra's: voxels wait in buckets of cost
//! (width `R(1)/16`), the lowest bucket is taken first, and a voxel whose
//! cost drops is queued again. A phase stops when no queued voxel is
//! reached (`D < R`); those left wait for the next phase. Two neighbours
//! whose costs sum below zero would lower each other by that sum on every
//! pass (the growth's *pumping pair*, [`crate::Extinction::pumps`]): as in
//! the growth, the negative one of a reached pair takes its final cost, 0,
//! at once.
//!
//! Storage: per voxel, its path cost and its step cost (two f32, kept
//! together so a relaxation reads one cache line), in 8³ bricks allocated
//! when the search first touches them (4 KiB each: the region's bricks and
//! a shell of one brick), plus the bucket queues (4 bytes per queued
//! voxel). The queues hold a voxel's place in the bricks, not its index in
//! the volume, so a neighbour in the same brick (7 in 8 of them) is a
//! fixed step away: no division to find the voxel's coordinates and no
//! table lookup (12 % less time than the volume index on the liver at
//! 1.5 mm, docs/BENCHMARKS.md). That is 8 bytes per voxel of the region's
//! bricks, against the CPU growth's 2.25 per voxel of its working box
//! (the scan's box, [`PathCostScan::reached_box`]): a seed whose region is
//! the whole volume (the air around a CT, say) costs 8 bytes per voxel of
//! the volume for the time of the scan. The step costs are stored because
//! reading the volume's value at every relaxation was the stall of a
//! third of the first version's profile samples. The undo log that rewinds
//! the scan to the λ chosen (see `Undo`) holds 8 bytes per label of a later
//! phase landing below the reach of the phase before (70,513 of them on
//! the liver at 1.5 mm).
//!
//! # Against the growth
//!
//! The growth ([`crate::CpuGrowth`], the WGSL kernels) works in fixed point
//! and rounds each step's extinction, so its region at λ can differ from
//! `D ≤ T(λ)` in voxels whose opacity lies within that rounding of ½ (half
//! a fixed-point unit per step of the path): a handful per hundred
//! thousand. The tests check it voxel by voxel after every phase (a
//! disagreeing voxel's real-valued opacity must lie within that bound of
//! ½) on random volumes, opacity ranges and neighbourhoods, and the sizes
//! on the abdomen's organs. The map at the λ chosen is then written from
//! the same costs ([`PathCostScan::into_map`], rewound to that λ's phase
//! with the undo log kept by [`PathCostScan::next_phase`]), not grown.

use super::OpacityError;
use super::auto_lambda::CANDIDATES;
use super::bounds::VoxelBounds;
use super::extinction::{Extinction, SANE_MAX};
use super::frontier::{DIRS, IS_FACE};
use super::limits::GrowthLimits;
use super::params::GrowthParams;
use super::seed::{Seed, SeedStats, seed_stats};
use crate::volume::{Sample, VolumeView};
use crate::with_voxels;
use voxflex_core::fresh_memory::populate_ahead;
use voxflex_core::prefetch::prefetch_read;

mod scan_map;

/// Cost of a voxel not reached yet.
const UNSEEN: f32 = f32::INFINITY;

/// Buckets per `R(1)`.
const BUCKETS_PER_UNIT: f32 = 16.0;

/// Slots of [`PathCostScan`]'s thresholds: the candidates, padded.
const THRESHOLD_SLOTS: usize = CANDIDATES.len().next_multiple_of(8);

/// How far down a bucket's stack the cell to prefetch lies (the pop
/// after next few; 4, 8 and 16 measured alike).
const PREFETCH_AHEAD: usize = 8;

/// Voxels processed between two checks of a phase's bound.
const CHECK_EVERY: u64 = 4096;

/// What a [`PathCostScan`] reads, on the CPU whatever the growth's
/// backend: the values the growth reads, given as values and the bounds
/// still to apply to them.
#[derive(Clone, Copy)]
pub struct ScanInput<'a> {
    /// The unbounded volume (seed statistics).
    pub volume: VolumeView<'a>,
    /// The values the costs come from (the volume or its bounded copy).
    pub values: VolumeView<'a>,
    /// Bounds still to apply to `values` (none when already applied).
    pub limits: GrowthLimits,
    /// The seed.
    pub seed: Seed,
}

/// What one phase of the scan found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhaseResult {
    /// Voxels with `D ≤ T(λ)` (opacity ≥ ½ at λ); a lower bound when `cut`.
    pub voxels: usize,
    /// Voxels taken from the queue and relaxed in this phase.
    pub visits: u64,
    /// Stopped as soon as `voxels` passed the bound given.
    pub cut: bool,
}

/// The path-cost search of one seed over increasing λ (see the module
/// docs). Voxel indices are linear, x fastest.
pub struct PathCostScan<'a> {
    values: VolumeView<'a>,
    limits: GrowthLimits,
    seed: [usize; 3],
    /// The growth's constants at the largest candidate λ: its capped
    /// excess ([`Extinction::excess`]) is the step cost `c_v`.
    ext: Extinction,
    /// `(o_max − o_min) σ_s` with the opacities in fixed point: `R(λ) =
    /// reach · λ`.
    reach: f32,
    /// Costs at or above this are never reached at any candidate λ.
    limit: f32,
    dims: [usize; 3],
    /// The neighbourhood's offsets (6 or 26 of [`DIRS`]), with each one's
    /// step between cells of one brick.
    offsets: Vec<Offset>,
    costs: Bricks,
    buckets: Vec<Vec<u32>>,
    /// Buckets per unit of cost (value units).
    per_bucket: f32,
    /// No bucket below this holds a voxel.
    lowest: usize,
    /// `bins[k]`: labelled voxels with `T(λ_{k−1}) < D ≤ T(λ_k)`.
    bins: Vec<usize>,
    /// `T(λ_k) = (o_max − 32768/65535) σ_s λ_k`, one per candidate, then
    /// +∞ to a whole number of vector lanes (see [`Self::bin`]).
    thresholds: [f32; THRESHOLD_SLOTS],
    phase: usize,
    /// The seed's statistics and the parameters (λ aside) the map is
    /// written with ([`PathCostScan::into_map`]).
    stats: SeedStats,
    params: GrowthParams,
    /// What the scan can be rewound with (see [`Undo`]).
    undo: Undo,
}

impl<'a> PathCostScan<'a> {
    /// Seeds a scan: statistics from `input.volume` (unbounded, as the
    /// growth's), costs from `input.values` with `input.limits` blocking
    /// voxels on top. Nothing is searched yet.
    pub fn new(input: ScanInput<'a>, params: GrowthParams) -> Result<Self, OpacityError> {
        let ScanInput {
            volume,
            values,
            limits,
            seed,
        } = input;
        params.validate()?;
        limits.validate()?;
        crate::check_volume(&values)?;
        if values.grid.dims != volume.grid.dims {
            return Err(OpacityError::VolumeMismatch {
                expected: volume.grid.dims,
                actual: values.grid.dims,
            });
        }
        let voxel = seed.resolve(&volume.grid)?;
        let dims = values.grid.dims;
        // The queues hold cells of whole 8³ bricks as u32.
        let cells = dims
            .iter()
            .map(|&d| d.div_ceil(BRICK) as u64)
            .product::<u64>()
            * BRICK3 as u64;
        if cells > 1 << 32 {
            return Err(OpacityError::VolumeTooLarge {
                dims,
                voxels: cells,
            });
        }
        let stats = seed_stats(volume, voxel, &params)?;
        let last = *CANDIDATES.last().unwrap();
        let ext = Extinction::new(
            &stats,
            &GrowthParams {
                lambda: last,
                ..params
            },
        )?;
        let last = last as f64;
        let sigma = stats.sigma as f64;
        let reach = (ext.q_max as f64 - ext.q_min as f64) / 65535.0 * sigma;
        let half = (ext.q_max as f64 - 32768.0) / 65535.0 * sigma;
        let width = (reach / BUCKETS_PER_UNIT as f64) as f32;
        let buckets = (last * BUCKETS_PER_UNIT as f64).ceil() as usize + 2;
        let mut scan = Self {
            values,
            limits,
            seed: voxel,
            ext,
            reach: reach as f32,
            limit: (reach * last) as f32,
            dims,
            offsets: DIRS
                .iter()
                .zip(IS_FACE)
                .filter(|&(_, face)| face || params.connectivity == 26)
                .map(|(&d, _)| Offset::new(d))
                .collect(),
            costs: Bricks::new(dims),
            buckets: vec![Vec::new(); buckets],
            per_bucket: 1.0 / width,
            lowest: 0,
            bins: vec![0; CANDIDATES.len() + 1],
            thresholds: std::array::from_fn(|k| {
                CANDIDATES
                    .get(k)
                    .map_or(f32::INFINITY, |&l| (half * l as f64) as f32)
            }),
            phase: 0,
            stats,
            params,
            undo: Undo::default(),
        };
        let cell = with_voxels!(values.data, |d| scan.cell_of(d, voxel));
        scan.label(cell, 0.0);
        Ok(scan)
    }

    /// Runs the next phase, `λ = CANDIDATES[k]` for the `k`-th call, and
    /// returns that λ with what the phase found; `None` after the last
    /// candidate. With `bound = Some(n)` the phase stops as soon as more
    /// than `n` voxels hold `D ≤ T(λ)` (the count only grows within a phase).
    pub fn next_phase(&mut self, bound: Option<usize>) -> Option<(f32, PhaseResult)> {
        let lambda = *CANDIDATES.get(self.phase)?;
        let r = self.reach * lambda;
        self.undo.below = self
            .phase
            .checked_sub(1)
            .map_or(0.0, |k| self.reach * CANDIDATES[k]);
        let (visits, cut) = with_voxels!(self.values.data, |s| self.relax_below(s, r, bound));
        self.undo.end_phase(visits, cut);
        let result = PhaseResult {
            voxels: self.voxels_at(self.phase),
            visits,
            cut,
        };
        self.phase += 1;
        Some((lambda, result))
    }

    /// The path cost `D` of voxel `p` as the search stands (value units;
    /// infinite when not labelled).
    #[cfg(test)]
    pub(crate) fn cost_at(&self, p: [usize; 3]) -> f32 {
        let b = self.costs.grid_index(p.map(|c| c / BRICK));
        match self.costs.table[b] {
            Bricks::NONE => UNSEEN,
            i => self.costs.pool[i as usize * BRICK3 + in_brick(p)].cost,
        }
    }

    /// Box (voxel indices) of the voxels reached at `lambda` (`D < R(λ)`) as
    /// the search stands: after the phase of `lambda`, or a superset once
    /// later phases lowered costs further. `None` when none is.
    pub fn reached_box(&self, lambda: f32) -> Option<VoxelBounds> {
        let r = self.reach * lambda;
        self.box_where(|cost| cost < r)
    }

    /// Box (voxel indices) of the cells whose cost satisfies `keep`; `None`
    /// when none does.
    fn box_where(&self, keep: impl Fn(f32) -> bool) -> Option<VoxelBounds> {
        let mut found: Option<VoxelBounds> = None;
        for (cells, origin) in self.costs.pool.chunks(BRICK3).zip(&self.costs.origin) {
            let lo = origin.map(|c| c as usize * BRICK);
            let hi = [0, 1, 2].map(|a| (lo[a] + BRICK).min(self.dims[a]) - 1);
            if found.is_some_and(|f| f.contains(&VoxelBounds { lo, hi })) {
                continue; // nothing in this brick can widen the box
            }
            for (o, cell) in cells.iter().enumerate() {
                if keep(cell.cost) {
                    let p = brick_coords(o);
                    let v = VoxelBounds::point([0, 1, 2].map(|a| lo[a] + p[a]));
                    found = Some(found.map_or(v, |f| f.union(&v)));
                }
            }
        }
        found
    }

    /// Voxels at `D ≤ T(λ_k)` now.
    fn voxels_at(&self, k: usize) -> usize {
        self.bins[..=k].iter().sum()
    }

    /// Takes queued voxels of cost below `r` until none is left (or the
    /// bound is passed) and relaxes their neighbours. Returns the voxels
    /// relaxed and whether the bound stopped it.
    fn relax_below<T: Sample>(&mut self, data: &[T], r: f32, bound: Option<usize>) -> (u64, bool) {
        let mut visits = 0u64;
        let mut deferred = Vec::new();
        loop {
            while self.lowest < self.buckets.len() && self.buckets[self.lowest].is_empty() {
                self.lowest += 1;
            }
            // Every voxel of cost below `r` is in a bucket up to `r`'s
            // (the same rounding puts both there).
            let b = self.lowest;
            if b >= self.buckets.len() || b > self.bucket_of(r) {
                break;
            }
            // Last in, first out: the search runs on from the voxel it just
            // reached, whose brick is in cache (first in, first out, or a
            // batch sorted by index, measured 1.2–1.5× slower).
            let Some(u) = self.buckets[b].pop() else {
                continue;
            };
            // The cell a few pops from now, and its neighbours: the loads
            // of a cell and its neighbours missed the cache in half of the
            // search's profile samples (docs/BENCHMARKS.md).
            let q = &self.buckets[b];
            if let Some(&later) = q.len().checked_sub(PREFETCH_AHEAD).and_then(|i| q.get(i)) {
                self.costs.prefetch_around(later as usize);
            }
            let d = self.costs.pool[u as usize].cost;
            if self.bucket_of(d) != b {
                continue; // queued again at a lower cost since
            }
            if d >= r {
                deferred.push(u); // in the bucket that straddles R: next phase
                continue;
            }
            visits += 1;
            self.relax(data, u as usize, d, r);
            if visits.is_multiple_of(CHECK_EVERY)
                && bound.is_some_and(|n| self.voxels_at(self.phase) > n)
            {
                self.requeue(deferred);
                return (visits, true);
            }
        }
        self.requeue(deferred);
        let cut = bound.is_some_and(|n| self.voxels_at(self.phase) > n);
        (visits, cut)
    }

    fn requeue(&mut self, deferred: Vec<u32>) {
        for u in deferred {
            let d = self.costs.pool[u as usize].cost;
            self.queue(u, d);
        }
    }

    /// Lowers the neighbours of reached cell `u` (cost `d < r`).
    fn relax<T: Sample>(&mut self, data: &[T], u: usize, d: f32, r: f32) {
        for i in 0..self.offsets.len() {
            let Some(cell) = self.neighbour(data, u, self.offsets[i]) else {
                continue;
            };
            let Cell { cost, step } = self.costs.pool[cell];
            let mut nd = (d + step).max(0.0);
            if nd >= self.limit || nd >= cost {
                continue;
            }
            if step < 0.0 && nd > 0.0 && nd < r && self.pumps(data, cell, step, nd, r) {
                nd = 0.0;
            }
            self.label(cell, nd);
        }
    }

    /// Whether cell `v` (step cost `c < 0`, about to take `nd`, reached)
    /// has a neighbour that is or becomes reached with which its costs sum
    /// below zero: then its converged cost is 0 (see the module docs).
    fn pumps<T: Sample>(&mut self, data: &[T], v: usize, c: f32, nd: f32, r: f32) -> bool {
        for i in 0..self.offsets.len() {
            let Some(cell) = self.neighbour(data, v, self.offsets[i]) else {
                continue;
            };
            let m = self.costs.pool[cell];
            if c + m.step < 0.0 && (m.cost < r || (nd + m.step).max(0.0) < r) {
                return true;
            }
        }
        false
    }

    /// Sets the cost of cell `cell` to `d`, lower than before, and queues
    /// it.
    #[inline(always)]
    fn label(&mut self, cell: usize, d: f32) {
        let old = std::mem::replace(&mut self.costs.pool[cell].cost, d);
        if d < self.undo.below {
            self.undo.log.push((cell as u32, old));
        }
        if old < UNSEEN {
            let was = self.bin(old);
            self.bins[was] -= 1;
        }
        let bin = self.bin(d);
        self.bins[bin] += 1;
        self.queue(cell as u32, d);
    }

    /// The cell of voxel `p`, its brick filled with step costs first when
    /// the search reaches it for the first time.
    fn cell_of<T: Sample>(&mut self, data: &[T], p: [usize; 3]) -> usize {
        self.brick_base(data, p.map(|c| c / BRICK)) + in_brick(p)
    }

    /// The first cell of the brick at brick coordinates `brick`, filled
    /// first when the search reaches it for the first time.
    #[inline(always)]
    fn brick_base<T: Sample>(&mut self, data: &[T], brick: [usize; 3]) -> usize {
        let b = self.costs.grid_index(brick);
        match self.costs.table[b] {
            Bricks::NONE => self.fill(data, b, brick),
            i => i as usize * BRICK3,
        }
    }

    /// The cell at offset `o` from cell `u`, when inside the volume: a
    /// fixed step within `u`'s brick, else the same place in the next brick
    /// (filled first when new). Cells of a brick past the volume's edge
    /// hold an infinite step cost, so they are never labelled.
    #[inline(always)]
    fn neighbour<T: Sample>(&mut self, data: &[T], u: usize, o: Offset) -> Option<usize> {
        let at = brick_coords(u % BRICK3);
        let moved = [0, 1, 2].map(|a| at[a].wrapping_add_signed(o.dir[a]));
        if moved.iter().all(|&m| m < BRICK) {
            return Some(u.wrapping_add_signed(o.within));
        }
        let home = self.costs.origin[u / BRICK3];
        let mut brick = [0; 3];
        for a in 0..3 {
            let shift = (moved[a] as isize).div_euclid(BRICK as isize);
            brick[a] = (home[a] as usize).wrapping_add_signed(shift);
            if brick[a] >= self.costs.bricks[a] {
                return None;
            }
        }
        Some(self.brick_base(data, brick) + in_brick(moved))
    }

    /// Allocates brick `b` (at brick coordinates `brick`) and fills its
    /// step costs.
    #[cold]
    #[inline(never)]
    fn fill<T: Sample>(&mut self, data: &[T], b: usize, brick: [usize; 3]) -> usize {
        let base = self.costs.pool.len();
        self.costs.table[b] = (base / BRICK3) as u32;
        self.costs.origin.push(brick.map(|c| c as u32));
        // Bricks are filled at the end of the pool, in order (one page each).
        let size = std::mem::size_of::<Cell>();
        let pool = &self.costs.pool;
        let (start, bytes) = (base * size, BRICK3 * size);
        populate_ahead(
            pool.as_ptr() as usize,
            pool.capacity() * size,
            start,
            start + bytes,
        );
        let lo = brick.map(|c| c * BRICK);
        self.costs.pool.resize(
            base + BRICK3,
            Cell {
                cost: UNSEEN,
                step: UNSEEN,
            },
        );
        let hi = [0, 1, 2].map(|a| (lo[a] + BRICK).min(self.dims[a]));
        for z in lo[2]..hi[2] {
            for y in lo[1]..hi[1] {
                let row = lo[0] + self.dims[0] * (y + self.dims[1] * z);
                let at = base + BRICK * ((y - lo[1]) + BRICK * (z - lo[2]));
                for x in lo[0]..hi[0] {
                    let c = self.step_cost(data[row + x - lo[0]].to_f32(), [x, y, z]);
                    self.costs.pool[at + x - lo[0]].step = c;
                }
            }
        }
        base
    }

    fn queue(&mut self, v: u32, d: f32) {
        let b = self.bucket_of(d);
        self.buckets[b].push(v);
        self.lowest = self.lowest.min(b);
    }

    fn bucket_of(&self, d: f32) -> usize {
        ((d * self.per_bucket) as usize).min(self.buckets.len() - 1)
    }

    /// The first candidate whose `T(λ)` holds `d`, or one past the last.
    #[inline]
    fn bin(&self, d: f32) -> usize {
        // The first `t ≥ d` is the number of `t < d`: costs are ≥ 0 (never
        // NaN: sums and maxima of finite step costs, clamped at 0), and the
        // thresholds either ascend (`o_max` > ½) or are all ≤ 0 (`o_max` ≤
        // ½, where no voxel reaches ½), so `t < d` holds on a prefix; the
        // padding (+∞) never counts. Counted without a branch — a few
        // vector compares — because every label takes one or two bins: a
        // bisection's branches cost a bare search a third of its time.
        self.thresholds.iter().map(|&t| (t < d) as usize).sum()
    }

    /// `c_v` (value units) of a voxel of value `x` at `p`: the growth's
    /// capped excess, read as [`SANE_MAX`] where a bound blocks the voxel
    /// (as [`GrowthLimits::apply`] writes it).
    #[inline]
    fn step_cost(&self, x: f32, p: [usize; 3]) -> f32 {
        let blocked = !self.limits.is_none()
            && self
                .limits
                .blocks(x, p, self.seed, self.values.grid.spacing.to_array())
                .is_some();
        self.ext.excess(if blocked { SANE_MAX } else { x })
    }
}

/// How the scan is rewound to the end of an earlier phase: the map is
/// written at the λ chosen, whose phase is usually not the last.
///
/// In phase `p` a label is logged (cell, cost before) only when its new
/// cost lies below `R(λ_{p−1})`, the reach of the phase before: a voxel
/// that stays at or above it was not reached at `λ_{p−1}` (nor at any
/// smaller λ) before or after, so its exact cost does not matter to a map
/// at those λ. Undoing a phase's log backwards then restores every cell
/// reached at the end of the phase before exactly, and leaves every other
/// one at or above that phase's reach — the first logged change of a cell
/// records either its cost at the phase's start or one that was already
/// unreached. Most labels of a later phase are of new voxels beyond
/// the last reach, which are not logged.
#[derive(Debug, Default)]
struct Undo {
    /// `(cell, cost before)` of each logged label, in order.
    log: Vec<(u32, f32)>,
    /// `log.len()` when each phase ended, with its visits and whether it was
    /// cut short.
    ends: Vec<(usize, u64, bool)>,
    /// Labels below this cost are logged (`R(λ_{p−1})`; 0 in the first
    /// phase, which has nothing before it).
    below: f32,
}

impl Undo {
    fn end_phase(&mut self, visits: u64, cut: bool) {
        self.ends.push((self.log.len(), visits, cut));
    }
}

/// Side of a brick of cells, voxels.
const BRICK: usize = 8;
/// Cells per brick.
const BRICK3: usize = BRICK * BRICK * BRICK;

/// The cell of voxel (or brick-relative position) `p` within its brick:
/// `x + 8 (y + 8 z)` of `p` modulo the brick.
#[inline(always)]
fn in_brick(p: [usize; 3]) -> usize {
    p[0] % BRICK + BRICK * (p[1] % BRICK + BRICK * (p[2] % BRICK))
}

/// The position within its brick of cell `o` (`0 .. 512`), x fastest:
/// [`in_brick`]'s inverse.
#[inline(always)]
fn brick_coords(o: usize) -> [usize; 3] {
    [o % BRICK, (o / BRICK) % BRICK, o / (BRICK * BRICK)]
}

/// One voxel's search state.
#[derive(Clone, Copy, Debug)]
struct Cell {
    /// Path cost `D` so far ([`UNSEEN`] before the voxel is labelled).
    cost: f32,
    /// Its step cost `c_v`.
    step: f32,
}

/// One neighbour offset of the search, voxels.
#[derive(Clone, Copy, Debug)]
struct Offset {
    /// The offset along x, y and z.
    dir: [isize; 3],
    /// The step between cell indices when both cells lie in one brick.
    within: isize,
}

impl Offset {
    fn new(dir: [isize; 3]) -> Self {
        let b = BRICK as isize;
        Self {
            dir,
            within: dir[0] + b * (dir[1] + b * dir[2]),
        }
    }
}

/// Cells in 8³ bricks, allocated (and their step costs computed, from
/// rows of the volume) when the search first touches them. A cell's index
/// in the pool (`brick · 512 + x + 8 (y + 8 z)`, local x fastest) is what
/// the queues hold.
struct Bricks {
    /// Bricks along x, y and z (the last of each may be partial).
    bricks: [usize; 3],
    /// Pool brick of each brick of the grid ([`Bricks::NONE`]: not yet).
    table: Vec<u32>,
    /// Brick coordinates of each pool brick.
    origin: Vec<[u32; 3]>,
    pool: Vec<Cell>,
}

impl Bricks {
    const NONE: u32 = u32::MAX;

    fn new(dims: [usize; 3]) -> Self {
        let bricks = dims.map(|d| d.div_ceil(BRICK));
        let n = bricks.iter().product();
        // Room for every brick, so the pool never moves: reserved, not
        // written, it costs no page until a brick is filled. Where the
        // system refuses that much address space, it grows as needed.
        let mut pool = Vec::new();
        let _ = pool.try_reserve_exact(n * BRICK3);
        Self {
            bricks,
            table: vec![Self::NONE; n],
            origin: Vec::new(),
            pool,
        }
    }

    /// Asks the cache for cell `c`'s line and the lines of its ±y and ±z
    /// neighbours within its brick (a brick's row of 8 cells is one
    /// 64-byte line, so these hold every in-brick neighbour).
    #[inline(always)]
    fn prefetch_around(&self, c: usize) {
        let at = self.pool.as_ptr().wrapping_add(c);
        let row = (BRICK * std::mem::size_of::<Cell>()) as isize;
        let plane = BRICK as isize * row;
        for offset in [0, row, -row, plane, -plane] {
            prefetch_read(at, offset);
        }
    }

    /// Index in [`Bricks::table`] of the brick at brick coordinates `b`.
    #[inline]
    fn grid_index(&self, b: [usize; 3]) -> usize {
        b[0] + self.bricks[0] * (b[1] + self.bricks[1] * b[2])
    }
}
