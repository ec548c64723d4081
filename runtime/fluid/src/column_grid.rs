//! The grid of vertical fluid columns over a cavity.

use crate::gravity_frame::GravityFrame;
use glam::DVec2;

/// `n_u × n_v` columns covering the cavity's bounding box in the plane
/// across gravity, in the [`GravityFrame`] (mm). Column `(i, j)` has its
/// centre at `origin + ((i + ½)·w, (j + ½)·d)` and index `i + j·n_u`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColumnGrid {
    /// The frame (u, v across, h up).
    pub frame: GravityFrame,
    /// Lower corner of the grid in (u, v), mm.
    pub origin: DVec2,
    /// Column width `w` along u and depth `d` along v, mm.
    pub cell: DVec2,
    /// Columns along u and v.
    pub n: [usize; 2],
}

impl ColumnGrid {
    /// `columns_per_side²` columns spanning `[lo, hi]` in (u, v) (mm). A
    /// zero extent along an axis (a cavity flat along gravity's normal
    /// plane) gets a one-micrometre width so the grid stays finite.
    pub fn spanning(frame: GravityFrame, lo: DVec2, hi: DVec2, columns_per_side: usize) -> Self {
        let n = columns_per_side.max(1);
        let extent = (hi - lo).max(DVec2::splat(1e-3));
        Self {
            frame,
            origin: lo,
            cell: extent / n as f64,
            n: [n, n],
        }
    }

    /// Number of columns.
    pub fn len(&self) -> usize {
        self.n[0] * self.n[1]
    }

    /// Whether the grid has no column (never, for a grid built by [`Self::spanning`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Cross-section `A = w·d` of every column, mm².
    pub fn column_area(&self) -> f64 {
        self.cell.x * self.cell.y
    }

    /// Centre of column `(i, j)` in (u, v), mm.
    #[inline]
    pub fn centre(&self, i: usize, j: usize) -> DVec2 {
        self.origin + (DVec2::new(i as f64, j as f64) + 0.5) * self.cell
    }
}

/// The tests' grid: 10 × 10 columns of 1 × 0.5 mm over [0, 10] × [0, 5]
/// mm, gravity along −z (centres at 0.5, 1.5, … along u; 0.25, 0.75, …
/// along v).
#[cfg(test)]
pub(crate) fn ten_by_five_mm() -> ColumnGrid {
    ColumnGrid::spanning(
        GravityFrame::new(glam::DVec3::NEG_Z),
        DVec2::ZERO,
        DVec2::new(10.0, 5.0),
        10,
    )
}
