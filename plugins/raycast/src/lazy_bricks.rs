//! [`LazyBricks`]: per-brick data of a volume, built on first use by the
//! rendering threads and dropped where the volume changes.
//!
//! A brick is 8³ *cells* (a cell = a trilinear footprint, named by its lower
//! corner voxel `i`, `0 ≤ i ≤ max(n, 2) − 2` per axis), so brick `b` holds
//! the cells `8b ..= 8b + 7`. What a brick stores is up to its user — the
//! Sobel gradients of its corners ([`crate::gradient_cache`]), which of its
//! cells the transfer function may show ([`crate::visible_cells`]) — and so
//! is how far beyond its cells it reads (its *reach*, which decides what a
//! change of the volume drops). Indices are voxel indices, x fastest.

use crate::macrocell::IndexBox;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Cells per brick edge.
pub const BRICK: usize = 8;

/// Voxels a brick reads beyond its cells' corners: `before` below voxel
/// `8b` and `after` above voxel `8b + 8`, on every axis.
#[derive(Clone, Copy, Debug)]
pub struct Reach {
    /// Voxels read below the brick's first corner.
    pub before: usize,
    /// Voxels read above the brick's last corner.
    pub after: usize,
}

/// One lazily built `T` per brick of a volume of `dims` voxels.
pub struct LazyBricks<T> {
    dims: [usize; 3],
    counts: [usize; 3],
    slots: Vec<OnceLock<T>>,
}

/// Where a cell sits: its brick's slot, the brick, and the cell's index
/// inside the brick (each `0..8`).
#[derive(Clone, Copy, Debug)]
pub struct CellPlace {
    /// Linear index of the brick (x fastest).
    pub slot: usize,
    /// Brick index per axis.
    pub brick: [usize; 3],
    /// The cell's index inside its brick per axis.
    pub local: [usize; 3],
}

impl<T: Send> LazyBricks<T> {
    /// No brick built yet, for a volume of `dims` voxels.
    pub fn new(dims: [usize; 3]) -> Self {
        let counts = dims.map(|n| (n.max(2) - 1).div_ceil(BRICK));
        Self {
            dims,
            counts,
            // Written on both threads: a slot per brick is megabytes of
            // fresh pages for a large volume.
            slots: (0..counts.iter().product())
                .into_par_iter()
                .map(|_| OnceLock::new())
                .collect(),
        }
    }

    /// The volume size (voxels).
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Bricks per axis.
    pub fn counts(&self) -> [usize; 3] {
        self.counts
    }

    /// The brick of the cell whose lower corner is voxel `i`.
    #[inline(always)]
    pub fn place(&self, i: [usize; 3]) -> CellPlace {
        let brick = [i[0] / BRICK, i[1] / BRICK, i[2] / BRICK];
        CellPlace {
            slot: brick[0] + self.counts[0] * (brick[1] + self.counts[1] * brick[2]),
            brick,
            local: [
                i[0] - brick[0] * BRICK,
                i[1] - brick[1] * BRICK,
                i[2] - brick[2] * BRICK,
            ],
        }
    }

    /// The brick at `place`, built by `build(brick)` if it is not yet.
    #[inline(always)]
    pub fn get_or_build(&self, place: &CellPlace, build: impl FnOnce([usize; 3]) -> T) -> &T {
        self.slots[place.slot].get_or_init(|| build(place.brick))
    }

    /// Drops every brick that reads a voxel of `region`, handing each built
    /// one to `dropped`.
    pub fn invalidate(&mut self, region: IndexBox, reach: Reach, mut dropped: impl FnMut(T)) {
        let range = |a: usize| {
            // Brick b reads voxels 8b − before ..= 8b + 8 + after.
            let lo = region.lo[a]
                .saturating_sub(BRICK + reach.after)
                .div_ceil(BRICK);
            let hi = ((region.hi[a] + reach.before) / BRICK).min(self.counts[a] - 1);
            lo..=hi
        };
        for bz in range(2) {
            for by in range(1) {
                for bx in range(0) {
                    let slot = &mut self.slots[bx + self.counts[0] * (by + self.counts[1] * bz)];
                    if let Some(t) = slot.take() {
                        dropped(t);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A region drops exactly the bricks whose read span (cells plus reach)
    /// holds one of its voxels, with and without a reach.
    #[test]
    fn invalidation_drops_exactly_the_bricks_that_read_the_region() {
        let dims = [33, 26, 20];
        for reach in [
            Reach {
                before: 0,
                after: 0,
            },
            Reach {
                before: 1,
                after: 1,
            },
        ] {
            for x in [0, 7, 8, 9, 10, 16, 17, 31, 32] {
                let mut bricks = LazyBricks::<[usize; 3]>::new(dims);
                let [nx, ny, nz] = bricks.counts();
                for bz in 0..nz {
                    for by in 0..ny {
                        for bx in 0..nx {
                            let p = bricks.place([8 * bx, 8 * by, 8 * bz]);
                            bricks.get_or_build(&p, |b| b);
                        }
                    }
                }
                let mut dropped = Vec::new();
                let region = IndexBox {
                    lo: [x, 12, 4],
                    hi: [x, 12, 4],
                };
                bricks.invalidate(region, reach, |b| dropped.push(b));
                let reads =
                    |v: usize, b: usize| 8 * b <= v + reach.before && v <= 8 * b + 8 + reach.after;
                for bz in 0..nz {
                    for by in 0..ny {
                        for bx in 0..nx {
                            let want = reads(x, bx) && reads(12, by) && reads(4, bz);
                            assert_eq!(
                                dropped.contains(&[bx, by, bz]),
                                want,
                                "{reach:?} voxel x = {x}, brick {:?}",
                                [bx, by, bz]
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn places_name_the_brick_and_the_cell_inside_it() {
        let bricks = LazyBricks::<()>::new([20, 9, 1]);
        assert_eq!(bricks.counts(), [3, 1, 1]);
        let p = bricks.place([17, 7, 0]);
        assert_eq!((p.slot, p.brick, p.local), (2, [2, 0, 0], [1, 7, 0]));
    }
}
