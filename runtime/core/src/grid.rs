//! [`Grid`]: the geometry of a regular voxel lattice.
//!
//! Conventions used everywhere in voxflex:
//! - **Voxel index** `(i, j, k)` addresses voxel centres; `i` runs fastest in
//!   memory (x-fastest, like NIfTI, MetaImage and NRRD).
//! - **World** coordinates are LPS millimetres (x grows towards the
//!   patient's left, y posterior, z superior: DICOM's frame). The centre of voxel `(i, j, k)` sits at
//!   `origin + (i, j, k) * spacing`: axis-aligned, spacing positive; the
//!   readers reorder a file's voxels into this frame
//!   (`voxflex_io::orientation`).

use glam::DVec3;

/// Geometry of a regular, axis-aligned voxel lattice.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Number of voxels along x, y, z.
    pub dims: [usize; 3],
    /// Distance between neighbouring voxel centres along x, y, z, in millimetres.
    pub spacing: DVec3,
    /// World position (millimetres) of the centre of voxel `(0, 0, 0)`.
    pub origin: DVec3,
}

impl Grid {
    /// A grid of `dims` voxels with the given spacing and origin (millimetres).
    pub fn new(dims: [usize; 3], spacing: DVec3, origin: DVec3) -> Self {
        Self {
            dims,
            spacing,
            origin,
        }
    }

    /// A grid of `dims` voxels with unit (1 mm) spacing, centred on the world origin.
    pub fn centred(dims: [usize; 3], spacing: DVec3) -> Self {
        let extent = DVec3::new(
            (dims[0].max(1) - 1) as f64,
            (dims[1].max(1) - 1) as f64,
            (dims[2].max(1) - 1) as f64,
        ) * spacing;
        Self::new(dims, spacing, -0.5 * extent)
    }

    /// Total number of voxels.
    pub fn len(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// True when the grid holds no voxel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Linear memory index of voxel `(i, j, k)` (x fastest).
    #[inline]
    pub fn linear(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// Voxel index `(i, j, k)` of a linear memory index.
    #[inline]
    pub fn unlinear(&self, l: usize) -> [usize; 3] {
        let i = l % self.dims[0];
        let r = l / self.dims[0];
        [i, r % self.dims[1], r / self.dims[1]]
    }

    /// World position (mm) of a (possibly fractional) voxel index.
    #[inline]
    pub fn index_to_world(&self, index: DVec3) -> DVec3 {
        self.origin + index * self.spacing
    }

    /// Fractional voxel index of a world position (mm).
    #[inline]
    pub fn world_to_index(&self, world: DVec3) -> DVec3 {
        (world - self.origin) / self.spacing
    }

    /// World-space (mm) box spanned by the voxel centres: `(min, max)`.
    pub fn world_bounds(&self) -> (DVec3, DVec3) {
        let last = DVec3::new(
            self.dims[0].saturating_sub(1) as f64,
            self.dims[1].saturating_sub(1) as f64,
            self.dims[2].saturating_sub(1) as f64,
        );
        (self.origin, self.index_to_world(last))
    }

    /// World position (mm) of the grid centre.
    pub fn centre(&self) -> DVec3 {
        let (a, b) = self.world_bounds();
        0.5 * (a + b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_world_round_trip() {
        let g = Grid::new(
            [4, 5, 6],
            DVec3::new(0.5, 1.0, 2.0),
            DVec3::new(-1.0, 2.0, 3.0),
        );
        let idx = DVec3::new(1.0, 2.0, 3.0);
        let w = g.index_to_world(idx);
        assert_eq!(w, DVec3::new(-0.5, 4.0, 9.0));
        assert!((g.world_to_index(w) - idx).length() < 1e-12);
        assert_eq!(g.unlinear(g.linear(3, 4, 5)), [3, 4, 5]);
        assert_eq!(g.len(), 120);
    }

    #[test]
    fn centred_grid_is_symmetric() {
        let g = Grid::centred([3, 3, 3], DVec3::ONE);
        assert_eq!(g.centre(), DVec3::ZERO);
    }
}
