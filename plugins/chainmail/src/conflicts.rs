//! Conflicting constraints: the link violations propagation cannot undo.
//!
//! Propagation restores every link constraint `|u_n − u_e|_a ≤ D_a` it can
//! (tested), but it never moves a fixed or held element. When a grab pulls
//! a rigid piece (or any tissue) further than the slack between it and a
//! fixed region, or two grabs pull apart, the links between them cannot all
//! hold: the model tears there. Relaxation never raises a link's violation
//! (it moves an element only into the intersection of its neighbours'
//! boxes), so violations can only grow while propagation runs; the model
//! measures them when propagation has settled after running ([`Conflicts`]),
//! reports the largest (`max_constraint_violation_mm` in `metrics.json`)
//! and warns when it exceeds [`TOLERANCE`].
//!
//! Violations between two free elements are not conflicts: arrival times
//! are whole ticks, so in a heterogeneous lattice two paths can tie or
//! swap order against their exact slacks, and a wave can settle with an
//! element that took its move from one neighbour still outside the box of
//! another reached as early. [`Conflicts::repair_seeds`] names, for each
//! such link, the end reached first; the model starts a repair wave from
//! them (see `ChainMail::start_repair_wave`) so that every link that can
//! hold does.
//!
//! The measure is incremental: each block owns the +x, +y and +z links of
//! its elements and keeps its largest violation; a check recomputes only
//! the blocks changed since the last one (and their −x, −y, −z neighbours,
//! which own the links into them).

use crate::blocks::Blocks;
use crate::lattice::{ABSENT, ElementLattice, FIXED, HELD, X_FACE};
use crate::state::State;
use rayon::prelude::*;

/// Violations up to this fraction of the element spacing are f32 rounding
/// (a clamped displacement of 100 mm is exact to ~1e-5 mm), not conflicts:
/// 1e-3 of the spacing (1 µm at 1 mm elements).
pub const TOLERANCE: f64 = 1e-3;

/// What kinds of constraint meet at violated links (bits).
pub type Kinds = u8;
/// A violated link has a fixed end (`fix`).
pub const FIXED_END: Kinds = 1;
/// A grab is involved: a violated link has a held end, or (set by the
/// model) grabs were held when the violation was measured — only a grab
/// moves elements, so it is what pulled the links apart.
pub const HELD_END: Kinds = 2;
/// A violated link has an end of rigid material (constraint 0).
pub const RIGID_END: Kinds = 4;

/// The words for a set of [`Kinds`], e.g. "fixed vs grab vs rigid".
pub fn describe(kinds: Kinds) -> String {
    let mut parts = Vec::new();
    for (bit, name) in [
        (FIXED_END, "fixed"),
        (HELD_END, "grab"),
        (RIGID_END, "rigid"),
    ] {
        if kinds & bit != 0 {
            parts.push(name);
        }
    }
    if parts.is_empty() {
        "elastic vs elastic (two pulls apart)".into()
    } else {
        parts.join(" vs ")
    }
}

/// The violated links of a block, or of the whole model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Violation {
    /// Largest violation, mm (0 when every link holds).
    pub mm: f32,
    /// The link's two elements (storage indices) for the largest.
    pub link: (u32, u32),
    /// Links violated by more than [`TOLERANCE`].
    pub count: u32,
    /// What meets at those links.
    pub kinds: Kinds,
}

impl Violation {
    fn merge(mut self, o: Violation) -> Violation {
        if o.mm > self.mm {
            self.mm = o.mm;
            self.link = o.link;
        }
        self.count += o.count;
        self.kinds |= o.kinds;
        self
    }
}

/// Per-block violations, kept up to date by [`Conflicts::check`].
pub struct Conflicts {
    per_block: Vec<Violation>,
    stale: Vec<bool>,
    stale_list: Vec<u32>,
}

impl Conflicts {
    /// Every block stale (nothing measured yet).
    pub fn new(blocks: &Blocks) -> Self {
        Self {
            per_block: vec![Violation::default(); blocks.len()],
            stale: vec![true; blocks.len()],
            stale_list: (0..blocks.len() as u32).collect(),
        }
    }

    /// Marks block `b` changed since the last check.
    #[inline]
    pub fn mark(&mut self, b: usize) {
        if !std::mem::replace(&mut self.stale[b], true) {
            self.stale_list.push(b as u32);
        }
    }

