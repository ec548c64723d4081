//! [`CpuGrowth`]: one opacity map grown on the CPU (rayon), stepwise or to
//! convergence.

use super::bounds::{VoxelBounds, grown_working_box, initial_working_box};
use super::extinction::Extinction;
use super::frontier::{Lattice, apply, count, enumerate, evaluate, group, marks_for};
use super::params::GrowthParams;
use super::report::GrowthReport;
use super::seed::{Seed, SeedStats, seed_stats};
use super::{OpacityError, check_volume};
use crate::opacity_map::OpacityMap;
use crate::volume::VolumeView;
use crate::with_voxels;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU16, AtomicU64, Ordering::Relaxed};

/// A region growing in progress on the CPU: the opacity field over a
/// working box that grows with the region, the frontier, and the counts.
///
/// The growth does not borrow the volume: every call that reads voxel
/// values takes it again (it must be the one the growth was seeded in; only
/// its dims can be checked).
///
/// Working memory: 2 bytes per voxel of the working box (the u16 field) +
/// 2 bits (candidate and done marks) + 8 bytes per frontier voxel (index
/// and value) and 8 per candidate during a step. The working box is the region's box plus a
/// margin of `max(8, extent/4)` voxels per side (see
/// [`super::bounds::grown_working_box`]); [`CpuGrowth::map`] crops to the
/// region.
#[derive(Debug)]
pub struct CpuGrowth {
    dims: [usize; 3],
    params: GrowthParams,
    stats: SeedStats,
    ext: Extinction,
    work: VoxelBounds,
    field: Vec<AtomicU16>,
    /// Two bits per box voxel: candidate, done (see `frontier`).
    marks: Vec<AtomicU64>,
    /// Voxels that changed in the last step, by group (see `frontier`).
    frontier: Vec<Vec<(u32, u16)>>,
    region: VoxelBounds,
    total: GrowthReport,
}

impl CpuGrowth {
    /// Seeds a growth: the seed voxel at `o_max`, every other voxel at
    /// `o_min`, the seed's 1-ring statistics measured. No step is run.
    pub fn new(volume: VolumeView<'_>, seed: &Seed, params: GrowthParams) -> Result<Self, OpacityError> {
        params.validate()?;
        check_volume(&volume)?;
        let voxel = seed.resolve(&volume.grid)?;
        let stats = seed_stats(volume, voxel, &params)?;
        let ext = Extinction::new(&stats, &params)?;
        let dims = volume.grid.dims;
        let region = VoxelBounds::point(voxel);
        let work = initial_working_box(&region, dims);
        let field: Vec<AtomicU16> = (0..work.len()).map(|_| AtomicU16::new(ext.q_min)).collect();
        let s = work.local_linear(voxel);
        field[s].store(ext.q_max, Relaxed);
        Ok(Self {
            dims,
            params,
            stats,
            ext,
            work,
            marks: marks_for(&field, ext.q_max),
            field,
            frontier: group([(s as u32, ext.q_max)], work.dims()),
            region,
            total: GrowthReport::default(),
        })
    }

    /// Runs up to `n` steps (fewer if it converges first) and reports them.
    /// Resumable: `step(a)` then `step(b)` equals `step(a + b)`.
    pub fn step(&mut self, volume: VolumeView<'_>, n: usize) -> Result<GrowthReport, OpacityError> {
        check_volume(&volume)?;
        if volume.grid.dims != self.dims {
            return Err(OpacityError::VolumeMismatch {
                expected: self.dims,
                actual: volume.grid.dims,
            });
        }
        let mut rep = GrowthReport::default();
        let mut tm = [0f64; 5];
        let prof = std::env::var_os("VOXFLEX_PHASES").is_some();
        for _ in 0..n {
            let t0 = std::time::Instant::now();
            if self.is_converged() {
                break;
            }
            if let Some(nb) = grown_working_box(&self.work, &self.region, self.dims) {
                self.regrow(nb);
                rep.regrows += 1;
            }
            let t1 = std::time::Instant::now();
            tm[0] += (t1 - t0).as_secs_f64();
            let lat = Lattice::new(&self.work, self.dims);
            let found = with_voxels!(volume.data, |s| enumerate(
                &lat,
                &self.field,
                &self.marks,
                &self.ext,
                s,
                &self.frontier
            ));
            let t2 = std::time::Instant::now();
            tm[1] += (t2 - t1).as_secs_f64();
            let changes = with_voxels!(volume.data, |s| evaluate(
                &lat,
                &self.field,
                &self.marks,
                &self.ext,
                s,
                &found
            ));
            let t3 = std::time::Instant::now();
            tm[2] += (t3 - t2).as_secs_f64();
            for b in changes.iter().filter_map(|c| c.bounds) {
                self.region = self.region.union(&b);
            }
            self.frontier = apply(&self.field, changes);
            let t4 = std::time::Instant::now();
            tm[3] += (t4 - t3).as_secs_f64();
            drop(found);
            tm[4] += t4.elapsed().as_secs_f64();
            rep.steps += 1;
            let _ = count;
            rep.useful += self.frontier_len() as u64;
        }
        if prof {
            eprintln!("PHASES regrow {:.0} enum {:.0} eval {:.0} apply {:.0} drop {:.0} ms", tm[0]*1e3, tm[1]*1e3, tm[2]*1e3, tm[3]*1e3, tm[4]*1e3);
        }
        rep.converged = self.is_converged();
        self.total.merge(&rep);
        Ok(rep)
    }

