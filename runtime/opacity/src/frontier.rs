//! The sparse frontier step on the CPU (rayon).
//!
//! One step, Jacobi style (every value a voxel is lifted from is the
//! previous step's):
//!
//! 1. **Lift** (over the frontier, the voxels `u` that changed in the
//!    previous step, each carrying its new value `q_u`): each neighbour (26, or 6)
//!    `v` that is not *done* (at its ceiling [`Extinction::ceiling`], e.g. at
//!    `q_max`) takes `max(q_v, rise(q_u, e_v))` in place. The frontier
//!    carries its values, so no lift reads a value written in this step, and
//!    `max` does not depend on the order: the field after the phase is the
//!    Jacobi update. A voxel that rises for the first time in the step is
//!    recorded (once — its state says so) with `e_v` and the value it rose
//!    to. The states of a neighbourhood are read three voxels per row, so
//!    only open neighbours cost a branch.
//! 2. **Finish** (over the raised voxels): the pump shortcut (a lifted voxel
//!    that forms a pumping pair with a neighbour jumps to `q_max`, its final
//!    value — see [`Extinction::pumps`]) and the states; the raised voxels
//!    with their values are the next frontier. A voxel that rose straight to
//!    its ceiling needs nothing here (its recorded value is final).
//!
//! A voxel that no changed neighbour lifts cannot change (its value already
//! dominates `rise(q_n, e_v)` for the unchanged `q_n`), so the step equals a
//! dense sweep of the whole volume, bit for bit, and every voxel it visits
//! (evaluates the update of) changes: every visit is useful. What the step
//! spends beyond that is the neighbour scan — 26 (or 6) state reads per changed
//! voxel, against the dense sweep's 27 reads per voxel of the volume.
//!
//! **States.** Two bits per box voxel: *unreached* (at `q_min`, never
//! raised — its value need not be read), *reached*, *raised* (in this step;
//! listed), *done*.
//!
//! **Parallel schedule without atomic read-modify-writes.** The frontier and
//! the raised voxels are kept in **groups** of `G` z-slabs of the working
//! box ([`group_slabs`], 4 unless a slab holds fewer than 32 voxels), and the
//! rayon tasks are groups. Lifting from group `g` writes values and states
//! only of voxels in slabs `Gg − 1 ..= Gg + G`, finishing it only of its own
//! voxels; with `G` large enough, groups of one parity never touch the same
//! state word (32 consecutive voxels) or voxel, so even groups run in
//! parallel, then odd groups, with plain loads and stores instead of locked
//! instructions (which on x86 serialise the memory accesses and cost more
//! than the arithmetic here). The result is deterministic, order included.
//! Working in slab groups also keeps each task's accesses to a few slabs,
//! so they stay in cache.
//!
//! Indices are linear (x fastest) in the working box; the box is kept at
//! least two voxels larger than the region (raised voxels lie within one
//! voxel of it, and the pump shortcut reads their neighbours), so a
//! neighbour outside the box is outside the volume.

use super::bounds::VoxelBounds;
use super::extinction::Extinction;
use crate::volume::Sample;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU16, AtomicU64, Ordering::Relaxed};
use voxflex_core::fast_div::FastDiv;

/// State of a voxel never raised: its value is `q_min`.
pub(crate) const UNREACHED: u64 = 0;
/// State of a voxel raised before, below its ceiling.
pub(crate) const REACHED: u64 = 1;
/// State of a voxel raised in the current step and listed, below its
/// ceiling.
pub(crate) const RAISED: u64 = 2;
/// State of a voxel at its ceiling ([`Extinction::ceiling`]): it can never
/// change again, so the lift skips it without reading its value.
pub(crate) const DONE: u64 = 3;

/// Word and bit shift of voxel `v`'s state (32 voxels per u64 word).
#[inline]
pub(crate) fn mark_slot(v: usize) -> (usize, u32) {
    (v >> 5, ((v & 31) * 2) as u32)
}

/// Box z-slabs per group, the unit of parallel work: at least 4, and more
/// when a slab holds fewer than 32 voxels, so that the mark words two groups
/// apart never meet (see the module docs). A mark word spans voxels of at
/// most `k = ⌈32 / (nx·ny)⌉` slabs either side, and a task writes states up
/// to one slab beyond its group, so `2k + 2` slabs keep groups `g` and
/// `g + 2` apart.
pub(crate) fn group_slabs(dims: [usize; 3]) -> usize {
    let k = 32usize.div_ceil((dims[0] * dims[1]).max(1));
    (2 * k + 2).max(4)
}

