//! A linear (P1) tetrahedron of isotropic linear-elastic material, in the
//! rest frame: shape-function gradients, volume, Lamé parameters, its
//! stiffness blocks, and its corotated forces and stiffness.
//!
//! Units: positions mm, gradients 1/mm, volume mm³, moduli Pa, forces µN.

use crate::polar::{rotation, signed_svd};
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::tet_mesh::TetMesh;
use voxflex_mesh::mesh_model::ElasticMaterial;

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
        stiffness_block(
            self.grads[a],
            self.grads[b],
            self.lambda,
            self.mu,
            self.volume,
        )
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

    /// The warped stiffness `k[4a + b]` and force offsets `f0[a]`
    /// ([`Element::corotate`]) at corner displacements `u` (mm), with the
    /// rotation's own stiffness ([`add_twist`]) when `twist` is
    /// `Some(clamp)`: one signed SVD of `F` gives both.
    pub fn linearise(&self, u: [DVec3; 4], k: &mut [DMat3], f0: &mut [DVec3], twist: Option<bool>) {
        let x = [0, 1, 2, 3].map(|a| self.rest[a] + u[a]);
        let f = self.deformation_gradient(x);
        let Some(clamp) = twist else {
            self.corotate(rotation(f), k, f0);
            return;
        };
        let svd = signed_svd(f);
        self.corotate(svd.0 * svd.2.transpose(), k, f0);
        add_twist(
            svd,
            &self.grads,
            self.volume,
            (self.lambda, self.mu),
            k,
            clamp,
        );
    }

    /// The elastic force on each corner (µN) and the strain energy (µN·mm)
    /// at corner displacements `u` (mm), from one rotation: what
    /// [`Element::elastic_force`] and [`Element::energy`] give.
    pub fn force_and_energy(&self, u: [DVec3; 4]) -> ([DVec3; 4], f64) {
        let x = [0, 1, 2, 3].map(|a| self.rest[a] + u[a]);
        let f = self.deformation_gradient(x);
        let r = rotation(f);
        let energy = self.volume * rotated_energy_density(r, f, self.lambda, self.mu);
        (self.force_with(r, u), energy)
    }

    /// The element's strain energy (µN·mm) at corner displacements `u`
    /// (mm): `V (μ |ε|² + λ/2 (tr ε)²)` with the corotated strain
    /// `ε = sym(Rᵀ F) − I`. [`Element::elastic_force`] is its gradient
    /// (the polar `Rᵀ F` is symmetric, so the rotation's own change does
    /// not contribute), which lets the static solver's line search use it
    /// as a merit function.
    pub fn energy(&self, u: [DVec3; 4]) -> f64 {
        let x = [0, 1, 2, 3].map(|a| self.rest[a] + u[a]);
        self.volume * energy_density(self.deformation_gradient(x), self.lambda, self.mu)
    }

    /// The elastic force on each corner (µN; the force the element resists
    /// with, `R K (Rᵀ x − X)`) at corner displacements `u` (mm), with the
    /// element's rotation taken from `u`.
    pub fn elastic_force(&self, u: [DVec3; 4]) -> [DVec3; 4] {
        self.force_with(self.rotation(u), u)
    }

    /// [`Element::elastic_force`] with the rotation `r` given.
    #[inline]
    fn force_with(&self, r: DMat3, u: [DVec3; 4]) -> [DVec3; 4] {
        let rt = r.transpose();
        let local = [0, 1, 2, 3].map(|b| rt * (self.rest[b] + u[b]) - self.rest[b]);
        [0, 1, 2, 3]
            .map(|a| r * (0..4).fold(DVec3::ZERO, |s, b| s + self.stiffness(a, b) * local[b]))
    }
}

/// The stiffness block (µN/mm) of shape-function gradients `ga`, `gb`
/// (1/mm) over volume `w` (mm³): `w (λ g_a g_bᵀ + μ g_b g_aᵀ + μ (g_a · g_b) I)`.
#[inline]
pub fn stiffness_block(ga: DVec3, gb: DVec3, lambda: f64, mu: f64, w: f64) -> DMat3 {
    let outer = |p: DVec3, q: DVec3| DMat3::from_cols(p * q.x, p * q.y, p * q.z);
    (outer(ga, gb) * lambda
        + outer(gb, ga) * mu
        + DMat3::from_diagonal(DVec3::splat(mu * ga.dot(gb))))
        * w
}

/// The corotated energy density (Pa = µN·mm/mm³) at deformation gradient
/// `f`: `μ |ε|² + λ/2 (tr ε)²` with `ε = sym(Rᵀ F) − I`, `R` its rotation.
#[inline]
pub fn energy_density(f: DMat3, lambda: f64, mu: f64) -> f64 {
    rotated_energy_density(rotation(f), f, lambda, mu)
}

