//! Propagation: move elements until every link constraint holds again.
//!
//! - [`jacobi_iteration`]: one iteration of the parallel timestamp
//!   propagation (Algorithm 1 with Algorithm 2's wavefront counters) over
//!   the active blocks, in one rayon launch. Every element reads the
//!   current copy; the moves found are written to it once every element
//!   has read it (Jacobi, with the moves as the second copy: an element
//!   that does not move is not written at all). An element takes the move of
//!   the neighbour whose arrival (`key + τ_link`) is the earliest among
//!   those that beat its own key *and* whose constraint box it violates; it
//!   moves to the nearest point of that box and takes the arrival as its
//!   key. Times are integers, so the outcome does not depend on the order
//!   of evaluation; ties go to the first link in [`LINKS`] order.
//! - [`gibson`]: the sequential 3D ChainMail of Gibson (1997): breadth-first
//!   from the moved elements, neighbours in [`LINKS`] order, each element
//!   moved at most once per deformation. The baseline.

use crate::blocks::{Blocks, FaceMask};
use crate::lattice::{ElementLattice, FIXED, HELD, LINKS};
use crate::relax_lanes::{RowBases, bytes8, lane_range, nonzero_lanes, splat_byte};
use crate::relax_passes::{RunRows, fold_runs, walk_block_row};
use crate::row_moves::{BlockRowMoves, RowMoves};
use crate::state::{MAX_TIME, State, arrival, earlier, wave};
use rayon::prelude::*;
use std::collections::VecDeque;
use std::sync::atomic::AtomicU32;
use wide::{f32x8, u32x8};

/// What one propagation iteration did.
#[derive(Clone, Debug, Default)]
pub struct IterationReport {
    /// `(block, face mask)` of every visited block.
    pub blocks: Vec<(u32, FaceMask)>,
    /// Elements evaluated.
    pub visits: u64,
    /// Elements that moved.
    pub updates: u64,
}

/// Elements that never take a neighbour's move.
#[inline]
fn pinned(cell: u8) -> bool {
    cell & (FIXED | HELD) != 0
}

/// One Jacobi iteration over `active` blocks (ascending), in the current
/// copy only: the other copy is neither read nor written.
///
/// The blocks are grouped into runs along x per block row (one rayon task
/// per block row), and each colour row of a run is scanned 8 slots at a
/// time: a window whose elements and neighbours share one material with no
/// cut link first tests, in vector arithmetic, whether any neighbour's
/// arrival beats an element's key. Far from a wavefront none does, and the
/// window is done without reading a position; otherwise, and in mixed
/// windows, each element runs `sponsor`. Each task lists its moves, and
/// they are written once every task has read the state, so every element
/// sees its neighbours as they were before the iteration.
pub fn jacobi_iteration(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    active: &[u32],
) -> IterationReport {
    let cur = state.cur;
    let rows = RunRows::new(blocks, active);
    let mut out: Vec<(u32, FaceMask)> = active.iter().map(|&b| (b, 0)).collect();
    let found: Vec<((u64, u64), Vec<Move>)> = rows
        .split(&mut out)
        .into_par_iter()
        .enumerate()
        .map_init(
            || (RowMoves::new(lat.hx), BlockRowMoves::new(lat.hx)),
            |(moves, acc), (r, part)| {
                let runs = rows.runs(r);
                let mut counts = (0u64, 0u64);
                let mut found = Vec::new();
                acc.clear();
                for colour in 0..2 {
                    walk_block_row(lat, blocks, runs, colour, moves, acc, |[j, k], q, moves| {
                        let rows = RowBases::new(lat, colour, j, k);
                        let mut row = RowFinds {
                            moves,
                            counts: &mut counts,
                            found: &mut found,
                        };
                        propagate_row(lat, state, cur, &rows, q, &mut row)
                    });
                }
                fold_runs(blocks, runs, acc, part);
                (counts, found)
            },
        )
        .collect();
    found.par_iter().for_each(|(_, moves)| {
        for m in moves {
            state.set(cur, m.n as usize, m.u);
            state.set_key(cur, m.n as usize, m.key);
        }
    });
    let (visits, updates) = found
        .iter()
        .fold((0, 0), |(v, u), ((cv, cu), _)| (v + cv, u + cu));
    IterationReport {
        visits,
        updates,
        blocks: out,
    }
}

/// An element's move found in a Jacobi iteration: storage index, new
/// displacement (mm) and arrival key.
#[derive(Clone, Copy, Debug)]
struct Move {
    n: u32,
    key: u32,
    u: [f32; 3],
}

