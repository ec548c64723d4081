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
//! direction of the weighted mean: moving a fraction `α < 2` of the way to
//! that minimum (`|1 − α| ≤ 1`: the local quadratic does not rise), then
//! clamping into the intersection of the neighbours' constraint boxes
//! (which holds the current position, so the clamped point lies between
//! it and the candidate), never raises `E` and never breaks a constraint.
//! `α` is the material's `elastic` times the over-relaxation factor ω
//! ([`crate::params::ChainMailParams::over_relaxation`]): plain
//! Gauss-Seidel (ω = 1) settles a region `L` elements across in ~`L²`
//! sweeps, over-relaxation with ω near `2 / (1 + sin(π / L))` in ~`L`. Plain Jacobi does not guarantee either
//! (on a bipartite lattice its checkerboard mode does not decay at α = 1),
//! converges about half as fast, and would need its own copy.
//!
//! Only the current copy is written; the model copies the relaxed blocks
//! into the other copy before a two-copy propagation (the GPU's, the
//! frontier schedule's) next runs
//! ([`crate::model::ChainMail`]), instead of writing both on every sweep.
//!
//! Two kinds of sweep share `relax_one`:
//! - [`sweep_scalar`], element by element in block order on one thread:
//!   the sequential baseline's relaxation.
//! - [`crate::relax_passes::sweep_runs`], the parallel model's: 8 elements at a time
//!   ([`crate::relax_lanes`]) over the runs of active blocks
//!   ([`crate::relax_passes`]).

use crate::blocks::{Blocks, CHANGED, FaceMask};
use crate::lattice::{ABSENT, ElementLattice, FIXED, HELD};
use crate::state::State;
use voxflex_core::ordered_reduce::ordered_reduce;

/// What one relaxation sweep did.
#[derive(Clone, Debug, Default)]
pub struct SweepReport {
    /// `(block, face mask)` of the visited blocks whose largest move was at
    /// least the tolerance.
    pub blocks: Vec<(u32, FaceMask)>,
    /// Largest move of an element, as a fraction of the element spacing.
    pub max_move: f64,
}

/// True when site `cell` is an element that relaxation may move.
#[inline]
pub(crate) fn movable(cell: u8) -> bool {
    cell & ABSENT != ABSENT && cell & (FIXED | HELD) == 0
}

/// One red-black sweep over `set` (blocks), element by element on one
/// thread; moves smaller than `tol` (fraction of the element spacing) do
/// not keep a block active.
pub fn sweep_scalar(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    set: &[u32],
    tol: f64,
) -> SweepReport {
    let inv = lat.spacing.map(|s| (1.0 / s) as f32);
    let mut per_block: Vec<(u32, FaceMask, f32)> = set.iter().map(|&b| (b, 0, 0.0)).collect();
    for colour in 0..2 {
        for slot in per_block.iter_mut() {
            let (lo, hi) = blocks.range(slot.0 as usize);
            for k in lo[2]..hi[2] {
                for j in lo[1]..hi[1] {
                    let start = lo[0] + (lo[0] + j + k + colour) % 2;
                    for i in (start..hi[0]).step_by(2) {
                        let c = [i, j, k];
                        let n = lat.linear(c);
                        if !movable(lat.cells[n]) {
                            continue;
                        }
                        let mv = relax_one(lat, state, n, c, inv);
                        if mv as f64 >= tol {
                            slot.1 |= CHANGED | Blocks::border(c, lo, hi);
                        }
                        slot.2 = slot.2.max(mv);
                    }
                }
            }
        }
    }
    SweepReport {
        max_move: per_block.iter().map(|p| p.2 as f64).fold(0.0, f64::max),
        blocks: per_block.into_iter().map(|p| (p.0, p.1)).collect(),
    }
}

