//! Which elements moved, per colour row and per block row, and the block
//! face masks derived from them.
//!
//! A kernel flags the slots of a colour row whose element moved by at least
//! the tolerance in a [`RowMoves`]; the walk over a block row ORs each
//! row's flags into a [`BlockRowMoves`] (per row parity, and per y/z block
//! face the row lies on), which is folded into the blocks' face masks once
//! per block row instead of once per colour row.

use crate::blocks::{CHANGED, FaceMask};
use wide::f32x8;

/// Per slot of a colour row: moved by at least the tolerance (a bit set),
/// and the largest move seen (fraction of the spacing).
#[derive(Clone, Debug, Default)]
pub struct RowMoves {
    bits: Vec<u64>,
    max: f32x8,
}

/// Words of flags for rows of `hx` slots, with a spare word past the last
/// slot's so that [`window`] may always read the word after.
fn words(hx: usize) -> usize {
    hx / 64 + 2
}

/// The flags of slots `a .. a + n` (`1 ≤ n ≤ 64`) of `bits` as the low `n`
/// bits.
#[inline(always)]
fn window(bits: &[u64], a: usize, n: usize) -> u64 {
    let (word, shift) = (a / 64, a % 64);
    let lo = bits[word] >> shift;
    let hi = if shift == 0 {
        0
    } else {
        bits[word + 1] << (64 - shift)
    };
    (lo | hi) & (u64::MAX >> (64 - n))
}

/// True when a slot in `a..b` is flagged in `bits`.
#[inline]
fn any(bits: &[u64], a: usize, b: usize) -> bool {
    (a..b)
        .step_by(64)
        .any(|s| window(bits, s, (b - s).min(64)) != 0)
}

/// True when slot `q` is flagged in `bits`.
#[inline]
fn get(bits: &[u64], q: usize) -> bool {
    bits[q / 64] >> (q % 64) & 1 != 0
}

impl RowMoves {
    /// Empty flags for rows of `hx` slots.
    pub fn new(hx: usize) -> Self {
        Self {
            bits: vec![0; words(hx)],
            max: f32x8::ZERO,
        }
    }

    /// Clears every flag (the largest move is kept).
    #[inline]
    pub fn clear(&mut self) {
        self.bits.fill(0);
    }

    /// Largest move recorded since the last call (or creation); restarts.
    pub fn take_max(&mut self) -> f32 {
        std::mem::take(&mut self.max)
            .to_array()
            .into_iter()
            .fold(0.0, f32::max)
    }

    /// Flags slot `q`.
    #[inline]
    pub fn mark(&mut self, q: usize) {
        self.bits[q / 64] |= 1 << (q % 64);
    }

    /// Records slot `q`'s move `mv` against the tolerance `tol`.
    #[inline]
    pub(crate) fn record(&mut self, q: usize, mv: f32, tol: f32) {
        if mv >= tol {
            self.mark(q);
        }
        self.max = self.max.fast_max(f32x8::splat(mv));
    }

    /// Flags the slots `w + l` for the set bits `l` of `lanes` and records
    /// the window's moves `mv`.
    #[inline]
    pub(crate) fn record8(&mut self, w: usize, lanes: u8, mv: f32x8) {
        let (word, shift) = (w / 64, w % 64);
        self.bits[word] |= (lanes as u64) << shift;
        if shift > 56 {
            self.bits[word + 1] |= (lanes as u64) >> (64 - shift);
        }
        self.max = self.max.fast_max(mv);
    }

    /// True when slot `q` moved by at least the tolerance.
    #[inline]
    pub fn get(&self, q: usize) -> bool {
        get(&self.bits, q)
    }

    /// True when a slot in `a..b` moved by at least the tolerance.
    #[inline]
    pub fn any(&self, a: usize, b: usize) -> bool {
        any(&self.bits, a, b)
    }
}

/// Face bits (`first` for the low face, `first << 1` for the high) of
/// coordinate `c` in the block range `[lo, hi)`.
#[inline]
pub fn face_bits(c: usize, lo: usize, hi: usize, first: u8) -> FaceMask {
    (if c == lo { first } else { 0 }) | (if c + 1 == hi { first << 1 } else { 0 })
}

/// Kinds of row a [`BlockRowMoves`] keeps apart: every row, then the rows
/// on the block's low y, high y, low z and high z faces (face mask bits
/// 2–5).
const KINDS: usize = 5;

/// The moves of the colour rows of one block row, OR-ed per row parity `p`
/// (slot `q` holds element `2q + p`) and per kind of row (see `KINDS`).
#[derive(Clone, Debug)]
pub struct BlockRowMoves {
    words: usize,
    /// `[parity][kind][word]`.
    acc: Vec<u64>,
    any: bool,
}

impl BlockRowMoves {
    /// Nothing moved, for rows of `hx` slots.
    pub fn new(hx: usize) -> Self {
        let words = words(hx);
        Self {
            words,
            acc: vec![0; 2 * KINDS * words],
            any: false,
        }
    }

