//! [`TetMask`]: which tetrahedra of the implicit sampling mesh are removed
//! (cut or carved away). Removed tetrahedra are skipped by the resampler, so
//! the voxels they covered get the background value.

use super::ResampleError;
use super::sampling_mesh::{SamplingMesh, TETS_PER_CELL};
use crate::grid::Grid;
use std::sync::atomic::{AtomicU64, Ordering};

/// Source of [`TetMask::generation`] values, unique across all masks of a
/// process, so a resampler can tell "the same mask, unchanged" from "another
/// mask" or "changed".
static NEXT_GENERATION: AtomicU64 = AtomicU64::new(1);

fn next_generation() -> u64 {
    NEXT_GENERATION.fetch_add(1, Ordering::Relaxed)
}

/// Per hexahedral cell, a 5-bit set of removed tetrahedra (bit `t` =
/// tetrahedron `t` of [`super::sampling_mesh::CELL_TETS`]).
///
/// One byte per cell, allocated only when the first tetrahedron is removed.
/// Tracks the box of cells (cell indices) ever changed and a generation
/// number that changes on every modification; the resampler uses both to
/// re-rasterise only the affected region.
#[derive(Clone, Debug)]
pub struct TetMask {
    mesh: SamplingMesh,
    bits: Vec<u8>,
    generation: u64,
    changed: Option<([usize; 3], [usize; 3])>,
}

impl TetMask {
    /// An empty mask (nothing removed, nothing allocated) for the sampling
    /// mesh of `source` (the grid being resampled).
    pub fn new(source: &Grid) -> Result<Self, ResampleError> {
        Ok(Self {
            mesh: SamplingMesh::new(source)?,
            bits: Vec::new(),
            generation: next_generation(),
            changed: None,
        })
    }

    /// Cells along x, y, z (one fewer than source voxels).
    pub fn cell_dims(&self) -> [usize; 3] {
        self.mesh.cell_dims()
    }

    /// Removes tetrahedron `t` (0..5) of `cell` (cell indices).
    pub fn remove(&mut self, cell: [usize; 3], t: usize) -> Result<(), ResampleError> {
        self.set(cell, t, true)
    }

    /// Restores tetrahedron `t` (0..5) of `cell` (cell indices).
    pub fn restore(&mut self, cell: [usize; 3], t: usize) -> Result<(), ResampleError> {
        self.set(cell, t, false)
    }

    fn set(&mut self, cell: [usize; 3], t: usize, removed: bool) -> Result<(), ResampleError> {
        let cd = self.mesh.cell_dims();
        if t >= TETS_PER_CELL || (0..3).any(|a| cell[a] >= cd[a]) {
            return Err(ResampleError::BadTet {
                cell,
                tet: t,
                cell_dims: cd,
            });
        }
        if self.bits.is_empty() {
            if !removed {
                return Ok(());
            }
            self.bits = vec![0; self.mesh.cell_count()];
        }
        let l = self.mesh.cell_linear(cell);
        let old = self.bits[l];
        let new = if removed {
            old | (1 << t)
        } else {
            old & !(1 << t)
        };
        if new != old {
            self.bits[l] = new;
            self.generation = next_generation();
            self.changed = Some(match self.changed {
                None => (cell, cell),
                Some((lo, hi)) => (
                    [lo[0].min(cell[0]), lo[1].min(cell[1]), lo[2].min(cell[2])],
                    [hi[0].max(cell[0]), hi[1].max(cell[1]), hi[2].max(cell[2])],
                ),
            });
        }
        Ok(())
    }

    /// True when tetrahedron `t` of `cell` is removed (false out of range).
    pub fn is_removed(&self, cell: [usize; 3], t: usize) -> bool {
        let cd = self.mesh.cell_dims();
        if t >= TETS_PER_CELL || (0..3).any(|a| cell[a] >= cd[a]) {
            return false;
        }
        self.cell_bits(self.mesh.cell_linear(cell)) & (1 << t) != 0
    }

    /// Removed-tetrahedra bits of a cell by linear cell index (0 if none).
    #[inline]
    pub fn cell_bits(&self, cell_linear: usize) -> u8 {
        self.bits.get(cell_linear).copied().unwrap_or(0)
    }

    /// True when nothing was ever removed (no memory allocated).
    pub fn is_empty(&self) -> bool {
        self.bits.is_empty()
    }

    /// The per-cell bytes (empty when nothing was ever removed).
    pub fn bytes(&self) -> &[u8] {
        &self.bits
    }

    /// Changes on every modification; unique across masks of a process.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Inclusive box (cell indices) of every cell ever changed, if any.
    pub fn changed_cells(&self) -> Option<([usize; 3], [usize; 3])> {
        self.changed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn lazy_allocation_and_generation() {
        let g = Grid::new([4, 5, 6], DVec3::ONE, DVec3::ZERO);
        let mut m = TetMask::new(&g).unwrap();
        assert!(m.is_empty());
        let g0 = m.generation();
        m.restore([0, 0, 0], 1).unwrap();
        assert!(m.is_empty(), "restoring allocates nothing");
        m.remove([2, 3, 4], 4).unwrap();
        assert!(!m.is_empty());
        assert_eq!(m.bytes().len(), 3 * 4 * 5);
        assert!(m.is_removed([2, 3, 4], 4));
        assert!(!m.is_removed([2, 3, 4], 3));
        assert_ne!(m.generation(), g0);
        let g1 = m.generation();
        m.remove([2, 3, 4], 4).unwrap();
        assert_eq!(m.generation(), g1, "no change, same generation");
        m.remove([0, 1, 0], 0).unwrap();
        assert_eq!(m.changed_cells(), Some(([0, 1, 0], [2, 3, 4])));
        assert!(m.remove([3, 0, 0], 0).is_err());
        assert!(m.remove([0, 0, 0], 5).is_err());
    }
}