    /// Re-measures the stale blocks (and the −x, −y, −z neighbours that own
    /// links into them) on the current copy and returns the whole model's
    /// violation. `tol_mm` is [`TOLERANCE`] in mm.
    pub fn check(
        &mut self,
        lat: &ElementLattice,
        state: &State,
        blocks: &Blocks,
        tol_mm: f32,
    ) -> Violation {
        let [cx, cy, _] = blocks.count;
        let mut list = std::mem::take(&mut self.stale_list);
        let direct = list.len();
        for i in 0..direct {
            let b = list[i] as usize;
            let c = [b % cx, (b / cx) % cy, b / (cx * cy)];
            for (a, stride) in [1, cx, cx * cy].into_iter().enumerate() {
                if c[a] > 0 && !std::mem::replace(&mut self.stale[b - stride], true) {
                    list.push((b - stride) as u32);
                }
            }
        }
        let measured: Vec<Violation> = list
            .par_iter()
            .map(|&b| block_violation(lat, state, blocks, b as usize, tol_mm))
            .collect();
        for (&b, v) in list.iter().zip(measured) {
            self.per_block[b as usize] = v;
            self.stale[b as usize] = false;
        }
        list.clear();
        self.stale_list = list;
        self.per_block
            .iter()
            .copied()
            .fold(Violation::default(), Violation::merge)
    }
}

impl Conflicts {
    /// After [`Conflicts::check`]: for every violated link (more than
    /// `tol_mm`) whose two ends are free (neither fixed nor held), the end
    /// with the earlier arrival key (the older wave, or the earlier time in
    /// one wave) — the one the other end should have followed. Storage
    /// indices, ascending, no repeats.
    pub fn repair_seeds(
        &self,
        lat: &ElementLattice,
        state: &State,
        blocks: &Blocks,
        tol_mm: f32,
    ) -> Vec<u32> {
        let violated: Vec<usize> = (0..self.per_block.len())
            .filter(|&b| self.per_block[b].count > 0)
            .collect();
        let mut seeds: Vec<u32> = violated
            .par_iter()
            .flat_map_iter(|&b| block_repair_seeds(lat, state, blocks, b, tol_mm))
            .collect();
        seeds.sort_unstable();
        seeds.dedup();
        seeds
    }
}

/// Calls `f(n, e, worst)` for every link block `b` owns (its elements'
/// +x, +y, +z links between present elements), elements in `(k, j, i)`
/// order and their links in that order, on the current copy: `worst` is the largest `|u_n − u_e|_a − D_a` over the
/// axes, mm.
fn for_each_owned_link(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    b: usize,
    mut f: impl FnMut(usize, usize, f32),
) {
    let cur = state.cur;
    let worst = |un: [f32; 3], ue: [f32; 3], d: [f32; 3]| {
        (0..3)
            .map(|a| (un[a] - ue[a]).abs() - d[a])
            .fold(f32::NEG_INFINITY, f32::max)
    };
    let interior = lat.interior();
    let (lo, hi) = blocks.range(b);
    for k in lo[2]..hi[2] {
        for j in lo[1]..hi[1] {
            for i in lo[0]..hi[0] {
                let c = [i, j, k];
                let n = lat.linear(c);
                let un = state.get(cur, n);
                let m = interior[n];
                if m != ABSENT && m & X_FACE == 0 {
                    // Every link there, uncut, to the same material.
                    let d = lat.material_link(m, m).d;
                    let off = lat.offsets(c);
                    for l in [0, 2, 4] {
                        let e = off[l].wrapping_add(n);
                        f(n, e, worst(un, state.get(cur, e), d));
                    }
                    continue;
                }
                if !lat.present(n) {
                    continue;
                }
                for l in [0, 2, 4] {
                    if let Some(e) = lat.neighbour(n, c, l).filter(|&e| lat.present(e)) {
                        f(n, e, worst(un, state.get(cur, e), lat.link(n, e).d));
                    }
                }
            }
        }
    }
}

