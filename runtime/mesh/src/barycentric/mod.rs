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

mod gpu;
#[cfg(any(test, feature = "test-support"))]
pub mod parity;
mod search;

pub use gpu::{GpuBinding, MAP_WGSL};

use crate::tet_mesh::TetMesh;
use glam::DVec3;
use rayon::prelude::*;
use search::{SurfaceGrid, TetGrid, clamped};
use std::sync::OnceLock;
use wide::f32x4;

/// Weights below `−CONTAINED` still count as inside (points on shared
/// faces, rounding).
pub(crate) const CONTAINED: f64 = 1e-9;

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

impl BarycentricBinding {
    /// Binds `n` rest points, `point(i)` in world mm.
    pub fn bind(mesh: &TetMesh, n: usize, point: impl Fn(usize) -> DVec3 + Sync) -> Self {
        let grid = TetGrid::new(mesh);
        // Built by the first point outside the mesh, if any.
        let surface = OnceLock::new();
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
                let surface = surface.get_or_init(|| SurfaceGrid::new(mesh));
                let (t, w) = surface.nearest(mesh, p);
                (t, quantised(w), true)
            })
            .collect();
        Self {
            outside: found.iter().filter(|f| f.2).count(),
            tet: found.iter().map(|f| f.0).collect(),
            weights: found.iter().map(|f| f.1).collect(),
        }
    }

    /// Point `i`'s displacement (mm) under the nodes' displacements `u`
    /// (mm, f64): one point of [`Self::map`], for the few a cut or a box
    /// query looks at.
    pub fn displacement_of(&self, mesh: &TetMesh, i: usize, u: &[DVec3]) -> DVec3 {
        let w = unpack(self.weights[i]);
        let tet = mesh.tets[self.tet[i] as usize];
        (0..4).map(|c| w[c] as f64 * u[tet[c] as usize]).sum()
    }

    /// Binds point `i` (rest position `p`, mm) to tetrahedron `t` of `mesh`
    /// by its clamped weights: a point outside `t` follows the point of `t`
    /// its weights clamp to (a cut moves a point carried across it to a
    /// tetrahedron of its own side, which it may lie just outside).
    pub fn bind_to(&mut self, mesh: &TetMesh, i: usize, t: u32, p: DVec3) {
        self.tet[i] = t;
        self.weights[i] = quantised(clamped(weights(mesh.corners(t as usize), p)));
    }

    /// Follows a removal of tetrahedra from the mesh the points were
    /// bound to (a carve): `new_index[t]` is old tetrahedron `t`'s index in
    /// `mesh` (the mesh after the removal) or `u32::MAX` where it is gone,
    /// `old` the mesh before, and `rest(i)` point `i`'s rest position (mm).
    /// Points of surviving tetrahedra keep their weights; the others bind
    /// to the nearest remaining tetrahedron by clamped weights, and those
    /// that were inside the removed one now count as outside. Returns how
    /// many points were bound anew.
    pub fn after_removal(
        &mut self,
        old: &TetMesh,
        mesh: &TetMesh,
        new_index: &[u32],
        rest: impl Fn(usize) -> DVec3 + Sync,
    ) -> usize {
        let surface = OnceLock::new();
        let rebound: Vec<(usize, u32, [u16; 3], bool)> = (0..self.len())
            .into_par_iter()
            .filter_map(|i| {
                let old_t = self.tet[i] as usize;
                if new_index[old_t] != u32::MAX {
                    return None;
                }
                let p = rest(i);
                let was_inside = weights(old.corners(old_t), p)
                    .iter()
                    .all(|&w| w >= -CONTAINED);
                let surface = surface.get_or_init(|| SurfaceGrid::new(mesh));
                let (t, w) = surface.nearest(mesh, p);
                // On a face the removed tetrahedron shared with a kept one:
                // still inside the proxy.
                let x = mesh.corners(t as usize);
                let on = (0..4).map(|k| x[k] * w[k]).sum::<DVec3>();
                let size = (x[1] - x[0]).length();
                let now_outside = (on - p).length() > 1e-9 * size;
                Some((i, t, quantised(w), was_inside && now_outside))
            })
            .collect();
        // Renumber the kept ones first (the rebound still hold old
        // indices of removed tetrahedra here), then write the rebound.
        for t in &mut self.tet {
            let new = new_index[*t as usize];
            if new != u32::MAX {
                *t = new;
            }
        }
        for &(i, t, w, newly_outside) in &rebound {
            self.tet[i] = t;
            self.weights[i] = w;
            self.outside += usize::from(newly_outside);
        }
        rebound.len()
    }

    /// Number of bound points.
    pub fn len(&self) -> usize {
        self.tet.len()
    }

    /// True when no point is bound.
    pub fn is_empty(&self) -> bool {
        self.tet.is_empty()
    }

    /// Adds point forces to the nodes (`nodes += Bᵀ forces`): each point's
    /// force spread over its tetrahedron's corners by its barycentric
    /// weights, the transpose of [`BarycentricBinding::gather`], so the
    /// nodal forces do the work the point forces do. One force per point;
    /// µN (any unit: the map is linear).
    pub fn spread(&self, mesh: &TetMesh, forces: &[DVec3], nodes: &mut [DVec3]) {
        for ((&t, &q), f) in self.tet.iter().zip(&self.weights).zip(forces) {
            let w = unpack(q);
            for (k, &n) in mesh.tets[t as usize].iter().enumerate() {
                nodes[n as usize] += w[k] as f64 * *f;
            }
        }
    }

    /// The bound points' values interpolated from per-node values
    /// (`out = B node_values`), in f64: the map of
    /// [`BarycentricBinding::map`] without its f32 arrays.
    pub fn gather(&self, mesh: &TetMesh, node_values: &[DVec3], out: &mut [DVec3]) {
        for ((o, &t), &q) in out.iter_mut().zip(&self.tet).zip(&self.weights) {
            let w = unpack(q);
            *o = mesh.tets[t as usize]
                .iter()
                .enumerate()
                .map(|(k, &n)| w[k] as f64 * node_values[n as usize])
                .sum();
        }
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
