//! The sparse frontier step on the CPU (rayon).
//!
//! One step, Jacobi style (every value read is the previous step's):
//!
//! 1. **Enumerate** (over the frontier, the voxels `u` that changed in the
//!    previous step): each 26-neighbour `v` is *tested*: it becomes a
//!    candidate when `u`'s new value lifts it, `rise(q_u, e_v) > q_v`, and it
//!    is not a candidate yet (a mark, so each voxel is listed once). Voxels
//!    marked *done* (at their ceiling [`Extinction::ceiling`], e.g. at
//!    `q_max`) are skipped without reading their value or computing their
//!    extinction; the marks of a neighbourhood are read three voxels per
//!    row, so only unmarked neighbours cost a branch. Candidates carry `e_v`.
//! 2. **Evaluate** (over the candidates, the field read-only): the update
//!    rule, then the pump shortcut (a lifted voxel that forms a pumping pair
//!    with a neighbour jumps to `q_max`, its final value — see
//!    [`Extinction::pumps`]); changed voxels are collected with their new
//!    value; the candidate mark is cleared and, for a voxel that reached its
//!    ceiling, the done mark set.
//! 3. **Apply**: the new values are stored; the changed voxels are the next
//!    frontier.
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
//! **Parallel schedule without atomic read-modify-writes.** The frontier and
//! the candidates are kept in **groups** of `G` z-slabs of the working box
//! ([`group_slabs`], 4 unless a slab holds fewer than 32 voxels), and the
//! rayon tasks are groups. Enumerating group `g` writes marks only of voxels
//! in slabs `Gg − 1 ..= Gg + G`, evaluating it only of its own voxels; with
//! `G` large enough, groups of one parity never touch the same mark word (32
//! consecutive voxels), so even groups run in parallel, then odd groups, and
//! the marks are updated with plain loads and stores instead of locked
//! instructions (which on x86 serialise the memory accesses and cost more
//! than the arithmetic here). Applying touches only each voxel's own value,
//! so all groups run at once. The result is deterministic, order included.
//! Working in slab groups also keeps each task's accesses to a few slabs,
//! so they stay in cache.
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

/// Mark of a voxel listed as a candidate in the current step.
pub(crate) const MARK_CANDIDATE: u64 = 1;
/// Mark of a voxel at its ceiling ([`Extinction::ceiling`]): it can never
/// change again, so the enumeration skips it without reading its value.
pub(crate) const MARK_DONE: u64 = 2;

/// Word and bit shift of voxel `v`'s two marks (32 voxels per u64 word).
#[inline]
pub(crate) fn mark_slot(v: usize) -> (usize, u32) {
    (v >> 5, ((v & 31) * 2) as u32)
}

/// Box z-slabs per group, the unit of parallel work: at least 4, and more
/// when a slab holds fewer than 32 voxels, so that the mark words two groups
/// apart never meet (see the module docs). A mark word spans voxels of at
/// most `k = ⌈32 / (nx·ny)⌉` slabs either side, and a task writes marks up
/// to one slab beyond its group, so `2k + 2` slabs keep groups `g` and
/// `g + 2` apart.
pub(crate) fn group_slabs(dims: [usize; 3]) -> usize {
    let k = 32usize.div_ceil((dims[0] * dims[1]).max(1));
    (2 * k + 2).max(4)
}

/// Marks for a field: no candidate, done where the value is `q_max`.
pub(crate) fn marks_for(field: &[AtomicU16], q_max: u16) -> Vec<AtomicU64> {
    (0..field.len().div_ceil(32))
        .into_par_iter()
        .map(|w| {
            let mut x = 0u64;
            for (i, q) in field[w * 32..(w * 32 + 32).min(field.len())].iter().enumerate() {
                if q.load(Relaxed) == q_max {
                    x |= MARK_DONE << (2 * i);
                }
            }
            AtomicU64::new(x)
        })
        .collect()
}

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

/// Division by a fixed `u32` with one 64×64→128-bit multiplication
/// (Lemire, Kaser & Kurz 2019: exact for every 32-bit dividend).
#[derive(Clone, Copy, Debug)]
struct FastDiv {
    d: u32,
    m: u64,
}

