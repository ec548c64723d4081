//! The output lattice of the resampler and integer voxel boxes.
//!
//! The output grid has the source's spacing and axes; its voxel `(0, 0, 0)`
//! sits on the source voxel index [`OutputGrid::origin_index`] (an integer
//! offset, possibly negative), so output voxel centres are integer points of
//! the source index space and an unmoved voxel lands exactly on its source
//! voxel. It starts as the source grid and only grows (never shrinks within a
//! session) to cover the deformed mesh.

use super::ResampleError;
use crate::grid::Grid;
use glam::DVec3;

/// Inclusive box of integer points in **source voxel index** units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VoxelBox {
    /// Lowest index along x, y, z.
    pub lo: [i32; 3],
    /// Highest index along x, y, z (inclusive).
    pub hi: [i32; 3],
}

impl VoxelBox {
    /// True when the box holds no point.
    pub fn is_empty(&self) -> bool {
        (0..3).any(|a| self.lo[a] > self.hi[a])
    }

    /// Points along x, y, z (0 when empty).
    pub fn dims(&self) -> [usize; 3] {
        if self.is_empty() {
            return [0; 3];
        }
        [0, 1, 2].map(|a| (self.hi[a] - self.lo[a]) as usize + 1)
    }

    /// Number of points.
    pub fn count(&self) -> u64 {
        self.dims().iter().map(|&d| d as u64).product()
    }

    /// The common part of two boxes (possibly empty).
    pub fn intersect(&self, o: &VoxelBox) -> VoxelBox {
        VoxelBox {
            lo: [0, 1, 2].map(|a| self.lo[a].max(o.lo[a])),
            hi: [0, 1, 2].map(|a| self.hi[a].min(o.hi[a])),
        }
    }

    /// True when `o` lies inside this box.
    pub fn contains(&self, o: &VoxelBox) -> bool {
        (0..3).all(|a| o.lo[a] >= self.lo[a] && o.hi[a] <= self.hi[a])
    }

    /// The integer points inside the continuous box `[min, max]` (source
    /// index units), grown by `pad` on every side. Non-finite input gives an
    /// empty box.
    pub fn from_continuous(min: [f32; 3], max: [f32; 3], pad: i32) -> VoxelBox {
        let cv = |v: f32| v.clamp(-1.0e9, 1.0e9) as i32;
        VoxelBox {
            lo: [0, 1, 2].map(|a| cv(min[a].ceil()) - pad),
            hi: [0, 1, 2].map(|a| cv(max[a].floor()) + pad),
        }
    }
}

/// The output lattice: `dims` voxels, voxel `(0, 0, 0)` at source voxel
/// index `origin_index`, the source's spacing and axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputGrid {
    /// Source voxel index (integer) of output voxel `(0, 0, 0)`.
    pub origin_index: [i32; 3],
    /// Output voxels along x, y, z.
    pub dims: [usize; 3],
}

impl OutputGrid {
    /// The output lattice equal to a source grid of `dims` voxels.
    pub fn same_as_source(dims: [usize; 3]) -> Self {
        Self {
            origin_index: [0; 3],
            dims,
        }
    }

    /// Number of output voxels.
    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// True when the grid holds no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Its voxel centres as a box of source index units.
    pub fn index_box(&self) -> VoxelBox {
        VoxelBox {
            lo: self.origin_index,
            hi: [0, 1, 2].map(|a| self.origin_index[a] + self.dims[a] as i32 - 1),
        }
    }

