//! Where column centres cross the surface: the 2-D point-in-triangle test
//! with a fill rule that gives every centre to exactly one triangle of a
//! tiled region, and the row scan that finds, per triangle and grid row,
//! the run of consecutive columns it crosses and the height there.
//!
//! Coordinates: (u, v, h) in the [`crate::GravityFrame`], mm.

use crate::column_grid::ColumnGrid;
use crate::distribute::{BarycentricPlane, RunBarycentric};
use crate::projection::{ProjectedSurface, ProjectedTriangle, Side};
use glam::{DVec2, DVec3};
use wide::f64x4;

/// The bit of [`Run::tag`] that marks a top triangle.
pub const TOP: u32 = 1 << 31;

/// Rows with at most this many candidate columns test each centre with the
/// fill rule directly, four at a time ([`TriangleTest::contains4`]); wider
/// ones compute the row's span first (a small triangle — most of the
/// bunny's at 200² — has one or two candidates per row, the icosphere's
/// about six).
const DIRECT_TEST_COLUMNS: usize = 8;

/// One triangle's crossings in one grid row: the consecutive columns
/// `first .. first + len` whose centres the fill rule puts inside it
/// (`len` may be 0), and the surface's height over them, which is linear
/// along the row (32 bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Run {
    /// Triangle crossed, with [`TOP`] set when it faces up (the columns
    /// leave the fluid there).
    pub tag: u32,
    /// First column crossed (index `i` along u).
    pub first: u32,
    /// Columns crossed.
    pub len: u32,
    /// The row (index `j` along v).
    pub row: u32,
    /// Height at the centre of column `first`, mm.
    pub height: f64,
    /// Height step from one column to the next, mm.
    pub step: f64,
}

impl Run {
    /// Whether the crossed triangle faces up.
    #[inline]
    pub fn top(&self) -> bool {
        self.tag & TOP != 0
    }

    /// The crossed triangle.
    #[inline]
    pub fn triangle(&self) -> usize {
        (self.tag & !TOP) as usize
    }

    /// Height at the centre of column `first + m`, mm.
    #[inline]
    pub fn height_at(&self, m: u32) -> f64 {
        self.height + m as f64 * self.step
    }
}

/// One triangle set up for the row scan: its fill-rule test, height plane
/// and crossing tag; its edges for the row spans are set up on first use
/// (most of a fine mesh's triangles never need them).
pub struct TriangleRaster {
    test: TriangleTest,
    height: HeightPlane,
    barycentric: BarycentricPlane,
    corners: [DVec2; 3],
    span: Option<SpanEdges>,
    tag: u32,
    /// Candidate columns `i0..i1`.
    columns: [usize; 2],
}

impl TriangleRaster {
    /// Triangle `t` of `p` (a classified one with candidates).
    #[inline(always)]
    pub fn new(p: &ProjectedSurface<'_>, t: usize) -> Self {
        let ids = p.surface.triangles[t];
        Self::of(
            t,
            ids,
            ids.map(|v| p.uvh[v as usize]),
            &p.triangles[t],
            p.grid.cell.x,
        )
    }

    /// Triangle `t` with vertices `ids` at `corners` ((u, v, h), mm),
    /// classified as `pt` (with candidates), on columns `cell_u` wide (mm).
    #[inline(always)]
    pub fn of(
        t: usize,
        ids: [u32; 3],
        corners: [DVec3; 3],
        pt: &ProjectedTriangle,
        cell_u: f64,
    ) -> Self {
        let q = corners.map(|c| c.truncate());
        let barycentric = BarycentricPlane::new(ids, q, cell_u);
        Self {
            test: TriangleTest::new(ids, q),
            height: HeightPlane::new(corners, barycentric.inv_area2()),
            barycentric,
            corners: q,
            span: None,
            tag: t as u32 | if pt.side == Side::Top { TOP } else { 0 },
            columns: pt.columns.map(|i| i as usize),
        }
    }

