//! Voxel boxes and the min/max **macro-cell grid** of empty-space
//! skipping.
//!
//! Macro-cell `c` (per axis) covers voxel indices `[c·s − 1, (c+1)·s + 1]`
//! (clamped) for edge `s` — the shared border voxel `(c+1)·s` and a halo of
//! one voxel each side, so every sample taken at a position inside the
//! cell `[c·s, (c+1)·s]`, trilinear (2³ voxels) or tricubic B-spline (4³
//! voxels, weights ≥ 0), reads only voxels the cell's `[min, max]` range
//! covers. A grid of `n` voxels has `max(1, ⌈(n−1)/s⌉)` cells. A cell
//! is empty for the composite mode when the transfer function has κ = 0 over
//! its whole range ([`crate::transfer::Lut::range_is_empty`]); the MIP mode
//! skips cells whose max cannot beat the ray's running maximum.

use crate::transfer::Lut;
use rayon::prelude::*;
use voxflex_core::deformation::DirtyRegion;
use voxflex_core::grid::Grid;
use voxflex_core::volume::Sample;

/// Largest leap distance, cells ([`MacroCells::leap_distances`]).
pub const LEAP_CAP: u8 = 16;

/// An inclusive box of voxel (or cell) indices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IndexBox {
    /// First index on each axis.
    pub lo: [usize; 3],
    /// Last index on each axis (inclusive).
    pub hi: [usize; 3],
}

impl IndexBox {
    /// Every index of a lattice of `dims` (which must be non-empty).
    pub fn all(dims: [usize; 3]) -> Self {
        Self {
            lo: [0; 3],
            hi: dims.map(|n| n.saturating_sub(1)),
        }
    }

    /// Number of indices in the box.
    pub fn len(&self) -> usize {
        (0..3).map(|a| self.hi[a] + 1 - self.lo[a]).product()
    }

    /// Never true (a box holds at least one index); for clippy's sake.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The smallest box holding both.
    pub fn union(&self, o: &IndexBox) -> IndexBox {
        IndexBox {
            lo: std::array::from_fn(|a| self.lo[a].min(o.lo[a])),
            hi: std::array::from_fn(|a| self.hi[a].max(o.hi[a])),
        }
    }
}

/// The voxels of `grid` a dirty world box (mm) may have changed: the box
/// converted to voxel indices, widened by one voxel for rounding and clamped
/// to the grid. `None` when nothing changed or the box misses the grid.
pub fn dirty_voxels(grid: &Grid, dirty: DirtyRegion) -> Option<IndexBox> {
    if grid.is_empty() {
        return None;
    }
    match dirty {
        DirtyRegion::None => None,
        DirtyRegion::All => Some(IndexBox::all(grid.dims)),
        DirtyRegion::Box { min, max } => {
            let a = grid.world_to_index(min);
            let b = grid.world_to_index(max);
            let (lo, hi) = (a.min(b), a.max(b));
            if !(lo.is_finite() && hi.is_finite()) {
                return Some(IndexBox::all(grid.dims));
            }
            let mut out = IndexBox::all(grid.dims);
            for ax in 0..3 {
                let n = grid.dims[ax] as f64;
                let l = (lo[ax].floor() - 1.0).max(0.0);
                let h = (hi[ax].ceil() + 1.0).min(n - 1.0);
                if l > n - 1.0 || h < 0.0 || l > h {
                    return None;
                }
                out.lo[ax] = l as usize;
                out.hi[ax] = h as usize;
            }
            Some(out)
        }
    }
}

/// Smallest and largest of `values` (not empty), compared in their own
/// type and then converted (the conversion is exact and monotone, so this
/// is the min/max of their f32 values). The volume is sanitised (no NaN),
/// so a comparison and a select do what `f32::min` / `max` do, in one
/// instruction each, and vectorise.
#[inline]
fn min_max<T: Sample + PartialOrd>(values: &[T]) -> (f32, f32) {
    let first = values[0];
    let (lo, hi) = values.iter().fold((first, first), |(lo, hi), &v| {
        (if v < lo { v } else { lo }, if v > hi { v } else { hi })
    });
    (lo.to_f32(), hi.to_f32())
}

/// `lo ← min(lo, row)`, `hi ← max(hi, row)` element by element (NaN-free).
#[inline]
fn fold_min_max<T: Sample + PartialOrd>(lo: &mut [T], hi: &mut [T], row: &[T]) {
    for (l, &x) in lo.iter_mut().zip(row) {
        *l = if x < *l { x } else { *l };
    }
    for (h, &x) in hi.iter_mut().zip(row) {
        *h = if x > *h { x } else { *h };
    }
}

