//! [`TetMask`]: which tetrahedra of the implicit sampling mesh are removed
//! (cut or carved away). Removed tetrahedra are skipped by the resampler, so
//! the voxels they covered get the background value.

use super::ResampleError;
use super::sampling_mesh::{CELL_TETS, SamplingMesh, TETS_PER_CELL};
use crate::cut_polygon::CutPolygon;
use crate::grid::Grid;
use glam::DVec3;
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

    /// Number of cells (bytes of a full mask).
    pub fn cell_count(&self) -> usize {
        self.mesh.cell_count()
    }

    /// Sets every cell's bits from `bits` (one byte per cell, x fastest, as
    /// [`Self::bytes`] of a full mask; bits above the fifth are ignored);
    /// returns whether anything changed.
    pub fn replace_bits(&mut self, bits: &[u8]) -> Result<bool, ResampleError> {
        let cd = self.mesh.cell_dims();
        if bits.len() != self.mesh.cell_count() {
            return Err(ResampleError::MaskMismatch {
                mask: [bits.len(), 1, 1],
                mesh: cd,
            });
        }
        let mut changed = false;
        for (l, &b) in bits.iter().enumerate() {
            let (old, new) = (self.cell_bits(l), b & 0x1f);
            if old != new {
                let cell = [l % cd[0], (l / cd[0]) % cd[1], l / (cd[0] * cd[1])];
                for t in 0..TETS_PER_CELL {
                    if (old ^ new) & (1 << t) != 0 {
                        self.set(cell, t, new & (1 << t) != 0)?;
                    }
                }
                changed = true;
            }
        }
        Ok(changed)
    }
}

/// The tetrahedra on the sampling-mesh edges that cross `cut`, among the
/// vertices of the inclusive voxel box `[a, b]` whose current positions
/// (world mm) are `positions` (x fastest over the box): `(linear cell
/// index, tetrahedron bits)`. A model removes these so its cut opens in the
/// resampled volume.
pub fn tets_cut_by(
    cell_dims: [usize; 3],
    (a, b): ([usize; 3], [usize; 3]),
    positions: &[DVec3],
    cut: &CutPolygon,
) -> Vec<(usize, u8)> {
    let size = [0, 1, 2].map(|k| b[k] - a[k] + 1);
    let stride = [1, size[0], size[0] * size[1]];
    let mut out = Vec::new();
    for (n, &p) in positions.iter().enumerate() {
        let v = [
            a[0] + n % size[0],
            a[1] + (n / size[0]) % size[1],
            a[2] + n / stride[2],
        ];
        for axis in 0..3 {
            if v[axis] == b[axis] {
                continue;
            }
            if cut.crosses(p, positions[n + stride[axis]]) {
                out.extend(tets_on_edge(cell_dims, v, axis));
            }
        }
    }
    out
}

/// The tetrahedra that have sampling-mesh vertex `v` (voxel indices) as a
/// corner: `(linear cell index, tetrahedron bits)` for each of the up to 8
/// cells around it. A model that removes the vertex (carving) removes these.
pub fn tets_at_vertex(cell_dims: [usize; 3], v: [usize; 3]) -> Vec<(usize, u8)> {
    tets_touching(cell_dims, v, &[0, 0, 0])
}

/// The tetrahedra that hold the mesh edge from vertex `a` to `a + e_axis`
/// (voxel indices): `(linear cell index, tetrahedron bits)` for each of the
/// up to 4 cells around it. A model that cuts that link removes these, so
/// the cut opens in the resampled volume.
pub fn tets_on_edge(cell_dims: [usize; 3], a: [usize; 3], axis: usize) -> Vec<(usize, u8)> {
    let mut e = [0usize; 3];
    e[axis] = 1;
    tets_touching(cell_dims, a, &e)
}

/// Tetrahedra of the cells around vertex `v` holding both `v` and `v + e`
/// (`e` = 0 for the vertex alone).
fn tets_touching(cell_dims: [usize; 3], v: [usize; 3], e: &[usize; 3]) -> Vec<(usize, u8)> {
    let mut out = Vec::new();
    // Cells whose corner set holds v (and v + e): cell = v − o, o ∈ {0,1}³.
    for o in 0..8usize {
        let off = [o & 1, (o >> 1) & 1, o >> 2];
        if (0..3).any(|a| v[a] < off[a] || off[a] + e[a] > 1) {
            continue;
        }
        let cell = [v[0] - off[0], v[1] - off[1], v[2] - off[2]];
        if (0..3).any(|a| cell[a] >= cell_dims[a]) {
            continue;
        }
        let ca = (off[0] + 2 * off[1] + 4 * off[2]) as u8;
        let cb = ((off[0] + e[0]) + 2 * (off[1] + e[1]) + 4 * (off[2] + e[2])) as u8;
        let parity = (cell[0] + cell[1] + cell[2]) & 1;
        let mut bits = 0u8;
        for (t, corners) in CELL_TETS[parity].iter().enumerate() {
            if corners.contains(&ca) && corners.contains(&cb) {
                bits |= 1 << t;
            }
        }
        if bits != 0 {
            out.push((
                cell[0] + cell_dims[0] * (cell[1] + cell_dims[1] * cell[2]),
                bits,
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn vertex_and_edge_neighbourhoods() {
        let cd = [3, 3, 3];
        // An interior vertex has 8 cells around it; each holds ≥ 1 tet with it.
        let v = tets_at_vertex(cd, [1, 1, 1]);
        assert_eq!(v.len(), 8);
        // Every tet holds 4 corners, so the 8 cells list each tet with the
        // vertex once: 1 (a corner tet) or 4 (central + 3 corner tets).
        let count: u32 = v.iter().map(|(_, b)| b.count_ones()).sum();
        assert!(count >= 8, "{count}");
        // A cube edge in the middle of 4 cells belongs to one tet per cell.
        let e = tets_on_edge(cd, [1, 1, 0], 2);
        assert_eq!(e.len(), 4);
        assert!(e.iter().all(|(_, b)| b.count_ones() == 1), "{e:?}");
        // A corner vertex of the mesh has one cell.
        assert_eq!(tets_at_vertex(cd, [0, 0, 0]).len(), 1);
        // Replace round-trips.
        let g = Grid::new([4, 4, 4], DVec3::ONE, DVec3::ZERO);
        let mut m = TetMask::new(&g).unwrap();
        let mut bits = vec![0u8; m.cell_count()];
        for (l, b) in &e {
            bits[*l] |= b;
        }
        assert!(m.replace_bits(&bits).unwrap());
        assert!(!m.replace_bits(&bits).unwrap());
        assert_eq!(m.bytes(), &bits[..]);
        assert!(m.replace_bits(&[0; 3]).is_err());
    }

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