    /// The run of row `j` (one of the triangle's candidate rows). In a row
    /// the centres the fill rule puts inside form one interval (the rule is
    /// the triangle nudged by a fixed `(ε, ε²)`, still convex). A row of at
    /// most eight candidates tests each, four at a time;
    /// a wider one takes the span where the row's centre line crosses the
    /// triangle and runs the exact test only from each end of it (one
    /// column of margin each side, so rounding in the span loses no centre)
    /// until it first succeeds: the centres between are inside. An empty
    /// run may have `first` past the candidates (its height is then
    /// meaningless).
    #[inline(always)]
    pub fn run(&mut self, grid: &ColumnGrid, inv_cell_u: f64, j: usize) -> Run {
        let [i0, i1] = self.columns;
        let [first, last] = if i1 - i0 <= DIRECT_TEST_COLUMNS {
            // one bit per candidate, without a branch per test
            let py = grid.origin.y + (j as f64 + 0.5) * grid.cell.y;
            let centres = |i: usize| {
                let i = f64x4::splat(i as f64) + f64x4::new([0.0, 1.0, 2.0, 3.0]);
                f64x4::splat(grid.origin.x) + (i + 0.5) * f64x4::splat(grid.cell.x)
            };
            let mut inside = self.test.contains4(centres(i0), py);
            if i1 - i0 > 4 {
                inside |= self.test.contains4(centres(i0 + 4), py) << 4;
            }
            inside &= (1 << (i1 - i0)) - 1;
            // no branch on an empty row either: then first > last
            [
                i0 + inside.trailing_zeros() as usize,
                i0 + (u32::BITS - inside.leading_zeros()) as usize,
            ]
        } else {
            self.scan(grid, inv_cell_u, j)
        };
        Run {
            tag: self.tag,
            first: first as u32,
            len: last.saturating_sub(first) as u32,
            row: j as u32,
            height: self.height.at(grid.centre(first, j)),
            step: self.height.slope.x * grid.cell.x,
        }
    }

    /// [`Self::run`] and the barycentric coordinates along it (the weight
    /// pass's, [`crate::distribute`]).
    #[inline(always)]
    pub fn run_with_barycentric(
        &mut self,
        grid: &ColumnGrid,
        inv_cell_u: f64,
        j: usize,
    ) -> (Run, RunBarycentric) {
        let run = self.run(grid, inv_cell_u, j);
        let bary = self.barycentric.run(grid.centre(run.first as usize, j));
        (run, bary)
    }

    /// The inside columns `[first, last)` of row `j` from its span.
    #[inline(always)]
    fn scan(&mut self, grid: &ColumnGrid, inv_cell_u: f64, j: usize) -> [usize; 2] {
        let [i0, i1] = self.columns;
        let v = grid.centre(0, j).y;
        let corners = self.corners;
        let edges = self.span.get_or_insert_with(|| SpanEdges::new(corners));
        let Some(span) = edges.at(v) else {
            return [i0, i0];
        };
        // Index ranges carry their own rounding (about an ulp of the
        // coordinates): widen the span's error bound by it.
        let err =
            span.err + 64.0 * f64::EPSILON * (span.lo.abs() + span.hi.abs() + grid.origin.x.abs());
        let within = |lo: f64, hi: f64| {
            let [a, b] = grid.columns_within(inv_cell_u, lo, hi);
            [a.max(i0), b.min(i1)]
        };
        // Centres outside [lo − err, hi + err] are outside the triangle;
        // centres inside [lo + err, hi − err] strictly inside it: only
        // those between (rare) need the exact fill-rule test.
        let [mut first, mut last] = within(span.lo - err, span.hi + err);
        let sure = if span.on_edge {
            [last, last]
        } else {
            within(span.lo + err, span.hi - err)
        };
        let (stop_left, stop_right) = if sure[0] < sure[1] {
            (sure[0], sure[1])
        } else {
            (last, first)
        };
        while first < stop_left && !self.test.contains(grid.centre(first, j)) {
            first += 1;
        }
        while last > first.max(stop_right) && !self.test.contains(grid.centre(last - 1, j)) {
            last -= 1;
        }
        [first, last]
    }
}

