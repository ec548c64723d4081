//! The cavity surface seen from above: vertices in the gravity frame, each
//! triangle classified top/bottom and given its candidate columns.

use crate::column_grid::ColumnGrid;
use crate::gravity_frame::GravityFrame;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use voxflex_core::triangle_surface::TriangleSurface;

/// Which way a triangle faces, seen along gravity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Normal up (against gravity): fluid lies below it; a column leaves the fluid here.
    Top,
    /// Normal down: fluid rests on it; a column enters the fluid here and its weight lands here.
    Bottom,
    /// Vertical (zero projected area): no column crosses it.
    Vertical,
}

/// One triangle as the column pass needs it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectedTriangle {
    /// Top, bottom or vertical.
    pub side: Side,
    /// Candidate column index ranges along u (`i0..i1`) and v (`j0..j1`).
    pub candidates: ([usize; 2], [usize; 2]),
}

impl ProjectedTriangle {
    /// Number of candidate columns (0 for a vertical triangle).
    pub fn candidate_count(&self) -> usize {
        if self.side == Side::Vertical {
            return 0;
        }
        let ([i0, i1], [j0, j1]) = self.candidates;
        (i1 - i0) * (j1 - j0)
    }
}

/// The surface in the gravity frame and its column grid.
#[derive(Clone, Debug)]
pub struct ProjectedSurface<'a> {
    /// The surface (world frame, mm).
    pub surface: &'a TriangleSurface,
    /// Each vertex's `(u, v, h)`, mm.
    pub uvh: Vec<DVec3>,
    /// The column grid over the projected bounding box.
    pub grid: ColumnGrid,
    /// Per triangle, its side and candidate columns.
    pub triangles: Vec<ProjectedTriangle>,
}

impl<'a> ProjectedSurface<'a> {
    /// Projects `surface` along `gravity` (any non-zero vector) onto a grid
    /// of `columns_per_side²` columns.
    pub fn new(surface: &'a TriangleSurface, gravity: DVec3, columns_per_side: usize) -> Self {
        Self::new_in(surface, gravity, columns_per_side, Vec::new(), Vec::new())
    }

    /// [`Self::new`] filling the given vectors (their capacity is reused:
    /// see [`Self::into_buffers`]).
    pub fn new_in(
        surface: &'a TriangleSurface,
        gravity: DVec3,
        columns_per_side: usize,
        mut uvh: Vec<DVec3>,
        mut triangles: Vec<ProjectedTriangle>,
    ) -> Self {
        let frame = GravityFrame::new(gravity);
        surface
            .vertices
            .par_iter()
            .map(|&p| frame.to_frame(p))
            .collect_into_vec(&mut uvh);
        let (lo, hi) = uvh
            .par_iter()
            .fold(
                || (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                |(lo, hi), p| (lo.min(p.truncate()), hi.max(p.truncate())),
            )
            .reduce(
                || (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let grid = ColumnGrid::spanning(frame, lo, hi, columns_per_side);
        surface
            .triangles
            .par_iter()
            .with_min_len(1024)
            .map(|tri| {
                let [a, b, c] = tri.map(|v| uvh[v as usize].truncate());
                let side = match signed_area2(a, b, c) {
                    x if x > 0.0 => Side::Top,
                    x if x < 0.0 => Side::Bottom,
                    _ => Side::Vertical,
                };
                ProjectedTriangle {
                    side,
                    candidates: grid.centres_within(a.min(b).min(c), a.max(b).max(c)),
                }
            })
            .collect_into_vec(&mut triangles);
        Self {
            surface,
            uvh,
            grid,
            triangles,
        }
    }

    /// The vectors this projection filled, for the next [`Self::new_in`].
    pub fn into_buffers(self) -> (Vec<DVec3>, Vec<ProjectedTriangle>) {
        (self.uvh, self.triangles)
    }

    /// Mean candidate columns per non-vertical triangle (the paper's `c`).
    pub fn mean_candidates(&self) -> f64 {
        let (sum, n) = self
            .triangles
            .iter()
            .filter(|t| t.side != Side::Vertical)
            .fold((0usize, 0usize), |(s, n), t| {
                (s + t.candidate_count(), n + 1)
            });
        if n == 0 { 0.0 } else { sum as f64 / n as f64 }
    }
}

/// Twice the signed area of the 2-D triangle `(a, b, c)`: positive when
/// counter-clockwise in (u, v), i.e. when the 3-D normal points up (the
/// frame is right-handed).
#[inline]
pub fn signed_area2(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}
