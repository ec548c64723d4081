//! [`PathCostScan::into_map`]: the converged opacity map at one scanned λ,
//! written from the scan's path costs instead of grown.
//!
//! At the end of λ's phase a reached voxel's cost `D` is its converged
//! path cost, so its converged opacity in real arithmetic is
//! `q_max − D · K` (fixed-point units, `K = 65535 / (λ σ_s)`, see the
//! [module docs](super)); it is rounded to the nearest unit **once**. The
//! growth ([`crate::CpuGrowth`]) rounds each step's extinction instead, so
//! the two maps differ by at most half a unit per step of a voxel's path
//! (the tests check that bound voxel by voxel), and the map written here is
//! the closer one to the real-valued rule.
//!
//! Its region (opacity ≥ ½) is the trial's, voxel for voxel: the voxels
//! with `D ≤ T(λ)` that the scan counted. Rounding can only move a voxel
//! whose real opacity lies within half a unit of ½ across it; such a
//! voxel is set to the side its cost puts it on (32768 or 32767).

use super::{BRICK, BRICK3, PathCostScan};
use crate::auto_lambda::CANDIDATES;
use crate::bounds::VoxelBounds;
use crate::extinction::Extinction;
use crate::params::GrowthParams;
use crate::report::GrowthReport;
use crate::runner::Grown;
use crate::{OpacityError, OpacityMap};
use rayon::prelude::*;

/// Fixed-point opacity ½: the region's threshold.
const HALF: u16 = 32768;

/// Converts the costs at the end of one phase to fixed-point opacity.
#[derive(Clone, Copy)]
struct CostToOpacity {
    /// `R(λ)`: costs at or above it are not reached (`o_min`).
    reach: f32,
    /// `T(λ)`: the region is `D ≤ T`, as the scan counted it.
    half: f32,
    /// `K` in f64 (fixed-point units per value unit).
    per_unit: f64,
    q_min: u16,
    q_max: u16,
}

impl CostToOpacity {
    #[inline]
    fn at(&self, d: f32) -> u16 {
        if d >= self.reach {
            return self.q_min; // not reached (or never labelled: +∞)
        }
        let real = self.q_max as f64 - d as f64 * self.per_unit;
        let mut q = real.round().clamp(0.0, 65535.0) as u16;
        if (q >= HALF) != (d <= self.half) {
            q = if d <= self.half { HALF } else { HALF - 1 };
        }
        q.clamp(self.q_min, self.q_max)
    }
}

impl PathCostScan<'_> {
    /// The converged map at `lambda`, one of the phases run (not cut
    /// short), written from the costs as they stood when its phase ended
    /// (later phases are undone first). The map's box holds the voxels
    /// above `o_min`, as a growth's does. The report counts no growth step:
    /// `visits` (all useful) are the scan's relaxations up to that phase.
    /// Errors when `lambda` is not such a phase.
    pub fn into_map(mut self, lambda: f32) -> Result<Grown, OpacityError> {
        let k = CANDIDATES[..self.phase]
            .iter()
            .position(|&l| l == lambda)
            .filter(|&k| !self.undo.ends[k].2)
            .ok_or(OpacityError::LambdaNotScanned {
                lambda,
                scanned: self.phase,
            })?;
        self.rewind(k);
        let ext = Extinction::new(
            &self.stats,
            &GrowthParams {
                lambda,
                ..self.params
            },
        )?;
        let convert = CostToOpacity {
            reach: self.reach * lambda,
            half: self.thresholds[k],
            per_unit: 65535.0 / (lambda as f64 * self.stats.sigma as f64),
            q_min: ext.q_min,
            q_max: ext.q_max,
        };
        let visits = self.undo.ends[..=k].iter().map(|e| e.1).sum();
        Ok(Grown {
            map: self.write_map(convert),
            report: GrowthReport {
                steps: 0,
                visits,
                useful: visits,
                converged: true,
                regrows: 0,
            },
            stats: self.stats,
            ext,
        })
    }

    /// Undoes the phases after phase `k` (see [`super::Undo`]).
    fn rewind(&mut self, k: usize) {
        let end = self.undo.ends[k].0;
        for &(cell, old) in self.undo.log[end..].iter().rev() {
            self.costs.pool[cell as usize].cost = old;
        }
        self.undo.log.truncate(end);
        self.undo.ends.truncate(k + 1);
    }

    /// The map of the voxels `convert` lifts above `o_min`. Each layer of
    /// bricks (one brick z) writes its own slab of the box, in parallel.
    fn write_map(&self, convert: CostToOpacity) -> OpacityMap {
        // The seed (cost 0, o_max > o_min by validation) is always in it.
        let b = self
            .box_where(|d| convert.at(d) > convert.q_min)
            .unwrap_or(VoxelBounds::point(self.seed));
        let dims = b.dims();
        let first = b.lo[2] / BRICK;
        let mut layers = vec![Vec::new(); b.hi[2] / BRICK + 1 - first];
        for (i, origin) in self.costs.origin.iter().enumerate() {
            let layer = (origin[2] as usize).checked_sub(first);
            if let Some(bricks) = layer.and_then(|l| layers.get_mut(l)) {
                bricks.push(i);
            }
        }
        // Zeroed pages are mapped lazily: each slab is filled (and its pages
        // faulted in) by its own task.
        let mut values = vec![0u16; b.len()];
        let mut slabs = Vec::with_capacity(layers.len());
        let mut rest = values.as_mut_slice();
        for layer in first..first + layers.len() {
            let z0 = (layer * BRICK).max(b.lo[2]);
            let z1 = (layer * BRICK + BRICK).min(b.hi[2] + 1);
            let (slab, after) = rest.split_at_mut((z1 - z0) * dims[0] * dims[1]);
            slabs.push((z0, slab));
            rest = after;
        }
        slabs
            .into_par_iter()
            .zip(layers)
            .for_each(|((z0, slab), bricks)| {
                slab.fill(convert.q_min);
                for i in bricks {
                    self.write_brick(i, &b, z0, slab, convert);
                }
            });
        OpacityMap {
            origin: b.lo,
            dims,
            outside: convert.q_min,
            values,
        }
    }

    /// Writes pool brick `i`'s cells inside box `b` into `slab`, the box's
    /// slices from `z0` on.
    fn write_brick(
        &self,
        i: usize,
        b: &VoxelBounds,
        z0: usize,
        slab: &mut [u16],
        convert: CostToOpacity,
    ) {
        let cells = &self.costs.pool[i * BRICK3..(i + 1) * BRICK3];
        let lo = self.costs.origin[i].map(|c| c as usize * BRICK);
        let hi = [0, 1, 2].map(|a| (lo[a] + BRICK).min(b.hi[a] + 1));
        let from = [0, 1, 2].map(|a| lo[a].max(b.lo[a]));
        if (0..3).any(|a| from[a] >= hi[a]) {
            return; // outside the box
        }
        let dims = b.dims();
        // Cells of a brick run x fastest, then y, then z (`in_brick`).
        for z in from[2]..hi[2] {
            for y in from[1]..hi[1] {
                let row = (y - b.lo[1] + dims[1] * (z - z0)) * dims[0];
                let cell = BRICK * ((y - lo[1]) + BRICK * (z - lo[2]));
                for x in from[0]..hi[0] {
                    slab[row + x - b.lo[0]] = convert.at(cells[cell + x - lo[0]].cost);
                }
            }
        }
    }
}
