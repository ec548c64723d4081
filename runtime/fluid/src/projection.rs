//! The cavity surface seen from above: vertices in the gravity frame, each
//! triangle classified top/bottom and given its candidate columns.

use crate::column_grid::ColumnGrid;
use crate::gravity_frame::GravityFrame;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use voxflex_core::triangle_surface::TriangleSurface;

/// Below this many vertices or triangles per piece a rayon split costs more
/// than it saves (the 5,120-triangle icosphere projects in one piece).
const MIN_PIECE: usize = 8192;

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

/// One triangle as the column pass needs it (20 bytes: the bunny has
/// 75,408 of them, written and read once per weighing).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProjectedTriangle {
    /// Top, bottom or vertical.
    pub side: Side,
    /// Candidate columns `i0..i1` along u: every column whose centre may
    /// lie in the triangle's (u, v) bounding box (empty when vertical).
    pub columns: [u32; 2],
    /// Candidate rows `j0..j1` along v (empty when vertical).
    pub rows: [u32; 2],
}

impl ProjectedTriangle {
    /// A vertical triangle: no candidates.
    pub const VERTICAL: Self = Self {
        side: Side::Vertical,
        columns: [0; 2],
        rows: [0; 2],
    };

    /// Number of candidate columns (0 for a vertical triangle).
    #[inline]
    pub fn candidate_count(&self) -> usize {
        let ([i0, i1], [j0, j1]) = (self.columns, self.rows);
        (i1 - i0) as usize * (j1 - j0) as usize
    }
}

/// The surface in the gravity frame and its column grid.
#[derive(Clone, Debug)]
pub struct ProjectedSurface<'a> {
    /// The surface (world frame, mm).
    pub surface: &'a TriangleSurface,
    /// Each vertex's `(u, v, h)` in the [`GravityFrame`], mm.
    pub uvh: Vec<DVec3>,
    /// The column grid over the projected bounding box.
    pub grid: ColumnGrid,
    /// Per triangle, its side and candidate columns ([`Self::classify`];
    /// empty on the CPU path, whose row scan classifies as it goes and
    /// keeps only [`Self::mean_candidates`]).
    pub triangles: Vec<ProjectedTriangle>,
    /// Mean candidate columns per non-vertical triangle (the paper's `c`).
    pub mean_candidates: f64,
}

impl<'a> ProjectedSurface<'a> {
    /// Projects `surface` along `gravity` (any non-zero vector) onto a grid
    /// of `columns_per_side²` columns.
    pub fn new(surface: &'a TriangleSurface, gravity: DVec3, columns_per_side: usize) -> Self {
        Self::new_in(surface, gravity, columns_per_side, Vec::new(), Vec::new())
    }

    /// [`Self::new`] filling the given vectors (their capacity is reused:
    /// see [`Self::into_buffers`]): [`Self::frame_in`], then
    /// [`Self::classify`].
    pub fn new_in(
        surface: &'a TriangleSurface,
        gravity: DVec3,
        columns_per_side: usize,
        uvh: Vec<DVec3>,
        triangles: Vec<ProjectedTriangle>,
    ) -> Self {
        let mut p = Self::frame_in(surface, gravity, columns_per_side, uvh, triangles);
        p.classify();
        p
    }

    /// The vertices in the gravity frame and the grid over their bounds
    /// (one pass over the vertices, both at once); `triangles` is left empty and
    /// `mean_candidates` 0 until [`Self::classify`] (or the CPU's row scan,
    /// [`crate::row_scan`], which classifies as it scans).
    pub fn frame_in(
        surface: &'a TriangleSurface,
        gravity: DVec3,
        columns_per_side: usize,
        mut uvh: Vec<DVec3>,
        mut triangles: Vec<ProjectedTriangle>,
    ) -> Self {
        let frame = GravityFrame::new(gravity);
        // Every element is overwritten below; resizing to the same length
        // (every call after the first) writes nothing.
        uvh.resize(surface.vertices.len(), DVec3::ZERO);
        let empty = || (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        let (lo, hi) = uvh
            .par_chunks_mut(MIN_PIECE)
            .zip(surface.vertices.par_chunks(MIN_PIECE))
            .map(|(out, world)| {
                let (mut lo, mut hi) = empty();
                for (o, &p) in out.iter_mut().zip(world) {
                    *o = frame.to_frame(p);
                    (lo, hi) = (lo.min(o.truncate()), hi.max(o.truncate()));
                }
                (lo, hi)
            })
            .reduce(empty, |a, b| (a.0.min(b.0), a.1.max(b.1)));
        triangles.clear();
        Self {
            surface,
            uvh,
            grid: ColumnGrid::spanning(frame, lo, hi, columns_per_side),
            triangles,
            mean_candidates: 0.0,
        }
    }

    /// Each triangle's side and candidate columns, and their mean (one
    /// pass over the triangles).
    pub fn classify(&mut self) {
        let classifier = self.classifier();
        // Every element is overwritten below; resizing to the same length
        // (every call after the first) writes nothing.
        self.triangles
            .resize(self.surface.triangles.len(), ProjectedTriangle::VERTICAL);
        let uvh = &self.uvh;
        let sums = self
            .triangles
            .par_chunks_mut(MIN_PIECE)
            .zip(self.surface.triangles.par_chunks(MIN_PIECE))
            .map(|(out, ids)| {
                let mut sums = CandidateSum::default();
                for (o, tri) in out.iter_mut().zip(ids) {
                    *o = classifier.classify(tri.map(|v| uvh[v as usize].truncate()));
                    sums.add(o);
                }
                sums
            })
            .reduce(CandidateSum::default, CandidateSum::merge);
        self.mean_candidates = sums.mean();
    }

    /// The per-triangle classification over this projection's grid.
    pub fn classifier(&self) -> Classifier {
        Classifier::new(&self.grid)
    }

    /// The vectors this projection filled, for the next [`Self::new_in`].
    pub fn into_buffers(self) -> (Vec<DVec3>, Vec<ProjectedTriangle>) {
        (self.uvh, self.triangles)
    }

    /// Mean candidate columns per non-vertical triangle (the paper's `c`).
    pub fn mean_candidates(&self) -> f64 {
        self.mean_candidates
    }
}

/// Candidate columns summed over non-vertical triangles (for their mean,
/// the paper's `c`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CandidateSum {
    /// Candidate columns.
    pub candidates: usize,
    /// Non-vertical triangles.
    pub triangles: usize,
}