impl FastDiv {
    fn new(d: u32) -> Self {
        let d = d.max(1);
        Self {
            d,
            m: if d == 1 { 0 } else { u64::MAX / d as u64 + 1 },
        }
    }

    /// `(n / d, n % d)`.
    #[inline(always)]
    fn div_rem(&self, n: u32) -> (u32, u32) {
        let q = if self.d == 1 {
            n
        } else {
            ((self.m as u128 * n as u128) >> 64) as u32
        };
        (q, n - q * self.d)
    }
}

/// The working box inside the volume: index arithmetic of the kernels.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lattice {
    lo: [usize; 3],
    bdim: [usize; 3],
    vdim: [usize; 3],
    div_x: FastDiv,
    div_y: FastDiv,
    /// Slabs per group.
    gs: usize,
    off_box: [isize; 26],
    off_vol: [isize; 26],
    /// Offsets of the 27-neighbourhood, cell `(dx+1) + 3(dy+1) + 9(dz+1)`.
    off27_box: [isize; 27],
    off27_vol: [isize; 27],
}

impl Lattice {
    pub(crate) fn new(work: &VoxelBounds, vdim: [usize; 3]) -> Self {
        let bdim = work.dims();
        let lin = |d: [usize; 3], o: [isize; 3]| o[0] + d[0] as isize * (o[1] + d[1] as isize * o[2]);
        let cell = |i: usize| [(i % 3) as isize - 1, ((i / 3) % 3) as isize - 1, (i / 9) as isize - 1];
        Self {
            lo: work.lo,
            bdim,
            vdim,
            div_x: FastDiv::new(bdim[0] as u32),
            div_y: FastDiv::new(bdim[1] as u32),
            gs: group_slabs(bdim),
            off_box: DIRS.map(|o| lin(bdim, o)),
            off_vol: DIRS.map(|o| lin(vdim, o)),
            off27_box: std::array::from_fn(|i| lin(bdim, cell(i))),
            off27_vol: std::array::from_fn(|i| lin(vdim, cell(i))),
        }
    }

    /// Box-local coordinates of box-linear index `l` (< 2³²).
    #[inline(always)]
    fn coords(&self, l: usize) -> [usize; 3] {
        let (r, x) = self.div_x.div_rem(l as u32);
        let (z, y) = self.div_y.div_rem(r);
        [x as usize, y as usize, z as usize]
    }

    /// True when all 26 neighbours of `c` lie in the box.
    #[inline(always)]
    fn interior(&self, c: [usize; 3]) -> bool {
        (0..3).all(|a| c[a] >= 1 && c[a] + 1 < self.bdim[a])
    }

    /// Volume-linear index of box-local coordinates `c`.
    #[inline(always)]
    fn vol_linear(&self, c: [usize; 3]) -> usize {
        (self.lo[0] + c[0]) + self.vdim[0] * ((self.lo[1] + c[1]) + self.vdim[1] * (self.lo[2] + c[2]))
    }

    /// Calls `f(box_linear, volume_linear, dz)` for each 26-neighbour of
    /// box voxel `l` (coordinates `c`) inside the box.
    #[inline(always)]
    fn for_each_neighbour(&self, l: usize, c: [usize; 3], mut f: impl FnMut(usize, usize, isize)) {
        let vl = self.vol_linear(c);
        let interior = self.interior(c);
        for (n, d) in DIRS.iter().enumerate() {
            let inside = interior
                || (0..3).all(|a| {
                    let p = c[a] as isize + d[a];
                    p >= 0 && (p as usize) < self.bdim[a]
                });
            if inside {
                f(
                    l.wrapping_add_signed(self.off_box[n]),
                    vl.wrapping_add_signed(self.off_vol[n]),
                    d[2],
                );
            }
        }
    }

    /// Volume voxel index of box-local coordinates.
    fn voxel(&self, c: [usize; 3]) -> [usize; 3] {
        [0, 1, 2].map(|a| self.lo[a] + c[a])
    }
}

