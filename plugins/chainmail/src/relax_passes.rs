//! The parallel model's relaxation passes over the lattice, built on the
//! row kernels of [`crate::relax_lanes`]:
//! - [`sweep_runs`]: one sweep over the active blocks, grouped into runs
//!   along x per block row (one rayon task per block row, so a colour row
//!   has one writer);
//! - [`sweep_dense`]: several sweeps over the whole lattice in one pass
//!   through memory, when most blocks are active.

use crate::blocks::{Blocks, FaceMask};
use crate::lattice::ElementLattice;
use crate::relax::SweepReport;
use crate::relax_lanes::relax_row;
use crate::row_moves::{BlockRowMoves, RowMoves, face_bits};
use crate::state::State;
use rayon::prelude::*;
use std::sync::atomic::AtomicUsize;
use std::sync::atomic::Ordering::{Acquire, Release};

/// A run of active blocks along x in one block row: blocks
/// `first .. first + len` (block indices, consecutive in x).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Run {
    pub first: u32,
    pub len: u32,
}

/// The runs of `set` (ascending block indices), grouped by block row.
pub(crate) fn runs_by_row(blocks: &Blocks, set: &[u32]) -> Vec<Vec<Run>> {
    let cx = blocks.count[0] as u32;
    let mut rows: Vec<Vec<Run>> = Vec::new();
    let mut last_row = u32::MAX;
    for &b in set {
        let row = b / cx;
        if row != last_row {
            rows.push(Vec::new());
            last_row = row;
        }
        let runs = rows.last_mut().expect("pushed above");
        match runs.last_mut() {
            Some(r) if r.first + r.len == b => r.len += 1,
            _ => runs.push(Run { first: b, len: 1 }),
        }
    }
    rows
}

/// One red-black sweep over the blocks of `set` (ascending), in parallel
/// and 8 slots at a time; moves smaller than `tol` (fraction of the element
/// spacing) do not keep a block active.
pub fn sweep_runs(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    set: &[u32],
    tol: f64,
) -> SweepReport {
    debug_assert!(set.windows(2).all(|w| w[0] < w[1]), "set must be ascending");
    let rows = runs_by_row(blocks, set);
    let mut results: Vec<BlockRowSweep> = rows
        .iter()
        .map(|runs| (run_blocks(runs), BlockRowMoves::new(lat.hx), 0.0))
        .collect();
    let tol = tol as f32;
    for colour in 0..2 {
        rows.par_iter()
            .zip(results.par_iter_mut())
            .for_each(|(runs, (out, acc, max))| {
                let mut moves = RowMoves::new(lat.hx);
                walk_block_row(
                    lat,
                    blocks,
                    runs,
                    colour,
                    &mut moves,
                    acc,
                    |jk, q, moves| relax_row(lat, state, colour, jk, q, tol, moves),
                );
                if colour == 1 {
                    fold_runs(blocks, runs, acc, out);
                }
                *max = max.max(moves.take_max());
            });
    }
    SweepReport {
        max_move: results.iter().map(|r| r.2 as f64).fold(0.0, f64::max),
        blocks: results.into_iter().flat_map(|r| r.0).collect(),
    }
}

/// One block row's part of a sweep: its blocks' masks, its moves over both
/// colours, and its largest move.
type BlockRowSweep = (Vec<(u32, FaceMask)>, BlockRowMoves, f32);

/// The blocks of a block row's runs, in order, each with an empty face
/// mask.
pub(crate) fn run_blocks(runs: &[Run]) -> Vec<(u32, FaceMask)> {
    runs.iter()
        .flat_map(|r| (r.first..r.first + r.len).map(|b| (b, 0)))
        .collect()
}

/// Walks colour `colour`'s rows of one block row: for each row `(j, k)`
/// and each run, `row((j, k), slots, moves)` processes the run's slots of
/// that row and flags in `moves` those that changed, which are then OR-ed
/// into `acc`. Shared by relaxation and propagation.
pub(crate) fn walk_block_row(
    lat: &ElementLattice,
    blocks: &Blocks,
    runs: &[Run],
    colour: usize,
    moves: &mut RowMoves,
    acc: &mut BlockRowMoves,
    mut row: impl FnMut([usize; 2], (usize, usize), &mut RowMoves),
) {
    let nx = lat.dims[0];
    let sx = blocks.size[0];
    let (lo, hi) = blocks.range(runs[0].first as usize);
    for k in lo[2]..hi[2] {
        for j in lo[1]..hi[1] {
            let p = (colour + j + k) & 1;
            moves.clear();
            for run in runs {
                let x0 = blocks.range(run.first as usize).0[0];
                let x1 = (x0 + run.len as usize * sx).min(nx);
                // Slots of this colour row in [x0, x1).
                row([j, k], ((x0 + 1 - p) / 2, (x1 + 1 - p) / 2), moves);
            }
            let yz_faces = face_bits(j, lo[1], hi[1], 1 << 2) | face_bits(k, lo[2], hi[2], 1 << 4);
            acc.add_row(moves, p, yz_faces);
        }
    }
}

/// Folds a block row's moves `acc` into the face masks of its runs' blocks
/// (`out`, in [`run_blocks`] order).
pub(crate) fn fold_runs(
    blocks: &Blocks,
    runs: &[Run],
    acc: &BlockRowMoves,
    out: &mut [(u32, FaceMask)],
) {
    let (nx, sx) = (blocks.dims[0], blocks.size[0]);
    let mut slot = 0;
    for run in runs {
        let x0 = blocks.range(run.first as usize).0[0];
        let x1 = (x0 + run.len as usize * sx).min(nx);
        let entries = &mut out[slot..slot + run.len as usize];
        acc.fold(x0, sx, x1, |b, bits| entries[b].1 |= bits);
        slot += run.len as usize;
    }
}

