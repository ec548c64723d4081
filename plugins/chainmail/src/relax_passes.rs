//! The parallel model's relaxation pass over the lattice, built on the row
//! kernels of [`crate::relax_lanes`].
//!
//! [`sweep_runs`]: one sweep over the active blocks, grouped into runs
//! along x per block row (one rayon task per block row, so a colour row has
//! one writer). The walk over a block row's colour rows is shared with
//! propagation.

use crate::blocks::{Blocks, FaceMask};
use crate::lattice::ElementLattice;
use crate::relax::SweepReport;
use crate::relax_lanes::relax_row;
use crate::row_moves::{BlockRowMoves, RowMoves, face_bits};
use crate::state::State;
use rayon::prelude::*;

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