/// The min/max macro-cell grid of a volume.
#[derive(Clone, Debug, PartialEq)]
pub struct MacroCells {
    /// Cell edge, voxels.
    pub cell: usize,
    /// Volume dims, voxels.
    pub dims: [usize; 3],
    /// Cells per axis.
    pub counts: [usize; 3],
    /// Smallest value of each cell (x fastest).
    pub min: Vec<f32>,
    /// Largest value of each cell.
    pub max: Vec<f32>,
}

impl MacroCells {
    /// Cells per axis for a volume of `dims` and cell edge `cell`.
    pub fn counts_for(dims: [usize; 3], cell: usize) -> [usize; 3] {
        dims.map(|n| n.saturating_sub(1).div_ceil(cell).max(1))
    }

    /// An unbuilt grid (every cell `[+∞, −∞]`).
    pub fn new(dims: [usize; 3], cell: usize) -> Self {
        let counts = Self::counts_for(dims, cell);
        let n = counts.iter().product();
        Self {
            cell,
            dims,
            counts,
            min: vec![f32::INFINITY; n],
            max: vec![f32::NEG_INFINITY; n],
        }
    }

    /// Total cells.
    pub fn len(&self) -> usize {
        self.min.len()
    }

    /// True when there is no cell.
    pub fn is_empty(&self) -> bool {
        self.min.is_empty()
    }

    /// The cells whose range covers any voxel of `voxels`.
    pub fn cells_touching(&self, voxels: IndexBox) -> IndexBox {
        Self::touching(self.dims, self.cell, voxels)
    }

    /// The cells (edge `cell`, volume of `dims` voxels) whose range covers
    /// any voxel of `voxels`.
    pub fn touching(dims: [usize; 3], cell: usize, voxels: IndexBox) -> IndexBox {
        let counts = Self::counts_for(dims, cell);
        IndexBox {
            lo: std::array::from_fn(|a| (voxels.lo[a].saturating_sub(2) / cell).min(counts[a] - 1)),
            hi: std::array::from_fn(|a| ((voxels.hi[a] + 1) / cell).min(counts[a] - 1)),
        }
    }

    /// Voxel range (inclusive) of cell `c` along axis `a`, halo included.
    #[inline]
    fn span(&self, a: usize, c: usize) -> (usize, usize) {
        let lo = (c * self.cell).saturating_sub(1);
        let hi = ((c + 1) * self.cell + 1).min(self.dims[a] - 1);
        (lo.min(self.dims[a] - 1), hi)
    }

    /// Recomputes the min/max of the cells in `cells` from `values`
    /// (`dims` voxels, x fastest, in their own scalar type).
    ///
    /// Separably, one layer of cells (z) per task: each voxel row of the
    /// layer's z-span is folded element by element into the (one or two)
    /// cell rows whose y-span holds it — a running min and max per voxel
    /// column, in the volume's own type, which the compiler vectorises (16
    /// lanes of i16 per AVX2 register) —, and each cell row is then
    /// reduced to its cells' x-spans once. A cell's span overlaps its
    /// neighbours' by its halo (`cell + 3` voxels per axis), so each voxel
    /// is folded about `((cell + 3) / cell)²` times (z and y overlap), not
    /// `((cell + 3) / cell)³` as cell by cell, and no cell waits on one
    /// long chain of comparisons.
    pub fn rebuild<T: Sample + PartialOrd>(&mut self, values: &[T], cells: IndexBox) {
        let [nx, ny, _] = self.dims;
        let (x0, w) = (cells.lo[0], cells.hi[0] + 1 - cells.lo[0]);
        let (y0, h) = (cells.lo[1], cells.hi[1] + 1 - cells.lo[1]);
        // The voxel columns the cells' x-spans cover.
        let (u0, u1) = (self.span(0, x0).0, self.span(0, cells.hi[0]).1);
        let len = u1 + 1 - u0;
        let this = &*self;
        let layers: Vec<(usize, Vec<f32>, Vec<f32>)> = (cells.lo[2]..=cells.hi[2])
            .into_par_iter()
            .map(|ck| {
                // Per cell row: the running min and max of each voxel column
                // (`None` until its first voxel row).
                let mut columns: Vec<Option<(Vec<T>, Vec<T>)>> = vec![None; h];
                let (k0, k1) = this.span(2, ck);
                let (v0, v1) = (this.span(1, y0).0, this.span(1, cells.hi[1]).1);
                for k in k0..=k1 {
                    for y in v0..=v1 {
                        let row = &values[(k * ny + y) * nx + u0..][..len];
                        for cj in this.cells_holding(1, y, y0, cells.hi[1]) {
                            match &mut columns[cj - y0] {
                                Some((lo, hi)) => fold_min_max(lo, hi, row),
                                empty => *empty = Some((row.to_vec(), row.to_vec())),
                            }
                        }
                    }
                }
                let (mut lo, mut hi) = (Vec::with_capacity(w * h), Vec::with_capacity(w * h));
                for column in &columns {
                    let (col_lo, col_hi) =
                        column.as_ref().expect("every cell row holds a voxel row");
                    for t in 0..w {
                        let (i0, i1) = this.span(0, x0 + t);
                        lo.push(min_max(&col_lo[i0 - u0..=i1 - u0]).0);
                        hi.push(min_max(&col_hi[i0 - u0..=i1 - u0]).1);
                    }
                }
                (ck, lo, hi)
            })
            .collect();
        let [cx, cy, _] = self.counts;
        for (ck, lo, hi) in layers {
            for j in 0..h {
                let c = x0 + cx * (y0 + j) + cx * cy * ck;
                self.min[c..c + w].copy_from_slice(&lo[j * w..(j + 1) * w]);
                self.max[c..c + w].copy_from_slice(&hi[j * w..(j + 1) * w]);
            }
        }
    }

