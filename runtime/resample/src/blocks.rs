//! Cell blocks: the unit of work of pass 1 and the unit of the deformed
//! bounding boxes the dirty-region logic keeps between calls.
//!
//! Block `(bx, by, bz)` holds the cells `[4 bx, 4 bx + 4) × …` (clipped to
//! the mesh) and so the vertices `[4 bx, 4 bx + 4] × …` (inclusive: a block
//! shares its upper vertex layer with the next block). Its [`BlockBounds`] is
//! the box of the deformed positions of those vertices, so it contains the
//! deformed bounding box of every tetrahedron of the block.
//!
//! Memory: 24 bytes per 64 cells (0.375 byte per voxel). The block edge
//! trades that memory (and the per-call scan of all block bounds) against
//! how tightly a dirty region is rounded out: the old deformed positions of
//! moved vertices are only known through their blocks' bounds.

use super::sampling_mesh::SamplingMesh;

/// Cells per block edge.
pub const BLOCK_EDGE: usize = 4;

/// Cells per block.
pub const CELLS_PER_BLOCK: usize = BLOCK_EDGE * BLOCK_EDGE * BLOCK_EDGE;

/// Box of the deformed positions of a block's vertices, **source voxel
/// index** units.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct BlockBounds {
    /// Lower corner.
    pub min: [f32; 3],
    /// Upper corner.
    pub max: [f32; 3],
}

impl BlockBounds {
    /// The empty box (min = +∞, max = −∞), the neutral element of [`Self::union`].
    pub const EMPTY: BlockBounds = BlockBounds {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };

    /// The smallest box holding both.
    pub fn union(&self, o: &BlockBounds) -> BlockBounds {
        BlockBounds {
            min: [0, 1, 2].map(|a| self.min[a].min(o.min[a])),
            max: [0, 1, 2].map(|a| self.max[a].max(o.max[a])),
        }
    }

    /// True when every coordinate is finite.
    pub fn is_finite(&self) -> bool {
        self.min.iter().chain(&self.max).all(|v| v.is_finite())
    }

    /// True when the box touches the inclusive integer box `[lo, hi]`.
    pub fn touches(&self, lo: [i32; 3], hi: [i32; 3]) -> bool {
        (0..3).all(|a| self.min[a] <= hi[a] as f32 && self.max[a] >= lo[a] as f32)
    }
}

/// The block decomposition of a sampling mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockLayout {
    cell_dims: [usize; 3],
    block_dims: [usize; 3],
}

impl BlockLayout {
    /// The blocks of a mesh.
    pub fn new(mesh: &SamplingMesh) -> Self {
        let cell_dims = mesh.cell_dims();
        Self {
            cell_dims,
            block_dims: cell_dims.map(|c| c.div_ceil(BLOCK_EDGE)),
        }
    }

    /// Blocks along x, y, z.
    pub fn block_dims(&self) -> [usize; 3] {
        self.block_dims
    }

    /// Number of blocks.
    pub fn count(&self) -> usize {
        self.block_dims.iter().product()
    }

    /// Block indices of a linear block index (x fastest).
    #[inline]
    pub fn block_of_linear(&self, b: usize) -> [usize; 3] {
        let d = self.block_dims;
        [b % d[0], (b / d[0]) % d[1], b / (d[0] * d[1])]
    }

    /// Linear index of a block.
    #[inline]
    pub fn linear(&self, b: [usize; 3]) -> usize {
        let d = self.block_dims;
        b[0] + d[0] * (b[1] + d[1] * b[2])
    }

    /// Cells of block `b` (linear): lower corner and exclusive upper corner.
    #[inline]
    pub fn cells(&self, b: usize) -> ([usize; 3], [usize; 3]) {
        let bi = self.block_of_linear(b);
        let lo = bi.map(|v| v * BLOCK_EDGE);
        let hi = [0, 1, 2].map(|a| (lo[a] + BLOCK_EDGE).min(self.cell_dims[a]));
        (lo, hi)
    }

    /// Vertices of block `b` (linear): inclusive lower and upper corners.
    #[inline]
    pub fn vertices(&self, b: usize) -> ([usize; 3], [usize; 3]) {
        self.cells(b)
    }

    /// Number of cells in block `b`.
    pub fn cell_count(&self, b: usize) -> usize {
        let (lo, hi) = self.cells(b);
        (0..3).map(|a| hi[a] - lo[a]).product()
    }

    /// Linear indices of the blocks whose vertex range meets the inclusive
    /// vertex box `[lo, hi]`.
    pub fn blocks_touching_vertices(&self, lo: [usize; 3], hi: [usize; 3]) -> Vec<u32> {
        let blo = lo.map(|v| v.saturating_sub(1) / BLOCK_EDGE);
        let bhi = [0, 1, 2].map(|a| (hi[a] / BLOCK_EDGE).min(self.block_dims[a] - 1));
        let mut out = Vec::new();
        for z in blo[2]..=bhi[2] {
            for y in blo[1]..=bhi[1] {
                for x in blo[0]..=bhi[0] {
                    out.push(self.linear([x, y, z]) as u32);
                }
            }
        }
        out
    }
}

/// Order-preserving map of `f32` to `u32` (for atomic min/max on the GPU):
/// `a < b ⇔ encode(a) < encode(b)` for non-NaN values.
#[inline]
pub fn encode_ordered(v: f32) -> u32 {
    let b = v.to_bits();
    if b & 0x8000_0000 != 0 {
        !b
    } else {
        b | 0x8000_0000
    }
}

/// Inverse of [`encode_ordered`].
#[inline]
pub fn decode_ordered(u: u32) -> f32 {
    f32::from_bits(if u & 0x8000_0000 != 0 {
        u & 0x7fff_ffff
    } else {
        !u
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use glam::DVec3;

    #[test]
    fn blocks_cover_cells_and_share_vertex_layers() {
        assert_eq!(BLOCK_EDGE, 4, "this test spells out 4-cell blocks");
        let mesh = SamplingMesh::new(&Grid::new([10, 5, 2], DVec3::ONE, DVec3::ZERO)).unwrap();
        let l = BlockLayout::new(&mesh);
        assert_eq!(l.block_dims(), [3, 1, 1]);
        assert_eq!(l.cells(0), ([0, 0, 0], [4, 4, 1]));
        assert_eq!(l.cells(2), ([8, 0, 0], [9, 4, 1]));
        assert_eq!(l.vertices(1), ([4, 0, 0], [8, 4, 1]));
        let total: usize = (0..l.count()).map(|b| l.cell_count(b)).sum();
        assert_eq!(total, mesh.cell_count());
        // Vertex 4 belongs to blocks 0 and 1; vertex 5 only to block 1.
        assert_eq!(l.blocks_touching_vertices([4, 0, 0], [4, 0, 0]), vec![0, 1]);
        assert_eq!(l.blocks_touching_vertices([5, 0, 0], [5, 4, 1]), vec![1]);
        assert_eq!(l.blocks_touching_vertices([9, 0, 0], [9, 0, 0]), vec![2]);
    }

    #[test]
    fn ordered_encoding() {
        let vals = [
            f32::NEG_INFINITY,
            -3.5,
            -1e-30,
            0.0,
            1e-30,
            2.0,
            1e30,
            f32::INFINITY,
        ];
        for w in vals.windows(2) {
            assert!(encode_ordered(w[0]) < encode_ordered(w[1]), "{w:?}");
        }
        for v in vals {
            assert_eq!(decode_ordered(encode_ordered(v)), v);
        }
    }
}
