//! Heterogeneous relaxation: every free element moves towards the weighted
//! mean of its neighbours' optimal positions for it (`w_l = 1 / (c_l + ε)`,
//! so rigid links dominate), by its material's elastic fraction.
//!
//! In displacements the optimal position of `n` for neighbour `e` is `u_e`,
//! and the energy the relaxation lowers (eq. (7)) is
//! `E = Σ_links w_l |u_n − u_e|²`.
//!
//! **Decision:** the sweep is red-black (elements with even `i + j + k`,
//! then odd) and in place, not Jacobi. Same-colour elements share no link,
//! so each half-sweep minimises `E` over its elements exactly in the
//! direction of the weighted mean: moving a fraction `α ≤ 1` of the way to
//! that minimum, then clamping into the intersection of the neighbours'
//! constraint boxes (which holds the current position), never raises `E`
//! and never breaks a constraint. Plain Jacobi does not guarantee either
//! (on a bipartite lattice its checkerboard mode does not decay at α = 1),
//! converges about half as fast, and would need its own copy. Both Jacobi
//! copies are written, so propagation can resume from either.

use crate::blocks::{Blocks, CHANGED, FaceMask};
use crate::lattice::{ABSENT, ElementLattice, FIXED, HELD};
use crate::state::State;
use rayon::prelude::*;

/// What one relaxation sweep did.
#[derive(Clone, Debug, Default)]
pub struct SweepReport {
    /// `(block, face mask)` of the visited blocks whose largest move was at
    /// least the tolerance.
    pub blocks: Vec<(u32, FaceMask)>,
    /// Largest move of an element, as a fraction of the element spacing.
    pub max_move: f64,
}

/// One red-black sweep over `set` (blocks); moves smaller than `tol`
/// (fraction of the element spacing) do not keep a block active.
pub fn sweep(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    set: &[u32],
    tol: f64,
    parallel: bool,
) -> SweepReport {
    let inv = lat.spacing.map(|s| 1.0 / s);
    let mut per_block = vec![(0u32, 0u8, 0f64); set.len()];
    for colour in 0..2 {
        let run = |(slot, &b): (&mut (u32, FaceMask, f64), &u32)| {
            let (lo, hi) = blocks.range(b as usize);
            slot.0 = b;
            let [nx, ny, nz] = lat.dims;
            let (sx, sxy) = (nx, nx * ny);
            for k in lo[2]..hi[2] {
                for j in lo[1]..hi[1] {
                    let inner_row = j > 0 && j + 1 < ny && k > 0 && k + 1 < nz;
                    let start = lo[0] + (lo[0] + j + k + colour) % 2;
                    for i in (start..hi[0]).step_by(2) {
                        let c = [i, j, k];
                        let n = lat.linear(c);
                        let cell = lat.cells[n];
                        if cell & ABSENT == ABSENT || cell & (FIXED | HELD) != 0 {
                            continue;
                        }
                        let nb = if inner_row && i > 0 && i + 1 < nx && lat.cut[n] == 0 {
                            [
                                Some(n + 1),
                                Some(n - 1),
                                Some(n + sx),
                                Some(n - sx),
                                Some(n + sxy),
                                Some(n - sxy),
                            ]
                        } else {
                            [
                                lat.neighbour(n, c, 0),
                                lat.neighbour(n, c, 1),
                                lat.neighbour(n, c, 2),
                                lat.neighbour(n, c, 3),
                                lat.neighbour(n, c, 4),
                                lat.neighbour(n, c, 5),
                            ]
                        };
                        let mv = relax_one(lat, state, n, nb, inv);
                        if mv > 0.0 {
                            if mv >= tol {
                                slot.1 |= CHANGED | Blocks::border(c, lo, hi);
                            }
                            slot.2 = slot.2.max(mv);
                        }
                    }
                }
            }
        };
        if parallel {
            per_block.par_iter_mut().zip(set.par_iter()).for_each(run);
        } else {
            per_block.iter_mut().zip(set.iter()).for_each(run);
        }
    }
    SweepReport {
        max_move: per_block.iter().map(|p| p.2).fold(0.0, f64::max),
        blocks: per_block.into_iter().map(|p| (p.0, p.1)).collect(),
    }
}

/// Relaxes element `n` with neighbour sites `nb` (in `LINKS` order; `None`
/// outside the lattice); returns how far it moved (largest axis, fraction
/// of the spacing).
#[inline]
fn relax_one(
    lat: &ElementLattice,
    state: &State,
    n: usize,
    nb: [Option<usize>; 6],
    inv: [f64; 3],
) -> f64 {
    let cur = state.cur;
    let mut sum = [0f32; 3];
    let mut wsum = 0f32;
    let mut lo = [f32::NEG_INFINITY; 3];
    let mut hi = [f32::INFINITY; 3];
    for e in nb.into_iter().flatten() {
        if !lat.present(e) {
            continue;
        }
        let link = lat.link(n, e);
        let ue = state.get(cur, e);
        for a in 0..3 {
            sum[a] += link.weight * ue[a];
            lo[a] = lo[a].max(ue[a] - link.d[a]);
            hi[a] = hi[a].min(ue[a] + link.d[a]);
        }
        wsum += link.weight;
    }
    if wsum == 0.0 {
        return 0.0;
    }
    let u = state.get(cur, n);
    let alpha = lat.material(n).elastic;
    let mut v = u;
    for a in 0..3 {
        let target = sum[a] / wsum;
        let cand = u[a] + alpha * (target - u[a]);
        if lo[a] <= hi[a] {
            v[a] = cand.max(lo[a]).min(hi[a]);
        }
    }
    if v == u {
        return 0.0;
    }
    for copy in 0..2 {
        state.set(copy, n, v);
    }
    let mut mv = 0f64;
    for a in 0..3 {
        mv = mv.max((v[a] - u[a]).abs() as f64 * inv[a]);
    }
    mv
}

/// The relaxation energy `Σ_links w_l |u_n − u_e|²` of the current state
/// (each link once).
pub fn energy(lat: &ElementLattice, state: &State) -> f64 {
    let cur = state.cur;
    (0..lat.len())
        .into_par_iter()
        .filter(|&n| lat.present(n))
        .map(|n| {
            let c = lat.coords(n);
            let un = state.get(cur, n);
            // +x, +y, +z links only.
            [0, 2, 4]
                .into_iter()
                .filter_map(|l| lat.neighbour(n, c, l))
                .filter(|&e| lat.present(e))
                .map(|e| {
                    let ue = state.get(cur, e);
                    let d2: f64 = (0..3).map(|a| ((un[a] - ue[a]) as f64).powi(2)).sum();
                    lat.link(n, e).weight as f64 * d2
                })
                .sum::<f64>()
        })
        .sum()
}
