//! Where column centres cross the surface: per triangle and grid row, the
//! run of consecutive columns whose centres the fill rule
//! ([`crate::fill_rule`]) puts inside it, the height there and the
//! barycentric coordinates the weight pass needs.
//!
//! Coordinates: (u, v) in the grid's index space
//! ([`crate::index_space::IndexSpace`]: column centres at integers),
//! heights h in the [`crate::GravityFrame`], mm.

use crate::distribute::RunBarycentric;
use crate::fill_rule::{RowTest, TriangleTest, column_lanes};
use crate::projection::{ProjectedTriangle, Side, classify};
use glam::{DVec2, DVec3};

/// The bit of [`Run::tag`] that marks a top triangle.
pub const TOP: u32 = 1 << 31;

/// Rows with at most this many candidate columns test each centre with the
/// fill rule directly, four at a time ([`TriangleTest::contains4`]); wider
/// ones compute the row's span first (a small triangle — most of the
/// bunny's at 200² — has one or two candidates per row, the icosphere's
/// about six).
pub const DIRECT_TEST_COLUMNS: usize = 8;

/// Triangles with at least this many candidate rows (and at most
/// [`DIRECT_TEST_COLUMNS`] columns) set up a [`RowTest`], which computes
/// the column half of each edge function once: it costs about what two
/// rows of the plain test do (the bunny's triangles, one or two rows at
/// 200², are faster without; the icosphere's, five or six, with).
pub const ROW_TEST_ROWS: u32 = 3;

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

/// One triangle set up for the row scan: its fill-rule test in index
/// space, what turns the test's edge functions into barycentric
/// coordinates and heights, and its crossing tag; its edges for the row
/// spans are set up on first use (most of a fine mesh's triangles never
/// need them).
pub struct TriangleRaster {
    test: TriangleTest,
    corners: [DVec2; 3],
    ids: [u32; 3],
    /// `side / |2·area|` of edges 0 and 1: an edge function times it is
    /// the opposite corner's barycentric coordinate.
    to_barycentric: [f64; 2],
    /// Change of barycentric coordinates 0 and 1 from one column to the next.
    per_column: [f64; 2],
    /// Heights of corner 2 and of corners 0 and 1 above it, mm.
    h2: f64,
    dh: [f64; 2],
    /// Height step from one column to the next, mm.
    step: f64,
    span: Option<SpanEdges>,
    tag: u32,
    /// Candidate columns `i0..i1`.
    columns: [usize; 2],
}

impl TriangleRaster {
    /// Triangle `t` with vertex ids `ids` at `corners` ((u, v) in the
    /// index space of a grid of `n` columns and rows, h in mm): its
    /// classification ([`classify`]: side, and candidates — the centres in
    /// its bounding box, the rows `j0..j1` to pass to [`Self::run`]), and
    /// the raster when it is not vertical and has candidates.
    #[inline(always)]
    pub fn of(
        t: usize,
        ids: [u32; 3],
        corners: [DVec3; 3],
        n: [usize; 2],
    ) -> (ProjectedTriangle, Option<Self>) {
        let q = corners.map(|c| c.truncate());
        let (pt, area2) = classify(q, n);
        if pt.candidate_count() == 0 {
            return (pt, None);
        }
        let (side, columns) = (pt.side, pt.columns);
        let test = TriangleTest::with_area(ids, q, area2);
        let inv = 1.0 / area2.abs();
        let to_barycentric = [test.edges[0].side * inv, test.edges[1].side * inv];
        // ∂(d × (p − a))/∂p.u = −d.v
        let per_column = [
            -test.edges[0].d.y * to_barycentric[0],
            -test.edges[1].d.y * to_barycentric[1],
        ];
        let h2 = corners[2].z;
        let dh = [corners[0].z - h2, corners[1].z - h2];
        let raster = Self {
            test,
            corners: q,
            ids,
            to_barycentric,
            per_column,
            h2,
            dh,
            step: per_column[0] * dh[0] + per_column[1] * dh[1],
            span: None,
            tag: t as u32 | if side == Side::Top { TOP } else { 0 },
            columns: columns.map(|i| i as usize),
        };
        (pt, Some(raster))
    }

    /// The run of row `j` (one of the triangle's candidate rows) and its
    /// barycentric coordinates. In a row the centres the fill rule puts
    /// inside form one interval (the rule is the triangle nudged by a fixed
    /// `(ε, ε²)`, still convex). A row of at most eight candidates tests
    /// each, four at a time; a wider one takes the span where the row's
    /// centre line crosses the triangle and runs the exact test only from
    /// each end of it (one column of margin each side, so rounding in the
    /// span loses no centre) until it first succeeds: the centres between
    /// are inside. An empty run may have `first` past the candidates (its
    /// height and coordinates are then meaningless).
    #[inline(always)]
    pub fn run(&mut self, j: usize) -> (Run, RunBarycentric) {
        let [i0, i1] = self.columns;
        let [first, last] = if i1 - i0 <= DIRECT_TEST_COLUMNS {
            self.bits(self.direct(j))
        } else {
            self.scan(j)
        };
        self.finish(first, last, j)
    }

