//! Propagation: move elements until every link constraint holds again.
//!
//! - [`jacobi_iteration`]: one iteration of the parallel timestamp
//!   propagation (Algorithm 1 with Algorithm 2's wavefront counters) over
//!   the active blocks, in one rayon launch. Every element reads the read
//!   copy and writes the write copy (Jacobi). An element takes the move of
//!   the neighbour whose arrival (`key + τ_link`) is the earliest among
//!   those that beat its own key *and* whose constraint box it violates; it
//!   moves to the nearest point of that box and takes the arrival as its
//!   key. Times are integers, so the outcome does not depend on the order
//!   of evaluation; ties go to the first link in [`LINKS`] order.
//! - [`gibson`]: the sequential 3D ChainMail of Gibson (1997): breadth-first
//!   from the moved elements, neighbours in [`LINKS`] order, each element
//!   moved at most once per deformation. The baseline.

use crate::blocks::{Blocks, CHANGED, FaceMask};
use crate::lattice::{ElementLattice, FIXED, HELD, LINKS};
use crate::state::{State, arrival, earlier, wave};
use rayon::prelude::*;
use std::collections::VecDeque;

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

/// One Jacobi iteration over `active` blocks; swaps the state's copies.
pub fn jacobi_iteration(
    lat: &ElementLattice,
    state: &mut State,
    blocks: &Blocks,
    active: &[u32],
) -> IterationReport {
    let rd = state.cur;
    let wr = 1 - rd;
    let st = &*state;
    let results: Vec<(u32, FaceMask, u64, u64)> = active
        .par_iter()
        .map(|&b| {
            let (lo, hi) = blocks.range(b as usize);
            let (mut mask, mut visits, mut updates) = (0u8, 0u64, 0u64);
            for k in lo[2]..hi[2] {
                for j in lo[1]..hi[1] {
                    for i in lo[0]..hi[0] {
                        let c = [i, j, k];
                        let n = lat.linear(c);
                        let cell = lat.cells[n];
                        if !lat.present(n) {
                            continue;
                        }
                        visits += 1;
                        if !pinned(cell)
                            && let Some((e, a)) = sponsor(lat, st, rd, n, c)
                        {
                            let link = lat.link(n, e);
                            st.set(wr, n, link.clamp(st.get(rd, n), st.get(rd, e)));
                            st.set_key(wr, n, a);
                            updates += 1;
                            mask |= CHANGED | Blocks::border(c, lo, hi);
                            continue;
                        }
                        st.carry(rd, n);
                    }
                }
            }
            (b, mask, visits, updates)
        })
        .collect();
    state.cur = wr;
    IterationReport {
        visits: results.iter().map(|r| r.2).sum(),
        updates: results.iter().map(|r| r.3).sum(),
        blocks: results.into_iter().map(|r| (r.0, r.1)).collect(),
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
                if !pinned(lat.cells[n])
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
