//! [`VisibleCells`]: per cell (trilinear footprint), whether the transfer
//! function may show any value inside it — the CPU path's empty-space
//! skipping below the macro cells.
//!
//! A macro cell is 8³ cells; one that holds a single visible voxel is
//! sampled everywhere, and on the `ct-bone` head three in four of those
//! samples lie in soft tissue next to bone and come out with κ = 0 (a
//! trilinear fetch of eight voxels, mostly cache misses, for nothing). A
//! trilinear value lies between the smallest and the largest of its cell's
//! eight corners (to a rounding), so a cell whose corners' table entries
//! all lie more than one entry outside the visible range
//! ([`crate::transfer::Lut::entries_may_show`]) can only give κ = 0: its
//! samples are skipped without reading the volume. The images do not
//! change, bit for bit; only the count of samples taken does.
//!
//! One bit per cell, 512 per 8³-cell brick (one cache line), built per
//! brick the first time a sample reaches it ([`LazyBricks`]): separable
//! min/max passes over the brick's 9³ corner voxels' table entries, and
//! the same or-ed over its aligned 2³ and 4³ blocks of cells, so a ray in
//! a hidden cell can jump past the largest hidden block around it
//! ([`VisibleCells::hidden_block`]). The
//! bits depend on the volume and on the table, so the renderer drops the
//! bricks a volume update reaches ([`VisibleCells::invalidate`]) and
//! starts over when the table changes. Not used with tricubic sampling
//! (its footprint is 4³ voxels) nor when empty-space skipping is off.

use crate::lazy_bricks::{BRICK, CellPlace, LazyBricks, Reach};
use crate::macrocell::IndexBox;
use crate::transfer::Lut;
use std::sync::OnceLock;
use voxflex_core::volume::Sample;

/// Corner voxels per brick edge.
const SIDE: usize = BRICK + 1;

/// A brick's cells read their own corners only.
const REACH: Reach = Reach {
    before: 0,
    after: 0,
};

/// One bit per cell of a brick: word `lz`, bit `lx + 8 ly`.
type Bits = [u64; BRICK];

/// One brick: its bits, the same or-ed over aligned blocks of 2³ cells
/// (bit `bx + 4 (by + 4 bz)`, `b = local / 2`) and of 4³ cells (bit
/// `bx + 2 (by + 2 bz)`, `b = local / 4`), and the box (local cell
/// indices, inclusive) of the cells whose bit is set (`None`: none is).
#[derive(Clone, Copy)]
struct Brick {
    bits: Bits,
    blocks2: u64,
    blocks4: u8,
    shown: Option<[[u8; 3]; 2]>,
}

/// Which cells of a volume the current transfer function may show, per
/// brick, built on first use.
pub struct VisibleCells {
    bricks: LazyBricks<Brick, BRICK>,
    /// The table's [`Lut::show_window`], found with the first brick.
    window: OnceLock<(f32, f32)>,
}

impl VisibleCells {
    /// Nothing built yet, for a volume of `dims` voxels.
    pub fn new(dims: [usize; 3]) -> Self {
        Self {
            // Room for every brick: none is ever left to the caller.
            bricks: LazyBricks::new(dims, usize::MAX),
            window: OnceLock::new(),
        }
    }

    /// The volume size (voxels).
    pub fn dims(&self) -> [usize; 3] {
        self.bricks.dims()
    }

    /// Drops every brick with a corner voxel in `region`.
    pub fn invalidate(&mut self, region: IndexBox) {
        self.bricks.invalidate(region, REACH);
    }

    /// False only when every trilinear value in the cell whose lower corner
    /// is voxel `i` has κ = 0 under `lut` (`values`: the volume, x fastest;
    /// `lut`: the table this cache was made for).
    #[inline(always)]
    pub fn may_show<T: Sample>(&self, values: &[T], lut: &Lut, i: [usize; 3]) -> bool {
        let place = self.bricks.place(i);
        let brick = self.brick(values, lut, &place);
        let [lx, ly, lz] = place.local;
        brick.bits[lz] >> (lx + BRICK * ly) & 1 != 0
    }