    /// ORs in the flags of a colour row of parity `p` that lies on the
    /// block faces `yz_faces` (face mask bits 2–5).
    #[inline]
    pub fn add_row(&mut self, row: &RowMoves, p: usize, yz_faces: FaceMask) {
        let w = self.words;
        if row.bits.iter().all(|&b| b == 0) {
            return;
        }
        self.any = true;
        for kind in 0..KINDS {
            if kind == 0 || yz_faces >> (kind + 1) & 1 == 1 {
                let acc = &mut self.acc[(p * KINDS + kind) * w..][..w];
                for (a, &b) in acc.iter_mut().zip(&row.bits) {
                    *a |= b;
                }
            }
        }
    }

    /// The flags of one parity and kind.
    #[inline(always)]
    fn bits(&self, p: usize, kind: usize) -> &[u64] {
        &self.acc[(p * KINDS + kind) * self.words..][..self.words]
    }

    /// Folds the moves into the blocks of x size `sx` that tile
    /// `x0..x_end` (element indices): calls `add(block offset from x0's
    /// block, face mask)` for each of them (0 when nothing moved).
    pub fn fold(&self, x0: usize, sx: usize, x_end: usize, mut add: impl FnMut(usize, FaceMask)) {
        let mut b = 0;
        let mut bx0 = x0;
        while bx0 < x_end {
            let bx1 = (bx0 + sx).min(x_end);
            let mut bits = 0;
            for p in 0..2 {
                if !self.any {
                    break;
                }
                // Slots of parity `p` in [bx0, bx1).
                let (sa, sb) = ((bx0 + 1 - p) / 2, (bx1 + 1 - p) / 2);
                if sb <= sa || !any(self.bits(p, 0), sa, sb) {
                    continue;
                }
                let all = self.bits(p, 0);
                bits |= CHANGED;
                // The x faces' elements, where they have this parity.
                if (bx0 + p).is_multiple_of(2) && get(all, sa) {
                    bits |= 1;
                }
                if (bx1 - 1 + p).is_multiple_of(2) && get(all, sb - 1) {
                    bits |= 2;
                }
                for kind in 1..KINDS {
                    if any(self.bits(p, kind), sa, sb) {
                        bits |= 1 << (kind + 1);
                    }
                }
            }
            add(b, bits);
            b += 1;
            bx0 = bx1;
        }
    }

    /// Forgets every move.
    pub fn clear(&mut self) {
        if self.any {
            self.acc.fill(0);
            self.any = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_windows_and_ranges() {
        let mut r = RowMoves::new(130);
        r.record8(60, 0b1000_0001, f32x8::ZERO);
        assert!(r.get(60) && r.get(67) && !r.get(61));
        assert!(r.any(61, 68) && !r.any(61, 67) && !r.any(0, 60));
        assert_eq!(window(&r.bits, 60, 8), 0b1000_0001);
        assert_eq!(window(&r.bits, 59, 9), 0b1_0000_0010);
        assert_eq!(window(&r.bits, 61, 6), 0);
        assert_eq!(window(&r.bits, 0, 64), 1 << 60);
        assert_eq!(window(&r.bits, 64, 64), 1 << 3);
        r.record(129, 1.0, 0.5);
        assert!(r.any(100, 130) && r.any(0, 130) && !r.any(68, 129));
        assert_eq!(r.take_max(), 1.0);
        assert_eq!(r.take_max(), 0.0);
    }

    /// The face masks of a block row, folded per row (the reference) and
    /// through a [`BlockRowMoves`], agree.
    #[test]
    fn folding_per_block_row_equals_folding_per_row() {
        let (nx, sx, hx) = (37usize, 8, 19);
        let (ylo, yhi, zlo, zhi) = (4, 8, 0, 3);
        let mut seed = 3u64;
        for _ in 0..200 {
            let mut acc = BlockRowMoves::new(hx);
            let mut reference = vec![0u8; nx.div_ceil(sx)];
            for k in zlo..zhi {
                for j in ylo..yhi {
                    for colour in 0..2 {
                        let p = (colour + j + k) & 1;
                        let mut row = RowMoves::new(hx);
                        for q in 0..(nx + 1 - p) / 2 {
                            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
                            if seed >> 60 == 0 {
                                row.mark(q);
                            }
                        }
                        let faces = face_bits(j, ylo, yhi, 1 << 2) | face_bits(k, zlo, zhi, 1 << 4);
                        acc.add_row(&row, p, faces);
                        // Per row: element i moved when its slot is flagged.
                        for i in (p..nx).step_by(2) {
                            if row.get((i - p) / 2) {
                                let b = i / sx;
                                let x = face_bits(i, b * sx, ((b + 1) * sx).min(nx), 1);
                                reference[b] |= CHANGED | faces | x;
                            }
                        }
                    }
                }
            }
            let mut folded = vec![0u8; reference.len()];
            acc.fold(0, sx, nx, |b, bits| folded[b] = bits);
            assert_eq!(folded, reference);
            acc.clear();
            acc.fold(0, sx, nx, |_, bits| assert_eq!(bits, 0));
        }
    }
}