/// States for a field: done at `q_max`, reached above `q_min`, unreached
/// at `q_min`; voxels outside `range` (box-linear) are taken as unreached.
/// Takes the field exclusively, so the values are read with plain loads
/// and each word's 32 states are computed without branches.
pub(crate) fn states_for(
    field: &mut [AtomicU16],
    range: std::ops::Range<usize>,
    q_min: u16,
    q_max: u16,
) -> Vec<AtomicU64> {
    field
        .par_chunks_mut(32)
        .enumerate()
        .map(|(w, chunk)| {
            let base = w * 32;
            if base + chunk.len() <= range.start || base >= range.end {
                return AtomicU64::new(UNREACHED);
            }
            let mut x = 0u64;
            for (i, q) in chunk.iter_mut().enumerate() {
                let v = base + i;
                let q = *q.get_mut();
                // UNREACHED 0, REACHED 1, DONE 3 (q ≥ q_max > q_min).
                let st = (q > q_min) as u64 | (((q >= q_max) as u64) << 1);
                let inside = (v >= range.start && v < range.end) as u64;
                x |= (st * inside) << (2 * i);
            }
            AtomicU64::new(x)
        })
        .collect()
}

/// The 26 neighbour directions.
pub(crate) const DIRS: [[isize; 3]; 26] = {
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

/// Which of [`DIRS`] are face neighbours (one non-zero component).
pub(crate) const IS_FACE: [bool; 26] = {
    let mut f = [false; 26];
    let mut n = 0;
    while n < 26 {
        let d = DIRS[n];
        f[n] = d[0].abs() + d[1].abs() + d[2].abs() == 1;
        n += 1;
    }
    f
};

/// Bits `2i` of the 6 face cells `i` of a 27-neighbourhood (cell `(dx+1) +
/// 3(dy+1) + 9(dz+1)`: 4, 10, 12, 14, 16, 22).
const FACES_EVEN: u64 = 1 << 8 | 1 << 20 | 1 << 24 | 1 << 28 | 1 << 32 | 1 << 44;

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
    /// Only the 6 face neighbours pass opacity on (`connectivity = 6`).
    faces_only: bool,
}

impl Lattice {
    pub(crate) fn new(work: &VoxelBounds, vdim: [usize; 3], connectivity: u32) -> Self {
        let bdim = work.dims();
        let lin =
            |d: [usize; 3], o: [isize; 3]| o[0] + d[0] as isize * (o[1] + d[1] as isize * o[2]);
        let cell = |i: usize| {
            [
                (i % 3) as isize - 1,
                ((i / 3) % 3) as isize - 1,
                (i / 9) as isize - 1,
            ]
        };
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
            faces_only: connectivity == 6,
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
        (self.lo[0] + c[0])
            + self.vdim[0] * ((self.lo[1] + c[1]) + self.vdim[1] * (self.lo[2] + c[2]))
    }