/// Which of the three voxels `r, r+1, r+2` carry a mark (bit i for `r+i`).
#[inline(always)]
fn marked3(marks: &[AtomicU64], r: usize) -> u64 {
    let (w, off) = mark_slot(r);
    let mut bits = marks[w].load(Relaxed) >> off;
    if off > 58 {
        bits |= marks[w + 1].load(Relaxed) << (64 - off);
    }
    let any = (bits | (bits >> 1)) & 0b01_0101;
    (any & 1) | ((any >> 1) & 2) | ((any >> 2) & 4)
}

/// Candidates found while enumerating group `g`, by the group they fall
/// in: `[g − 1, g, g + 1]`.
pub(crate) type Found = [Vec<(u32, i32)>; 3];

/// Phase 1: the candidates of the next step, each with its extinction, from
/// the frontier's groups (see the module docs for the schedule).
pub(crate) fn enumerate<T: Sample>(
    lat: &Lattice,
    field: &[AtomicU16],
    marks: &[AtomicU64],
    ext: &Extinction,
    values: &[T],
    frontier: &[Vec<(u32, u16)>],
) -> Vec<Found> {
    /// Tests neighbour `v` (volume index `vv`, z offset `dz` from the
    /// frontier voxel at slab `z`) of a voxel holding `qu`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn test<T: Sample>(
        field: &[AtomicU16],
        marks: &[AtomicU64],
        ext: &Extinction,
        values: &[T],
        qu: u16,
        (v, vv): (usize, usize),
        slot: usize,
        out: &mut Found,
    ) {
        let (w, sh) = mark_slot(v);
        // Plain load and store: no other task writes this word now.
        let word = marks[w].load(Relaxed);
        if (word >> sh) & (MARK_CANDIDATE | MARK_DONE) != 0 {
            return;
        }
        let q = field[v].load(Relaxed);
        let e = ext.fixed(values[vv].to_f32());
        if ext.rise(qu, e) <= q {
            if ext.ceiling(e) <= q {
                // Never liftable (e.g. a wall around the region): skip it
                // from now on.
                marks[w].store(word | (MARK_DONE << sh), Relaxed);
            }
            return;
        }
        marks[w].store(word | (MARK_CANDIDATE << sh), Relaxed);
        out[slot].push((v as u32, e));
    }

    let (bx, bxy) = (lat.bdim[0], lat.bdim[0] * lat.bdim[1]);
    let mut found: Vec<Found> = (0..frontier.len()).map(|_| Found::default()).collect();
    for parity in 0..2 {
        found
            .par_iter_mut()
            .enumerate()
            .filter(|(g, _)| g % 2 == parity)
            .for_each(|(g, out)| {
                // Slot of a neighbour at slab z + dz: its group minus g, plus 1.
                let slot = |z: usize, dz: isize| (z as isize + dz) as usize / lat.gs + 1 - g;
                for &(u, qu) in &frontier[g] {
                    let l = u as usize;
                    let c = lat.coords(l);
                    if lat.interior(c) {
                        // The marks of the 27-neighbourhood, three per row.
                        let mut marked = 1u64 << 13;
                        for dz in 0..3 {
                            for dy in 0..3 {
                                let r = (l - 1 + dy * bx + dz * bxy) - bx - bxy;
                                marked |= marked3(marks, r) << (3 * (dy + 3 * dz));
                            }
                        }
                        let vl = lat.vol_linear(c);
                        let mut free = !marked & ((1u64 << 27) - 1);
                        while free != 0 {
                            let i = free.trailing_zeros() as usize;
                            free &= free - 1;
                            let v = l.wrapping_add_signed(lat.off27_box[i]);
                            let vv = vl.wrapping_add_signed(lat.off27_vol[i]);
                            let s = slot(c[2], (i / 9) as isize - 1);
                            test(field, marks, ext, values, qu, (v, vv), s, out);
                        }
                    } else {
                        lat.for_each_neighbour(l, c, |v, vv, dz| {
                            test(field, marks, ext, values, qu, (v, vv), slot(c[2], dz), out)
                        });
                    }
                }
            });
    }
    found
}

