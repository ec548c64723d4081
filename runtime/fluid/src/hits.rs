//! Where column centres cross the surface: the 2-D point-in-triangle test
//! with a fill rule that gives every centre to exactly one triangle of a
//! tiled region, and the height and barycentric coordinates there.

use crate::column_grid::ColumnGrid;
use crate::projection::{ProjectedSurface, Side};
use crate::schedule::lane_candidates;
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// One crossing of a column with the surface (16 bytes: the pass moves
/// tens of thousands of them; the barycentric coordinates are recomputed
/// for the few that carry weight).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Column index (`i + j·n_u`).
    pub column: u32,
    /// Triangle crossed, with [`TOP`] set when it faces up (the column
    /// leaves the fluid there).
    pub triangle_and_side: u32,
    /// Height of the crossing in the gravity frame, mm. The section pass
    /// replaces a bottom crossing's height by the height of fluid above it
    /// up to its matching top crossing, and a top crossing's by 0.
    pub height: f64,
}

/// The bit of [`Hit::triangle_and_side`] that marks a top triangle.
pub const TOP: u32 = 1 << 31;

impl Hit {
    /// Whether the crossed triangle faces up.
    #[inline]
    pub fn top(&self) -> bool {
        self.triangle_and_side & TOP != 0
    }

    /// The crossed triangle.
    #[inline]
    pub fn triangle(&self) -> usize {
        (self.triangle_and_side & !TOP) as usize
    }
}

/// Every crossing of every column, found by `k` workers per triangle, in
/// unordered batches (merged by [`crate::sections::bucket_by_column`]).
///
/// The `n·k` workers (triangle `w / k`, lane `w % k`) are cut into
/// `batches.len()` contiguous runs of equal length, one rayon task each —
/// leveraging evens out the work per worker, so equal runs are equal
/// work. Each batch keeps its capacity from the previous call.
pub fn find_hits(p: &ProjectedSurface<'_>, k: usize, batches: &mut Vec<Vec<Hit>>) {
    let workers = p.triangles.len() * k;
    let tasks = (4 * rayon::current_num_threads()).clamp(1, workers.max(1));
    batches.resize_with(tasks, Vec::new);
    let per_task = workers.div_ceil(tasks);
    batches.par_iter_mut().enumerate().for_each(|(b, out)| {
        out.clear();
        // A task's workers are consecutive: set each triangle up once.
        let mut raster: Option<(usize, Option<TriangleRaster>)> = None;
        for worker in b * per_task..((b + 1) * per_task).min(workers) {
            let t = worker / k;
            if raster.as_ref().is_none_or(|(rt, _)| *rt != t) {
                raster = Some((t, TriangleRaster::new(p, t)));
            }
            if let Some((_, Some(r))) = &raster {
                r.lane(&p.grid, worker % k, k, out);
            }
        }
    });
}

/// One triangle set up for testing column centres: its fill-rule test,
/// height plane and crossing tag.
struct TriangleRaster {
    q: [DVec2; 3],
    test: TriangleTest,
    height: HeightPlane,
    tag: u32,
    /// Candidate columns `i0..i1`, rows `j0..j1`.
    candidates: ([usize; 2], [usize; 2]),
}

impl TriangleRaster {
    /// `None` for a triangle with no candidate column.
    fn new(p: &ProjectedSurface<'_>, t: usize) -> Option<Self> {
        let pt = p.triangles[t];
        if pt.candidate_count() == 0 {
            return None;
        }
        let ids = p.surface.triangles[t];
        let corners = ids.map(|v| p.uvh[v as usize]);
        let q = corners.map(|c| c.truncate());
        Some(Self {
            q,
            test: TriangleTest::new(ids, q),
            height: HeightPlane::new(corners),
            tag: t as u32 | if pt.side == Side::Top { TOP } else { 0 },
            candidates: pt.candidates,
        })
    }

