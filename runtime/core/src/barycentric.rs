//! Barycentric binding: rest points embedded in a tetrahedral proxy, and the
//! map that moves them with the proxy's nodes.
//!
//! [`BarycentricBinding::bind`] finds, for each rest point (world mm), the
//! tetrahedron that contains it and its four barycentric weights, through a
//! uniform grid of tetrahedron bounding boxes. A point outside every
//! tetrahedron binds to the nearest one by its clamped weights (negative
//! weights set to zero and the rest renormalised, so the point follows the
//! nearest surface point) and is counted in [`BarycentricBinding::outside`].
//! [`BarycentricBinding::map`] is then, per point, `u = Σ w_i u_i` over the
//! four nodes' displacements (mm), so affine motions are reproduced.
//!
//! **Decision:** weights are stored as three 16-bit fractions (the fourth
//! is one minus their sum): 10 bytes per point with the tetrahedron index
//! instead of 20. Mapping 256³ points streams those bytes every frame and is
//! bound by memory, so this is what brings it under 50 ms on two cores; the
//! quantisation moves a point by at most 1/65535 of its tetrahedron's size
//! (1.5e-5 of a cell: far below the resampler's f32 rounding of world
//! positions at 100 mm).

use crate::tet_mesh::TetMesh;
use glam::DVec3;
use rayon::prelude::*;
use wide::f32x4;

/// Weights below `−CONTAINED` still count as inside (points on shared
/// faces, rounding).
const CONTAINED: f64 = 1e-9;

/// Rest points bound to a tetrahedral mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct BarycentricBinding {
    /// Tetrahedron of each point.
    pub tet: Vec<u32>,
    /// Weights of corners 1, 2, 3 of each point's tetrahedron in units of
    /// 1/65535 (corner 0 takes the rest; none negative).
    pub weights: Vec<[u16; 3]>,
    /// Points that lie outside every tetrahedron (bound to the nearest).
    pub outside: usize,
}