/// [`Conflicts::repair_seeds`] of block `b`.
fn block_repair_seeds(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    b: usize,
    tol_mm: f32,
) -> Vec<u32> {
    let free = |n: usize| lat.cells[n] & (FIXED | HELD) == 0;
    let cur = state.cur;
    let mut seeds = Vec::new();
    for_each_owned_link(lat, state, blocks, b, |n, e, worst| {
        if worst > tol_mm && free(n) && free(e) {
            // Keys order by wave, then time: the smaller was reached first.
            seeds.push(if state.key(cur, e) < state.key(cur, n) {
                e
            } else {
                n
            } as u32);
        }
    });
    seeds
}

/// The violation of the links block `b` owns (its elements' +x, +y, +z
/// links), on the current copy.
fn block_violation(
    lat: &ElementLattice,
    state: &State,
    blocks: &Blocks,
    b: usize,
    tol_mm: f32,
) -> Violation {
    let mut v = Violation::default();
    for_each_owned_link(lat, state, blocks, b, |n, e, worst| {
        if worst > v.mm {
            v.mm = worst;
            v.link = (n as u32, e as u32);
        }
        if worst > tol_mm {
            v.count += 1;
            v.kinds |= kinds_of(lat, n) | kinds_of(lat, e);
        }
    });
    v
}

/// The constraint kinds element `n` brings to a link.
fn kinds_of(lat: &ElementLattice, n: usize) -> Kinds {
    let cell = lat.cells[n];
    let mut k = 0;
    if cell & FIXED != 0 {
        k |= FIXED_END;
    }
    if cell & HELD != 0 {
        k |= HELD_END;
    }
    if lat.material(n).d == [0.0; 3] {
        k |= RIGID_END;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::LINKS;
    use crate::tests::{params, volume};

    /// The owned links and their violations, by the fast interior path and
    /// the general one, against every +x, +y, +z link found one element at
    /// a time: two materials, holes, cut links, the lattice's faces, odd
    /// `nx`, a pseudo-random state.
    #[test]
    fn owned_links_are_every_forward_link_once_with_its_violation() {
        let v = volume([13, 9, 7], |i, j, k| match (i * 5 + j * 3 + k) % 23 {
            0 => 0,
            r if r < 6 => 200,
            _ => 100,
        });
        let mats = "{ range = [50, 150], constraint = 0.2 }, \
                    { range = [150, 256], constraint = [0.05, 0.1, 0.02] }";
        let mut lat = ElementLattice::new(v.view(), &params("", mats)).unwrap();
        for (c, l) in [
            ([4, 4, 3], 0),
            ([6, 2, 2], 2),
            ([6, 2, 2], 5),
            ([12, 8, 6], 1),
        ] {
            let n = lat.linear(c);
            lat.cut_link(n, l);
        }
        let state = State::new(lat.len());
        let mut x = 0x2545_f491_4f6c_dd1du64;
        for n in 0..lat.len() {
            let mut u = [0f32; 3];
            for a in &mut u {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                *a = (x >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
            }
            state.set(state.cur, n, u);
        }
        let blocks = Blocks::new(lat.dims, [4, 4, 4]);
        let mut got = Vec::new();
        for b in 0..blocks.len() {
            for_each_owned_link(&lat, &state, &blocks, b, |n, e, w| got.push((n, e, w)));
        }
        let mut want = Vec::new();
        for n in (0..lat.len()).filter(|&n| lat.present(n)) {
            let c = lat.coords(n);
            for l in (0..LINKS.len()).filter(|l| LINKS[*l].1 > 0) {
                if let Some(e) = lat.neighbour(n, c, l).filter(|&e| lat.present(e)) {
                    let (un, ue, d) = (state.get(0, n), state.get(0, e), lat.link(n, e).d);
                    let w = (0..3)
                        .map(|a| (un[a] - ue[a]).abs() - d[a])
                        .fold(f32::MIN, f32::max);
                    want.push((n, e, w));
                }
            }
        }
        let interior = (0..lat.len())
            .filter(|&n| lat.interior()[n] & X_FACE == 0 && lat.interior()[n] != ABSENT);
        assert!(interior.count() > 50, "the fast path is exercised");
        got.sort_by_key(|t| (t.0, t.1));
        want.sort_by_key(|t| (t.0, t.1));
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert_eq!((g.0, g.1), (w.0, w.1));
            assert_eq!(g.2.to_bits(), w.2.to_bits(), "link {:?}", (g.0, g.1));
        }
    }
}