/// What the scan of one row records: the moved slots, `(visits, updates)`
/// and the moves themselves.
struct RowFinds<'a> {
    moves: &'a mut RowMoves,
    counts: &'a mut (u64, u64),
    found: &'a mut Vec<Move>,
}

impl RowFinds<'_> {
    /// Element `n` in slot `q` of the row moves to `u` with arrival `key`.
    #[inline]
    fn push(&mut self, q: usize, n: usize, u: [f32; 3], key: u32) {
        self.moves.mark(q);
        self.counts.1 += 1;
        self.found.push(Move {
            n: n as u32,
            key,
            u,
        });
    }
}

/// Propagates into slots `qa..qb` of one colour row, recording the moves
/// in `row`.
fn propagate_row(
    lat: &ElementLattice,
    st: &State,
    rd: usize,
    rows: &RowBases,
    (qa, qb): (usize, usize),
    row: &mut RowFinds,
) {
    if lat.hx < 8 {
        for q in qa..qb {
            propagate_slot(lat, st, rd, rows, q, row);
        }
        return;
    }
    let mut q = qa;
    while q < qb {
        // The last window may start earlier and overlap slots already
        // done: those lanes are left alone.
        let w = q.min(lat.hx - 8);
        let (from, to) = (q - w, (qb - w).min(8));
        let range = lane_range(from, to);
        if !uniform_window(lat, st, rd, rows, w, range, row) {
            for lane in from..to {
                propagate_slot(lat, st, rd, rows, w + lane, row);
            }
        }
        q = w + 8;
    }
}

/// One Jacobi step of the 8 lanes of the window at slot `w`, in vector
/// arithmetic, when the window is uniform: one material, every element
/// and every link there and uncut, but for the links that leave the
/// lattice's x faces. Records the moves of the lanes in `range` in `row`
/// and returns true; returns false, recording nothing, for any other
/// window.
///
/// The choice is [`sponsor`]'s, lane-wise: with `rank(k) = k ^ MAX_TIME`
/// (wave in the high bits, reversed time in the low), arrival `a` is
/// [`earlier`] than key `b` exactly when `rank(a) > rank(b)`, so the
/// sponsor is the violated neighbour of largest rank, the first in
/// [`LINKS`] order on ties.
#[allow(clippy::too_many_arguments)]
fn uniform_window(
    lat: &ElementLattice,
    st: &State,
    rd: usize,
    rows: &RowBases,
    w: usize,
    range: u8,
    row: &mut RowFinds,
) -> bool {
    let own = rows.own + w;
    let own_cells = bytes8(&lat.cells, own);
    let nb = rows.window(w);
    // Interior windows, and those on the lattice's x faces with the links
    // that leave it masked off.
    let Some(m) = rows.window_material_x_faces(lat, w) else {
        return false;
    };
    let (minus_x_edge, plus_x_edge) = rows.x_edges(w, lat.dims[0]);
    let off_lattice = [
        u32x8::from(LANE_WORDS[plus_x_edge as usize]),
        u32x8::from(LANE_WORDS[minus_x_edge as usize]),
    ];
    let link = *lat.material_link(m, m);
    let tau = u32x8::splat(link.tau);
    let time = u32x8::splat(MAX_TIME);
    let (keys, u) = (&st.key[rd], &st.u[rd]);
    let kn = load_u32(keys, own);
    let rank_n = kn ^ time;
    let pinned = nonzero_lanes(own_cells & splat_byte(FIXED | HELD));
    // Per link: the lanes whose neighbour's arrival beats their key, from
    // the keys alone. Far from a wavefront no lane has one, and the window
    // is done without reading a position.
    let mut beats = [u32x8::ZERO; 6];
    let mut ranks = [u32x8::ZERO; 6];
    let mut any = u32x8::ZERO;
    for (l, &e) in nb.iter().enumerate() {
        let ke = load_u32(keys, e);
        // `arrival`: reached, and the time does not overflow.
        let mut reached = !ke.simd_eq(u32x8::ZERO) & ((ke & time) + tau).simd_le(time);
        if l < 2 {
            reached &= !off_lattice[l];
        }
        ranks[l] = (ke + tau) ^ time;
        beats[l] = reached & ranks[l].simd_gt(rank_n);
        any |= beats[l];
    }
    row.counts.0 += range.count_ones() as u64;
    if any.to_bitmask() as u8 & range & !pinned == 0 {
        return true;
    }
    // Written out: array `map` closures are not reliably inlined here.
    let un = [
        load_f32(&u[0], own),
        load_f32(&u[1], own),
        load_f32(&u[2], own),
    ];
    let d = [
        f32x8::splat(link.d[0]),
        f32x8::splat(link.d[1]),
        f32x8::splat(link.d[2]),
    ];
    let mut best_rank = u32x8::ZERO;
    let mut best_u = un;
    let mut found = u32x8::ZERO;
    for (l, &e) in nb.iter().enumerate() {
        // A direction no lane's key loses to cannot sponsor: skipped
        // (the links ahead of the wavefront).
        if beats[l].to_bitmask() == 0 {
            continue;
        }
        let rank = ranks[l];
        let ue = [load_f32(&u[0], e), load_f32(&u[1], e), load_f32(&u[2], e)];
        let mut violated = f32x8::ZERO;
        for a in 0..3 {
            violated |= un[a].simd_lt(ue[a] - d[a]) | un[a].simd_gt(ue[a] + d[a]);
        }
        let violated: u32x8 = bytemuck::cast(violated);
        let better = beats[l] & rank.simd_gt(best_rank) & violated;
        best_rank = better.select(rank, best_rank);
        let better_f: f32x8 = bytemuck::cast(better);
        for a in 0..3 {
            best_u[a] = better_f.select(ue[a], best_u[a]);
        }
        found |= better;
    }
    let moved = found.to_bitmask() as u8 & range & !pinned;
    // `Link::clamp` towards the sponsor.
    let v = [0, 1, 2].map(|a| {
        un[a]
            .fast_max(best_u[a] - d[a])
            .fast_min(best_u[a] + d[a])
            .to_array()
    });
    let keys = (best_rank ^ time).to_array();
    for lane in 0..8 {
        if moved >> lane & 1 == 1 {
            let u = [v[0][lane], v[1][lane], v[2][lane]];
            row.push(w + lane, own + lane, u, keys[lane]);
        }
    }
    true
}