    /// The crossings worker `lane` of `k` finds: on the CPU the workers
    /// split the triangle's candidate *rows* (`lane, lane + k, …`). In a
    /// row, the centres the fill rule puts inside form one interval (the
    /// rule is the triangle nudged by a fixed `(ε, ε²)`, still convex), so
    /// the exact test runs only from each end of the row's span (one
    /// column of margin each side, so rounding in the span loses no
    /// centre) until it first succeeds; the centres between are inside.
    fn lane(&self, grid: &ColumnGrid, lane: usize, k: usize, out: &mut Vec<Hit>) {
        let ([i0, i1], [j0, j1]) = self.candidates;
        for j in lane_candidates(lane, k, j1 - j0).map(|r| j0 + r) {
            let v = grid.centre(0, j).y;
            let Some(span) = row_span(self.q, v) else {
                continue;
            };
            // Index ranges carry their own rounding (about an ulp of the
            // coordinates): widen the span's error bound by it.
            let err = span.err
                + 64.0 * f64::EPSILON * (span.lo.abs() + span.hi.abs() + grid.origin.x.abs());
            let within = |lo: f64, hi: f64| {
                let [a, b] = grid.columns_within(lo, hi);
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
            let row = j * grid.n[0];
            out.extend((first..last).map(|i| Hit {
                column: (i + row) as u32,
                triangle_and_side: self.tag,
                height: self.height.at(grid.centre(i, j)),
            }));
        }
    }
}

/// The plane through a triangle's corners as height over (u, v).
struct HeightPlane {
    origin: DVec3,
    slope: DVec2,
}

impl HeightPlane {
    fn new(c: [DVec3; 3]) -> Self {
        let (e1, e2) = (c[1] - c[0], c[2] - c[0]);
        let n = e1.cross(e2); // n.z ≠ 0: vertical triangles have no candidates
        Self {
            origin: c[0],
            slope: DVec2::new(-n.x / n.z, -n.y / n.z),
        }
    }

    #[inline]
    fn at(&self, p: DVec2) -> f64 {
        self.origin.z + self.slope.dot(p - self.origin.truncate())
    }
}

/// Where a row's centre line crosses a projected triangle.
struct RowSpan {
    /// Lowest and highest u of the crossing, mm.
    lo: f64,
    hi: f64,
    /// A bound on the rounding error of `lo` and `hi`, mm (generous: 128
    /// ulps of the interpolation's largest term).
    err: f64,
    /// The line runs along an edge: the span is boundary, not interior.
    on_edge: bool,
}

/// Where the line `v = const` crosses the 2-D triangle `q`, or `None` when
/// it misses it.
fn row_span(q: [DVec2; 3], v: f64) -> Option<RowSpan> {
    let mut s = RowSpan {
        lo: f64::INFINITY,
        hi: f64::NEG_INFINITY,
        err: 0.0,
        on_edge: false,
    };
    for (a, b) in [(q[0], q[1]), (q[1], q[2]), (q[2], q[0])] {
        if (a.y - v) * (b.y - v) > 0.0 {
            continue;
        }
        if a.y == b.y {
            s.on_edge = true;
            s.lo = s.lo.min(a.x.min(b.x));
            s.hi = s.hi.max(a.x.max(b.x));
            continue;
        }
        let dx = b.x - a.x;
        let dy = b.y - a.y;
        let u = a.x + (v - a.y) * dx / dy;
        let scale =
            a.x.abs() + b.x.abs() + dx.abs() * (1.0 + (v.abs() + a.y.abs() + b.y.abs()) / dy.abs());
        s.err = s.err.max(128.0 * f64::EPSILON * scale);
        s.lo = s.lo.min(u);
        s.hi = s.hi.max(u);
    }
    (s.lo <= s.hi).then_some(s)
}

/// A projected triangle's inside test. Each edge function is evaluated
/// along the edge's *canonical* direction (lower vertex index first), so
/// the two triangles sharing an edge compute bit-identical values of
/// opposite meaning; a centre exactly on an edge or a vertex is decided by
/// the sign the edge function takes at `p + (ε, ε²)` (simulation of
/// simplicity), which gives it to exactly one of the triangles tiling the
/// region around it.
struct TriangleTest {
    /// Canonical edges opposite corners 0, 1, 2: start, end, and `±1` for
    /// whether the triangle's interior is on the canonical edge's left.
    edges: [(DVec2, DVec2, f64); 3],
    /// Twice the signed area (u, v).
    #[cfg(test)]
    area2: f64,
}

impl TriangleTest {
    fn new(ids: [u32; 3], q: [DVec2; 3]) -> Self {
        let area2 = crate::projection::signed_area2(q[0], q[1], q[2]);
        let orient = area2.signum();
        let edge = |a: usize, b: usize| {
            let (x, y) = (ids[a], ids[b]);
            if x < y {
                (q[a], q[b], orient)
            } else {
                (q[b], q[a], -orient)
            }
        };
        Self {
            // opposite corner 0 is edge 1→2, corner 1: 2→0, corner 2: 0→1
            edges: [edge(1, 2), edge(2, 0), edge(0, 1)],
            #[cfg(test)]
            area2,
        }
    }

