//! The mid-edge layer of quadratic (P2, 10-node) tetrahedra as `map` sees
//! it: a solver with quadratic elements keeps one node per proxy edge, and
//! the bound points follow the quadratic interpolation
//!
//! `u(λ) = Σ_a λ_a u_a + Σ_(a,b) 4 λ_a λ_b d_ab`, `d_ab = u_ab − (u_a + u_b) / 2`,
//!
//! over the tetrahedron's corners `a` and edges `(a, b)` (the 10 quadratic
//! shape functions `λ_a (2 λ_a − 1)` and `4 λ_a λ_b` rearranged): the
//! linear map of the corners plus each edge's deviation `d_ab` from the
//! straight line between its ends, so the linear solvers' map is this one
//! with every `d` zero. Displacements in mm; `λ` are the binding's
//! barycentric weights in the proxy tetrahedron's corner order.

use crate::barycentric::{BarycentricBinding, unpack};
use glam::DVec3;
use rayon::prelude::*;

/// A tetrahedron's six edges as pairs of its corners, in the order of the
/// VTK quadratic tetrahedron (cell type 24): 01, 12, 02, 03, 13, 23.
pub const TET_EDGES: [[usize; 2]; 6] = [[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]];

/// The mid-edge layer of a quadratic solver, borrowed for `map`.
#[derive(Clone, Copy, Debug)]
pub struct EdgeLayer<'a> {
    /// Per proxy tetrahedron, its edges' indices in `deviation`, in
    /// [`TET_EDGES`] order.
    pub tet_edges: &'a [[u32; 6]],
    /// Per edge, the mid-edge node's displacement minus the mean of its
    /// ends' (mm).
    pub deviation: &'a [DVec3],
}

impl EdgeLayer<'_> {
    /// The quadratic part (mm) at barycentric weights `w` of tetrahedron `t`.
    #[inline]
    pub fn correction(&self, t: usize, w: [f32; 4]) -> DVec3 {
        let edges = &self.tet_edges[t];
        TET_EDGES
            .iter()
            .zip(edges)
            .map(|([a, b], &e)| self.deviation[e as usize] * (4.0 * w[*a] as f64 * w[*b] as f64))
            .sum()
    }

    /// Adds the quadratic part to the linear map `out` (mm, x/y/z arrays)
    /// of `binding`'s points.
    pub fn add_to_map(&self, binding: &BarycentricBinding, out: [&mut [f32]; 3]) {
        let [x, y, z] = out;
        x.par_iter_mut()
            .zip(y.par_iter_mut())
            .zip(z.par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, ((x, y), z))| {
                let c = self.correction(binding.tet[i] as usize, unpack(binding.weights[i]));
                *x += c.x as f32;
                *y += c.y as f32;
                *z += c.z as f32;
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_correction_is_the_edge_deviation_at_its_midpoint_and_zero_at_corners() {
        let deviation: Vec<DVec3> = (0..6).map(|e| DVec3::splat(e as f64 + 1.0)).collect();
        let tet_edges = [[0, 1, 2, 3, 4, 5]];
        let layer = EdgeLayer {
            tet_edges: &tet_edges,
            deviation: &deviation,
        };
        for a in 0..4 {
            let mut w = [0.0; 4];
            w[a] = 1.0;
            assert_eq!(layer.correction(0, w), DVec3::ZERO, "corner {a}");
        }
        for (k, [a, b]) in TET_EDGES.iter().enumerate() {
            let mut w = [0.0; 4];
            (w[*a], w[*b]) = (0.5, 0.5);
            assert_eq!(layer.correction(0, w), deviation[k], "edge {k}");
        }
        // At the centroid each edge weighs 4/16.
        let sum: DVec3 = deviation.iter().copied().sum();
        assert!((layer.correction(0, [0.25; 4]) - sum * 0.25).length() < 1e-7);
    }
}