    /// The cells `first ..= last` along axis `a` whose span holds voxel `v`
    /// (one, or two where the halos overlap).
    fn cells_holding(
        &self,
        a: usize,
        v: usize,
        first: usize,
        last: usize,
    ) -> impl Iterator<Item = usize> + '_ {
        let c = v / self.cell;
        (c.saturating_sub(1).max(first)..=(c + 1).min(last)).filter(move |&c| {
            let (lo, hi) = self.span(a, c);
            lo <= v && v <= hi
        })
    }

    /// Per-cell emptiness under a transfer function (1 = every sample in the
    /// cell has κ = 0).
    pub fn empty_flags(&self, lut: &Lut) -> Vec<u8> {
        self.min
            .par_iter()
            .zip(&self.max)
            .map(|(&lo, &hi)| lut.range_is_empty(lo, hi) as u8)
            .collect()
    }

    /// The **leap distance** of every cell for composite rendering: 0 for a
    /// cell some sample of which may be visible under `lut`, else the
    /// Chebyshev distance (in cells, capped at [`LEAP_CAP`]) to the nearest
    /// such cell. Every cell within `d − 1` cells of a cell at distance `d`
    /// is empty, so a ray can jump to the exit of that `(2d − 1)³` block at
    /// once. Computed by three separable passes ([`crate::leap`]), to the
    /// same distances as `shaders/raycast/leap.wgsl`.
    pub fn leap_distances(&self, lut: &Lut) -> Vec<u8> {
        crate::leap::chebyshev_distances(&self.empty_flags(lut), self.counts)
    }

    /// Smallest and largest value over all cells (`(0, 0)` if unbuilt).
    pub fn value_range(&self) -> (f32, f32) {
        let lo = self.min.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = self.max.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        if lo <= hi { (lo, hi) } else { (0.0, 0.0) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DVec3;

    fn brute(values: &[f32], dims: [usize; 3], cell: usize) -> MacroCells {
        let mut m = MacroCells::new(dims, cell);
        let [cx, cy, _] = m.counts;
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let v = values[i + dims[0] * (j + dims[1] * k)];
                    // Every cell whose span [c·s − 1, (c+1)·s + 1] holds (i, j, k).
                    let cand = |x: usize, a: usize| {
                        (0..m.counts[a])
                            .filter(|&c| c * cell <= x + 1 && x <= (c + 1) * cell + 1)
                            .collect::<Vec<_>>()
                    };
                    for &ck in &cand(k, 2) {
                        for &cj in &cand(j, 1) {
                            for &ci in &cand(i, 0) {
                                let c = ci + cx * (cj + cy * ck);
                                m.min[c] = m.min[c].min(v);
                                m.max[c] = m.max[c].max(v);
                            }
                        }
                    }
                }
            }
        }
        m
    }

    fn field(dims: [usize; 3]) -> Vec<f32> {
        (0..dims.iter().product::<usize>())
            .map(|l| ((l * 7919) % 1013) as f32 - 500.0)
            .collect()
    }

    #[test]
    fn full_build_matches_brute_force() {
        for dims in [[17, 9, 8], [16, 16, 16], [1, 5, 3], [2, 2, 2]] {
            let v = field(dims);
            let mut m = MacroCells::new(dims, 4);
            let all = IndexBox::all(m.counts);
            m.rebuild(&v, all);
            assert_eq!(m, brute(&v, dims, 4), "{dims:?}");
            // The same values stored as i16 and u8 give the same cells.
            let ints: Vec<i16> = v.iter().map(|&x| x as i16).collect();
            let mut typed = MacroCells::new(dims, 4);
            typed.rebuild(&ints, all);
            assert_eq!(typed, m, "i16 {dims:?}");
            let bytes: Vec<u8> = v.iter().map(|&x| (x + 500.0) as u8).collect();
            typed.rebuild(&bytes, all);
            let shifted: Vec<f32> = bytes.iter().map(|&b| b as f32).collect();
            assert_eq!(typed, brute(&shifted, dims, 4), "u8 {dims:?}");
        }
    }

    #[test]
    fn dirty_rebuild_equals_full_rebuild() {
        let dims = [30, 21, 19];
        let grid = Grid::new(dims, DVec3::new(0.5, 1.0, 2.0), DVec3::new(-3.0, 4.0, 1.0));
        let mut v = field(dims);
        let mut m = MacroCells::new(dims, 8);
        m.rebuild(&v, IndexBox::all(m.counts));
        // Change a local box of voxels, including a cell-border voxel (i = 8, 16).
        for k in 5..=9 {
            for j in 7..=8 {
                for i in 8..=16 {
                    v[i + dims[0] * (j + dims[1] * k)] = 5000.0 + i as f32;
                }
            }
        }
        let lo = grid.index_to_world(DVec3::new(8.0, 7.0, 5.0));
        let hi = grid.index_to_world(DVec3::new(16.0, 8.0, 9.0));
        let vox = dirty_voxels(&grid, DirtyRegion::Box { min: lo, max: hi }).unwrap();
        assert!(vox.lo[0] <= 8 && vox.hi[0] >= 16);
        // The exact changed voxels (no rounding margin) must be enough.
        let exact = IndexBox {
            lo: [8, 7, 5],
            hi: [16, 8, 9],
        };
        let cells = m.cells_touching(exact);
        assert!(cells.len() < m.len());
        m.rebuild(&v, cells);
        let mut full = MacroCells::new(dims, 8);
        full.rebuild(&v, IndexBox::all(full.counts));
        assert_eq!(m, full);
        assert_eq!(m, brute(&v, dims, 8));
    }

    #[test]
    fn leap_distances_are_capped_chebyshev_distances() {
        use crate::transfer::{ControlPoint, TransferFunction, ValueUnits};
        // Opaque above 0.5; cells are empty unless they hold a "1".
        let tf = TransferFunction {
            points: vec![
                ControlPoint {
                    value: 0.0,
                    rgba: [0.0; 4],
                },
                ControlPoint {
                    value: 0.5,
                    rgba: [0.0; 4],
                },
                ControlPoint {
                    value: 0.6,
                    rgba: [1.0; 4],
                },
            ],
            units: ValueUnits::Data,
            gaussian: None,
        };
        let lut = tf.lut((0.0, 1.0), 1.0);
        let dims = [150, 90, 41];
        let mut v = vec![0f32; dims.iter().product()];
        for (i, j, k) in [(3, 4, 5), (140, 80, 40), (75, 10, 20)] {
            v[i + dims[0] * (j + dims[1] * k)] = 1.0;
        }
        let mut m = MacroCells::new(dims, 4);
        m.rebuild(&v, IndexBox::all(m.counts));
        let empty = m.empty_flags(&lut);
        let leap = m.leap_distances(&lut);
        let full = empty.iter().filter(|&&e| e == 0).count();
        assert!(full > 0 && full < 30);
        assert_eq!(leap, crate::leap::tests::brute(&empty, m.counts));
    }

    #[test]
    fn dirty_boxes_convert_to_voxels() {
        let grid = Grid::new([10, 10, 10], DVec3::ONE, DVec3::ZERO);
        assert_eq!(dirty_voxels(&grid, DirtyRegion::None), None);
        assert_eq!(
            dirty_voxels(&grid, DirtyRegion::All),
            Some(IndexBox::all([10; 3]))
        );
        let b = dirty_voxels(
            &grid,
            DirtyRegion::Box {
                min: DVec3::splat(2.5),
                max: DVec3::splat(3.5),
            },
        )
        .unwrap();
        assert_eq!(b.lo, [1; 3]);
        assert_eq!(b.hi, [5; 3]);
        let miss = DirtyRegion::Box {
            min: DVec3::splat(20.0),
            max: DVec3::splat(30.0),
        };
        assert_eq!(dirty_voxels(&grid, miss), None);
    }
}