    /// 0 when the cell whose lower corner is voxel `i` may show (as
    /// [`VisibleCells::may_show`]); else the edge, in cells, of the largest
    /// block of its brick that holds it, is aligned to that edge (8, 4, 2
    /// or 1: the brick, an octant, …) and shows nothing. A ray may pass
    /// such a block without sampling it.
    #[inline(always)]
    pub fn hidden_block<T: Sample>(&self, values: &[T], lut: &Lut, i: [usize; 3]) -> usize {
        let place = self.bricks.place(i);
        let brick = self.brick(values, lut, &place);
        let [lx, ly, lz] = place.local;
        if brick.bits[lz] >> (lx + BRICK * ly) & 1 != 0 {
            0
        } else if brick.blocks2 >> (lx / 2 + 4 * (ly / 2 + 4 * (lz / 2))) & 1 != 0 {
            1
        } else if brick.blocks4 >> (lx / 4 + 2 * (ly / 4 + 2 * (lz / 4))) & 1 != 0 {
            2
        } else if brick.shown.is_some() {
            4
        } else {
            BRICK
        }
    }

    /// The box of the cells (lower-corner voxel indices, inclusive) of brick
    /// `b` that the table may show; `None` when it shows none. Builds the
    /// brick if needed (arguments as [`VisibleCells::may_show`]).
    pub fn shown_cells<T: Sample>(
        &self,
        values: &[T],
        lut: &Lut,
        b: [usize; 3],
    ) -> Option<IndexBox> {
        let place = self.bricks.place(b.map(|b| b * BRICK));
        let [lo, hi] = self.brick(values, lut, &place).shown?;
        // A partial brick's cells past the grid repeat its last voxels:
        // clipped to the last cell, `max(n, 2) − 2`.
        let last = self.dims().map(|n| n.max(2) - 2);
        let cells = IndexBox {
            lo: std::array::from_fn(|a| (b[a] * BRICK + lo[a] as usize).min(last[a])),
            hi: std::array::from_fn(|a| (b[a] * BRICK + hi[a] as usize).min(last[a])),
        };
        Some(cells)
    }

    #[inline(always)]
    fn brick<T: Sample>(&self, values: &[T], lut: &Lut, place: &CellPlace) -> &Brick {
        let brick = self.bricks.get_or_build(place, |b| {
            let window = *self.window.get_or_init(|| lut.show_window());
            let bits = brick_bits(values, self.bricks.dims(), window, b);
            let (blocks2, blocks4) = blocks(&bits);
            Brick {
                shown: shown_box(&bits),
                bits,
                blocks2,
                blocks4,
            }
        });
        brick.expect("the pool has room for every brick")
    }
}

/// The bits or-ed over aligned blocks of 2³ cells (`bx + 4 (by + 4 bz)`)
/// and of 4³ cells (`bx + 2 (by + 2 bz)`): a word's 8 × 8 layer or-ed
/// with the next layer, with the next row (8 bits up) and the next
/// column, leaves each 2³ block's answer at its even (x, y) bit.
fn blocks(bits: &Bits) -> (u64, u8) {
    let mut b2 = 0u64;
    for m in 0..BRICK / 2 {
        let w = bits[2 * m] | bits[2 * m + 1];
        let w = w | w >> BRICK;
        let w = w | w >> 1;
        for q in 0..16 {
            let (x, y) = (q % 4, q / 4);
            b2 |= (w >> (2 * x + 2 * BRICK * y) & 1) << (q + 16 * m);
        }
    }
    let mut b4 = 0u8;
    for q in 0..8 {
        let (x, y, z) = (q % 2, q / 2 % 2, q / 4);
        // The 2³ blocks (2x + dx, 2y + dy, 2z + dz) of 4³ block (x, y, z).
        let mut any = 0u64;
        for d in 0..8 {
            let (dx, dy, dz) = (d % 2, d / 2 % 2, d / 4);
            any |= b2 >> (2 * x + dx + 4 * (2 * y + dy + 4 * (2 * z + dz))) & 1;
        }
        b4 |= (any as u8) << q;
    }
    (b2, b4)
}

