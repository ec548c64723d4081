//! The relaxation of one colour row, 8 slots at a time ([`wide::f32x8`]).
//!
//! In the red-black storage order the six neighbours of 8 consecutive slots
//! are 8 consecutive slots of the other colour (see
//! [`crate::lattice`]), so a window of 8 elements loads its neighbours as
//! 6 vectors per axis. A window takes one of three kernels:
//! - **uniform**: the 8 elements and their 48 neighbours exist, share one
//!   material and no link is cut. Every link has the same weight, so the
//!   weighted mean of `relax_one` is the plain mean of the six.
//! - **masked**: the present elements and neighbours share one material,
//!   but some links are missing (the lattice's faces, absent sites, cut
//!   links). A lane mask per direction drops them from the mean and from the
//!   constraint box; per-lane masks are built from the site bytes with word
//!   arithmetic (no per-lane branches).
//! - **scalar** (`relax_one` per element): materials differ inside the
//!   window, or a neighbour window would leave the arrays.
//!
//! Every kernel writes only the current Jacobi copy and records, per slot,
//! whether the element moved by at least the tolerance ([`RowMoves`]).

use crate::lattice::{ABSENT, ElementLattice, FIXED, HELD, Order, X_FACE};
use crate::relax::{movable, relax_one};
use crate::row_moves::RowMoves;
use crate::state::State;
use std::sync::atomic::AtomicU32;
use wide::f32x8;

/// Relaxes slots `qa..qb` of colour `colour`'s row `(j, k)`, recording
/// their moves (fraction of the spacing) against `tol` in `moves`.
pub fn relax_row(
    lat: &ElementLattice,
    state: &State,
    colour: usize,
    [j, k]: [usize; 2],
    (qa, qb): (usize, usize),
    tol: f32,
    moves: &mut RowMoves,
) {
    let rows = RowBases::new(lat, colour, j, k);
    let inv = lat.spacing.map(|s| (1.0 / s) as f32);
    if lat.hx < 8 {
        for q in qa..qb {
            relax_slot(lat, state, &rows, q, inv, tol, moves);
        }
        return;
    }
    let mut q = qa;
    while q < qb {
        // The last window may start earlier and overlap slots already
        // relaxed: those lanes are masked.
        let w = q.min(lat.hx - 8);
        let lanes = (q - w, (qb - w).min(8));
        relax_window(lat, state, &rows, w, lanes, inv, tol, moves);
        q = w + 8;
    }
}

/// A colour row `(j, k)`: storage index of its slot 0, the storage indices
/// of its six neighbour rows shifted so that slot `q`'s neighbour is at
/// `base + q` (in [`crate::lattice::LINKS`] order; wrapping), and the
/// directions with no neighbour row (the lattice's faces).
pub(crate) struct RowBases {
    /// Storage index of slot 0 of the row.
    pub own: usize,
    /// Storage index (wrapping) that slot 0's neighbour along each link
    /// would have.
    pub nb: [usize; 6],
    /// Bit `l`: no element of this row has a neighbour along link `l`
    /// (for ±x: set only when the lattice is one element wide).
    pub missing: u8,
    /// Row parity: slot `q` holds element `i = 2q + p`.
    pub p: usize,
    /// The row's element indices `(j, k)`.
    pub jk: [usize; 2],
}

impl RowBases {
    /// The six neighbour windows of the window at slot `w`.
    #[inline(always)]
    pub fn window(&self, w: usize) -> [usize; 6] {
        // Written out: array `map` closures are not reliably inlined here.
        let r = &self.nb;
        [
            r[0].wrapping_add(w),
            r[1].wrapping_add(w),
            r[2].wrapping_add(w),
            r[3].wrapping_add(w),
            r[4].wrapping_add(w),
            r[5].wrapping_add(w),
        ]
    }

    /// The material of the 8-slot window at slot `w` when every lane is an
    /// interior element of it ([`ElementLattice::interior`]): all six links
    /// of every lane exist and are uncut, and every neighbour is of it too.
    #[inline(always)]
    pub fn window_material(&self, lat: &ElementLattice, w: usize) -> Option<u8> {
        let x = bytes8(lat.interior(), self.own + w);
        let m = x as u8;
        (m != ABSENT && x == splat_byte(m)).then_some(m)
    }