    /// Whether the fill rule puts `p` inside.
    #[inline]
    fn contains(&self, p: DVec2) -> bool {
        self.edges.iter().all(|&(a, b, side)| {
            let d = b - a;
            let value = d.perp_dot(p - a);
            let sign = if value != 0.0 {
                value.signum()
            } else if d.y != 0.0 {
                -d.y.signum()
            } else {
                d.x.signum()
            };
            sign * side > 0.0
        })
    }

    /// Barycentric coordinates of `p` if the fill rule puts it inside.
    #[cfg(test)]
    fn barycentric(&self, p: DVec2) -> Option<[f64; 3]> {
        if !self.contains(p) {
            return None;
        }
        let e = self
            .edges
            .map(|(a, b, side)| (b - a).perp_dot(p - a) * side);
        let total = self.area2.abs();
        let (b0, b1) = (e[0] / total, e[1] / total);
        Some([b0, b1, 1.0 - b0 - b1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_split(diagonal_02: bool) -> [TriangleTest; 2] {
        // unit square 0=(0,0) 1=(1,0) 2=(1,1) 3=(0,1), both halves CCW
        let q = [DVec2::ZERO, DVec2::X, DVec2::ONE, DVec2::Y];
        let tri = |ids: [u32; 3]| TriangleTest::new(ids, ids.map(|i| q[i as usize]));
        if diagonal_02 {
            [tri([0, 1, 2]), tri([0, 2, 3])]
        } else {
            [tri([0, 1, 3]), tri([1, 2, 3])]
        }
    }

    #[test]
    fn every_point_of_a_tiled_square_falls_in_exactly_one_half() {
        let pts =
            (0..=8).flat_map(|i| (0..=8).map(move |j| DVec2::new(i as f64 / 8.0, j as f64 / 8.0)));
        for diag in [true, false] {
            let halves = square_split(diag);
            for p in pts.clone() {
                let inside = halves.iter().filter(|t| t.barycentric(p).is_some()).count();
                // The square's own boundary belongs to it or to a neighbour;
                // inside the open square exactly one half claims the point.
                let interior = p.x > 0.0 && p.x < 1.0 && p.y > 0.0 && p.y < 1.0;
                if interior {
                    assert_eq!(inside, 1, "{p} (diagonal 0–2: {diag})");
                } else {
                    assert!(inside <= 1, "{p}");
                }
            }
        }
    }

    /// A fan of triangles around a shared vertex (integer coordinates, so
    /// the vertex and the spokes' midpoints lie exactly on the edges), with
    /// every rotation of the vertex numbering: the centre vertex and each
    /// spoke's midpoint belong to exactly one triangle.
    #[test]
    fn a_shared_vertex_and_its_spokes_belong_to_exactly_one_triangle() {
        let rim = [
            DVec2::new(2.0, 0.0),
            DVec2::new(2.0, 2.0),
            DVec2::new(-1.0, 2.0),
            DVec2::new(-2.0, 0.0),
            DVec2::new(-2.0, -2.0),
            DVec2::new(1.0, -2.0),
        ];
        for shift in 0..7u32 {
            // vertex ids: the centre gets `shift`, the rim the others in turn
            let id = |v: usize| (v as u32 + shift) % 7;
            let points: Vec<DVec2> = std::iter::once(DVec2::ZERO).chain(rim).collect();
            let fan: Vec<TriangleTest> = (0..6)
                .map(|r| {
                    let ids = [0, 1 + r, 1 + (r + 1) % 6].map(id);
                    let q = [0, 1 + r, 1 + (r + 1) % 6].map(|v| points[v]);
                    TriangleTest::new(ids, q)
                })
                .collect();
            let mut probes = vec![DVec2::ZERO];
            probes.extend(rim.iter().map(|&p| p / 2.0));
            for p in probes {
                let claims = fan.iter().filter(|t| t.contains(p)).count();
                assert_eq!(claims, 1, "{p} (numbering shift {shift})");
            }
        }
    }

    #[test]
    fn barycentric_coordinates_rebuild_the_point() {
        let q = [
            DVec2::new(0.0, 0.0),
            DVec2::new(4.0, 1.0),
            DVec2::new(1.0, 3.0),
        ];
        for ids in [[0u32, 1, 2], [2, 1, 0]] {
            let t = TriangleTest::new(ids, ids.map(|i| q[i as usize]));
            let p = DVec2::new(1.5, 1.2);
            let b = t.barycentric(p).unwrap();
            let corners = ids.map(|i| q[i as usize]);
            let back = corners[0] * b[0] + corners[1] * b[1] + corners[2] * b[2];
            assert!((back - p).length() < 1e-12, "{ids:?}: {back}");
            assert!(t.barycentric(DVec2::new(3.0, 3.0)).is_none());
        }
    }
}