impl CandidateSum {
    /// Counts one triangle.
    #[inline]
    pub fn add(&mut self, t: &ProjectedTriangle) {
        let counted = t.side != Side::Vertical;
        self.candidates += t.candidate_count();
        self.triangles += usize::from(counted);
    }

    /// Both sums.
    pub fn merge(self, o: Self) -> Self {
        Self {
            candidates: self.candidates + o.candidates,
            triangles: self.triangles + o.triangles,
        }
    }

    /// Mean candidates per counted triangle (0 for none).
    pub fn mean(&self) -> f64 {
        if self.triangles == 0 {
            0.0
        } else {
            self.candidates as f64 / self.triangles as f64
        }
    }
}

/// A triangle's side and candidate columns from its projected corners —
/// the one classification both paths use.
#[derive(Clone, Copy, Debug)]
pub struct Classifier {
    window: CandidateWindow,
}

impl Classifier {
    fn new(grid: &ColumnGrid) -> Self {
        Self {
            window: CandidateWindow::new(grid),
        }
    }

    /// Side and candidates of the triangle with projected corners `q` (mm).
    #[inline(always)]
    pub fn classify(&self, q: [DVec2; 3]) -> ProjectedTriangle {
        let [a, b, c] = q;
        let area2 = signed_area2(a, b, c);
        if area2 == 0.0 || area2.is_nan() {
            return ProjectedTriangle::VERTICAL;
        }
        let (columns, rows) = self.window.within(a.min(b).min(c), a.max(b).max(c));
        ProjectedTriangle {
            side: if area2 > 0.0 { Side::Top } else { Side::Bottom },
            columns,
            rows,
        }
    }
}

/// The grid's column index ranges of (u, v) boxes, by multiplication with
/// the inverse cell size (no division per triangle). The ranges are
/// widened by a slack that covers the rounding of the index arithmetic and
/// of the column centres, so they hold every centre inside the box (and,
/// rarely, one more).
#[derive(Clone, Copy, Debug)]
struct CandidateWindow {
    origin: DVec2,
    inv_cell: DVec2,
    /// Index units (columns).
    slack: f64,
    n: [usize; 2],
}

impl CandidateWindow {
    /// For boxes within the grid's span (mm, the grid's frame).
    fn new(grid: &ColumnGrid) -> Self {
        let inv_cell = 1.0 / grid.cell;
        let hi = grid.origin + grid.cell * DVec2::new(grid.n[0] as f64, grid.n[1] as f64);
        let magnitude = hi.abs().max(grid.origin.abs()).max_element();
        let n = grid.n[0].max(grid.n[1]) as f64;
        Self {
            origin: grid.origin,
            inv_cell,
            slack: 16.0 * f64::EPSILON * (n + 1.0 + 2.0 * magnitude * inv_cell.max_element()),
            n: grid.n,
        }
    }

    /// Columns `i0..i1` and rows `j0..j1` whose centres may lie in `[lo, hi]`.
    #[inline]
    fn within(&self, lo: DVec2, hi: DVec2) -> ([u32; 2], [u32; 2]) {
        // centre(i) = o + (i + ½)·c ≥ lo  ⇔  i ≥ (lo − o)/c − ½
        let a = (lo - self.origin) * self.inv_cell - 0.5 - self.slack;
        let b = (hi - self.origin) * self.inv_cell - 0.5 + self.slack;
        let range = |a: f64, b: f64, n: usize| {
            let first = a.ceil().max(0.0) as u32;
            let last = (b.floor() + 1.0).clamp(0.0, n as f64) as u32;
            [first.min(last), last]
        };
        (range(a.x, b.x, self.n[0]), range(a.y, b.y, self.n[1]))
    }
}

/// Twice the signed area of the 2-D triangle `(a, b, c)`: positive when
/// counter-clockwise in (u, v), i.e. when the 3-D normal points up (the
/// frame is right-handed).
#[inline]
pub fn signed_area2(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_candidate_window_holds_the_centres_of_the_box_and_at_most_one_more() {
        let g = crate::column_grid::ten_by_five_mm();
        let w = CandidateWindow::new(&g);
        // centres at 0.5, 1.5, … along u; 0.25, 0.75, … along v
        assert_eq!(
            w.within(DVec2::new(0.5, 0.3), DVec2::new(2.4, 0.75)),
            ([0, 2], [1, 2])
        );
        assert_eq!(
            w.within(DVec2::new(0.6, 0.3), DVec2::new(2.4, 0.7)),
            ([1, 2], [1, 1])
        );
        let (u, _) = w.within(DVec2::new(-5.0, 0.0), DVec2::new(-1.0, 1.0));
        assert_eq!(u[0], u[1], "a box left of the grid holds no centre");
        let (u, _) = w.within(DVec2::new(-1.0, 0.0), DVec2::new(20.0, 1.0));
        assert_eq!(u, [0, 10]);
    }
}
