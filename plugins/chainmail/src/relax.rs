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
//! converges about half as fast, and would need its own copy.
//!
//! Only the current Jacobi copy is written; the model copies the relaxed
//! blocks into the other copy once, before propagation next runs
//! ([`crate::model::ChainMail`]), instead of writing both on every sweep.
//!
//! Two sweeps share [`relax_one`]:
//! - [`sweep_scalar`], element by element in block order on one thread:
//!   the sequential baseline's relaxation.
//! - [`sweep`], the parallel model's: the active blocks are grouped into
//!   runs along x per block row (one rayon task per block row, so a row of
//!   elements has one writer), and each colour row of a run is relaxed 8
//!   slots at a time ([`wide::f32x8`]; the red-black storage order makes
//!   the neighbours of 8 slots 8 consecutive slots). A window whose 8
//!   elements and their 48 neighbours share one material and no cut link
//!   takes the uniform-link kernel (equal weights, so the weighted mean is
//!   the plain mean); any other window, and the elements on the lattice's
//!   faces, take [`relax_one`].

use crate::blocks::{Blocks, CHANGED, FaceMask};
use crate::lattice::{ABSENT, ElementLattice, FIXED, HELD};
use crate::state::State;
use rayon::prelude::*;
use std::sync::atomic::AtomicU32;
use wide::f32x8;

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
fn movable(cell: u8) -> bool {
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

/// A run of active blocks along x in one block row: blocks
/// `first .. first + len` (block indices, consecutive in x).
#[derive(Clone, Copy, Debug)]
struct Run {
    first: u32,
    len: u32,
}

/// The runs of `set` (ascending block indices), grouped by block row.
fn runs_by_row(blocks: &Blocks, set: &[u32]) -> Vec<Vec<Run>> {
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

/// One red-black sweep over `set` (blocks, ascending), in parallel and 8
/// slots at a time; moves smaller than `tol` (fraction of the element
/// spacing) do not keep a block active.
pub fn sweep(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    set: &[u32],
    tol: f64,
) -> SweepReport {
    debug_assert!(set.windows(2).all(|w| w[0] < w[1]), "set must be ascending");
    let rows = runs_by_row(blocks, set);
    let mut results: Vec<Vec<(u32, FaceMask, f32)>> = rows
        .iter()
        .map(|runs| {
            runs.iter()
                .flat_map(|r| (r.first..r.first + r.len).map(|b| (b, 0, 0.0)))
                .collect()
        })
        .collect();
    let tol = tol as f32;
    for colour in 0..2 {
        rows.par_iter().zip(results.par_iter_mut()).for_each_init(
            Vec::new,
            |scratch, (runs, out)| {
                relax_block_row(lat, state, blocks, runs, colour, tol, scratch, out)
            },
        );
    }
    let results: Vec<(u32, FaceMask, f32)> = results.into_iter().flatten().collect();
    SweepReport {
        max_move: results.iter().map(|p| p.2 as f64).fold(0.0, f64::max),
        blocks: results.into_iter().map(|p| (p.0, p.1)).collect(),
    }
}

/// Relaxes colour `colour` of the runs of one block row; `out` holds
/// `(block, mask, max move)` for the runs' blocks in order.
#[allow(clippy::too_many_arguments)]
fn relax_block_row(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    runs: &[Run],
    colour: usize,
    tol: f32,
    scratch: &mut Vec<f32>,
    out: &mut [(u32, FaceMask, f32)],
) {
    let order = lat.order();
    let [nx, ny, nz] = lat.dims;
    let sx = blocks.size[0];
    let inv = lat.spacing.map(|s| (1.0 / s) as f32);
    let (lo, hi) = blocks.range(runs[0].first as usize);
    scratch.clear();
    scratch.resize(lat.hx, 0.0);
    for k in lo[2]..hi[2] {
        for j in lo[1]..hi[1] {
            let (row, p) = order.row(colour, j, k);
            let inner = j > 0 && j + 1 < ny && k > 0 && k + 1 < nz;
            // Slots whose element has both x neighbours: 1 ≤ 2q + p ≤ nx − 2.
            let (vlo, vhi) = (1 - p, (nx - p) / 2);
            // Inner rows only: the neighbour rows exist.
            let bases = (inner && vhi >= vlo + 8).then(|| RowBases::new(order, colour, j, k));
            let yz_faces = face_bits(j, lo[1], hi[1], 1 << 2) | face_bits(k, lo[2], hi[2], 1 << 4);
            let mut slot = 0;
            for run in runs {
                let x0 = blocks.range(run.first as usize).0[0];
                let x1 = (x0 + run.len as usize * sx).min(nx);
                // Slots of this colour row in [x0, x1).
                let (qa, qb) = ((x0 + 1 - p) / 2, (x1 + 1 - p) / 2);
                scratch[qa..qb].fill(0.0);
                let (mut q, mut q_end) = (qa, qb);
                if let Some(bases) = &bases {
                    // Slots outside [vlo, vhi) go one by one.
                    while q < qb && q < vlo {
                        scratch[q] = relax_slot(lat, state, row, q, p, [j, k], inv);
                        q += 1;
                    }
                    while q_end > q && q_end > vhi {
                        q_end -= 1;
                        scratch[q_end] = relax_slot(lat, state, row, q_end, p, [j, k], inv);
                    }
                    while q < q_end {
                        // The last window may start earlier and overlap
                        // slots already relaxed: those lanes are masked.
                        let w = q.min(vhi - 8);
                        let lanes = (q - w, (q_end - w).min(8));
                        relax_window(lat, state, bases, w, lanes, scratch, inv);
                        q = w + 8;
                    }
                } else {
                    for (q, m) in scratch.iter_mut().enumerate().take(qb).skip(qa) {
                        *m = relax_slot(lat, state, row, q, p, [j, k], inv);
                    }
                }
                // Fold the row's moves into the run's blocks.
                for b in 0..run.len as usize {
                    let bx0 = x0 + b * sx;
                    let bx1 = (bx0 + sx).min(nx);
                    let (sa, sb) = ((bx0 + 1 - p) / 2, (bx1 + 1 - p) / 2);
                    let m = scratch[sa..sb].iter().fold(0f32, |m, &v| m.max(v));
                    let entry = &mut out[slot + b];
                    entry.2 = entry.2.max(m);
                    if m >= tol {
                        let mut bits = CHANGED | yz_faces;
                        if (bx0 + p).is_multiple_of(2) && scratch[(bx0 - p) / 2] >= tol {
                            bits |= 1;
                        }
                        if (bx1 - 1 + p).is_multiple_of(2) && scratch[(bx1 - 1 - p) / 2] >= tol {
                            bits |= 2;
                        }
                        entry.1 |= bits;
                    }
                }
                slot += run.len as usize;
            }
        }
    }
}

/// Face bits (`first` for the low face, `first << 1` for the high) of
/// coordinate `c` in the block range `[lo, hi)`.
#[inline]
fn face_bits(c: usize, lo: usize, hi: usize, first: u8) -> FaceMask {
    (if c == lo { first } else { 0 }) | (if c + 1 == hi { first << 1 } else { 0 })
}

/// Relaxes the element in slot `q` of the colour row starting at `row`
/// (parity `p`, row `(j, k)`), if it is movable; returns its move.
#[inline]
fn relax_slot(
    lat: &ElementLattice,
    state: &State,
    row: usize,
    q: usize,
    p: usize,
    jk: [usize; 2],
    inv: [f32; 3],
) -> f32 {
    let n = row + q;
    let i = 2 * q + p;
    if i >= lat.dims[0] || !movable(lat.cells[n]) {
        return 0.0;
    }
    relax_one(lat, state, n, [i, jk[0], jk[1]], inv)
}

/// Loads 8 consecutive values of a state array as f32.
#[inline(always)]
fn load8(s: &[AtomicU32], at: usize) -> f32x8 {
    let w = &s[at..at + 8];
    // SAFETY: `AtomicU32` has the size, alignment and bit validity of
    // `u32`, so 8 of them read as `[f32; 8]`. During a half-sweep no thread
    // writes these slots except the one reading them (a colour row has one
    // writer, and the other colour is only read), so the plain read does not
    // race.
    f32x8::from(unsafe { std::ptr::read_unaligned(w.as_ptr() as *const [f32; 8]) })
}

/// Stores 8 consecutive values of a state array.
#[inline(always)]
fn store8(s: &[AtomicU32], at: usize, v: f32x8) {
    let w = &s[at..at + 8];
    // SAFETY: as in `load8`; `AtomicU32` is an `UnsafeCell`, so writing
    // through a pointer from a shared slice is allowed, and this thread is
    // the only one accessing these slots in this half-sweep.
    unsafe { std::ptr::write_unaligned(w.as_ptr() as *mut [f32; 8], v.to_array()) }
}

/// Loads 8 consecutive site bytes as one word.
#[inline(always)]
fn bytes8(s: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(s[at..at + 8].try_into().expect("8 bytes"))
}

/// Every byte of a word set to `b`.
const fn splat_byte(b: u8) -> u64 {
    b as u64 * 0x0101_0101_0101_0101
}

/// Storage indices of slot 0 of a colour row `(j, k)` and of its six
/// neighbour rows (in [`crate::lattice::LINKS`] order, shifted so that
/// slot `q`'s neighbour is at `base + q`; wrapping).
struct RowBases {
    own: usize,
    nb: [usize; 6],
    p: usize,
    jk: [usize; 2],
}

impl RowBases {
    fn new(order: crate::lattice::Order, colour: usize, j: usize, k: usize) -> Self {
        let (own, p) = order.row(colour, j, k);
        let other = 1 - colour;
        let same = order.row(other, j, k).0;
        let up = |j: usize, k: usize| order.row(other, j, k).0;
        Self {
            own,
            nb: [
                same + p,
                (same + p).wrapping_sub(1),
                up(j + 1, k),
                up(j - 1, k),
                up(j, k + 1),
                up(j, k - 1),
            ],
            p,
            jk: [j, k],
        }
    }
}

/// Relaxes lanes `from..to` of the 8-slot window at slot `w` of a colour
/// row (an inner row; every slot of the window has all six neighbours);
/// writes the lanes' moves into `moves[w..w + 8]`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn relax_window(
    lat: &ElementLattice,
    state: &State,
    rows: &RowBases,
    w: usize,
    (from, to): (usize, usize),
    moves: &mut [f32],
    inv: [f32; 3],
) {
    let own = rows.own + w;
    let nb = rows.nb.map(|r| r.wrapping_add(w));
    let cells = &lat.cells;
    let own_cells = bytes8(cells, own);
    let m = (own_cells & 0x3f) as u8;
    const MAT: u64 = splat_byte(ABSENT);
    let uniform = m != ABSENT
        && own_cells & MAT == splat_byte(m)
        && bytes8(&lat.cut, own) == 0
        && nb.iter().all(|&e| bytes8(cells, e) & MAT == splat_byte(m));
    if !uniform {
        for lane in from..to {
            moves[w + lane] = relax_slot(lat, state, rows.own, w + lane, rows.p, rows.jk, inv);
        }
        return;
    }
    let link = lat.links[m as usize * lat.materials.len() + m as usize];
    let alpha = f32x8::splat(lat.materials[m as usize].elastic);
    // Lanes to write: inside `from..to` and neither held nor fixed.
    let mut lanes = [0f32; 8];
    for (lane, v) in lanes.iter_mut().enumerate() {
        let flags = (own_cells >> (8 * lane)) as u8 & (FIXED | HELD);
        if lane >= from && lane < to && flags == 0 {
            *v = f32::from_bits(u32::MAX);
        }
    }
    let write = f32x8::from(lanes);
    let sixth = f32x8::splat(1.0 / 6.0);
    let cur = &state.u[state.cur];
    let mut mv = f32x8::ZERO;
    for a in 0..3 {
        let arr = &cur[a];
        let u = load8(arr, own);
        let n0 = load8(arr, nb[0]);
        let (mut sum, mut lo, mut hi) = (n0, n0, n0);
        for &e in &nb[1..] {
            let v = load8(arr, e);
            sum += v;
            lo = lo.max(v);
            hi = hi.min(v);
        }
        let d = f32x8::splat(link.d[a]);
        let (lo, hi) = (lo - d, hi + d);
        let cand = u + alpha * (sum * sixth - u);
        let clamped = cand.max(lo).min(hi);
        let ok = lo.simd_le(hi) & write;
        let v = ok.select(clamped, u);
        store8(arr, own, v);
        mv = mv.max((v - u).abs() * f32x8::splat(inv[a]));
    }
    // Keep the lanes outside `from..to` as they were.
    let prev = f32x8::from(<[f32; 8]>::try_from(&moves[w..w + 8]).expect("8 slots"));
    let mv = write.select(mv, prev);
    moves[w..w + 8].copy_from_slice(&mv.to_array());
}

/// Relaxes element `n` (coordinates `c`) towards the weighted mean of its
/// neighbours, clamped into their constraint boxes, in the current copy;
/// returns how far it moved (largest axis, fraction of the spacing).
#[inline]
fn relax_one(lat: &ElementLattice, state: &State, n: usize, c: [usize; 3], inv: [f32; 3]) -> f32 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ChainMailParams;
    use voxflex_core::glam::DVec3;
    use voxflex_core::grid::Grid;
    use voxflex_core::volume::{Volume, VoxelData};

    /// A 37×13×11 lattice (odd `nx`: padding slots) of two materials with
    /// holes, cut links, held and fixed elements, and a random state.
    fn setup() -> (ElementLattice, Blocks) {
        let dims = [37, 13, 11];
        let grid = Grid::new(dims, DVec3::ONE, DVec3::ZERO);
        let mut data = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let r2 = (i as i64 - 25).pow(2) + (j as i64 - 6).pow(2) + (k as i64 - 5).pow(2);
                    data.push(match (r2, (i * 7 + j * 3 + k) % 97) {
                        (_, 0) => 0, // hole
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
        let (lat, blocks) = setup();
        // Every block but a few, so runs have gaps and windows overlap them.
        let set: Vec<u32> = (0..blocks.len() as u32).filter(|b| b % 7 != 3).collect();
        let (a, b) = (random_state(&lat), random_state(&lat));
        for it in 0..6 {
            let ra = sweep(&lat, &a, &blocks, &set, 1e-3);
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
        let rows = runs_by_row(&blocks, &[0, 1, 3, 4, 6]);
        let shape: Vec<Vec<(u32, u32)>> = rows
            .iter()
            .map(|r| r.iter().map(|r| (r.first, r.len)).collect())
            .collect();
        assert_eq!(shape, vec![vec![(0, 2), (3, 2)], vec![(6, 1)]]);
    }
}