/// A uniform grid over the mesh bounds; each cell lists the tetrahedra
/// whose bounding boxes overlap it (compressed rows).
struct TetGrid {
    lo: DVec3,
    cell: f64,
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl TetGrid {
    fn new(mesh: &TetMesh) -> Self {
        let (lo, hi) = mesh.bounds();
        // About one tetrahedron per cell (at most 1024 cells per axis).
        let extent = hi - lo;
        let volume = extent.x.max(1e-9) * extent.y.max(1e-9) * extent.z.max(1e-9);
        let cell = (volume / mesh.tets.len() as f64)
            .cbrt()
            .max(extent.max_element() / 1024.0)
            .max(1e-9);
        let dims = [0, 1, 2].map(|a| ((extent[a] / cell).floor() as usize + 1).min(1024));
        let range = |t: usize| {
            let x = mesh.corners(t);
            let (a, b) = x
                .iter()
                .fold((x[0], x[0]), |(a, b), p| (a.min(*p), b.max(*p)));
            (
                Self::cell_of(lo, cell, dims, a),
                Self::cell_of(lo, cell, dims, b),
            )
        };
        let linear = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
        let mut count = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        for t in 0..mesh.tets.len() {
            let (a, b) = range(t);
            for k in a[2]..=b[2] {
                for j in a[1]..=b[1] {
                    for i in a[0]..=b[0] {
                        count[linear([i, j, k]) + 1] += 1;
                    }
                }
            }
        }
        for c in 1..count.len() {
            count[c] += count[c - 1];
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; *count.last().unwrap_or(&0) as usize];
        for t in 0..mesh.tets.len() {
            let (a, b) = range(t);
            for k in a[2]..=b[2] {
                for j in a[1]..=b[1] {
                    for i in a[0]..=b[0] {
                        let c = linear([i, j, k]);
                        items[fill[c] as usize] = t as u32;
                        fill[c] += 1;
                    }
                }
            }
        }
        Self {
            lo,
            cell,
            dims,
            start: count,
            items,
        }
    }

    fn cell_of(lo: DVec3, cell: f64, dims: [usize; 3], p: DVec3) -> [usize; 3] {
        [0, 1, 2].map(|a| (((p[a] - lo[a]) / cell).floor().max(0.0) as usize).min(dims[a] - 1))
    }

    /// The tetrahedra listed in the cells at Chebyshev distance `ring` from
    /// cell `c` (cell indices).
    fn ring(&self, c: [usize; 3], ring: usize, mut visit: impl FnMut(u32)) {
        let r = ring as isize;
        for dk in -r..=r {
            for dj in -r..=r {
                for di in -r..=r {
                    if di.abs().max(dj.abs()).max(dk.abs()) != r {
                        continue;
                    }
                    let q = [c[0] as isize + di, c[1] as isize + dj, c[2] as isize + dk];
                    if (0..3).any(|a| q[a] < 0 || q[a] >= self.dims[a] as isize) {
                        continue;
                    }
                    let l = q[0] as usize
                        + self.dims[0] * (q[1] as usize + self.dims[1] * q[2] as usize);
                    for &t in &self.items[self.start[l] as usize..self.start[l + 1] as usize] {
                        visit(t);
                    }
                }
            }
        }
    }
}

/// Barycentric weights of `p` in the tetrahedron with corners `x` (f64).
#[inline]
pub fn weights(x: [DVec3; 4], p: DVec3) -> [f64; 4] {
    let (e1, e2, e3) = (x[1] - x[0], x[2] - x[0], x[3] - x[0]);
    let d = p - x[0];
    let det = e1.dot(e2.cross(e3));
    let w1 = d.dot(e2.cross(e3)) / det;
    let w2 = e1.dot(d.cross(e3)) / det;
    let w3 = e1.dot(e2.cross(d)) / det;
    [1.0 - w1 - w2 - w3, w1, w2, w3]
}

/// Weights in units of 1/65535 of corners 1–3 (their sum at most 65535).
fn quantised(w: [f64; 4]) -> [u16; 3] {
    let mut q = [1, 2, 3].map(|k| (w[k].clamp(0.0, 1.0) * 65535.0).round() as u32);
    let sum: u32 = q.iter().sum();
    if sum > 65535 {
        let big = (0..3).max_by_key(|&k| q[k]).expect("three weights");
        q[big] -= sum - 65535;
    }
    q.map(|v| v as u16)
}

/// The four weights (sum 1) of a quantised set.
#[inline]
pub fn unpack(q: [u16; 3]) -> [f32; 4] {
    const UNIT: f32 = 1.0 / 65535.0;
    let w = q.map(|v| v as f32 * UNIT);
    [1.0 - w[0] - w[1] - w[2], w[0], w[1], w[2]]
}

/// `w` with negative weights set to zero, renormalised (rounding on shared
/// faces).
fn clamped(w: [f64; 4]) -> [f64; 4] {
    let c = w.map(|v| v.max(0.0));
    let s: f64 = c.iter().sum();
    c.map(|v| v / s)
}

/// The point of triangle `t` nearest `p` (Ericson, *Real-Time Collision
/// Detection*, 5.1.5), as weights of the triangle's corners.
fn nearest_on_triangle(t: [DVec3; 3], p: DVec3) -> [f64; 3] {
    let (a, b, c) = (t[0], t[1], t[2]);
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    [1.0 - v - w, v, w]
}

/// The weights of the point of tetrahedron `x` nearest `p` (`p`'s own
/// weights when it is inside), and the squared distance (mm²).
fn nearest_in_tet(x: [DVec3; 4], p: DVec3) -> ([f64; 4], f64) {
    let w = weights(x, p);
    if w.iter().all(|&v| v >= -CONTAINED) {
        return (clamped(w), 0.0);
    }
    let mut best = ([0.0; 4], f64::INFINITY);
    for skip in 0..4 {
        let idx: Vec<usize> = (0..4).filter(|&k| k != skip).collect();
        let f = nearest_on_triangle([x[idx[0]], x[idx[1]], x[idx[2]]], p);
        let q = x[idx[0]] * f[0] + x[idx[1]] * f[1] + x[idx[2]] * f[2];
        let d = (q - p).length_squared();
        if d < best.1 {
            let mut w = [0.0; 4];
            for (m, &k) in idx.iter().enumerate() {
                w[k] = f[m];
            }
            best = (w, d);
        }
    }
    best
}

impl BarycentricBinding {
    /// Binds `n` rest points, `point(i)` in world mm.
    pub fn bind(mesh: &TetMesh, n: usize, point: impl Fn(usize) -> DVec3 + Sync) -> Self {
        let grid = TetGrid::new(mesh);
        let found: Vec<(u32, [u16; 3], bool)> = (0..n)
            .into_par_iter()
            .map(|i| {
                let p = point(i);
                let c = TetGrid::cell_of(grid.lo, grid.cell, grid.dims, p);
                let mut inside = None;
                grid.ring(c, 0, |t| {
                    if inside.is_none() {
                        let w = weights(mesh.corners(t as usize), p);
                        if w.iter().all(|&v| v >= -CONTAINED) {
                            inside = Some((t, clamped(w)));
                        }
                    }
                });
                if let Some((t, w)) = inside {
                    return (t, quantised(w), false);
                }
                let (t, w) = nearest(mesh, &grid, c, p);
                (t, quantised(w), true)
            })
            .collect();
        Self {
            outside: found.iter().filter(|f| f.2).count(),
            tet: found.iter().map(|f| f.0).collect(),
            weights: found.iter().map(|f| f.1).collect(),
        }
    }

