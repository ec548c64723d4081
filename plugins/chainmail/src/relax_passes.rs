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

/// The runs of a set of blocks (ascending block indices), grouped by
/// block row, in two flat arrays built once per pass.
pub(crate) struct RunRows {
    runs: Vec<Run>,
    /// Per block row `r`: its runs start at `runs[starts[r].0]` and its
    /// blocks at `set[starts[r].1]`; one more entry closes the last row.
    starts: Vec<(u32, u32)>,
}

impl RunRows {
    /// The runs of `set` (ascending, no repeats: a block row met twice
    /// would get two writers).
    pub(crate) fn new(blocks: &Blocks, set: &[u32]) -> Self {
        debug_assert!(set.windows(2).all(|w| w[0] < w[1]), "set must be ascending");
        let cx = blocks.count[0] as u32;
        let mut runs: Vec<Run> = Vec::new();
        let mut starts = Vec::new();
        let mut last_row = u32::MAX;
        for (i, &b) in set.iter().enumerate() {
            let row = b / cx;
            if row != last_row {
                starts.push((runs.len() as u32, i as u32));
                last_row = row;
                runs.push(Run { first: b, len: 1 });
                continue;
            }
            match runs.last_mut() {
                Some(r) if r.first + r.len == b => r.len += 1,
                _ => runs.push(Run { first: b, len: 1 }),
            }
        }
        starts.push((runs.len() as u32, set.len() as u32));
        Self { runs, starts }
    }

    /// Block rows.
    pub(crate) fn len(&self) -> usize {
        self.starts.len() - 1
    }

    /// The runs of block row `r`.
    pub(crate) fn runs(&self, r: usize) -> &[Run] {
        &self.runs[self.starts[r].0 as usize..self.starts[r + 1].0 as usize]
    }

    /// `per_block` (one entry per block of the set, in its order) split
    /// into the block rows' parts.
    pub(crate) fn split<'a, T>(&self, mut per_block: &'a mut [T]) -> Vec<&'a mut [T]> {
        (0..self.len())
            .map(|r| {
                let n = (self.starts[r + 1].1 - self.starts[r].1) as usize;
                let (row, rest) = std::mem::take(&mut per_block).split_at_mut(n);
                per_block = rest;
                row
            })
            .collect()
    }
}

/// Buffers [`sweep_runs`] keeps between sweeps: each block row's moves
/// over both colours and its largest move.
#[derive(Default)]
pub struct SweepScratch {
    rows: Vec<(BlockRowMoves, f32)>,
    hx: usize,
}

impl SweepScratch {
    /// `rows` cleared accumulators for rows of `hx` slots.
    fn take(&mut self, rows: usize, hx: usize) -> &mut [(BlockRowMoves, f32)] {
        if self.hx != hx {
            self.rows.clear();
            self.hx = hx;
        }
        for (acc, max) in &mut self.rows {
            acc.clear();
            *max = 0.0;
        }
        if self.rows.len() < rows {
            self.rows
                .resize_with(rows, || (BlockRowMoves::new(hx), 0.0));
        }
        &mut self.rows[..rows]
    }
}

/// One red-black sweep over the blocks of `set` (ascending), in parallel
/// and 8 slots at a time; moves smaller than `tol` (fraction of the element
/// spacing) do not keep a block active. `scratch` carries buffers from one
/// sweep to the next.
pub fn sweep_runs(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    set: &[u32],
    tol: f64,
    scratch: &mut SweepScratch,
) -> SweepReport {
    let rows = RunRows::new(blocks, set);
    let mut out: Vec<(u32, FaceMask)> = set.iter().map(|&b| (b, 0)).collect();
    let mut parts = rows.split(&mut out);
    let accs = scratch.take(rows.len(), lat.hx);
    let tol = tol as f32;
    for colour in 0..2 {
        accs.par_iter_mut()
            .zip(parts.par_iter_mut())
            .enumerate()
            .for_each_init(
                || RowMoves::new(lat.hx),
                |moves, (r, ((acc, max), part))| {
                    let runs = rows.runs(r);
                    walk_block_row(lat, blocks, runs, colour, moves, acc, |jk, q, moves| {
                        relax_row(lat, state, colour, jk, q, tol, moves)
                    });
                    if colour == 1 {
                        fold_runs(blocks, runs, acc, part);
                    }
                    *max = max.max(moves.take_max());
                },
            );
    }
    SweepReport {
        max_move: accs.iter().map(|r| r.1 as f64).fold(0.0, f64::max),
        blocks: out,
    }
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
/// (`out`, in the runs' order).
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