/// The plane through a triangle's corners as height over (u, v).
struct HeightPlane {
    origin: DVec3,
    slope: DVec2,
}

impl HeightPlane {
    #[inline(always)]
    /// Through the corners `c`; `inv_area2` is `1 / n.z` (twice the signed
    /// projected area's inverse, which the barycentric plane has: `n.z` is
    /// that area, computed the same way).
    fn new(c: [DVec3; 3], inv_area2: f64) -> Self {
        let (e1, e2) = (c[1] - c[0], c[2] - c[0]);
        let n = e1.cross(e2); // n.z ≠ 0: vertical triangles have no candidates
        Self {
            origin: c[0],
            slope: DVec2::new(-n.x, -n.y) * inv_area2,
        }
    }

    #[inline(always)]
    fn at(&self, p: DVec2) -> f64 {
        self.origin.z + self.slope.dot(p - self.origin.truncate())
    }
}

/// Where a row's centre line crosses a projected triangle.
struct RowSpan {
    /// Lowest and highest u of the crossing, mm.
    lo: f64,
    hi: f64,
    /// A bound on the rounding error of `lo` and `hi`, mm.
    err: f64,
    /// The line runs along an edge: the span is boundary, not interior.
    on_edge: bool,
}

/// A triangle's edges set up for [`RowSpan`]s: `du/dv` and the error bound
/// once per edge instead of once per row.
struct SpanEdges([SpanEdge; 3]);

struct SpanEdge {
    a: DVec2,
    b: DVec2,
    /// `du/dv` along the edge (0 when horizontal).
    du_dv: f64,
    /// A bound on the rounding of the crossing's u at any v between the
    /// ends (generous: 128 ulps of the interpolation's largest term), mm.
    err: f64,
}

impl SpanEdges {
    #[inline(always)]
    fn new(q: [DVec2; 3]) -> Self {
        Self([(q[0], q[1]), (q[1], q[2]), (q[2], q[0])].map(|(a, b)| {
            let (dx, dy) = (b.x - a.x, b.y - a.y);
            if dy == 0.0 {
                return SpanEdge {
                    a,
                    b,
                    du_dv: 0.0,
                    err: 0.0,
                };
            }
            // |v| ≤ |a.y| + |b.y| for v between the ends
            let scale =
                a.x.abs() + b.x.abs() + dx.abs() * (1.0 + 2.0 * (a.y.abs() + b.y.abs()) / dy.abs());
            SpanEdge {
                a,
                b,
                du_dv: dx / dy,
                err: 128.0 * f64::EPSILON * scale,
            }
        }))
    }

    /// Where the line `v = const` crosses the triangle, or `None` when it
    /// misses it.
    #[inline(always)]
    fn at(&self, v: f64) -> Option<RowSpan> {
        let mut s = RowSpan {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
            err: 0.0,
            on_edge: false,
        };
        for e in &self.0 {
            let (a, b) = (e.a, e.b);
            if (a.y - v) * (b.y - v) > 0.0 {
                continue;
            }
            if a.y == b.y {
                s.on_edge = true;
                s.lo = s.lo.min(a.x.min(b.x));
                s.hi = s.hi.max(a.x.max(b.x));
                continue;
            }
            let u = a.x + (v - a.y) * e.du_dv;
            s.err = s.err.max(e.err);
            s.lo = s.lo.min(u);
            s.hi = s.hi.max(u);
        }
        (s.lo <= s.hi).then_some(s)
    }
}

/// A projected triangle's inside test. Each edge function is evaluated
/// along the edge's *canonical* direction (lower vertex index first), so
/// the two triangles sharing an edge compute bit-identical values of
/// opposite meaning; a centre exactly on an edge or a vertex is decided by
/// the sign the edge function takes at `p + (ε, ε²)` (simulation of
/// simplicity), which gives it to exactly one of the triangles tiling the
/// region around it.
struct TriangleTest {
    /// Canonical edges opposite corners 0, 1, 2.
    edges: [EdgeFunction; 3],
    /// Twice the signed area (u, v).
    #[cfg(test)]
    area2: f64,
}