    /// Number of bound points.
    pub fn len(&self) -> usize {
        self.tet.len()
    }

    /// True when no point is bound.
    pub fn is_empty(&self) -> bool {
        self.tet.is_empty()
    }

    /// The bound points' displacements (mm) from the nodes' `node_u` (mm,
    /// x/y/z arrays), written into `out`.
    pub fn map(&self, mesh: &TetMesh, node_u: [&[f32]; 3], out: [&mut [f32]; 3]) {
        const CHUNK: usize = 1 << 14;
        let [ox, oy, oz] = out;
        // Each node's displacement as one 4-lane vector: a point then reads
        // four vectors instead of twelve scalars.
        let nodes: Vec<f32x4> = (0..node_u[0].len())
            .map(|n| f32x4::from([node_u[0][n], node_u[1][n], node_u[2][n], 0.0]))
            .collect();
        ox.par_chunks_mut(CHUNK)
            .zip(oy.par_chunks_mut(CHUNK))
            .zip(oz.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((x, y), z))| {
                let first = c * CHUNK;
                let tets = &self.tet[first..first + x.len()];
                let weights = &self.weights[first..first + x.len()];
                for (i, (&t, &q)) in tets.iter().zip(weights).enumerate() {
                    let tet = mesh.tets[t as usize];
                    let w = unpack(q);
                    let u = nodes[tet[0] as usize] * w[0]
                        + nodes[tet[1] as usize] * w[1]
                        + nodes[tet[2] as usize] * w[2]
                        + nodes[tet[3] as usize] * w[3];
                    let u = u.to_array();
                    (x[i], y[i], z[i]) = (u[0], u[1], u[2]);
                }
            });
    }
}

