//! The column grid's index space, where the CPU's row scan works: column
//! `(i, j)`'s centre is the integer point `(i, j)`.
//!
//! Each vertex is mapped once per triangle that uses it, by the same
//! operations, so the triangles sharing a vertex see bit-identical
//! coordinates and the fill rule stays watertight. The map is affine, so
//! barycentric coordinates and the heights interpolated with them are the
//! same in either space (up to rounding); the centres being exact integers
//! spares the row scan computing them, and the candidate columns of a
//! triangle are simply the integers inside its bounding box.

use crate::column_grid::ColumnGrid;
use glam::DVec2;

/// The affine map from (u, v) in the [`crate::GravityFrame`] (mm) to
/// column indices (centres at integers; fractional in between).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IndexSpace {
    origin: DVec2,
    inv_cell: DVec2,
}

impl IndexSpace {
    /// The index space of `grid`.
    pub fn of(grid: &ColumnGrid) -> Self {
        Self {
            origin: grid.origin,
            inv_cell: 1.0 / grid.cell,
        }
    }

    /// `q` (mm) in index units.
    #[inline(always)]
    pub fn to_index(&self, q: DVec2) -> DVec2 {
        (q - self.origin) * self.inv_cell - 0.5
    }

    /// The columns `[i0, i1)` and rows `[j0, j1)` whose centres lie in the
    /// box `[lo, hi]` (index units), clipped to a grid of `n` columns and
    /// rows; empty ranges have their start at their end.
    #[inline(always)]
    pub fn within(n: [usize; 2], lo: DVec2, hi: DVec2) -> ([u32; 2], [u32; 2]) {
        let n = DVec2::new(n[0] as f64, n[1] as f64);
        let first = lo.ceil().max(DVec2::ZERO);
        let last = (hi.floor() + 1.0).min(n).max(DVec2::ZERO);
        let first = first.min(last);
        (
            [first.x as u32, last.x as u32],
            [first.y as u32, last.y as u32],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centres_map_to_integers_and_boxes_to_the_centres_inside() {
        let g = crate::column_grid::ten_by_five_mm();
        assert_eq!(g.cell, DVec2::new(1.0, 0.5));
        let s = IndexSpace::of(&g);
        assert_eq!(s.to_index(g.centre(3, 7)), DVec2::new(3.0, 7.0));
        // centres at 0.5, 1.5, … mm along u (index 0, 1, …); 0.25, 0.75, … along v
        let box_of = |lo: DVec2, hi: DVec2| IndexSpace::within(g.n, s.to_index(lo), s.to_index(hi));
        assert_eq!(
            box_of(DVec2::new(0.5, 0.3), DVec2::new(2.4, 0.75)),
            ([0, 2], [1, 2])
        );
        assert_eq!(
            box_of(DVec2::new(0.6, 0.3), DVec2::new(2.4, 0.7)),
            ([1, 2], [1, 1])
        );
        // a box ending exactly on a centre holds it
        let (u, _) = box_of(DVec2::new(0.6, 0.3), DVec2::new(2.5, 0.7));
        assert_eq!(u, [1, 3]);
        let (u, _) = box_of(DVec2::new(-5.0, 0.0), DVec2::new(-1.0, 1.0));
        assert_eq!(u[0], u[1], "a box left of the grid holds no centre");
        let (u, _) = box_of(DVec2::new(12.0, 0.0), DVec2::new(20.0, 1.0));
        assert_eq!(u[0], u[1], "nor one right of it");
        let (u, _) = box_of(DVec2::new(-1.0, 0.0), DVec2::new(20.0, 1.0));
        assert_eq!(u, [0, 10]);
    }
}
