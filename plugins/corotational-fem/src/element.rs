//! A linear (P1) tetrahedron of isotropic linear-elastic material, in the
//! rest frame: shape-function gradients, volume, Lamé parameters, its
//! stiffness blocks, and its corotated forces and stiffness.
//!
//! Units: positions mm, gradients 1/mm, volume mm³, moduli Pa, forces µN.

use crate::polar::rotation;
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::mesh_model::ElasticMaterial;
use voxflex_core::tet_mesh::TetMesh;

/// One tetrahedron's precomputed rest quantities.
#[derive(Clone, Debug)]
pub struct Element {
    /// Node indices.
    pub nodes: [u32; 4],
    /// Rest positions of the corners, mm.
    pub rest: [DVec3; 4],
    /// Gradients of the four shape functions, 1/mm.
    pub grads: [DVec3; 4],
    /// Inverse of the rest edge matrix `[X1 − X0, X2 − X0, X3 − X0]`.
    pub dm_inv: DMat3,
    /// Rest volume, mm³.
    pub volume: f64,
    /// Lamé λ, Pa.
    pub lambda: f64,
    /// Lamé μ, Pa.
    pub mu: f64,
}

impl Element {
    /// Tetrahedron `t` of `mesh` (positively oriented).
    pub fn new(mesh: &TetMesh, t: usize, material: &ElasticMaterial) -> Self {
        let nodes = mesh.tets[t];
        let rest = nodes.map(|n| mesh.nodes[n as usize]);
        let dm = DMat3::from_cols(rest[1] - rest[0], rest[2] - rest[0], rest[3] - rest[0]);
        let dm_inv = dm.inverse();
        // Row i of Dm⁻¹ is the gradient of the barycentric coordinate of
        // corner i + 1.
        let r = dm_inv.transpose();
        let (g1, g2, g3) = (r.x_axis, r.y_axis, r.z_axis);
        let (lambda, mu) = material.lame();
        Self {
            nodes,
            rest,
            grads: [-(g1 + g2 + g3), g1, g2, g3],
            dm_inv,
            volume: dm.determinant() / 6.0,
            lambda,
            mu,
        }
    }

    /// The rest stiffness block coupling corners `a` and `b` (µN/mm):
    /// `V (λ g_a g_bᵀ + μ g_b g_aᵀ + μ (g_a · g_b) I)`.
    #[inline]
    pub fn stiffness(&self, a: usize, b: usize) -> DMat3 {
        let (ga, gb) = (self.grads[a], self.grads[b]);
        let outer = |p: DVec3, q: DVec3| DMat3::from_cols(p * q.x, p * q.y, p * q.z);
        (outer(ga, gb) * self.lambda
            + outer(gb, ga) * self.mu
            + DMat3::from_diagonal(DVec3::splat(self.mu * ga.dot(gb))))
            * self.volume
    }

    /// The deformation gradient at corner positions `x` (mm).
    #[inline]
    pub fn deformation_gradient(&self, x: [DVec3; 4]) -> DMat3 {
        DMat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]) * self.dm_inv
    }

    /// The element's rotation at displacements `u` (mm) of its corners.
    #[inline]
    pub fn rotation(&self, u: [DVec3; 4]) -> DMat3 {
        let x = [0, 1, 2, 3].map(|a| self.rest[a] + u[a]);
        rotation(self.deformation_gradient(x))
    }

    /// The corotated stiffness blocks `R K_ab Rᵀ` (written to `k[4a + b]`)
    /// and the rotation's force offsets `f0_a = Σ_b R K_ab (X_b − Rᵀ X_b)`
    /// (µN; written to `f0[a]`), so that the elastic force is
    /// `f_int = K_rot u − f0`.
    #[inline]
    pub fn corotate(&self, r: DMat3, k: &mut [DMat3], f0: &mut [DVec3]) {
        let rt = r.transpose();
        let offset = self.rest.map(|x| x - rt * x);
        for a in 0..4 {
            let mut f = DVec3::ZERO;
            for b in 0..4 {
                let rk = r * self.stiffness(a, b);
                k[4 * a + b] = rk * rt;
                f += rk * offset[b];
            }
            f0[a] = f;
        }
    }

    /// The elastic force on each corner (µN; the force the element resists
    /// with, `R K (Rᵀ x − X)`) at corner displacements `u` (mm), with the
    /// element's rotation taken from `u`.
    pub fn elastic_force(&self, u: [DVec3; 4]) -> [DVec3; 4] {
        let r = self.rotation(u);
        let rt = r.transpose();
        let local = [0, 1, 2, 3].map(|b| rt * (self.rest[b] + u[b]) - self.rest[b]);
        [0, 1, 2, 3]
            .map(|a| r * (0..4).fold(DVec3::ZERO, |s, b| s + self.stiffness(a, b) * local[b]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DQuat;

    fn element() -> Element {
        let nodes = vec![
            DVec3::new(0.1, 0.0, 0.2),
            DVec3::new(2.0, 0.3, 0.0),
            DVec3::new(0.4, 1.7, 0.1),
            DVec3::new(0.2, 0.5, 1.9),
        ];
        let mesh = TetMesh::new("one", nodes, vec![[0, 1, 2, 3]], vec![0]).unwrap();
        Element::new(&mesh, 0, &ElasticMaterial::new(1000.0, 0.3, 1e-6))
    }

    #[test]
    fn gradients_and_stiffness_have_the_linear_elements_properties() {
        let e = element();
        // Gradients sum to zero and reproduce linear fields.
        let sum: DVec3 = e.grads.iter().copied().sum();
        assert!(sum.length() < 1e-12);
        let a = DVec3::new(0.3, -1.2, 0.7);
        let grad: DVec3 = (0..4).map(|i| e.grads[i] * a.dot(e.rest[i])).sum();
        assert!((grad - a).length() < 1e-12);
        // K is symmetric and a translation produces no force.
        for i in 0..4 {
            for j in 0..4 {
                let d = e.stiffness(i, j) - e.stiffness(j, i).transpose();
                assert!(d.to_cols_array().iter().all(|x| x.abs() < 1e-9));
            }
            let t: DVec3 = (0..4)
                .map(|j| e.stiffness(i, j) * DVec3::new(1.0, 2.0, 3.0))
                .sum();
            assert!(t.length() < 1e-9);
        }
    }

    #[test]
    fn a_rigid_rotation_produces_no_force() {
        let e = element();
        let q = DMat3::from_quat(DQuat::from_axis_angle(
            DVec3::new(0.2, 1.0, 0.4).normalize(),
            std::f64::consts::FRAC_PI_2,
        ));
        let u = e.rest.map(|x| q * x - x);
        let f = e.elastic_force(u);
        // Against the force a stretch of the same size would make.
        let stretched = e.rest.map(|x| x * 0.01);
        let scale = e
            .elastic_force(stretched)
            .iter()
            .map(|v| v.length())
            .fold(0.0, f64::max);
        let worst = f.iter().map(|v| v.length()).fold(0.0, f64::max);
        assert!(worst <= 1e-9 * scale * 100.0, "{worst} vs {scale}");
    }
}