/// `LANE_WORDS[m]`: lane `l` all ones where bit `l` of `m` is set.
static LANE_WORDS: [[u32; 8]; 256] = {
    let mut t = [[0u32; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let mut l = 0;
        while l < 8 {
            if m >> l & 1 == 1 {
                t[m][l] = u32::MAX;
            }
            l += 1;
        }
        m += 1;
    }
    t
};

/// Loads 8 consecutive words of a state array.
#[inline(always)]
fn load_u32(s: &[AtomicU32], at: usize) -> u32x8 {
    let w = &s[at..at + 8];
    // SAFETY: `AtomicU32` has the size, alignment and bit validity of
    // `u32`. While a Jacobi iteration scans, no thread writes the state
    // (the moves are written after the scan), so the plain read does not
    // race.
    u32x8::from(unsafe { std::ptr::read_unaligned(w.as_ptr() as *const [u32; 8]) })
}

/// Loads 8 consecutive values of a state array as f32.
#[inline(always)]
fn load_f32(s: &[AtomicU32], at: usize) -> f32x8 {
    bytemuck::cast(load_u32(s, at))
}

/// Propagates into the element in slot `q` of a row, if there is one.
#[inline]
fn propagate_slot(
    lat: &ElementLattice,
    st: &State,
    rd: usize,
    rows: &RowBases,
    q: usize,
    row: &mut RowFinds,
) {
    let n = rows.own + q;
    let c = [2 * q + rows.p, rows.jk[0], rows.jk[1]];
    if c[0] >= lat.dims[0] || !lat.present(n) {
        return;
    }
    row.counts.0 += 1;
    if !pinned(lat.cells[n])
        && let Some((e, a)) = sponsor(lat, st, rd, n, c)
    {
        let link = lat.link(n, e);
        row.push(q, n, link.clamp(st.get(rd, n), st.get(rd, e)), a);
    }
}

/// The neighbour whose move element `n` takes, with the arrival key.
#[inline]
fn sponsor(
    lat: &ElementLattice,
    st: &State,
    rd: usize,
    n: usize,
    c: [usize; 3],
) -> Option<(usize, u32)> {
    let kn = st.key(rd, n);
    let mut best: Option<(usize, u32)> = None;
    let mut un = None;
    let off = lat.offsets(c);
    let [nx, ny, nz] = lat.dims;
    // Links that leave the lattice or were cut, as a bit mask.
    let closed = lat.cut[n]
        | u8::from(c[0] + 1 == nx)
        | u8::from(c[0] == 0) << 1
        | u8::from(c[1] + 1 == ny) << 2
        | u8::from(c[1] == 0) << 3
        | u8::from(c[2] + 1 == nz) << 4
        | u8::from(c[2] == 0) << 5;
    for (l, off) in off.into_iter().enumerate() {
        if closed & (1 << l) != 0 {
            continue;
        }
        let e = off.wrapping_add(n);
        if !lat.present(e) {
            continue;
        }
        let ke = st.key(rd, e);
        if ke == 0 {
            continue;
        }
        let link = lat.link(n, e);
        let Some(a) = arrival(ke, link.tau) else {
            continue;
        };
        if !earlier(a, kn) || best.is_some_and(|(_, b)| !earlier(a, b)) {
            continue;
        }
        let u = *un.get_or_insert_with(|| st.get(rd, n));
        if link.violated(u, st.get(rd, e)) {
            best = Some((e, a));
        }
    }
    best
}

/// Sequential Gibson ChainMail of one deformation (wave `w`) from the
/// already-moved `sources` (their keys set to wave `w`), on the current
/// copy; moved elements are mirrored into the other copy. Returns the
/// number of elements moved.
pub fn gibson(lat: &ElementLattice, state: &State, sources: &[usize], w: u32) -> u64 {
    let cur = state.cur;
    let mut queue: VecDeque<usize> = sources.iter().copied().collect();
    let mut moved = 0u64;
    while let Some(e) = queue.pop_front() {
        let c = lat.coords(e);
        let ue = state.get(cur, e);
        let ke = state.key(cur, e);
        for l in 0..LINKS.len() {
            let Some(n) = lat.neighbour(e, c, l) else {
                continue;
            };
            if !lat.present(n) || pinned(lat.cells[n]) || wave(state.key(cur, n)) == w {
                continue;
            }
            let link = lat.link(n, e);
            let un = state.get(cur, n);
            if link.violated(un, ue) {
                let k = arrival(ke, link.tau).unwrap_or(ke);
                state.set(cur, n, link.clamp(un, ue));
                state.set_key(cur, n, k);
                state.carry(cur, n);
                moved += 1;
                queue.push_back(n);
            }
        }
    }
    moved
}

/// What one frontier iteration did.
#[derive(Clone, Debug, Default)]
pub struct FrontierReport {
    /// Elements that moved (ascending).
    pub updated: Vec<u32>,
    /// Elements evaluated.
    pub visits: u64,
}

/// One Jacobi iteration over an element work-list instead of blocks:
/// `candidates` (ascending, unique) are the elements that moved in the last
/// iteration and their neighbours — the only ones whose sponsor can change.
/// Every candidate writes the write copy (its move, or a copy of its
/// value), so elements outside the list hold equal copies; swaps the
/// state's copies.
pub fn frontier_iteration(
    lat: &ElementLattice,
    state: &mut State,
    candidates: &[u32],
) -> FrontierReport {
    let rd = state.cur;
    let wr = 1 - rd;
    let st = &*state;
    let updated: Vec<u32> = candidates
        .par_chunks(2048)
        .flat_map_iter(|chunk| {
            let mut out = Vec::new();
            for &n in chunk {
                let n = n as usize;
                // A carve may have removed a listed element since the list
                // was made: it has no links (and no material) any more.
                if lat.present(n)
                    && !pinned(lat.cells[n])
                    && let Some((e, a)) = sponsor(lat, st, rd, n, lat.coords(n))
                {
                    let link = lat.link(n, e);
                    st.set(wr, n, link.clamp(st.get(rd, n), st.get(rd, e)));
                    st.set_key(wr, n, a);
                    out.push(n as u32);
                } else {
                    st.carry(rd, n);
                }
            }
            out
        })
        .collect();
    state.cur = wr;
    FrontierReport {
        visits: candidates.len() as u64,
        updated,
    }
}

/// The next work-list: `updated` and their present neighbours, ascending,
/// each once.
pub fn next_frontier(lat: &ElementLattice, updated: &[u32]) -> Vec<u32> {
    let mut next: Vec<u32> = updated
        .par_iter()
        .flat_map_iter(|&n| {
            let n = n as usize;
            let c = lat.coords(n);
            std::iter::once(n as u32).chain(
                (0..LINKS.len())
                    .filter_map(move |l| lat.neighbour(n, c, l))
                    .filter(|&e| lat.present(e))
                    .map(|e| e as u32),
            )
        })
        .collect();
    next.par_sort_unstable();
    next.dedup();
    next
}