/// `sweeps` red-black sweeps over the whole lattice in one pass through
/// memory (temporal blocking); returns the last sweep's report, every block
/// listed.
///
/// The `2 · sweeps` half-sweeps ("stages": red of sweep 0, black of sweep
/// 0, red of sweep 1, …) walk the z planes as a skewed wavefront: at step
/// `t`, stage `s` relaxes its colour on plane `t − s`. A stage reads the
/// other colour on planes `z − 1 … z + 1`, which stage `s − 1` finished one
/// step earlier and stage `s + 1` has not touched yet, so the result is
/// exactly that of the sweeps one after the other, while a plane stays in
/// cache for all stages. The stages are split into one contiguous group
/// per thread (a pipeline); the first stage of a group waits until the
/// previous group's last stage has finished plane `z + 1` (a release/acquire
/// counter per stage), and no group ever waits on a later one.
pub fn sweep_dense(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    tol: f64,
    sweeps: usize,
) -> SweepReport {
    let stages = 2 * sweeps.max(1);
    let nz = lat.dims[2];
    let threads = rayon::current_num_threads().clamp(1, stages);
    let progress: Vec<AtomicUsize> = (0..stages).map(|_| AtomicUsize::new(0)).collect();
    let tol = tol as f32;
    let plane_blocks = blocks.count[0] * blocks.count[1];
    // Each group's masks (of the last sweep's stages) and largest move.
    let group = |g: usize| -> (Vec<FaceMask>, f32) {
        let first = g * stages / threads;
        let last = (g + 1) * stages / threads;
        let mut masks = vec![0; if last + 2 > stages { blocks.len() } else { 0 }];
        let mut moves = RowMoves::new(lat.hx);
        let mut acc = BlockRowMoves::new(lat.hx);
        let mut max = 0f32;
        for step in 0..nz + (last - first) - 1 {
            for s in first..last {
                let Some(z) = step.checked_sub(s - first).filter(|&z| z < nz) else {
                    continue;
                };
                if s == first && s > 0 {
                    wait_for(&progress[s - 1], (z + 2).min(nz));
                }
                let report = s + 2 >= stages;
                let base = plane_blocks * (z / blocks.size[2]);
                let plane = if report {
                    &mut masks[base..base + plane_blocks]
                } else {
                    &mut []
                };
                dense_plane(
                    lat,
                    state,
                    blocks,
                    s % 2,
                    z,
                    tol,
                    &mut moves,
                    &mut acc,
                    plane,
                );
                let m = moves.take_max();
                if report {
                    max = max.max(m);
                }
                progress[s].store(z + 1, Release);
            }
        }
        (masks, max)
    };
    let results: Vec<(Vec<FaceMask>, f32)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (1..threads)
            .map(|g| {
                let group = &group;
                scope.spawn(move || group(g))
            })
            .collect();
        let mut out = vec![group(0)];
        out.extend(
            handles
                .into_iter()
                .map(|h| h.join().expect("relaxation thread")),
        );
        out
    });
    let mut masks = vec![0; blocks.len()];
    let mut max_move = 0f64;
    for (m, max) in results {
        for (o, b) in masks.iter_mut().zip(m) {
            *o |= b;
        }
        max_move = max_move.max(max as f64);
    }
    SweepReport {
        blocks: masks
            .into_iter()
            .enumerate()
            .map(|(b, m)| (b as u32, m))
            .collect(),
        max_move,
    }
}

/// Spins, then yields, until `counter` reaches `need`.
fn wait_for(counter: &AtomicUsize, need: usize) {
    let mut spins = 0u32;
    while counter.load(Acquire) < need {
        spins += 1;
        if spins < 1 << 10 {
            std::hint::spin_loop();
        } else {
            std::thread::yield_now();
        }
    }
}

/// Relaxes colour `colour` on the whole plane `z`; ORs the face masks of
/// the plane's blocks (x fastest, then y) into `plane` unless it is empty.
#[allow(clippy::too_many_arguments)]
fn dense_plane(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    colour: usize,
    z: usize,
    tol: f32,
    moves: &mut RowMoves,
    acc: &mut BlockRowMoves,
    plane: &mut [FaceMask],
) {
    let [nx, ny, nz] = lat.dims;
    let [sx, sy, sz] = blocks.size;
    let cx = blocks.count[0];
    let zlo = (z / sz) * sz;
    let z_faces = face_bits(z, zlo, (zlo + sz).min(nz), 1 << 4);
    for j in 0..ny {
        let p = (colour + j + z) & 1;
        moves.clear();
        relax_row(
            lat,
            state,
            colour,
            [j, z],
            (0, (nx + 1 - p) / 2),
            tol,
            moves,
        );
        if !plane.is_empty() {
            let (by, ylo) = (j / sy, (j / sy) * sy);
            let yhi = (ylo + sy).min(ny);
            acc.add_row(moves, p, z_faces | face_bits(j, ylo, yhi, 1 << 2));
            if j + 1 == yhi {
                // The block row's last row: fold it.
                let row = &mut plane[cx * by..cx * (by + 1)];
                acc.fold(0, sx, nx, |b, bits| row[b] |= bits);
                acc.clear();
            }
        }
    }
}
