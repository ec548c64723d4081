//! The capped **Chebyshev distance transform** behind the macro cells' leap
//! distances ([`crate::macrocell::MacroCells::leap_distances`]).
//!
//! For every cell of a `counts[0] × counts[1] × counts[2]` grid (x fastest)
//! the distance, in cells and capped at [`LEAP_CAP`], to the nearest cell
//! that is not empty: `max(|Δx|, |Δy|, |Δz|)`. Three separable passes, as
//! `shaders/raycast/leap.wgsl` computes it one cell per invocation:
//!
//! - along x, the distance to the nearest non-empty cell of the row — one
//!   sweep each way, O(n);
//! - along y, then z, `d(c) = min over |o| < cap of max(|o|, src(c + o e))`:
//!   here whole rows (y) or planes (z) at a time, element by element, so
//!   the loop over the 2 × 15 offsets runs over bytes the compiler packs
//!   32 to an instruction.
//!
//! The WGSL twin tests `o ≥ best` per cell to stop early; the minimum is
//! the same either way (an offset `o ≥ best` gives `max(o, ·) ≥ best`), so
//! the two agree exactly. On the 512 × 512 × 133 CT (64 × 64 × 17 cells)
//! the per-cell form took ~3.3 ms of the CPU frame, this one well under
//! a millisecond (docs/BENCHMARKS.md).

use crate::macrocell::LEAP_CAP;
use rayon::prelude::*;

/// Capped Chebyshev distances from every cell to the nearest cell whose
/// `empty` flag is 0, for a grid of `counts` cells (x fastest).
pub fn chebyshev_distances(empty: &[u8], counts: [usize; 3]) -> Vec<u8> {
    let [cx, cy, cz] = counts;
    assert_eq!(empty.len(), cx * cy * cz, "one flag per cell");
    let mut along_x = vec![0u8; empty.len()];
    along_x
        .par_chunks_mut(cx)
        .zip(empty.par_chunks(cx))
        .for_each(|(out, row)| row_distances(row, out));
    // Along y: lines of `cy` rows of `cx` cells inside each z plane.
    let mut along_y = vec![0u8; empty.len()];
    along_y
        .par_chunks_mut(cx * cy)
        .zip(along_x.par_chunks(cx * cy))
        .for_each(|(out, src)| spread(src, out, cx));
    // Along z: one line of `cz` planes.
    let mut along_z = vec![0u8; empty.len()];
    along_z
        .par_chunks_mut(cx * cy)
        .enumerate()
        .for_each(|(z, out)| spread_row(&along_y, out, cx * cy, cz, z));
    along_z
}

/// Along one row: the distance to the nearest non-empty cell, capped.
fn row_distances(empty: &[u8], out: &mut [u8]) {
    let mut d = LEAP_CAP;
    for (o, &e) in out.iter_mut().zip(empty) {
        d = if e == 0 {
            0
        } else {
            d.saturating_add(1).min(LEAP_CAP)
        };
        *o = d;
    }
    let mut d = LEAP_CAP;
    for (o, &e) in out.iter_mut().zip(empty).rev() {
        d = if e == 0 {
            0
        } else {
            d.saturating_add(1).min(LEAP_CAP)
        };
        *o = (*o).min(d);
    }
}

/// The y pass inside one z plane: `src` and `out` hold rows of `row` cells.
fn spread(src: &[u8], out: &mut [u8], row: usize) {
    let n = src.len() / row.max(1);
    for (i, chunk) in out.chunks_mut(row).enumerate() {
        spread_row(src, chunk, row, n, i);
    }
}

/// `out[e] = min over |o| < min(cap, n) of max(|o|, src[(i + o)·len + e])`
/// (offsets leaving `0..n` skipped), with `src` holding `n` lines of `len`
/// cells.
fn spread_row(src: &[u8], out: &mut [u8], len: usize, n: usize, i: usize) {
    out.fill(LEAP_CAP);
    for o in 0..usize::from(LEAP_CAP).min(n) {
        let floor = o as u8;
        for q in [i.wrapping_sub(o), i + o] {
            if q < n {
                let line = &src[q * len..(q + 1) * len];
                for (b, &v) in out.iter_mut().zip(line) {
                    *b = (*b).min(v.max(floor));
                }
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The definition, cell by cell (also the macro cells' reference).
    pub(crate) fn brute(empty: &[u8], counts: [usize; 3]) -> Vec<u8> {
        let [cx, cy, cz] = counts;
        let full: Vec<[usize; 3]> = (0..empty.len())
            .filter(|&l| empty[l] == 0)
            .map(|l| [l % cx, (l / cx) % cy, l / (cx * cy)])
            .collect();
        let mut out = Vec::with_capacity(empty.len());
        for z in 0..cz {
            for y in 0..cy {
                for x in 0..cx {
                    let d = full
                        .iter()
                        .map(|n| x.abs_diff(n[0]).max(y.abs_diff(n[1])).max(z.abs_diff(n[2])))
                        .min()
                        .unwrap_or(usize::MAX)
                        .min(usize::from(LEAP_CAP));
                    out.push(d as u8);
                }
            }
        }
        out
    }

    /// Sparse and dense patterns, no full cell at all, 1-cell axes and axes
    /// longer than the cap, against the definition.
    #[test]
    fn distances_are_the_capped_chebyshev_distances() {
        for (counts, one_in) in [
            ([70, 9, 40], 900),
            ([37, 41, 5], 97),
            ([5, 6, 7], 3),
            ([1, 1, 30], 11),
            ([50, 1, 1], 13),
            ([12, 12, 12], 0),
            ([1, 1, 1], 1),
        ] {
            let len = counts.iter().product::<usize>();
            let empty: Vec<u8> = (0..len)
                .map(|l| {
                    let h = (l as u32).wrapping_mul(2_654_435_761) >> 7;
                    u8::from(one_in == 0 || !h.is_multiple_of(one_in))
                })
                .collect();
            assert_eq!(
                chebyshev_distances(&empty, counts),
                brute(&empty, counts),
                "{counts:?}, one full cell in {one_in}"
            );
        }
    }
}
