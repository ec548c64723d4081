//! The sparse frontier step on the CPU (rayon).
//!
//! One step, Jacobi style (every value read is the previous step's):
//!
//! 1. **Enumerate** (parallel over the frontier, the voxels `u` that changed
//!    in the previous step): each 26-neighbour `v` is *tested*: it becomes a
//!    candidate when `u`'s new value lifts it, `rise(q_u, e_v) > q_v`, and it
//!    is not a candidate yet (a bit of the `flags` bitset, set with
//!    `fetch_or`, so each voxel is listed once). Candidates carry `e_v`.
//! 2. **Evaluate** (parallel over the candidates, the field read-only): the
//!    update rule, then the pump shortcut (a lifted voxel that forms a
//!    pumping pair with a neighbour jumps to `q_max`, its final value — see
//!    [`Extinction::pumps`]); changed voxels are collected with their new
//!    value; the candidate bit is cleared.
//! 3. **Apply** (parallel): the new values are stored; the changed voxels
//!    are the next frontier.
//!
//! A voxel none of whose neighbours changed cannot change (its value
//! already dominates `max_n q_n − e_v` for the unchanged `q_n`), and one
//! that no changed neighbour lifts does not change either, so the test of
//! phase 1 is exact: every candidate changes in phase 2 (every visit is
//! useful), and the step equals a dense sweep of the whole volume, bit for
//! bit (with the pump shortcut, at convergence). What the sparse step still
//! spends beyond the useful evaluations is the enumeration: 26 neighbour
//! tests per changed voxel — work proportional to the changes, against the
//! dense sweep's 27 reads per voxel of the volume per step.
//!
//! Indices are linear (x fastest) in the working box; the box is kept at
//! least two voxels larger than the region (candidates lie within one voxel
//! of it, and the pump shortcut reads their neighbours), so a neighbour
//! outside the box is outside the volume.

use super::bounds::VoxelBounds;
use super::extinction::Extinction;
use crate::volume::Sample;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU16, AtomicU64, Ordering::Relaxed};

/// Frontier or candidate entries per rayon task.
const CHUNK: usize = 2048;

/// The 26 neighbour directions.
const DIRS: [[isize; 3]; 26] = {
    let mut d = [[0isize; 3]; 26];
    let mut n = 0;
    let mut z = -1;
    while z <= 1 {
        let mut y = -1;
        while y <= 1 {
            let mut x = -1;
            while x <= 1 {
                if x != 0 || y != 0 || z != 0 {
                    d[n] = [x, y, z];
                    n += 1;
                }
                x += 1;
            }
            y += 1;
        }
        z += 1;
    }
    d
};

/// The working box inside the volume: index arithmetic of the kernels.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lattice {
    lo: [usize; 3],
    bdim: [usize; 3],
    vdim: [usize; 3],
    off_box: [isize; 26],
    off_vol: [isize; 26],
}

impl Lattice {
    pub(crate) fn new(work: &VoxelBounds, vdim: [usize; 3]) -> Self {
        let bdim = work.dims();
        let lin = |d: [usize; 3], o: [isize; 3]| o[0] + d[0] as isize * (o[1] + d[1] as isize * o[2]);
        Self {
            lo: work.lo,
            bdim,
            vdim,
            off_box: DIRS.map(|o| lin(bdim, o)),
            off_vol: DIRS.map(|o| lin(vdim, o)),
        }
    }

    /// Box-local coordinates of box-linear index `l`.
    #[inline]
    fn coords(&self, l: usize) -> [usize; 3] {
        let x = l % self.bdim[0];
        let r = l / self.bdim[0];
        [x, r % self.bdim[1], r / self.bdim[1]]
    }

    /// Volume-linear index of box-local coordinates `c`.
    #[inline]
    fn vol_linear(&self, c: [usize; 3]) -> usize {
        (self.lo[0] + c[0]) + self.vdim[0] * ((self.lo[1] + c[1]) + self.vdim[1] * (self.lo[2] + c[2]))
    }