    /// Runs to convergence and reports the steps it took from here.
    pub fn run(&mut self, volume: VolumeView<'_>) -> Result<GrowthReport, OpacityError> {
        self.step(volume, usize::MAX)
    }

    /// True when no voxel can change any more.
    pub fn is_converged(&self) -> bool {
        self.frontier.iter().all(Vec::is_empty)
    }

    /// The map as it stands, over the region's box (voxels that ever rose
    /// above `o_min`, plus the seed); `outside` is `o_min`.
    pub fn map(&self) -> OpacityMap {
        let r = self.region;
        let d = r.dims();
        let mut values = vec![0u16; r.len()];
        values.par_chunks_mut(d[0] * d[1]).enumerate().for_each(|(z, slab)| {
            for (y, row) in slab.chunks_mut(d[0]).enumerate() {
                let start = self.work.local_linear([r.lo[0], r.lo[1] + y, r.lo[2] + z]);
                for (x, o) in row.iter_mut().enumerate() {
                    *o = self.field[start + x].load(Relaxed);
                }
            }
        });
        OpacityMap {
            origin: r.lo,
            dims: d,
            outside: self.ext.q_min,
            values,
        }
    }

    /// Counts of every step run so far.
    pub fn report(&self) -> GrowthReport {
        self.total
    }

    /// The seed's statistics (`d_s`, σ_s).
    pub fn stats(&self) -> &SeedStats {
        &self.stats
    }

    /// The constants of the update rule.
    pub fn extinction(&self) -> &Extinction {
        &self.ext
    }

    /// The parameters the growth was seeded with.
    pub fn params(&self) -> &GrowthParams {
        &self.params
    }

    /// Box (voxel indices) of the voxels raised so far, seed included.
    pub fn region(&self) -> VoxelBounds {
        self.region
    }

    /// Box (voxel indices) the working field covers.
    pub fn working_box(&self) -> VoxelBounds {
        self.work
    }

    /// Voxels that changed in the last step (the next step's sources).
    pub fn frontier_len(&self) -> usize {
        self.frontier.iter().map(Vec::len).sum()
    }

    /// Bytes of working state held between steps (field, bitset, frontier).
    pub fn working_bytes(&self) -> usize {
        self.field.len() * 2 + self.marks.len() * 8 + self.frontier.iter().map(|g| g.capacity() * 8).sum::<usize>()
    }

    /// Moves the field into a larger working box (`nb ⊇ self.work`).
    fn regrow(&mut self, nb: VoxelBounds) {
        let old = self.work;
        let od = old.dims();
        let nd = nb.dims();
        let q_min = self.ext.q_min;
        let mut values = vec![q_min; nb.len()];
        values.par_chunks_mut(nd[0] * nd[1]).enumerate().for_each(|(z, slab)| {
            let vz = nb.lo[2] + z;
            if vz < old.lo[2] || vz > old.hi[2] {
                return;
            }
            for y in 0..od[1] {
                let vy = old.lo[1] + y;
                let dst = (old.lo[0] - nb.lo[0]) + nd[0] * (vy - nb.lo[1]);
                let src = old.local_linear([old.lo[0], vy, vz]);
                for x in 0..od[0] {
                    slab[dst + x] = self.field[src + x].load(Relaxed);
                }
            }
        });
        self.field = values.into_iter().map(AtomicU16::new).collect();
        self.marks = marks_for(&self.field, self.ext.q_max);
        let moved = self.frontier.iter().flatten().map(|&(l, q)| (nb.local_linear(old.voxel_of(l as usize)) as u32, q));
        self.frontier = group(moved.collect::<Vec<_>>(), nb.dims());
        self.work = nb;
    }
}