    /// The material of the 8-slot window at slot `w` when every lane is an
    /// interior element of it, or one but for its link across the
    /// lattice's x faces ([`X_FACE`]).
    #[inline(always)]
    pub fn window_material_x_faces(&self, lat: &ElementLattice, w: usize) -> Option<u8> {
        let x = bytes8(lat.interior(), self.own + w) & !splat_byte(X_FACE);
        let m = x as u8;
        (m != ABSENT && x == splat_byte(m)).then_some(m)
    }

    /// Lanes of the window at slot `w` on the lattice's x faces: element 0
    /// has no −x neighbour and element `nx − 1` no +x neighbour. Returns
    /// `(−x lanes, +x lanes)`.
    #[inline]
    pub fn x_edges(&self, w: usize, nx: usize) -> (u8, u8) {
        let p = self.p;
        let minus = u8::from(w == 0 && p == 0);
        let last = (nx - 1 - p) / 2; // slot of the last element of this parity
        let plus = if (nx - 1 - p).is_multiple_of(2) && last >= w && last < w + 8 {
            1u8 << (last - w)
        } else {
            0
        };
        (minus, plus)
    }

    /// The bases of colour `colour`'s row `(j, k)`.
    pub fn new(lat: &ElementLattice, colour: usize, j: usize, k: usize) -> Self {
        let order: Order = lat.order();
        let [nx, ny, nz] = lat.dims;
        let (own, p) = order.row(colour, j, k);
        let other = 1 - colour;
        let same = order.row(other, j, k).0;
        let row = |j: usize, k: usize| order.row(other, j, k).0;
        let missing = (u8::from(nx == 1) * 0b11)
            | (u8::from(j + 1 == ny) << 2)
            | (u8::from(j == 0) << 3)
            | (u8::from(k + 1 == nz) << 4)
            | (u8::from(k == 0) << 5);
        Self {
            own,
            nb: [
                same + p,
                (same + p).wrapping_sub(1),
                if j + 1 < ny { row(j + 1, k) } else { own },
                if j > 0 { row(j - 1, k) } else { own },
                if k + 1 < nz { row(j, k + 1) } else { own },
                if k > 0 { row(j, k - 1) } else { own },
            ],
            missing,
            p,
            jk: [j, k],
        }
    }
}

/// Relaxes slot `q` of a row one element at a time, if it holds a movable
/// element.
#[inline]
fn relax_slot(
    lat: &ElementLattice,
    state: &State,
    rows: &RowBases,
    q: usize,
    inv: [f32; 3],
    tol: f32,
    moves: &mut RowMoves,
) {
    let n = rows.own + q;
    let i = 2 * q + rows.p;
    if i >= lat.dims[0] || !movable(lat.cells[n]) {
        return;
    }
    let mv = relax_one(lat, state, n, [i, rows.jk[0], rows.jk[1]], inv);
    moves.record(q, mv, tol);
}

/// The 8-slot windows `at .. at + 8` of the three state arrays of one
/// copy, bounds-checked once for all of them (the kernels then load and
/// store without checks).
struct Windows<'a> {
    ptr: [*const AtomicU32; 3],
    _arrays: &'a [Vec<AtomicU32>; 3],
}

impl<'a> Windows<'a> {
    /// `arrays` (of equal length), whose windows at every index of
    /// `starts` must lie inside them.
    #[inline(always)]
    fn new(arrays: &'a [Vec<AtomicU32>; 3], starts: &[usize]) -> Self {
        let end = starts.iter().fold(0, |m, &s| m.max(s.wrapping_add(8)));
        let len = arrays[0].len();
        assert!(
            arrays.iter().all(|a| a.len() == len) && end <= len && starts.iter().all(|&s| s < end),
            "relaxation window outside the state"
        );
        Self {
            ptr: [arrays[0].as_ptr(), arrays[1].as_ptr(), arrays[2].as_ptr()],
            _arrays: arrays,
        }
    }