    /// Linear output index (x fastest) of a voxel given in source index units.
    #[inline(always)]
    pub fn linear(&self, q: [i32; 3]) -> usize {
        let x = (q[0] - self.origin_index[0]) as usize;
        let y = (q[1] - self.origin_index[1]) as usize;
        let z = (q[2] - self.origin_index[2]) as usize;
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// The world geometry (mm) of this lattice, for a source grid.
    pub fn world_grid(&self, source: &Grid) -> Grid {
        let o = DVec3::new(
            self.origin_index[0] as f64,
            self.origin_index[1] as f64,
            self.origin_index[2] as f64,
        );
        Grid::new(self.dims, source.spacing, source.index_to_world(o))
    }

    /// This grid grown to cover `need` (plus `margin` voxels on each side
    /// that has to grow), or `None` when it already covers it. Fails when
    /// the result would exceed `max_voxels` or the index range of `i32`.
    pub fn grown_to_cover(
        &self,
        need: &VoxelBox,
        margin: usize,
        max_voxels: u64,
    ) -> Result<Option<OutputGrid>, ResampleError> {
        let cur = self.index_box();
        if need.is_empty() || cur.contains(need) {
            return Ok(None);
        }
        let m = margin.min(1 << 20) as i64;
        let mut lo = [0i64; 3];
        let mut hi = [0i64; 3];
        for a in 0..3 {
            lo[a] = cur.lo[a] as i64;
            hi[a] = cur.hi[a] as i64;
            if (need.lo[a] as i64) < lo[a] {
                lo[a] = need.lo[a] as i64 - m;
            }
            if (need.hi[a] as i64) > hi[a] {
                hi[a] = need.hi[a] as i64 + m;
            }
        }
        let dims = [0, 1, 2].map(|a| (hi[a] - lo[a] + 1) as u64);
        let voxels = dims.iter().map(|&d| d as u128).product::<u128>();
        let fits_i32 = (0..3).all(|a| lo[a] > -(1 << 30) && hi[a] < (1 << 30));
        if voxels > max_voxels as u128 || !fits_i32 {
            return Err(ResampleError::OutputTooLarge {
                dims: dims.map(|d| d as usize),
                max_voxels,
                // Only the caller knows the source's voxel count; the
                // planner (`plan::drive`) fills the factor in.
                max_output_factor: f64::NAN,
            });
        }
        Ok(Some(OutputGrid {
            origin_index: lo.map(|v| v as i32),
            dims: dims.map(|d| d as usize),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grows_only_where_needed_and_never_shrinks() {
        let g = OutputGrid::same_as_source([10, 10, 10]);
        let inside = VoxelBox {
            lo: [2, 0, 3],
            hi: [9, 9, 9],
        };
        assert_eq!(g.grown_to_cover(&inside, 4, 1 << 20).unwrap(), None);
        let need = VoxelBox {
            lo: [-2, 1, 1],
            hi: [5, 12, 5],
        };
        let g2 = g.grown_to_cover(&need, 4, 1 << 20).unwrap().unwrap();
        assert_eq!(g2.origin_index, [-6, 0, 0]);
        assert_eq!(g2.dims, [16, 17, 10]);
        assert!(g2.index_box().contains(&g.index_box()));
        assert_eq!(g2.linear([-6, 0, 0]), 0);
        assert_eq!(g2.linear([-5, 1, 1]), 1 + 16 + 16 * 17);
        assert!(matches!(
            g.grown_to_cover(&need, 4, 1000),
            Err(ResampleError::OutputTooLarge { .. })
        ));
    }

    #[test]
    fn continuous_to_integer_box() {
        let b = VoxelBox::from_continuous([0.5, -1.0, -0.2], [3.0, 2.9, -0.1], 0);
        assert_eq!(b.lo, [1, -1, 0]);
        assert_eq!(b.hi, [3, 2, -1]);
        assert!(b.is_empty());
        assert_eq!(b.count(), 0);
        let w = VoxelBox::from_continuous([0.5, -1.0, -0.2], [3.0, 2.9, 0.1], 1);
        assert_eq!(w.dims(), [5, 6, 3]);
    }

    #[test]
    fn world_grid_keeps_spacing() {
        let src = Grid::new(
            [4, 4, 4],
            DVec3::new(0.5, 1.0, 2.0),
            DVec3::new(10.0, 0.0, 0.0),
        );
        let g = OutputGrid {
            origin_index: [-2, 0, 1],
            dims: [8, 4, 4],
        };
        let w = g.world_grid(&src);
        assert_eq!(w.origin, DVec3::new(9.0, 0.0, 2.0));
        assert_eq!(w.spacing, src.spacing);
    }
}