/// [`energy_density`] with `f`'s rotation `r` given.
#[inline]
pub fn rotated_energy_density(r: DMat3, f: DMat3, lambda: f64, mu: f64) -> f64 {
    let d = r.transpose() * f - DMat3::IDENTITY;
    let e = (d + d.transpose()) * 0.5;
    let trace = e.x_axis.x + e.y_axis.y + e.z_axis.z;
    let squares = e.x_axis.length_squared() + e.y_axis.length_squared() + e.z_axis.length_squared();
    mu * squares + 0.5 * lambda * trace * trace
}

/// Adds to `k[n a + b]` (`n = grads.len()`) the part of the energy's
/// Hessian that the corotated stiffness `R K Rᵀ` leaves out: the change of
/// the rotation itself, over volume `w` (mm³) with shape-function
/// gradients `grads` (1/mm) and Lamé `(λ, μ)` (Pa), from the signed SVD
/// `F = U Σ Vᵀ` ([`signed_svd`]). With
/// `ψ_i = ∂ψ/∂σ_i = 2μ (σ_i − 1) + λ (Σσ − 3)`, the Hessian has, on each
/// twist mode `T_ij = (u_i v_jᵀ − u_j v_iᵀ)/√2`, the eigenvalue
/// `(ψ_i + ψ_j)/(σ_i + σ_j)` where `R K Rᵀ` has 0 (Smith et al. 2019);
/// it is added where positive (an element in tension resists turning);
/// where negative (compression) it is added too unless `clamp`, which
/// keeps the tangent positive definite (projected Newton).
pub fn add_twist(
    (uu, sigma, vv): (DMat3, DVec3, DMat3),
    grads: &[DVec3],
    w: f64,
    (lambda, mu): (f64, f64),
    k: &mut [DMat3],
    clamp: bool,
) {
    let n = grads.len();
    let s = sigma.to_array();
    let stretch = s[0] + s[1] + s[2] - 3.0;
    let psi = s.map(|si| 2.0 * mu * (si - 1.0) + lambda * stretch);
    let mut tg = [DVec3::ZERO; 10];
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        let (ui, uj, vi, vj) = (uu.col(i), uu.col(j), vv.col(i), vv.col(j));
        let denom = s[i] + s[j];
        let eigen = (psi[i] + psi[j]) / denom;
        if !(denom > 1e-9 && (eigen > 0.0 || !clamp)) {
            continue;
        }
        // T g_a for each node.
        for (t, g) in tg.iter_mut().zip(grads) {
            *t = (ui * vj.dot(*g) - uj * vi.dot(*g)) * std::f64::consts::FRAC_1_SQRT_2;
        }
        let weight = eigen * w;
        for a in 0..n {
            for b in 0..n {
                let (p, q) = (tg[a], tg[b]);
                k[n * a + b] += DMat3::from_cols(p * q.x, p * q.y, p * q.z) * weight;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::element_checks::{
        assert_force_is_energy_gradient, assert_tangent_is_jacobian, force_jacobian,
        large_rotation, largest_entry, rotated_stretch, skewed_tetrahedron,
    };
    use voxflex_core::glam::DQuat;

    fn element() -> Element {
        let mesh = skewed_tetrahedron();
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
    fn the_elastic_force_is_the_gradient_of_the_energy() {
        // A large rotation and a stretch: central differences of the energy
        // against the force, component by component.
        let e = element();
        let q = large_rotation();
        let u = e
            .rest
            .map(|x| q * DMat3::from_diagonal(DVec3::new(1.2, 0.9, 1.05)) * x - x);
        assert_force_is_energy_gradient(u, e.elastic_force(u), |u| e.energy(*u));
        assert!(e.energy(e.rest.map(|x| q * x - x)).abs() < 1e-9 * e.energy(u));
    }

    #[test]
    fn with_the_twist_part_the_tangent_is_the_forces_jacobian_in_tension() {
        // Rotated and stretched in every direction (all twist eigenvalues
        // positive, none left out): R K Rᵀ plus the twist part against
        // central differences of the force.
        let e = element();
        let m = rotated_stretch();
        let u = e.rest.map(|x| m * x - x);
        let mut without = vec![DMat3::ZERO; 16];
        let mut f0 = [DVec3::ZERO; 4];
        e.linearise(u, &mut without, &mut f0, None);
        let mut k = vec![DMat3::ZERO; 16];
        e.linearise(u, &mut k, &mut f0, Some(true));
        let jac = force_jacobian(u, |u| e.elastic_force(*u));
        assert_tangent_is_jacobian(&k, &jac, 4);
        // How far the tangent without the twist part is from the Jacobian.
        let gap: Vec<DMat3> = jac.iter().zip(&without).map(|(j, w)| *j - *w).collect();
        let (scale, missing) = (largest_entry(&k), largest_entry(&gap));
        assert!(
            missing > 1e-2 * scale,
            "the twist part matters here ({missing} of {scale})"
        );
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