    /// Calls `f(box_linear, volume_linear)` for each 26-neighbour of box
    /// voxel `l` (coordinates `c`) inside the box.
    #[inline(always)]
    fn for_each_neighbour(&self, l: usize, c: [usize; 3], mut f: impl FnMut(usize, usize)) {
        let vl = self.vol_linear(c);
        let interior = (0..3).all(|a| c[a] >= 1 && c[a] + 1 < self.bdim[a]);
        if interior {
            for n in 0..26 {
                f(
                    l.wrapping_add_signed(self.off_box[n]),
                    vl.wrapping_add_signed(self.off_vol[n]),
                );
            }
        } else {
            for (n, d) in DIRS.iter().enumerate() {
                let inside = (0..3).all(|a| {
                    let p = c[a] as isize + d[a];
                    p >= 0 && (p as usize) < self.bdim[a]
                });
                if inside {
                    f(
                        l.wrapping_add_signed(self.off_box[n]),
                        vl.wrapping_add_signed(self.off_vol[n]),
                    );
                }
            }
        }
    }

    /// Volume voxel index of box-local coordinates.
    fn voxel(&self, c: [usize; 3]) -> [usize; 3] {
        [0, 1, 2].map(|a| self.lo[a] + c[a])
    }
}

/// Phase 1: the candidates of the next step, each with its extinction.
pub(crate) fn enumerate<T: Sample>(
    lat: &Lattice,
    field: &[AtomicU16],
    flags: &[AtomicU64],
    ext: &Extinction,
    values: &[T],
    frontier: &[u32],
) -> Vec<(u32, i32)> {
    let parts: Vec<Vec<(u32, i32)>> = frontier
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut out = Vec::with_capacity(chunk.len() * 2);
            for &u in chunk {
                let l = u as usize;
                let qu = field[l].load(Relaxed);
                lat.for_each_neighbour(l, lat.coords(l), |v, vv| {
                    let q = field[v].load(Relaxed);
                    if q == ext.q_max {
                        return;
                    }
                    let word = &flags[v >> 6];
                    let bit = 1u64 << (v & 63);
                    if word.load(Relaxed) & bit != 0 {
                        return;
                    }
                    let e = ext.fixed(values[vv].to_f32());
                    if ext.rise(qu, e) <= q {
                        return;
                    }
                    if word.fetch_or(bit, Relaxed) & bit == 0 {
                        out.push((v as u32, e));
                    }
                });
            }
            out
        })
        .collect();
    if parts.len() == 1 {
        return parts.into_iter().next().unwrap_or_default();
    }
    parts.concat()
}

/// What phase 2 found in one chunk of candidates.
#[derive(Debug, Default)]
pub(crate) struct Changes {
    /// `(box-linear index, new value)` of every voxel that rose.
    pub(crate) values: Vec<(u32, u16)>,
    /// Volume voxel-index box of those voxels (`None` when none rose).
    pub(crate) bounds: Option<VoxelBounds>,
}

/// Phase 2: evaluates the update rule at every candidate (the field is only
/// read), with the pump shortcut ([`Extinction::pumps`]), and clears the
/// candidate bits.
pub(crate) fn evaluate<T: Sample>(
    lat: &Lattice,
    field: &[AtomicU16],
    flags: &[AtomicU64],
    ext: &Extinction,
    values: &[T],
    candidates: &[(u32, i32)],
) -> Vec<Changes> {
    candidates
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut out = Changes::default();
            for &(v, e) in chunk {
                let l = v as usize;
                let c = lat.coords(l);
                let mut m = 0u16;
                lat.for_each_neighbour(l, c, |n, _| m = m.max(field[n].load(Relaxed)));
                let old = field[l].load(Relaxed);
                let mut new = ext.rise(m, e).max(old);
                if new > old && ext.may_pump(new, e) {
                    let mut pump = false;
                    lat.for_each_neighbour(l, c, |n, vn| {
                        pump |= ext.pumps(new, e, ext.fixed(values[vn].to_f32()), field[n].load(Relaxed));
                    });
                    if pump {
                        new = ext.q_max;
                    }
                }
                flags[l >> 6].fetch_and(!(1u64 << (l & 63)), Relaxed);
                if new > old {
                    out.values.push((v, new));
                    let p = VoxelBounds::point(lat.voxel(c));
                    out.bounds = Some(out.bounds.map_or(p, |b| b.union(&p)));
                }
            }
            out
        })
        .collect()
}

/// Phase 3: stores the new values; returns the next frontier.
pub(crate) fn apply(field: &[AtomicU16], changes: &[Changes]) -> Vec<u32> {
    changes.par_iter().for_each(|c| {
        for &(v, q) in &c.values {
            field[v as usize].store(q, Relaxed);
        }
    });
    let n = changes.iter().map(|c| c.values.len()).sum();
    let mut next = Vec::with_capacity(n);
    for c in changes {
        next.extend(c.values.iter().map(|&(v, _)| v));
    }
    next
}