/// What phase 2 found in one group.
#[derive(Debug, Default)]
pub(crate) struct Changes {
    /// `(box-linear index, new value)` of every voxel that rose.
    pub(crate) values: Vec<(u32, u16)>,
    /// Volume voxel-index box of those voxels (`None` when none rose).
    pub(crate) bounds: Option<VoxelBounds>,
}

/// The candidates of group `g`: those its own task and its neighbours'
/// tasks found in it.
fn candidates_of(found: &[Found], g: usize) -> impl Iterator<Item = &(u32, i32)> {
    let below = g.checked_sub(1).map(|h| &found[h][2]);
    let above = found.get(g + 1).map(|f| &f[0]);
    below.into_iter().chain([&found[g][1]]).chain(above).flatten()
}

/// Number of candidates in `found`.
pub(crate) fn count(found: &[Found]) -> usize {
    found.iter().flat_map(|f| f.iter()).map(Vec::len).sum()
}

/// Phase 2: evaluates the update rule at every candidate (the field is only
/// read), with the pump shortcut ([`Extinction::pumps`]), and updates the
/// marks. One task per group, even groups then odd ones.
pub(crate) fn evaluate<T: Sample>(
    lat: &Lattice,
    field: &[AtomicU16],
    marks: &[AtomicU64],
    ext: &Extinction,
    values: &[T],
    found: &[Found],
) -> Vec<Changes> {
    let mut changes: Vec<Changes> = (0..found.len()).map(|_| Changes::default()).collect();
    for parity in 0..2 {
        changes
            .par_iter_mut()
            .enumerate()
            .filter(|(g, _)| g % 2 == parity)
            .for_each(|(g, out)| {
            for &(v, e) in candidates_of(found, g) {
                let l = v as usize;
                let c = lat.coords(l);
                let mut m = 0u16;
                lat.for_each_neighbour(l, c, |n, _, _| m = m.max(field[n].load(Relaxed)));
                let old = field[l].load(Relaxed);
                let mut new = ext.rise(m, e).max(old);
                if new > old && ext.may_pump(new, e) {
                    let mut pump = false;
                    lat.for_each_neighbour(l, c, |n, vn, _| {
                        pump |= ext.pumps(new, e, ext.fixed(values[vn].to_f32()), field[n].load(Relaxed));
                    });
                    if pump {
                        new = ext.q_max;
                    }
                }
                // Clear the candidate mark; set the done mark at the ceiling.
                // Plain load and store: no other task writes this word now.
                let (w, sh) = mark_slot(l);
                let done = if new == ext.ceiling(e) { MARK_DONE } else { 0 };
                let word = marks[w].load(Relaxed);
                marks[w].store(word ^ ((MARK_CANDIDATE | done) << sh), Relaxed);
                if new > old {
                    out.values.push((v, new));
                    let p = VoxelBounds::point(lat.voxel(c));
                    out.bounds = Some(out.bounds.map_or(p, |b| b.union(&p)));
                }
            }
            });
    }
    changes
}

/// Phase 3: stores the new values; the changes, by group, are the next
/// frontier.
pub(crate) fn apply(field: &[AtomicU16], changes: Vec<Changes>) -> Vec<Vec<(u32, u16)>> {
    changes.par_iter().for_each(|c| {
        for &(v, q) in &c.values {
            field[v as usize].store(q, Relaxed);
        }
    });
    changes.into_iter().map(|c| c.values).collect()
}

/// Buckets frontier entries (box-linear index, value) into the groups of a
/// box of `dims`.
pub(crate) fn group(entries: impl IntoIterator<Item = (u32, u16)>, dims: [usize; 3]) -> Vec<Vec<(u32, u16)>> {
    let gs = group_slabs(dims);
    let per_group = dims[0] * dims[1] * gs;
    let mut groups = vec![Vec::new(); dims[2].div_ceil(gs)];
    for (l, q) in entries {
        groups[l as usize / per_group].push((l, q));
    }
    groups
}