/// Relaxes element `n` (coordinates `c`) towards the weighted mean of its
/// neighbours, clamped into their constraint boxes, in the current copy;
/// returns how far it moved (largest axis, fraction of the spacing).
#[inline]
pub(crate) fn relax_one(
    lat: &ElementLattice,
    state: &State,
    n: usize,
    c: [usize; 3],
    inv: [f32; 3],
) -> f32 {
    let cur = state.cur;
    let mut sum = [0f32; 3];
    let mut wsum = 0f32;
    let mut lo = [f32::NEG_INFINITY; 3];
    let mut hi = [f32::INFINITY; 3];
    let off = lat.offsets(c);
    let inner = lat.cut[n] == 0 && (0..3).all(|a| c[a] > 0 && c[a] + 1 < lat.dims[a]);
    for (l, off) in off.into_iter().enumerate() {
        let e = if inner {
            off.wrapping_add(n)
        } else {
            match lat.neighbour(n, c, l) {
                Some(e) => e,
                None => continue,
            }
        };
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
    state.set(cur, n, v);
    let mut mv = 0f32;
    for a in 0..3 {
        mv = mv.max((v[a] - u[a]).abs() * inv[a]);
    }
    mv
}

/// Elements per partial sum of [`energy`].
const ENERGY_CHUNK: usize = 1 << 14;

/// The relaxation energy `Σ_links w_l |u_n − u_e|²` of the current state
/// (each link once), the same bits on any thread count
/// ([`voxflex_core::ordered_reduce`]).
pub fn energy(lat: &ElementLattice, state: &State) -> f64 {
    let cur = state.cur;
    let element = |n: usize| -> f64 {
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
    };
    let part =
        |r: std::ops::Range<usize>| -> f64 { r.filter(|&n| lat.present(n)).map(element).sum() };
    ordered_reduce(lat.len(), ENERGY_CHUNK, true, part, 0.0, |a, b| a + b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ChainMailParams;
    use crate::relax_passes::{RunRows, SweepScratch, sweep_runs};
    use voxflex_core::glam::DVec3;
    use voxflex_core::grid::Grid;
    use voxflex_core::volume::{Volume, VoxelData};

    /// A 37×13×11 lattice (odd `nx`: padding slots) of two materials with
    /// holes, cut links, held and fixed elements, and a random state.
    ///
    /// `clean`: a 34×13×11 lattice (even `nx`) of the same materials with
    /// no hole, cut or flag, where whole rows take the uniform kernel.
    fn setup_with(clean: bool) -> (ElementLattice, Blocks) {
        let dims = if clean { [34, 13, 11] } else { [37, 13, 11] };
        let grid = Grid::new(dims, DVec3::ONE, DVec3::ZERO);
        let mut data = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let r2 = (i as i64 - 25).pow(2) + (j as i64 - 6).pow(2) + (k as i64 - 5).pow(2);
                    data.push(match (r2, (i * 7 + j * 3 + k) % 97) {
                        (_, 0) if !clean => 0, // hole
                        (r2, _) if r2 < 12 => 200,
                        _ => 100,
                    });
                }
            }
        }
        let vol = Volume {
            grid,
            data: VoxelData::U8(data),
        };
        let params = ChainMailParams::from_toml(
            "materials = [{ range = [50, 150], constraint = 0.2, elastic = 0.7 }, \
             { range = [150, 256], constraint = [0.05, 0.1, 0.02], elastic = 1.0 }]",
        )
        .unwrap();
        let mut lat = ElementLattice::new(vol.view(), &params).unwrap();
        if clean {
            return (lat, Blocks::new(dims, [8, 4, 4]));
        }
        for c in [[10, 5, 5], [11, 5, 5], [12, 6, 4], [30, 2, 9]] {
            let n = lat.linear(c);
            lat.cut_link(n, 0);
            lat.cut_link(n, 2);
        }
        for (c, flag) in [([14, 6, 5], HELD), ([3, 3, 3], FIXED), ([20, 7, 6], FIXED)] {
            let n = lat.linear(c);
            lat.cells[n] |= flag;
        }
        (lat, Blocks::new(dims, [8, 4, 4]))
    }

    /// A reproducible pseudo-random state, displacements within ±0.05 mm.
    fn random_state(lat: &ElementLattice) -> State {
        let s = State::new(lat.len());
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        for n in 0..lat.len() {
            let mut v = [0f32; 3];
            for a in v.iter_mut() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *a = ((x >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.1;
            }
            s.set(0, n, v);
        }
        s
    }

    #[test]
    fn vector_sweep_matches_the_scalar_sweep() {
        for clean in [false, true] {
            vector_matches_scalar(clean);
        }
    }

    fn vector_matches_scalar(clean: bool) {
        let (lat, blocks) = setup_with(clean);
        // Two blocks in three, so runs have gaps and windows overlap them.
        let set: Vec<u32> = (0..blocks.len() as u32).filter(|b| b % 3 != 1).collect();
        let (a, b) = (random_state(&lat), random_state(&lat));
        let mut scratch = SweepScratch::default();
        for it in 0..6 {
            let ra = sweep_runs(&lat, &a, &blocks, &set, 1e-3, &mut scratch);
            let rb = sweep_scalar(&lat, &b, &blocks, &set, 1e-3);
            assert_eq!(ra.blocks, rb.blocks, "sweep {it}: block masks differ");
            assert!((ra.max_move - rb.max_move).abs() < 1e-5);
            for n in 0..lat.len() {
                let (ua, ub) = (a.get(0, n), b.get(0, n));
                for k in 0..3 {
                    assert!(
                        (ua[k] - ub[k]).abs() <= 1e-5,
                        "sweep {it}, element {:?}: {ua:?} vs {ub:?}",
                        lat.coords(n)
                    );
                }
            }
        }
        // The sweep moved elements, and never the held, fixed or absent.
        let fresh = random_state(&lat);
        let moved = (0..lat.len()).filter(|&n| a.get(0, n) != fresh.get(0, n));
        assert!(moved.clone().count() > lat.len() / 2);
        assert!(moved.clone().all(|n| movable(lat.cells[n])));
        assert!(moved.into_iter().all(|n| lat.coords(n)[0] < lat.dims[0]));
    }

    #[test]
    fn runs_group_consecutive_blocks_per_block_row() {
        let blocks = Blocks::new([40, 8, 4], [8, 4, 4]); // 5 × 2 × 1 blocks
        let set = [0, 1, 3, 4, 6];
        let rows = RunRows::new(&blocks, &set);
        let shape: Vec<Vec<(u32, u32)>> = (0..rows.len())
            .map(|r| rows.runs(r).iter().map(|r| (r.first, r.len)).collect())
            .collect();
        assert_eq!(shape, vec![vec![(0, 2), (3, 2)], vec![(6, 1)]]);
        // Per-block entries split by block row, in the set's order.
        let mut per_block = set;
        let parts = rows.split(&mut per_block);
        assert_eq!(parts.len(), 2);
        assert_eq!((&*parts[0], &*parts[1]), (&[0, 1, 3, 4][..], &[6][..]));
        assert_eq!(RunRows::new(&blocks, &[]).len(), 0);
    }
}
