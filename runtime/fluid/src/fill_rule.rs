//! The fill rule: a point-in-triangle test that gives every point of a
//! region tiled by triangles to exactly one of them — including points
//! exactly on an edge or a vertex — so no column is counted twice or lost
//! where two triangles meet.
//!
//! Coordinates: any 2-D frame in which the triangles sharing an edge have
//! bit-identical corners (the row scan uses the grid's index space,
//! [`crate::index_space`]).

use glam::DVec2;
use wide::f64x4;

/// A projected triangle's inside test. Each edge function is evaluated
/// along the edge's *canonical* direction (lower vertex index first), so
/// the two triangles sharing an edge compute bit-identical values of
/// opposite meaning; a centre exactly on an edge or a vertex is decided by
/// the sign the edge function takes at `p + (ε, ε²)` (simulation of
/// simplicity), which gives it to exactly one of the triangles tiling the
/// region around it.
pub struct TriangleTest {
    /// Canonical edges opposite corners 0, 1, 2.
    pub edges: [EdgeFunction; 3],
    /// Twice the signed area (u, v).
    #[cfg(test)]
    area2: f64,
}

/// One canonical edge of a [`TriangleTest`].
pub struct EdgeFunction {
    /// Start and direction `end − start` of the canonical edge.
    pub a: DVec2,
    /// See [`Self::a`].
    pub d: DVec2,
    /// `±1`: whether the triangle's interior is on the canonical edge's
    /// left. [`Self::value`] times `side` is twice the signed area of the
    /// point and the edge taken in the triangle's order: the opposite
    /// corner's barycentric coordinate times twice the triangle's area.
    pub side: f64,
    /// Whether a point exactly on the edge's line belongs to the interior
    /// (the sign at `p + (ε, ε²)`: `−sign(d.v)`, or `sign(d.u)` when the
    /// edge runs along u, times `side`).
    tie_inside: bool,
}

impl TriangleTest {
    /// The triangle with vertex ids `ids` at `q`.
    #[cfg(test)]
    pub fn new(ids: [u32; 3], q: [DVec2; 3]) -> Self {
        Self::with_area(ids, q, crate::projection::signed_area2(q[0], q[1], q[2]))
    }

    /// The triangle with vertex ids `ids` at `q`, twice its signed area
    /// being `area2` (non-zero).
    #[inline(always)]
    pub fn with_area(ids: [u32; 3], q: [DVec2; 3], area2: f64) -> Self {
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
    pub fn contains(&self, p: DVec2) -> bool {
        // `&` and `|`, not `&&` and `||`: no branch per edge
        self.edges.iter().fold(true, |inside, e| {
            let value = e.value(p);
            inside & ((value * e.side > 0.0) | ((value == 0.0) & e.tie_inside))
        })
    }

    /// [`Self::contains`] at four points `(px[l], py)`, bit `l` set when
    /// inside: the same IEEE operations lane by lane, so the same answers.
    #[inline(always)]
    pub fn contains4(&self, px: f64x4, py: f64) -> u32 {
        let (zero, py) = (f64x4::ZERO, f64x4::splat(py));
        let inside = self
            .edges
            .iter()
            .fold(f64x4::splat(-1.0).simd_lt(zero), |inside, e| {
                let value = f64x4::splat(e.d.x) * (py - f64x4::splat(e.a.y))
                    - f64x4::splat(e.d.y) * (px - f64x4::splat(e.a.x));
                let tie = f64x4::splat(e.tie_mask());
                inside
                    & ((value * f64x4::splat(e.side)).simd_gt(zero) | (value.simd_eq(zero) & tie))
            });
        inside.to_bitmask()
    }

    /// Barycentric coordinates of `p` if the fill rule puts it inside.
    #[cfg(test)]
    pub fn barycentric(&self, p: DVec2) -> Option<[f64; 3]> {
        if !self.contains(p) {
            return None;
        }
        let e = self.edges.each_ref().map(|e| e.value(p) * e.side);
        let total = self.area2.abs();
        let (b0, b1) = (e[0] / total, e[1] / total);
        Some([b0, b1, 1.0 - b0 - b1])
    }
}

/// A triangle's fill-rule test along the rows of one block of up to eight
/// consecutive columns: the part of each edge function that depends only
/// on the column is computed once per triangle, so a row costs one
/// subtraction and the sign tests per edge and lane. The edge's side is
/// folded into its coefficients (a sign flip is exact and rounding is
/// symmetric), so `side·value` comes out bit for bit as
/// [`TriangleTest::contains`] gets it: the same answers.
pub struct RowTest {
    /// Per edge: `side·d.u`, `a.v` and the tie mask (all bits set when a
    /// point on the edge's line is inside).
    rows: [(f64, f64, f64x4); 3],
    /// Per edge, per block of four columns: `side·d.v·(i − a.u)`.
    columns: [[f64x4; 2]; 3],
    /// Whether the second block holds any column.
    second: bool,
    /// One bit per column of the block.
    valid: u32,
}

impl RowTest {
    /// The test of `test` over the columns `first .. first + count`
    /// (`count` ≤ 8), whose centres are at `u = first, first + 1, …`.
    #[inline(always)]
    pub fn new(test: &TriangleTest, first: usize, count: usize) -> Self {
        debug_assert!(count <= 8);
        let (block0, block1) = (column_lanes(first), column_lanes(first + 4));
        let edge = |e: &EdgeFunction| {
            let sy = f64x4::splat(e.side * e.d.y);
            let ax = f64x4::splat(e.a.x);
            [sy * (block0 - ax), sy * (block1 - ax)]
        };
        let row = |e: &EdgeFunction| (e.side * e.d.x, e.a.y, f64x4::splat(e.tie_mask()));
        Self {
            rows: test.edges.each_ref().map(row),
            columns: test.edges.each_ref().map(edge),
            second: count > 4,
            valid: (1u32 << count) - 1,
        }
    }

    /// The columns of the block inside on the row `v = py`: bit `l` for
    /// column `first + l`.
    #[inline(always)]
    pub fn inside(&self, py: f64) -> u32 {
        let zero = f64x4::ZERO;
        let block = |b: usize| {
            let all = f64x4::splat(-1.0).simd_lt(zero);
            (0..3).fold(all, |inside, e| {
                let (sx, ay, tie) = self.rows[e];
                let value = f64x4::splat(sx * (py - ay)) - self.columns[e][b];
                inside & (value.simd_gt(zero) | (value.simd_eq(zero) & tie))
            })
        };
        let mut inside = block(0).to_bitmask();
        if self.second {
            inside |= block(1).to_bitmask() << 4;
        }
        inside & self.valid
    }
}

/// The index-space centres of columns `first .. first + 4` (u), as lanes.
#[inline(always)]
pub fn column_lanes(first: usize) -> f64x4 {
    f64x4::splat(first as f64) + f64x4::new([0.0, 1.0, 2.0, 3.0])
}

impl EdgeFunction {
    /// All bits set when a point on the edge's line is inside, else zero:
    /// the tie rule as a lane mask, not a branch.
    #[inline(always)]
    fn tie_mask(&self) -> f64 {
        f64::from_bits(0u64.wrapping_sub(u64::from(self.tie_inside)))
    }

    /// The edge function at `p`: `d × (p − a)` — the same operations
    /// [`TriangleTest::contains4`] runs lane by lane.
    #[inline(always)]
    pub fn value(&self, p: DVec2) -> f64 {
        self.d.x * (p.y - self.a.y) - self.d.y * (p.x - self.a.x)
    }
}

#[cfg(test)]
#[path = "fill_rule_tests.rs"]
mod tests;