    /// Loads axis `a`'s window at `at`, one of the checked starts.
    #[inline(always)]
    fn load(&self, a: usize, at: usize) -> f32x8 {
        // SAFETY: `at + 8 <= len` was checked in `new`; `AtomicU32` has the
        // size, alignment and bit validity of `u32`, so 8 of them read as
        // `[f32; 8]`. While a colour is relaxed no thread writes these
        // slots except the one reading them (a colour row has one writer
        // and the other colour is only read), so the plain read does not
        // race.
        f32x8::from(unsafe { std::ptr::read_unaligned(self.ptr[a].add(at) as *const [f32; 8]) })
    }

    /// Stores axis `a`'s window at `at`, one of the checked starts.
    #[inline(always)]
    fn store(&self, a: usize, at: usize, v: f32x8) {
        // SAFETY: as in `load`; `AtomicU32` is an `UnsafeCell`, so writing
        // through a pointer from a shared slice is allowed, and this thread
        // is the only one accessing these slots while it relaxes them.
        unsafe { std::ptr::write_unaligned(self.ptr[a].add(at) as *mut [f32; 8], v.to_array()) }
    }
}

/// Loads 8 consecutive site bytes as one word (lane `l` in byte `l`).
#[inline(always)]
pub(crate) fn bytes8(s: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(s[at..at + 8].try_into().expect("8 bytes"))
}

/// Lanes `from..to` (`from ≤ to ≤ 8`) as bits.
#[inline]
pub(crate) fn lane_range(from: usize, to: usize) -> u8 {
    (((1u16 << to) - 1) & !((1u16 << from) - 1)) as u8
}

/// Every byte of a word set to `b`.
pub(crate) const fn splat_byte(b: u8) -> u64 {
    b as u64 * 0x0101_0101_0101_0101
}

/// Material bits of every byte.
pub(crate) const MAT: u64 = splat_byte(ABSENT);

/// Lane bits (bit `l` for byte `l`) of the non-zero bytes of `x`.
#[inline(always)]
pub(crate) fn nonzero_lanes(x: u64) -> u8 {
    const LOW7: u64 = splat_byte(0x7f);
    let high = (((x & LOW7) + LOW7) | x) & splat_byte(0x80);
    pack_lanes(high >> 7)
}