    /// Calls `f(box_linear, volume_linear, dz)` for each neighbour (26, or
    /// the 6 face neighbours) of box voxel `l` (coordinates `c`) inside the
    /// box.
    #[inline(always)]
    fn for_each_neighbour(&self, l: usize, c: [usize; 3], mut f: impl FnMut(usize, usize, isize)) {
        let vl = self.vol_linear(c);
        let skip = |n: usize| self.faces_only && !IS_FACE[n];
        if self.interior(c) {
            for (n, d) in DIRS.iter().enumerate() {
                if skip(n) {
                    continue;
                }
                f(
                    l.wrapping_add_signed(self.off_box[n]),
                    vl.wrapping_add_signed(self.off_vol[n]),
                    d[2],
                );
            }
        } else {
            for (n, d) in DIRS.iter().enumerate() {
                if skip(n) {
                    continue;
                }
                let inside = (0..3).all(|a| {
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
    }

    /// Volume voxel index of box-local coordinates.
    fn voxel(&self, c: [usize; 3]) -> [usize; 3] {
        [0, 1, 2].map(|a| self.lo[a] + c[a])
    }
}

/// Whether the three voxels `r, r+1, r+2` are done, at bits 0, 2, 4.
#[inline(always)]
fn done3(states: &[AtomicU64], r: usize) -> u64 {
    let (w, off) = mark_slot(r);
    let lo = states[w].load(Relaxed);
    // Three voxels (6 bits) straddle two words only from bit 60 on.
    let bits = if off <= 58 {
        lo >> off
    } else {
        let hi = states.get(w + 1).map_or(0, |m| m.load(Relaxed));
        (lo >> off) | (hi << (64 - off))
    };
    bits & (bits >> 1) & 0b01_0101
}

/// Bits `2i` for the 27 cells `i` of a neighbourhood.
const CELLS_EVEN: u64 = 0x0015_5555_5555_5555;

/// A voxel raised in a step: box-linear index, extinction, the value it
/// first rose to (final when it is the voxel's ceiling).
pub(crate) type Raised = (u32, i32, u16);

/// Voxels raised while lifting from group `g`'s frontier, by the group they
/// fall in: `[g − 1, g, g + 1]`.
pub(crate) type Found = [Vec<Raised>; 3];

/// What a step's two passes ([`lift`], [`finish`]) fill — the raised
/// voxels by group, then the changes by group (the next frontier) — and
/// from how many frontier entries they run on the pool. The lists are
/// emptied, not dropped, between steps: fresh lists grew by reallocation
/// every step (a ninth of a 1.5 mm liver growth's time).
#[derive(Debug)]
pub(crate) struct StepLists {
    /// Raised voxels by group and neighbour slot (the last step's).
    pub(crate) found: Vec<Found>,
    /// Changes by group (swapped into the frontier after each step).
    pub(crate) changes: Vec<Changes>,
    /// A step's passes run on the pool from this many frontier entries
    /// ([`PARALLEL_ENTRIES`]; tests set it to check both schedules).
    pub(crate) parallel_from: usize,
}

impl StepLists {
    /// Empty lists; passes on the pool from `parallel_from` entries.
    pub(crate) fn new(parallel_from: usize) -> Self {
        Self {
            found: Vec::new(),
            changes: Vec::new(),
            parallel_from,
        }
    }
}

/// Below this many frontier entries (or raised voxels) a step's passes run
/// on the calling thread. Each pass over the groups is a fork and a join,
/// four a step, and a step's frontier is small: on the abdomen's liver
/// ~860 entries a step at 3 mm, ~3,900 at 1.5 mm on average over ~190
/// steps. Split over the two cores of the benchmark machine, every step's
/// passes made the whole growth slower, not faster (3 mm: 13.7–14.9 ms
/// against 7.3–7.4 on one thread), so they ran on the pool from 8,192
/// entries. Since a step keeps its lists ([`StepLists`]) a pass's fork
/// costs less, and from 1,024 entries the 1.5 mm growth took 46–48 ms
/// against 48–54 (medians of four interleaved rounds of nine), the 3 mm
/// one the same (docs/BENCHMARKS.md, "Figures: the growth on one thread"
/// and after).
pub(crate) const PARALLEL_ENTRIES: usize = 1024;

/// Runs `f` on the items of `items` whose index has parity `parity` (the
/// groups one pass may touch at once), on the pool when `parallel`. Either
/// way each item is visited once by its own call, so the results are the
/// same.
fn each_of_parity<X: Send>(
    items: &mut [X],
    parity: usize,
    parallel: bool,
    f: impl Fn((usize, &mut X)) + Sync + Send,
) {
    if parallel {
        items
            .par_iter_mut()
            .enumerate()
            .filter(|(g, _)| g % 2 == parity)
            .for_each(f);
    } else {
        items
            .iter_mut()
            .enumerate()
            .filter(|(g, _)| g % 2 == parity)
            .for_each(f);
    }
}

/// Phase 1: lifts the neighbours of the frontier in place; returns the
/// raised voxels (see the module docs for the schedule). On the pool once
/// the frontier holds `parallel_from` entries ([`PARALLEL_ENTRIES`]).
pub(crate) fn lift<T: Sample>(
    lat: &Lattice,
    field: &[AtomicU16],
    states: &[AtomicU64],
    ext: &Extinction,
    values: &[T],
    frontier: &[Vec<(u32, u16)>],
    passes: &mut StepLists,
) {
    let StepLists {
        found,
        parallel_from,
        ..
    } = passes;
    /// Lifts neighbour `v` (volume index `vv`) of a frontier voxel that
    /// holds `qu`; records it in `out[slot]` the first time it rises.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn lift_one<T: Sample>(
        field: &[AtomicU16],
        states: &[AtomicU64],
        ext: &Extinction,
        values: &[T],
        qu: u16,
        (v, vv): (usize, usize),
        slot: usize,
        out: &mut Found,
    ) {
        let (w, sh) = mark_slot(v);
        // Plain loads and stores: no other task touches this voxel or state
        // word now.
        let word = states[w].load(Relaxed);
        let st = (word >> sh) & 3;
        if st == DONE {
            return;
        }
        let q = if st == UNREACHED {
            ext.q_min
        } else {
            field[v].load(Relaxed)
        };
        let e = ext.fixed(values[vv].to_f32());
        let new = ext.rise(qu, e);
        let ceiling = ext.ceiling(e);
        let next = if new > q {
            field[v].store(new, Relaxed);
            if st != RAISED {
                out[slot].push((v as u32, e, new));
            }
            if new >= ceiling { DONE } else { RAISED }
        } else if q >= ceiling {
            // Never liftable again (e.g. a wall around the region).
            DONE
        } else {
            st
        };
        if next != st {
            states[w].store(word ^ ((st ^ next) << sh), Relaxed);
        }
    }

    let (bx, bxy) = (lat.bdim[0], lat.bdim[0] * lat.bdim[1]);
    // The lists of the step before, emptied: their capacity is kept (fresh
    // lists grew by reallocation every step).
    found.resize_with(frontier.len(), Found::default);
    found.iter_mut().flatten().for_each(Vec::clear);
    let parallel = frontier.iter().map(Vec::len).sum::<usize>() >= *parallel_from;
    for parity in 0..2 {
        each_of_parity(found, parity, parallel, |(g, out)| {
            let g0 = g * lat.gs;
            for &(u, qu) in &frontier[g] {
                let l = u as usize;
                let c = lat.coords(l);
                // Slot of a neighbour at slab z + dz: its group − g + 1.
                let zr = c[2] - g0;
                let slot = |dz: isize| {
                    if dz < 0 && zr == 0 {
                        0
                    } else if dz > 0 && zr + 1 == lat.gs {
                        2
                    } else {
                        1
                    }
                };
                if lat.interior(c) {
                    // Which of the 27-neighbourhood are done, three per
                    // row, at bit 2i for cell i.
                    let mut done = 1u64 << 26;
                    for row in 0..9 {
                        let (dy, dz) = (row % 3, row / 3);
                        let r = (l - 1 + dy * bx + dz * bxy) - bx - bxy;
                        done |= done3(states, r) << (6 * row);
                    }
                    let vl = lat.vol_linear(c);
                    let cells = if lat.faces_only {
                        FACES_EVEN
                    } else {
                        CELLS_EVEN
                    };
                    let mut open = !done & cells;
                    while open != 0 {
                        let i = (open.trailing_zeros() / 2) as usize;
                        open &= open - 1;
                        let v = l.wrapping_add_signed(lat.off27_box[i]);
                        let vv = vl.wrapping_add_signed(lat.off27_vol[i]);
                        lift_one(
                            field,
                            states,
                            ext,
                            values,
                            qu,
                            (v, vv),
                            slot((i / 9) as isize - 1),
                            out,
                        );
                    }
                } else {
                    lat.for_each_neighbour(l, c, |v, vv, dz| {
                        lift_one(field, states, ext, values, qu, (v, vv), slot(dz), out)
                    });
                }
            }
        });
    }
}

/// What phase 2 found in one group.
#[derive(Debug, Default)]
pub(crate) struct Changes {
    /// `(box-linear index, new value)` of every voxel that rose: the next
    /// frontier.
    pub(crate) values: Vec<(u32, u16)>,
    /// Volume voxel-index box of those voxels (`None` when none rose).
    pub(crate) bounds: Option<VoxelBounds>,
}

/// The raised voxels of group `g`: those its own task and its neighbours'
/// tasks found in it.
fn raised_in(found: &[Found], g: usize) -> impl Iterator<Item = &Raised> {
    let below = g.checked_sub(1).map(|h| &found[h][2]);
    let above = found.get(g + 1).map(|f| &f[0]);
    below
        .into_iter()
        .chain([&found[g][1]])
        .chain(above)
        .flatten()
}

/// Number of raised voxels in `found`.
pub(crate) fn count(found: &[Found]) -> usize {
    found.iter().flat_map(|f| f.iter()).map(Vec::len).sum()
}

/// Phase 2: the pump shortcut ([`Extinction::pumps`]) on the raised voxels,
/// their states, and the next frontier. One task per group, even groups
/// then odd ones; on the pool once `parallel_from` voxels were raised.
pub(crate) fn finish<T: Sample>(
    lat: &Lattice,
    field: &[AtomicU16],
    states: &[AtomicU64],
    ext: &Extinction,
    values: &[T],
    passes: &mut StepLists,
) {
    let StepLists {
        found,
        changes,
        parallel_from,
    } = passes;
    let found: &[Found] = found;
    // Emptied, capacity kept, as `lift`'s lists.
    changes.resize_with(found.len(), Changes::default);
    for c in changes.iter_mut() {
        c.values.clear();
        c.bounds = None;
    }
    let parallel = count(found) >= *parallel_from;
    for parity in 0..2 {
        each_of_parity(changes, parity, parallel, |(g, out)| {
            let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
            for &(v, e, first) in raised_in(found, g) {
                let l = v as usize;
                let c = lat.coords(l);
                let ceiling = ext.ceiling(e);
                let mut q = first;
                if first < ceiling {
                    // Raised below its ceiling: later lifts of the step may
                    // have raised it further.
                    q = field[l].load(Relaxed);
                    if ext.may_pump(q, e) {
                        // Neighbours' values after this step's lift: a jump
                        // of another voxel to q_max does not change whether
                        // it is reached, so the order of jumps does not
                        // matter.
                        let mut pump = false;
                        lat.for_each_neighbour(l, c, |n, vn, _| {
                            pump |= ext.pumps(
                                q,
                                e,
                                ext.fixed(values[vn].to_f32()),
                                field[n].load(Relaxed),
                            );
                        });
                        if pump {
                            q = ext.q_max;
                            field[l].store(q, Relaxed);
                        }
                    }
                    // Plain load and store: no other task writes this word
                    // now.
                    let (w, sh) = mark_slot(l);
                    let st = if q >= ceiling { DONE } else { REACHED };
                    let word = states[w].load(Relaxed) & !(3 << sh);
                    states[w].store(word | (st << sh), Relaxed);
                }
                out.values.push((v, q));
                for a in 0..3 {
                    lo[a] = lo[a].min(c[a]);
                    hi[a] = hi[a].max(c[a]);
                }
            }
            if !out.values.is_empty() {
                out.bounds = Some(VoxelBounds {
                    lo: lat.voxel(lo),
                    hi: lat.voxel(hi),
                });
            }
        });
    }
}

/// Buckets frontier entries (box-linear index, value) into the groups of a
/// box of `dims`.
pub(crate) fn group(
    entries: impl IntoIterator<Item = (u32, u16)>,
    dims: [usize; 3],
) -> Vec<Vec<(u32, u16)>> {
    let gs = group_slabs(dims);
    let per_group = dims[0] * dims[1] * gs;
    let mut groups = vec![Vec::new(); dims[2].div_ceil(gs)];
    for (l, q) in entries {
        groups[l as usize / per_group].push((l, q));
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_face_tables_name_the_six_face_neighbours() {
        assert_eq!(IS_FACE.iter().filter(|&&f| f).count(), 6);
        let cell = |d: [isize; 3]| ((d[0] + 1) + 3 * (d[1] + 1) + 9 * (d[2] + 1)) as u32;
        let from_dirs = DIRS
            .iter()
            .zip(IS_FACE)
            .filter(|(_, f)| *f)
            .fold(0u64, |m, (d, _)| m | 1 << (2 * cell(*d)));
        assert_eq!(from_dirs, FACES_EVEN);
        assert_eq!(FACES_EVEN & !CELLS_EVEN, 0);
    }
}
