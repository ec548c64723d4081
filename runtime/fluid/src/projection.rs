//! The cavity surface seen from above: vertices in the gravity frame and
//! then in the column grid's index space, each triangle classified
//! top/bottom and given its candidate columns.

use crate::column_grid::ColumnGrid;
use crate::error::FluidError;
use crate::gravity_frame::GravityFrame;
use crate::index_space::IndexSpace;
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
    /// Each vertex's `(u, v)` in the grid's [`IndexSpace`] (column
    /// centres at integers) and its height `h` in the [`GravityFrame`], mm.
    /// Mapped once per vertex, so the triangles sharing a vertex see
    /// bit-identical coordinates (the fill rule's premise).
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
    /// of `columns_per_side²` columns; refuses a surface with a vertex
    /// that is not finite.
    pub fn new(
        surface: &'a TriangleSurface,
        gravity: DVec3,
        columns_per_side: usize,
    ) -> Result<Self, FluidError> {
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
    ) -> Result<Self, FluidError> {
        let mut p = Self::frame_in(surface, gravity, columns_per_side, uvh, triangles)?;
        p.classify();
        Ok(p)
    }

    /// The vertices in the gravity frame and the grid over their bounds
    /// (one pass over the vertices), then their `(u, v)` in the grid's
    /// index space (a second); `triangles` is left empty and
    /// `mean_candidates` 0 until [`Self::classify`] (or the CPU's row scan,
    /// [`crate::row_scan`], which classifies as it scans). A vertex that is
    /// not finite (a deformation that diverged) is refused, naming it: it
    /// would otherwise drop out of the grid and its triangles' fluid with it.
    pub fn frame_in(
        surface: &'a TriangleSurface,
        gravity: DVec3,
        columns_per_side: usize,
        mut uvh: Vec<DVec3>,
        mut triangles: Vec<ProjectedTriangle>,
    ) -> Result<Self, FluidError> {
        let frame = GravityFrame::new(gravity);
        // Every element is overwritten below; resizing to the same length
        // (every call after the first) writes nothing.
        uvh.resize(surface.vertices.len(), DVec3::ZERO);
        let empty = || {
            let (lo, hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
            (lo, hi, true)
        };
        let (lo, hi, finite) = uvh
            .par_chunks_mut(MIN_PIECE)
            .zip(surface.vertices.par_chunks(MIN_PIECE))
            .map(|(out, world)| {
                let (mut lo, mut hi, mut finite) = empty();
                for (o, &p) in out.iter_mut().zip(world) {
                    *o = frame.to_frame(p);
                    (lo, hi) = (lo.min(o.truncate()), hi.max(o.truncate()));
                    finite &= o.is_finite();
                }
                (lo, hi, finite)
            })
            .reduce(empty, |a, b| (a.0.min(b.0), a.1.max(b.1), a.2 & b.2));
        if !finite {
            let (i, p) = (surface.vertices.iter().enumerate())
                .find(|(_, p)| !p.is_finite())
                .expect("a vertex that is not finite");
            return Err(FluidError::Surface(format!(
                "cavity vertex {i} is at {p} mm, not a finite position: the deformation \
                 that moved it has diverged; weigh a surface whose vertices are all finite"
            )));
        }
        let grid = ColumnGrid::spanning(frame, lo, hi, columns_per_side);
        let space = IndexSpace::of(&grid);
        uvh.par_chunks_mut(MIN_PIECE).for_each(|out| {
            for o in out {
                *o = space.to_index(o.truncate()).extend(o.z);
            }
        });
        triangles.clear();
        Ok(Self {
            surface,
            uvh,
            grid,
            triangles,
            mean_candidates: 0.0,
        })
    }

    /// Each triangle's side and candidate columns, and their mean (one
    /// pass over the triangles; the CPU's row scan classifies the same way
    /// as it goes).
    pub fn classify(&mut self) {
        let n = self.grid.n;
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
                    *o = classify(tri.map(|v| uvh[v as usize].truncate()), n).0;
                    sums.add(o);
                }
                sums
            })
            .reduce(CandidateSum::default, CandidateSum::merge);
        self.mean_candidates = sums.mean();
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

/// A triangle's side and candidate columns from its corners `q` in the
/// grid's index space (`n` columns and rows), and twice its signed area
/// there (0 or NaN for a vertical one) — the one classification both paths
/// use. The candidates are the integer points of its bounding box, so no
/// rounding slack is needed: the fill rule, which decides each, works on
/// the same coordinates.
#[inline(always)]
pub fn classify(q: [DVec2; 3], n: [usize; 2]) -> (ProjectedTriangle, f64) {
    let [a, b, c] = q;
    let area2 = signed_area2(a, b, c);
    if area2 == 0.0 || area2.is_nan() {
        return (ProjectedTriangle::VERTICAL, area2);
    }
    let (columns, rows) = IndexSpace::within(n, a.min(b).min(c), a.max(b).max(c));
    let side = if area2 > 0.0 { Side::Top } else { Side::Bottom };
    (
        ProjectedTriangle {
            side,
            columns,
            rows,
        },
        area2,
    )
}

/// Twice the signed area of the 2-D triangle `(a, b, c)`: positive when
/// counter-clockwise in (u, v), i.e. when the 3-D normal points up (the
/// frame is right-handed).
#[inline]
pub fn signed_area2(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}