/// Lane bits of a word whose bytes are each 0 or 1.
#[inline(always)]
fn pack_lanes(ones: u64) -> u8 {
    (ones.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u8
}

/// An all-ones lane.
const ON: f32 = f32::from_bits(u32::MAX);

/// `LANES[m]`: lane `l` all ones where bit `l` of `m` is set.
static LANES: [[f32; 8]; 256] = {
    let mut t = [[0f32; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let mut l = 0;
        while l < 8 {
            if m >> l & 1 == 1 {
                t[m][l] = ON;
            }
            l += 1;
        }
        m += 1;
    }
    t
};

/// The lane mask of bits `m`, loaded from [`LANES`] (building it lane by
/// lane and reading it back as a vector would stall store forwarding).
#[inline(always)]
fn lanes(m: u8) -> f32x8 {
    f32x8::from(LANES[m as usize])
}

/// Relaxes lanes `from..to` of the 8-slot window at slot `w` of a row;
/// records their moves.
#[allow(clippy::too_many_arguments)]
#[inline]
fn relax_window(
    lat: &ElementLattice,
    state: &State,
    rows: &RowBases,
    w: usize,
    (from, to): (usize, usize),
    inv: [f32; 3],
    tol: f32,
    moves: &mut RowMoves,
) {
    let cells = &lat.cells;
    let own = rows.own + w;
    let nb = rows.window(w);
    let range = lane_range(from, to);
    let own_cells = bytes8(cells, own);
    // The common case first, with the fewest checks: 8 free elements of
    // one material, all 48 neighbours there, of that material, uncut.
    if own_cells & splat_byte(FIXED | HELD) == 0
        && let Some(m) = rows.window_material(lat, w)
    {
        uniform_window::<false>(
            lat, state, own, &nb, m, range, [0xff; 2], inv, tol, moves, w,
        );
        return;
    }
    let (minus_x_edge, plus_x_edge) = rows.x_edges(w, lat.dims[0]);
    // The next most common case: the same, but for the lattice's x faces
    // (the first and last windows of every inner row).
    if own_cells & splat_byte(FIXED | HELD) == 0
        && let Some(m) = rows.window_material_x_faces(lat, w)
    {
        let x_links = [!plus_x_edge, !minus_x_edge];
        uniform_window::<true>(lat, state, own, &nb, m, range, x_links, inv, tol, moves, w);
        return;
    }
    let cut = bytes8(&lat.cut, own);
    // Lanes holding an element (padding slots past the row are absent).
    let present = nonzero_lanes((own_cells & MAT) ^ MAT) & range;
    if present == 0 {
        return;
    }
    let m = (own_cells >> (8 * present.trailing_zeros()) & 0x3f) as u8;
    let same_material = nonzero_lanes((own_cells & MAT) ^ splat_byte(m)) & present == 0;
    let free = !nonzero_lanes(own_cells & splat_byte(FIXED | HELD));
    let write = present & free;
    // Per direction: lanes whose link exists, is not cut and reaches a
    // present element of the same material.
    let mut link_lanes = [0u8; 6];
    let mut masked = same_material;
    for (l, ll) in link_lanes.iter_mut().enumerate() {
        if !masked || rows.missing >> l & 1 == 1 {
            continue;
        }
        let e = nb[l];
        if e > lat.len() - 8 {
            // The window would leave the arrays (first and last rows).
            masked = false;
            continue;
        }
        let nbytes = bytes8(cells, e);
        let there = nonzero_lanes((nbytes & MAT) ^ MAT);
        let uncut = !pack_lanes(cut >> l & splat_byte(1));
        let edge = match l {
            0 => plus_x_edge,
            1 => minus_x_edge,
            _ => 0,
        };
        *ll = there & uncut & !edge;
        masked &= nonzero_lanes((nbytes & MAT) ^ splat_byte(m)) & *ll & present == 0;
    }
    if masked {
        masked_window(
            lat,
            state,
            own,
            &nb,
            &link_lanes,
            m,
            write,
            inv,
            tol,
            moves,
            w,
        );
    } else {
        for lane in from..to {
            relax_slot(lat, state, rows, w + lane, inv, tol, moves);
        }
    }
}

/// The uniform kernel: all six neighbours of every lane exist, share
/// material `m` with it, and no link is cut. With `X_FACES`, the ±x links
/// exist only in the lanes `x_links = [+x, −x]` (the window touches the
/// lattice's x faces); the result is then bit-identical to
/// [`masked_window`]'s with those masks, in fewer operations.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn uniform_window<const X_FACES: bool>(
    lat: &ElementLattice,
    state: &State,
    own: usize,
    nb: &[usize; 6],
    m: u8,
    write: u8,
    x_links: [u8; 2],
    inv: [f32; 3],
    tol: f32,
    moves: &mut RowMoves,
    w: usize,
) {
    let link = *lat.material_link(m, m);
    let alpha = f32x8::splat(lat.materials[m as usize].elastic);
    let write_mask = lanes(write);
    let (plus_x, minus_x) = (lanes(x_links[0]), lanes(x_links[1]));
    let inv_count = if X_FACES {
        let four = f32x8::splat(4.0);
        f32x8::ONE / (four + (plus_x & f32x8::ONE) + (minus_x & f32x8::ONE))
    } else {
        f32x8::splat(1.0 / 6.0)
    };
    let cur = &state.u[state.cur];
    let mut mv = f32x8::ZERO;
    let starts = [own, nb[0], nb[1], nb[2], nb[3], nb[4], nb[5]];
    let arr = Windows::new(cur, &starts);
    let (neg, pos) = (f32x8::splat(f32::NEG_INFINITY), f32x8::splat(f32::INFINITY));
    for (a, &inv_a) in inv.iter().enumerate() {
        let u = arr.load(a, own);
        let n0 = arr.load(a, nb[0]);
        let n1 = arr.load(a, nb[1]);
        // Summed in the masked kernel's order, so both round alike.
        let (mut sum, mut lo, mut hi) = if X_FACES {
            (
                (plus_x & n0) + (minus_x & n1),
                plus_x.select(n0, neg).fast_max(minus_x.select(n1, neg)),
                plus_x.select(n0, pos).fast_min(minus_x.select(n1, pos)),
            )
        } else {
            (n0 + n1, n0.fast_max(n1), n0.fast_min(n1))
        };
        for &e in &nb[2..] {
            let v = arr.load(a, e);
            sum += v;
            lo = lo.fast_max(v);
            hi = hi.fast_min(v);
        }
        let d = f32x8::splat(link.d[a]);
        let (lo, hi) = (lo - d, hi + d);
        let cand = u + alpha * (sum * inv_count - u);
        let clamped = cand.fast_max(lo).fast_min(hi);
        let v = (lo.simd_le(hi) & write_mask).select(clamped, u);
        arr.store(a, own, v);
        mv = mv.fast_max((v - u).abs() * f32x8::splat(inv_a));
    }
    let moved = mv.simd_ge(f32x8::splat(tol)).to_bitmask() as u8 & write;
    moves.record8(w, moved, write_mask & mv);
}

/// The masked kernel: lane `i` of direction `l` takes part where bit `i`
/// of `link_lanes[l]` is set; every present element and neighbour has
/// material `m`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn masked_window(
    lat: &ElementLattice,
    state: &State,
    own: usize,
    nb: &[usize; 6],
    link_lanes: &[u8; 6],
    m: u8,
    write: u8,
    inv: [f32; 3],
    tol: f32,
    moves: &mut RowMoves,
    w: usize,
) {
    let link = *lat.material_link(m, m);
    let alpha = f32x8::splat(lat.materials[m as usize].elastic);
    let l = link_lanes;
    let masks = [
        lanes(l[0]),
        lanes(l[1]),
        lanes(l[2]),
        lanes(l[3]),
        lanes(l[4]),
        lanes(l[5]),
    ];
    let count = masks.iter().fold(f32x8::ZERO, |c, &k| c + (k & f32x8::ONE));
    let write_mask = lanes(write) & count.simd_gt(f32x8::ZERO);
    let inv_count = f32x8::ONE / count.fast_max(f32x8::ONE);
    let cur = &state.u[state.cur];
    let mut mv = f32x8::ZERO;
    // Only the directions some lane uses are loaded (and checked).
    let mut starts = [own; 7];
    for l in 0..6 {
        if link_lanes[l] != 0 {
            starts[l + 1] = nb[l];
        }
    }
    let arr = Windows::new(cur, &starts);
    for (a, &inv_a) in inv.iter().enumerate() {
        let u = arr.load(a, own);
        let (mut sum, mut lo, mut hi) = (
            f32x8::ZERO,
            f32x8::splat(f32::NEG_INFINITY),
            f32x8::splat(f32::INFINITY),
        );
        for l in 0..6 {
            if link_lanes[l] == 0 {
                continue;
            }
            let v = arr.load(a, nb[l]);
            sum += masks[l] & v;
            lo = lo.fast_max(masks[l].select(v, f32x8::splat(f32::NEG_INFINITY)));
            hi = hi.fast_min(masks[l].select(v, f32x8::splat(f32::INFINITY)));
        }
        let d = f32x8::splat(link.d[a]);
        let (lo, hi) = (lo - d, hi + d);
        let cand = u + alpha * (sum * inv_count - u);
        let clamped = cand.fast_max(lo).fast_min(hi);
        let v = (lo.simd_le(hi) & write_mask).select(clamped, u);
        arr.store(a, own, v);
        mv = mv.fast_max((v - u).abs() * f32x8::splat(inv_a));
    }
    let moved = mv.simd_ge(f32x8::splat(tol)).to_bitmask() as u8 & write;
    moves.record8(w, moved, write_mask & mv);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lane_bits_from_bytes() {
        assert_eq!(nonzero_lanes(0), 0);
        assert_eq!(nonzero_lanes(0x0100_00ff_0000_8000), 0b1001_0010);
        assert_eq!(nonzero_lanes(u64::MAX), 0xff);
        assert_eq!(pack_lanes(0x0100_0001_0000_0001), 0b1001_0001);
    }
}
