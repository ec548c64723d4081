//! [`CpuGrowth`]: one opacity map grown on the CPU (rayon), stepwise or to
//! convergence.

use super::bounds::{VoxelBounds, grown_working_box};
use super::frontier::{
    Lattice, PARALLEL_ENTRIES, Raised, StepLists, count, finish, group, lift, states_for,
};
use super::params::GrowthParams;
use super::report::GrowthReport;
use super::seed::Seed;
use super::state::{Growth, GrowthState};
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
/// 2 bits (the voxel's state) + 8 bytes per frontier voxel (index and
/// value), and during a step 12 bytes per raised voxel. The working box is
/// the region's box plus a margin of `max(8, extent/2)` voxels per side (see
/// [`super::bounds::grown_working_box`]); [`CpuGrowth::map`] crops to the
/// region.
#[derive(Debug)]
pub struct CpuGrowth {
    state: GrowthState,
    field: Vec<AtomicU16>,
    /// Two bits per box voxel: unreached, reached, raised, done (see
    /// `frontier`).
    states: Vec<AtomicU64>,
    /// Voxels that changed in the last step, by group (see `frontier`).
    frontier: Vec<Vec<(u32, u16)>>,
    /// A step's lists (kept between steps for their capacity) and when its
    /// passes run on the pool.
    passes: StepLists,
}

impl CpuGrowth {
    /// Seeds a growth: the seed voxel at `o_max`, every other voxel at
    /// `o_min`, the seed's neighbourhood statistics measured. No step is run.
    pub fn new(
        volume: VolumeView<'_>,
        seed: &Seed,
        params: GrowthParams,
    ) -> Result<Self, OpacityError> {
        Self::with_room(volume, seed, params, None)
    }

    /// [`CpuGrowth::new`] with a working box that covers `room` (voxel
    /// indices) from the start — where the region is expected to end, e.g.
    /// from the automatic λ's scan — so the field is allocated once instead
    /// of being copied into larger boxes as the region grows (and never
    /// larger than the region needs). The map does not depend on it.
    pub fn with_room(
        volume: VolumeView<'_>,
        seed: &Seed,
        params: GrowthParams,
        room: Option<VoxelBounds>,
    ) -> Result<Self, OpacityError> {
        params.validate()?;
        check_volume(&volume)?;
        let (state, s) = GrowthState::seed(volume, seed, params, room)?;
        let (ext, work) = (state.ext, state.work);
        let mut field: Vec<AtomicU16> =
            (0..work.len()).map(|_| AtomicU16::new(ext.q_min)).collect();
        field[s].store(ext.q_max, Relaxed);
        Ok(Self {
            state,
            states: states_for(&mut field, 0..work.len(), ext.q_min, ext.q_max),
            field,
            frontier: group([(s as u32, ext.q_max)], work.dims()),
            passes: StepLists::new(PARALLEL_ENTRIES),
        })
    }

    /// Runs up to `n` steps (fewer if it converges first) and reports them.
    /// Resumable: `step(a)` then `step(b)` equals `step(a + b)`.
    pub fn step(&mut self, volume: VolumeView<'_>, n: usize) -> Result<GrowthReport, OpacityError> {
        check_volume(&volume)?;
        if volume.grid.dims != self.state.dims {
            return Err(OpacityError::VolumeMismatch {
                expected: self.state.dims,
                actual: volume.grid.dims,
            });
        }
        let mut rep = GrowthReport::default();
        for _ in 0..n {
            if self.is_converged() {
                break;
            }
            if let Some(nb) =
                grown_working_box(&self.state.work, &self.state.region, self.state.dims)
            {
                self.regrow(nb);
                rep.regrows += 1;
            }
            let lat = Lattice::new(
                &self.state.work,
                self.state.dims,
                self.state.params.connectivity,
            );
            with_voxels!(volume.data, |s| lift(
                &lat,
                &self.field,
                &self.states,
                &self.state.ext,
                s,
                &self.frontier,
                &mut self.passes
            ));
            with_voxels!(volume.data, |s| finish(
                &lat,
                &self.field,
                &self.states,
                &self.state.ext,
                s,
                &mut self.passes
            ));
            let StepLists { found, changes, .. } = &mut self.passes;
            for b in changes.iter().filter_map(|c| c.bounds) {
                self.state.region = self.state.region.union(&b);
            }
            // The changes become the frontier; the old frontier's lists the
            // next step's changes (emptied by `finish`).
            debug_assert_eq!(self.frontier.len(), changes.len(), "one list per group");
            for (f, c) in self.frontier.iter_mut().zip(changes.iter_mut()) {
                std::mem::swap(f, &mut c.values);
            }
            rep.steps += 1;
            rep.visits += count(found) as u64;
            rep.useful += self.frontier_len() as u64;
        }
        rep.converged = self.is_converged();
        self.state.total.merge(&rep);
        Ok(rep)
    }