/// One canonical edge of a [`TriangleTest`].
struct EdgeFunction {
    /// Start (mm) and direction `end − start` of the canonical edge.
    a: DVec2,
    d: DVec2,
    /// `±1`: whether the triangle's interior is on the canonical edge's left.
    side: f64,
    /// Whether a point exactly on the edge's line belongs to the interior
    /// (the sign at `p + (ε, ε²)`: `−sign(d.v)`, or `sign(d.u)` when the
    /// edge runs along u, times `side`).
    tie_inside: bool,
}

impl TriangleTest {
    #[inline(always)]
    fn new(ids: [u32; 3], q: [DVec2; 3]) -> Self {
        let area2 = crate::projection::signed_area2(q[0], q[1], q[2]);
        let orient = area2.signum();
        // Selects on values, not branches or indices: which way an edge
        // runs is a coin toss. Negating `qb − qa` is exactly `qa − qb`.
        let edge = |ia: u32, ib: u32, qa: DVec2, qb: DVec2| {
            let swap = ia > ib;
            let flip = if swap { -1.0 } else { 1.0 };
            let a = if swap { qb } else { qa };
            let d = (qb - qa) * flip;
            let side = orient * flip;
            let tie = if d.y != 0.0 {
                -d.y.signum()
            } else {
                d.x.signum()
            };
            EdgeFunction {
                a,
                d,
                side,
                tie_inside: tie * side > 0.0,
            }
        };
        let [q0, q1, q2] = q;
        Self {
            // opposite corner 0 is edge 1→2, corner 1: 2→0, corner 2: 0→1
            edges: [
                edge(ids[1], ids[2], q1, q2),
                edge(ids[2], ids[0], q2, q0),
                edge(ids[0], ids[1], q0, q1),
            ],
            #[cfg(test)]
            area2,
        }
    }

    /// Whether the fill rule puts `p` inside.
    #[inline(always)]
    fn contains(&self, p: DVec2) -> bool {
        // `&` and `|`, not `&&` and `||`: no branch per edge
        self.edges.iter().fold(true, |inside, e| {
            let value = e.d.perp_dot(p - e.a);
            inside & ((value * e.side > 0.0) | ((value == 0.0) & e.tie_inside))
        })
    }

    /// [`Self::contains`] at four points `(px[l], py)`, bit `l` set when
    /// inside: the same IEEE operations lane by lane, so the same answers.
    #[inline(always)]
    fn contains4(&self, px: f64x4, py: f64) -> u32 {
        let (zero, py) = (f64x4::ZERO, f64x4::splat(py));
        let inside = self
            .edges
            .iter()
            .fold(f64x4::splat(-1.0).simd_lt(zero), |inside, e| {
                let value = f64x4::splat(e.d.x) * (py - f64x4::splat(e.a.y))
                    - f64x4::splat(e.d.y) * (px - f64x4::splat(e.a.x));
                // all bits set when a tie is inside: a mask, not a branch
                let tie = f64x4::splat(f64::from_bits(0u64.wrapping_sub(u64::from(e.tie_inside))));
                inside
                    & ((value * f64x4::splat(e.side)).simd_gt(zero) | (value.simd_eq(zero) & tie))
            });
        inside.to_bitmask()
    }

    /// Barycentric coordinates of `p` if the fill rule puts it inside.
    #[cfg(test)]
    fn barycentric(&self, p: DVec2) -> Option<[f64; 3]> {
        if !self.contains(p) {
            return None;
        }
        let e = self
            .edges
            .each_ref()
            .map(|e| e.d.perp_dot(p - e.a) * e.side);
        let total = self.area2.abs();
        let (b0, b1) = (e[0] / total, e[1] / total);
        Some([b0, b1, 1.0 - b0 - b1])
    }
}

#[cfg(test)]
#[path = "hits_tests.rs"]
mod tests;