/// The box of the set bits: z from the non-zero words, y from their
/// non-zero bytes, x from the bits of all bytes together.
fn shown_box(bits: &Bits) -> Option<[[u8; 3]; 2]> {
    let z: Vec<usize> = (0..BRICK).filter(|&z| bits[z] != 0).collect();
    let (&z0, &z1) = (z.first()?, z.last()?);
    let rows = bits.iter().fold(0u64, |a, w| a | w);
    let y_set = (0..BRICK).filter(|y| rows >> (BRICK * y) & 0xff != 0);
    let (y0, y1) = y_set.fold((BRICK, 0), |(lo, hi), y| (lo.min(y), hi.max(y)));
    let x_bits = (0..BRICK).fold(0u64, |a, y| a | (rows >> (BRICK * y) & 0xff));
    let x0 = x_bits.trailing_zeros() as usize;
    let x1 = 63 - x_bits.leading_zeros() as usize;
    Some([[x0, y0, z0].map(|v| v as u8), [x1, y1, z1].map(|v| v as u8)])
}

/// The bits of brick `b`. A cell may show when the table entries of its
/// corners span a visible entry ([`Lut::entries_may_show`]): when one
/// corner lies at or above the low threshold of the table's
/// [`Lut::show_window`] (the `(t_lo, t_hi)` argument: the same answer in data
/// values) and one at or below its high one. So each row of 9 corner voxels
/// (indices clamped to the grid, so a 1-voxel axis reads its one voxel
/// twice) becomes two 9-bit masks, and a cell's answer is the masks or-ed
/// over its x pair, y pair and z pair: integer ors on 81 pairs of masks
/// instead of two flags per voxel folded three times.
#[cold]
fn brick_bits<T: Sample>(
    values: &[T],
    dims: [usize; 3],
    (t_lo, t_hi): (f32, f32),
    b: [usize; 3],
) -> Bits {
    let index = |a: usize, h: usize| (b[a] * BRICK + h).min(dims[a] - 1);
    let xs: [usize; SIDE] = std::array::from_fn(|h| index(0, h));
    // A brick clear of the grid's last x reads its rows as one run.
    let run = (xs[SIDE - 1] == xs[0] + BRICK).then_some(xs[0]);
    // Per corner row (hy, hz): the voxels at or above t_lo, at or below
    // t_hi, each or-ed with its x neighbour (bit x: cells x, x + 1).
    let mut above = [[0u16; SIDE]; SIDE];
    let mut below = [[0u16; SIDE]; SIDE];
    for hz in 0..SIDE {
        for hy in 0..SIDE {
            let row = &values[dims[0] * (index(1, hy) + dims[1] * index(2, hz))..];
            let v: [f32; SIDE] = match run {
                Some(x0) => {
                    let r: &[T; SIDE] = row[x0..x0 + SIDE].try_into().expect("SIDE voxels");
                    r.map(T::to_f32)
                }
                None => std::array::from_fn(|x| row[xs[x]].to_f32()),
            };
            let (mut a, mut w) = (0u16, 0u16);
            for (x, v) in v.into_iter().enumerate() {
                a |= u16::from(v >= t_lo) << x;
                w |= u16::from(v <= t_hi) << x;
            }
            above[hz][hy] = a | a >> 1;
            below[hz][hy] = w | w >> 1;
        }
    }
    let mut bits = [0u64; BRICK];
    for (lz, word) in bits.iter_mut().enumerate() {
        for ly in 0..BRICK {
            let pair = |m: &[[u16; SIDE]; SIDE]| {
                m[lz][ly] | m[lz][ly + 1] | m[lz + 1][ly] | m[lz + 1][ly + 1]
            };
            let show = pair(&above) & pair(&below) & 0xff;
            *word |= u64::from(show) << (BRICK * ly);
        }
    }
    bits
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filters::trilinear8;
    use crate::transfer::TransferFunction;
    use voxflex_core::glam::Vec3;

    fn volume(dims: [usize; 3], seed: u32) -> Vec<f32> {
        (0..dims.iter().product::<usize>())
            .map(|l| {
                let h = (l as u32 ^ seed).wrapping_mul(2_654_435_761) >> 20;
                // Mostly soft tissue, a few bone voxels.
                if h.is_multiple_of(23) {
                    900.0
                } else {
                    (h % 97) as f32
                }
            })
            .collect()
    }

    /// Every cell: the bit is the brute-force answer (the entry span of
    /// the cell's corners, one entry wider, shown) on grids with partial
    /// bricks and 1- and 2-voxel axes; a cell is never hidden while one of
    /// its trilinear values is shown.
    #[test]
    fn bits_are_the_cells_entry_spans() {
        let lut = TransferFunction::preset("ct-bone")
            .unwrap()
            .lut((-1024.0, 3071.0), 1.0);
        let (mut hidden, mut shown) = (0, 0);
        for dims in [[19, 10, 17], [1, 9, 3], [2, 2, 2], [8, 9, 1], [17, 17, 17]] {
            let v = volume(dims, 7);
            let cells = VisibleCells::new(dims);
            let max0 = dims.map(|n| n.max(2) - 2);
            for k in 0..=max0[2] {
                for j in 0..=max0[1] {
                    for i in 0..=max0[0] {
                        let corners: [f32; 8] = std::array::from_fn(|c| {
                            let at = |a: usize, d: usize| ([i, j, k][a] + d).min(dims[a] - 1);
                            let (x, y, z) = (at(0, c & 1), at(1, c >> 1 & 1), at(2, c >> 2));
                            v[x + dims[0] * (y + dims[1] * z)]
                        });
                        let entries = corners.map(|c| lut.entry(c));
                        let lo = *entries.iter().min().unwrap();
                        let hi = *entries.iter().max().unwrap();
                        let want = lut.entries_may_show(lo, hi);
                        let got = cells.may_show(&v, &lut, [i, j, k]);
                        assert_eq!(got, want, "{dims:?} cell {:?}", [i, j, k]);
                        if got {
                            shown += 1;
                            continue;
                        }
                        hidden += 1;
                        for f in [0.0, 0.31, 0.5, 0.999, 1.0] {
                            let f = Vec3::new(f, 1.0 - f, 0.5 * f);
                            let value = trilinear8(corners, f);
                            assert!(lut.lookup_visible(value).is_none(), "{value}");
                        }
                    }
                }
            }
        }
        assert!(
            shown > 100 && hidden > 100,
            "{shown} shown, {hidden} hidden"
        );
    }

    /// The hidden block of every cell is the largest aligned block of its
    /// brick (8, 4, 2 or 1 cells) whose cells all are hidden (brute force
    /// over `may_show`), 0 for a cell that may show; grids with partial
    /// bricks, volumes from nearly empty to nearly full.
    #[test]
    fn hidden_blocks_are_the_largest_empty_aligned_blocks() {
        let lut = TransferFunction::preset("ct-bone")
            .unwrap()
            .lut((-1024.0, 3071.0), 1.0);
        let mut seen = [0usize; 9];
        for (dims, bone) in [([19, 10, 17], 5), ([33, 26, 20], 40), ([17, 17, 17], 400)] {
            let mut v = vec![0.0; dims.iter().product()];
            for n in 0..bone {
                let l = (n as u32).wrapping_mul(2_654_435_761) as usize % v.len();
                v[l] = 900.0;
            }
            let cells = VisibleCells::new(dims);
            let max0 = dims.map(|n| n - 2);
            let hidden_box = |lo: [usize; 3], edge: usize| {
                (lo[2]..lo[2] + edge).all(|k| {
                    (lo[1]..lo[1] + edge).all(|j| {
                        (lo[0]..lo[0] + edge).all(|i| {
                            // Cells past the grid repeat its last ones.
                            let c = [i.min(max0[0]), j.min(max0[1]), k.min(max0[2])];
                            !cells.may_show(&v, &lut, c)
                        })
                    })
                })
            };
            for k in 0..=max0[2] {
                for j in 0..=max0[1] {
                    for i in 0..=max0[0] {
                        let want = [8, 4, 2, 1, 0]
                            .into_iter()
                            .find(|&e| e == 0 || hidden_box([i, j, k].map(|c| c / e * e), e))
                            .unwrap();
                        let got = cells.hidden_block(&v, &lut, [i, j, k]);
                        assert_eq!(got, want, "{dims:?} cell {:?}", [i, j, k]);
                        seen[got] += 1;
                    }
                }
            }
        }
        assert!(
            [0, 1, 2, 4, 8].iter().all(|&e| seen[e] > 10),
            "every answer occurs: {seen:?}"
        );
    }

    /// The shown box of every brick is the box of its set bits (brute
    /// force), `None` for a brick with none.
    #[test]
    fn shown_cells_are_the_box_of_the_set_bits() {
        let lut = TransferFunction::preset("ct-bone")
            .unwrap()
            .lut((-1024.0, 3071.0), 1.0);
        let (mut some, mut none) = (0, 0);
        for seed in 0..6 {
            let dims = [19, 10, 17];
            let mut v = vec![0.0; dims.iter().product()];
            // A few bone voxels per seed, so bricks show little or nothing.
            for n in 0..(seed * 3) {
                let l = ((n as u32).wrapping_mul(2_654_435_761) ^ (seed as u32 * 40_503)) as usize
                    % v.len();
                v[l] = 900.0;
            }
            let cells = VisibleCells::new(dims);
            let max0 = dims.map(|n| n - 2);
            let counts = max0.map(|m| m / 8 + 1);
            for bz in 0..counts[2] {
                for by in 0..counts[1] {
                    for bx in 0..counts[0] {
                        let mut want: Option<IndexBox> = None;
                        for k in 8 * bz..(8 * bz + 8).min(max0[2] + 1) {
                            for j in 8 * by..(8 * by + 8).min(max0[1] + 1) {
                                for i in 8 * bx..(8 * bx + 8).min(max0[0] + 1) {
                                    if cells.may_show(&v, &lut, [i, j, k]) {
                                        let c = IndexBox {
                                            lo: [i, j, k],
                                            hi: [i, j, k],
                                        };
                                        want = Some(want.map_or(c, |w| w.union(&c)));
                                    }
                                }
                            }
                        }
                        let got = cells.shown_cells(&v, &lut, [bx, by, bz]);
                        assert_eq!(got, want, "seed {seed} brick {:?}", [bx, by, bz]);
                        if got.is_some() { some += 1 } else { none += 1 }
                    }
                }
            }
        }
        assert!(
            some > 5 && none > 5,
            "{some} with shown cells, {none} without"
        );
    }

    /// The margin of one table entry: a cell whose corners reach the entry
    /// just below the first visible one is shown.
    #[test]
    fn cells_next_to_the_visible_range_are_shown() {
        let lut = TransferFunction::preset("ct-bone")
            .unwrap()
            .lut((-1024.0, 3071.0), 1.0);
        let first = lut.visible.0;
        let value_of = |e: usize| lut.lo + (e as f32 + 0.5) / lut.scale;
        for (e, shown) in [(first - 3, false), (first - 2, true), (first, true)] {
            let dims = [2, 2, 2];
            let v = vec![value_of(e); 8];
            assert_eq!(lut.entry(v[0]), e);
            let cells = VisibleCells::new(dims);
            assert_eq!(
                cells.may_show(&v, &lut, [0, 0, 0]),
                shown,
                "entry {e} (first visible {first})"
            );
        }
    }

    /// A changed voxel drops its brick: the bit follows the new value.
    #[test]
    fn invalidated_bricks_are_rebuilt_from_the_new_volume() {
        let lut = TransferFunction::preset("ct-bone")
            .unwrap()
            .lut((-1024.0, 3071.0), 1.0);
        let dims = [12, 3, 3];
        let mut v = vec![0.0; 12 * 9];
        let mut cells = VisibleCells::new(dims);
        assert!(!cells.may_show(&v, &lut, [9, 0, 0]));
        v[10 + 12 * (1 + 3)] = 1000.0;
        assert!(
            !cells.may_show(&v, &lut, [9, 0, 0]),
            "not dropped: still the old bits"
        );
        cells.invalidate(IndexBox {
            lo: [10, 1, 1],
            hi: [10, 1, 1],
        });
        assert!(cells.may_show(&v, &lut, [9, 0, 0]));
        assert!(cells.may_show(&v, &lut, [10, 1, 1]));
        assert!(!cells.may_show(&v, &lut, [0, 0, 0]));
    }
}