    /// Runs every later step's passes on the pool from `entries` frontier
    /// entries on (0: always; `usize::MAX`: never) — for the tests that
    /// check both schedules give the same map.
    #[cfg(test)]
    pub(crate) fn set_parallel_from(&mut self, entries: usize) {
        self.passes.parallel_from = entries;
    }

    /// Runs to convergence and reports the steps it took from here.
    pub fn run(&mut self, volume: VolumeView<'_>) -> Result<GrowthReport, OpacityError> {
        self.step(volume, usize::MAX)
    }

    /// True when no voxel can change any more.
    pub fn is_converged(&self) -> bool {
        self.frontier.iter().all(Vec::is_empty)
    }

    /// The field's row `(y, z)` of the region's box (box-local indices):
    /// the voxels `x = 0 .. dims[0]` of that row.
    fn region_row(&self, y: usize, z: usize) -> &[AtomicU16] {
        let r = self.state.region;
        let start = self
            .state
            .work
            .local_linear([r.lo[0], r.lo[1] + y, r.lo[2] + z]);
        &self.field[start..start + r.dims()[0]]
    }

    /// The map as it stands, over the region's box (voxels that ever rose
    /// above `o_min`, plus the seed); `outside` is `o_min`.
    pub fn map(&self) -> OpacityMap {
        let r = self.state.region;
        let d = r.dims();
        let mut values = vec![0u16; r.len()];
        values
            .par_chunks_mut(d[0] * d[1])
            .enumerate()
            .for_each(|(z, slab)| {
                for (y, row) in slab.chunks_mut(d[0]).enumerate() {
                    for (o, q) in row.iter_mut().zip(self.region_row(y, z)) {
                        *o = q.load(Relaxed);
                    }
                }
            });
        OpacityMap {
            origin: r.lo,
            dims: d,
            outside: self.state.ext.q_min,
            values,
        }
    }

    /// Voxels that changed in the last step (the next step's sources).
    pub fn frontier_len(&self) -> usize {
        self.frontier.iter().map(Vec::len).sum()
    }

    /// Bytes of working state held between steps (field, state bits,
    /// frontier, and the step's lists kept for their capacity).
    pub fn working_bytes(&self) -> usize {
        use std::mem::size_of;
        let StepLists { found, changes, .. } = &self.passes;
        let entries = (self
            .frontier
            .iter()
            .chain(changes.iter().map(|c| &c.values)))
        .map(|g| g.capacity() * size_of::<(u32, u16)>())
        .sum::<usize>();
        let raised = (found.iter().flatten())
            .map(|r| r.capacity() * size_of::<Raised>())
            .sum::<usize>();
        self.field.len() * 2 + self.states.len() * 8 + entries + raised
    }

    /// Moves the field into a larger working box (`nb ⊇ self.state.work`).
    fn regrow(&mut self, nb: VoxelBounds) {
        let old = self.state.work;
        let od = old.dims();
        let nd = nb.dims();
        let q_min = self.state.ext.q_min;
        // Built in place, in parallel (a sequential map into atomics costs
        // more than the copy when the box becomes the whole volume).
        let field: Vec<AtomicU16> = (0..nb.len())
            .into_par_iter()
            .map(|_| AtomicU16::new(q_min))
            .collect();
        field
            .par_chunks(nd[0] * nd[1])
            .enumerate()
            .for_each(|(z, slab)| {
                let vz = nb.lo[2] + z;
                if vz < old.lo[2] || vz > old.hi[2] {
                    return;
                }
                for y in 0..od[1] {
                    let vy = old.lo[1] + y;
                    let dst = (old.lo[0] - nb.lo[0]) + nd[0] * (vy - nb.lo[1]);
                    let src = old.local_linear([old.lo[0], vy, vz]);
                    for x in 0..od[0] {
                        slab[dst + x].store(self.field[src + x].load(Relaxed), Relaxed);
                    }
                }
            });
        self.field = field;
        // Voxels outside the old box's slabs are unreached (state 0).
        let plane = nd[0] * nd[1];
        let slabs = (old.lo[2] - nb.lo[2]) * plane..(old.hi[2] + 1 - nb.lo[2]) * plane;
        self.states = states_for(
            &mut self.field,
            slabs,
            self.state.ext.q_min,
            self.state.ext.q_max,
        );
        let moved = self
            .frontier
            .iter()
            .flatten()
            .map(|&(l, q)| (nb.local_linear(old.voxel_of(l as usize)) as u32, q));
        self.frontier = group(moved.collect::<Vec<_>>(), nb.dims());
        self.state.work = nb;
    }
}

impl Growth for CpuGrowth {
    fn state(&self) -> &GrowthState {
        &self.state
    }
}