/// The tetrahedron nearest `p` and the weights of its nearest point,
/// searching rings of grid cells outward from cell `c` (`p`'s cell, or the
/// nearest one when `p` lies outside the grid). Cells of ring `r + 1` lie
/// at least `r` cell widths from `p` (projecting `p` onto the grid's box
/// never lengthens a distance to it), so the search stops once that bound
/// passes the best distance found.
fn nearest(mesh: &TetMesh, grid: &TetGrid, c: [usize; 3], p: DVec3) -> (u32, [f64; 4]) {
    let mut best: Option<(f64, u32, [f64; 4])> = None;
    let max_ring = grid.dims.iter().copied().max().unwrap_or(1);
    for r in 0..=max_ring {
        grid.ring(c, r, |t| {
            let (w, d) = nearest_in_tet(mesh.corners(t as usize), p);
            if best.is_none_or(|b| d < b.0) {
                best = Some((d, t, w));
            }
        });
        if let Some((d, ..)) = best
            && r as f64 * grid.cell >= d.sqrt()
        {
            break;
        }
    }
    let (_, t, w) = best.expect("a mesh has at least one tetrahedron");
    (t, w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::proxy::uniform_proxy;

    fn mesh() -> TetMesh {
        let grid = Grid::new(
            [12, 9, 7],
            DVec3::new(1.0, 1.5, 2.0),
            DVec3::new(-4.0, 2.0, 1.0),
        );
        uniform_proxy(&grid, 3, |_| Some(0)).unwrap()
    }

    /// Pseudo-random points in the box `[lo, hi]`.
    fn points(lo: DVec3, hi: DVec3, n: usize) -> Vec<DVec3> {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        (0..n)
            .map(|_| {
                let mut r = [0f64; 3];
                for v in &mut r {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    *v = (x >> 11) as f64 / (1u64 << 53) as f64;
                }
                lo + (hi - lo) * DVec3::from_array(r)
            })
            .collect()
    }

    #[test]
    fn the_map_reproduces_an_affine_motion_exactly() {
        let m = mesh();
        let (lo, hi) = m.bounds();
        let pts = points(lo, hi, 3000);
        let b = BarycentricBinding::bind(&m, pts.len(), |i| pts[i]);
        assert_eq!(b.outside, 0);
        let a = [
            [0.02, -0.01, 0.03],
            [0.015, 0.01, -0.02],
            [-0.01, 0.025, 0.005],
        ];
        let shift = [0.7, -1.1, 0.4];
        let field = |p: DVec3, r: usize| -> f64 {
            a[r][0] * p.x + a[r][1] * p.y + a[r][2] * p.z + shift[r]
        };
        let node_u: Vec<Vec<f32>> = (0..3)
            .map(|r| m.nodes.iter().map(|p| field(*p, r) as f32).collect())
            .collect();
        let mut out = [
            vec![0f32; pts.len()],
            vec![0f32; pts.len()],
            vec![0f32; pts.len()],
        ];
        let [ox, oy, oz] = &mut out;
        b.map(&m, [&node_u[0], &node_u[1], &node_u[2]], [ox, oy, oz]);
        for (i, p) in pts.iter().enumerate() {
            for (r, axis) in out.iter().enumerate() {
                let e = (axis[i] as f64 - field(*p, r)).abs();
                assert!(e < 1e-5, "point {p}: axis {r} off by {e} mm");
            }
        }
        // Every weight set is a convex combination.
        for &q in &b.weights {
            let w = unpack(q);
            assert!(w.iter().all(|&v| v >= -1e-6), "{w:?}");
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn points_outside_bind_to_the_nearest_tetrahedron_and_are_counted() {
        let m = mesh();
        let (lo, hi) = m.bounds();
        let pts = [
            lo - DVec3::splat(3.0),
            hi + DVec3::new(5.0, 0.0, 0.0),
            (lo + hi) / 2.0,
            DVec3::new(hi.x + 1.0, (lo.y + hi.y) / 2.0, (lo.z + hi.z) / 2.0),
        ];
        let b = BarycentricBinding::bind(&m, pts.len(), |i| pts[i]);
        assert_eq!(b.outside, 3);
        for (i, p) in pts.iter().enumerate() {
            let x = m.corners(b.tet[i] as usize);
            let w = unpack(b.weights[i]);
            let q: DVec3 = (0..4).map(|k| x[k] * w[k] as f64).sum();
            // The bound point is the nearest point of the mesh's box.
            let nearest = p.clamp(lo, hi);
            assert!(
                (q - nearest).length() < 1e-4,
                "{p}: bound to {q}, want {nearest}"
            );
        }
    }
}