    /// Whether a [`RowTest`] pays for the candidate `rows`: at most
    /// [`DIRECT_TEST_COLUMNS`] columns, at least [`ROW_TEST_ROWS`] rows.
    #[inline(always)]
    pub fn wants_row_test(&self, rows: [u32; 2]) -> bool {
        let [i0, i1] = self.columns;
        i1 - i0 <= DIRECT_TEST_COLUMNS && rows[1] - rows[0] >= ROW_TEST_ROWS
    }

    /// The [`RowTest`] over this triangle's candidate columns (at most
    /// [`DIRECT_TEST_COLUMNS`]).
    #[inline(always)]
    pub fn row_test(&self) -> RowTest {
        let [i0, i1] = self.columns;
        RowTest::new(&self.test, i0, i1 - i0)
    }

    /// [`Self::run`] with the triangle's [`Self::row_test`].
    #[inline(always)]
    pub fn run_with(&self, test: &RowTest, j: usize) -> (Run, RunBarycentric) {
        let [first, last] = self.bits(test.inside(j as f64));
        self.finish(first, last, j)
    }

    /// The inside columns `[first, last)` from one bit per candidate (no
    /// branch on an empty row either: then `first > last`).
    #[inline(always)]
    fn bits(&self, inside: u32) -> [usize; 2] {
        let i0 = self.columns[0];
        [
            i0 + inside.trailing_zeros() as usize,
            i0 + (u32::BITS - inside.leading_zeros()) as usize,
        ]
    }

    /// The run `[first, last)` of row `j` with its height and barycentric
    /// coordinates.
    #[inline(always)]
    fn finish(&self, first: usize, last: usize, j: usize) -> (Run, RunBarycentric) {
        // the edge functions at the run's first centre, as the test computed them
        let at = DVec2::new(first as f64, j as f64);
        let [e0, e1] = [0, 1].map(|e| self.test.edges[e].value(at));
        let b = [e0 * self.to_barycentric[0], e1 * self.to_barycentric[1]];
        let run = Run {
            tag: self.tag,
            first: first as u32,
            len: last.saturating_sub(first) as u32,
            row: j as u32,
            height: self.h2 + b[0] * self.dh[0] + b[1] * self.dh[1],
            step: self.step,
        };
        let barycentric = RunBarycentric {
            corners: self.ids,
            at_first: b,
            per_column: self.per_column,
        };
        (run, barycentric)
    }

    /// The candidates of row `j` (at most eight) inside, tested four at a
    /// time: bit `l` for column `i0 + l`.
    #[inline(always)]
    fn direct(&self, j: usize) -> u32 {
        let [i0, i1] = self.columns;
        let py = j as f64;
        let mut inside = self.test.contains4(column_lanes(i0), py);
        if i1 - i0 > 4 {
            inside |= self.test.contains4(column_lanes(i0 + 4), py) << 4;
        }
        inside & ((1 << (i1 - i0)) - 1)
    }

    /// The inside columns `[first, last)` of row `j` from its span.
    #[inline(always)]
    fn scan(&mut self, j: usize) -> [usize; 2] {
        let [i0, i1] = self.columns;
        let v = j as f64;
        let corners = self.corners;
        let edges = self.span.get_or_insert_with(|| SpanEdges::new(corners));
        let Some(span) = edges.at(v) else {
            return [i0, i0];
        };
        // Index ranges carry their own rounding (about an ulp of the
        // coordinates): widen the span's error bound by it.
        let err = span.err + 64.0 * f64::EPSILON * (span.lo.abs() + span.hi.abs());
        let within = |lo: f64, hi: f64| {
            let a = lo.ceil().max(i0 as f64);
            let b = (hi.floor() + 1.0).min(i1 as f64);
            [a as usize, b.max(a) as usize]
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
        let centre = |i: usize| DVec2::new(i as f64, v);
        while first < stop_left && !self.test.contains(centre(first)) {
            first += 1;
        }
        while last > first.max(stop_right) && !self.test.contains(centre(last - 1)) {
            last -= 1;
        }
        [first, last]
    }
}

/// Where a row's centre line crosses a projected triangle.
struct RowSpan {
    /// Lowest and highest u of the crossing (index units).
    lo: f64,
    hi: f64,
    /// A bound on the rounding error of `lo` and `hi` (index units).
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
    /// ends (generous: 128 ulps of the interpolation's largest term) (index units).
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

#[cfg(test)]
#[path = "hits_tests.rs"]
mod tests;
