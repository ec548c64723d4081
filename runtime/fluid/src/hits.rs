//! Where column centres cross the surface: the 2-D point-in-triangle test
//! with a fill rule that gives every centre to exactly one triangle of a
//! tiled region, and the height and barycentric coordinates there.

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

/// Every crossing of every column, found by `k` workers per triangle
/// (unordered).
pub fn find_hits(p: &ProjectedSurface<'_>, k: usize) -> Vec<Hit> {
    let n = p.triangles.len();
    (0..n * k)
        .into_par_iter()
        .with_min_len(64)
        .fold(Vec::new, |mut acc, worker| {
            triangle_lane_hits(p, worker / k, worker % k, k, &mut acc);
            acc
        })
        .reduce(Vec::new, |mut a, mut b| {
            if a.len() < b.len() {
                std::mem::swap(&mut a, &mut b);
            }
            a.append(&mut b);
            a
        })
}

/// The crossings worker `lane` of `k` finds for triangle `t`.
fn triangle_lane_hits(
    p: &ProjectedSurface<'_>,
    t: usize,
    lane: usize,
    k: usize,
    out: &mut Vec<Hit>,
) {
    let pt = p.triangles[t];
    let count = pt.candidate_count();
    if count == 0 {
        return;
    }
    let ids = p.surface.triangles[t];
    let corners = ids.map(|v| p.uvh[v as usize]);
    let test = TriangleTest::new(ids, corners.map(|c| c.truncate()));
    let ([i0, i1], [j0, _]) = pt.candidates;
    let width = i1 - i0;
    for m in lane_candidates(lane, k, count) {
        let (i, j) = (i0 + m % width, j0 + m / width);
        if let Some(bary) = test.barycentric(p.grid.centre(i, j)) {
            let h =
                DVec3::from_array(bary).dot(DVec3::new(corners[0].z, corners[1].z, corners[2].z));
            out.push(Hit {
                column: (i + j * p.grid.n[0]) as u32,
                triangle_and_side: t as u32 | if pt.side == Side::Top { TOP } else { 0 },
                height: h,
            });
        }
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
    /// Canonical edges opposite corners 0, 1, 2: start, end, and `±1` for
    /// whether the triangle's interior is on the canonical edge's left.
    edges: [(DVec2, DVec2, f64); 3],
    /// Twice the signed area (u, v).
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
            area2,
        }
    }

    /// Barycentric coordinates of `p` if the fill rule puts it inside.
    fn barycentric(&self, p: DVec2) -> Option<[f64; 3]> {
        let mut e = [0.0; 3];
        for (out, &(a, b, side)) in e.iter_mut().zip(&self.edges) {
            let d = b - a;
            let value = d.perp_dot(p - a);
            let sign = if value != 0.0 {
                value.signum()
            } else if d.y != 0.0 {
                -d.y.signum()
            } else {
                d.x.signum()
            };
            if sign * side <= 0.0 {
                return None;
            }
            *out = value * side;
        }
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
