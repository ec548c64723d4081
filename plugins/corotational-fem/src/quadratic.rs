//! A quadratic (P2, 10-node) tetrahedron of isotropic linear-elastic
//! material: four corners and six mid-edge nodes (straight edges, in the
//! VTK quadratic-tetrahedron order [`TET_EDGES`]), the shape functions
//! `λ_a (2 λ_a − 1)` and `4 λ_a λ_b` of the barycentric coordinates, and
//! the 4-point Gauss rule of degree 2 (points at `(a, b, b, b)` and its
//! permutations, `a = (5 + 3√5)/20`, `b = (5 − √5)/20`, weight `V/4`), which
//! integrates the P2 stiffness (products of linear gradients) exactly.
//!
//! Corotation is **per quadrature point**: at each point `q` the
//! deformation gradient `F_q` is polar-decomposed (signed, as for the
//! linear elements) into `R_q S_q` and the material is the corotated linear
//! one, `ψ = μ |ε|² + λ/2 (tr ε)²` with `ε = sym(R_qᵀ F_q) − I`. Unlike one
//! rotation per element from its corners, this keeps the elastic force the
//! exact gradient of an energy (the polar `R_qᵀ F_q` is symmetric, so the
//! rotation's own change does not contribute), so the static solver's
//! Newton iterations, their exact tangent (the twist part per point) and
//! their line search on the potential work unchanged; and it follows a
//! bent element's rotation varying inside it, which a single rotation
//! cannot. The cost is four polar decompositions per element instead of
//! one.
//!
//! Units: positions mm, gradients 1/mm, volume mm³, moduli Pa, forces µN.

use crate::element::{add_twist, energy_density, rotated_energy_density, stiffness_block};
use crate::polar::{rotation, signed_svd};
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::tet_mesh::TetMesh;
use voxflex_mesh::mesh_model::ElasticMaterial;
use voxflex_mesh::mesh_model::edge_layer::TET_EDGES;

/// Nodes of a quadratic tetrahedron.
pub const NODES: usize = 10;

/// The Gauss points' barycentric coordinates: `A` at one corner, `B` at
/// the others.
const A: f64 = 0.585_410_196_624_968_5;
const B: f64 = 0.138_196_601_125_010_5;

/// One quadrature point's shape-function gradients and weight.
#[derive(Clone, Debug)]
pub struct QuadraturePoint {
    /// Gradients of the ten shape functions there, 1/mm.
    pub grads: [DVec3; NODES],
    /// The point's share of the volume, mm³.
    pub weight: f64,
}

/// One quadratic tetrahedron's precomputed rest quantities.
#[derive(Clone, Debug)]
pub struct Quadratic {
    /// Node indices: the four corners, then the six mid-edge nodes in
    /// [`TET_EDGES`] order.
    pub nodes: [u32; NODES],
    /// Rest positions of the nodes, mm.
    pub rest: [DVec3; NODES],
    /// The four Gauss points.
    pub points: [QuadraturePoint; 4],
    /// Rest volume, mm³.
    pub volume: f64,
    /// Lamé λ, Pa.
    pub lambda: f64,
    /// Lamé μ, Pa.
    pub mu: f64,
}

/// The ten shape functions' values at barycentric coordinates `l`.
pub fn shape_functions(l: [f64; 4]) -> [f64; NODES] {
    let mut n = [0.0; NODES];
    for a in 0..4 {
        n[a] = l[a] * (2.0 * l[a] - 1.0);
    }
    for (k, [a, b]) in TET_EDGES.iter().enumerate() {
        n[4 + k] = 4.0 * l[*a] * l[*b];
    }
    n
}

impl Quadratic {
    /// Tetrahedron `t` of `mesh` (positively oriented), whose mid-edge
    /// nodes are `edge_nodes` (in [`TET_EDGES`] order).
    pub fn new(mesh: &TetMesh, t: usize, edge_nodes: [u32; 6], material: &ElasticMaterial) -> Self {
        let corners = mesh.tets[t];
        let x = corners.map(|n| mesh.nodes[n as usize]);
        let dm = DMat3::from_cols(x[1] - x[0], x[2] - x[0], x[3] - x[0]);
        let r = dm.inverse().transpose();
        let g = [
            -(r.x_axis + r.y_axis + r.z_axis),
            r.x_axis,
            r.y_axis,
            r.z_axis,
        ];
        let volume = dm.determinant() / 6.0;
        let mut nodes = [0u32; NODES];
        let mut rest = [DVec3::ZERO; NODES];
        nodes[..4].copy_from_slice(&corners);
        rest[..4].copy_from_slice(&x);
        for (k, [a, b]) in TET_EDGES.iter().enumerate() {
            nodes[4 + k] = edge_nodes[k];
            rest[4 + k] = (x[*a] + x[*b]) * 0.5;
        }
        let points = [0, 1, 2, 3].map(|q| {
            let mut l = [B; 4];
            l[q] = A;
            let mut grads = [DVec3::ZERO; NODES];
            for a in 0..4 {
                grads[a] = g[a] * (4.0 * l[a] - 1.0);
            }
            for (k, [a, b]) in TET_EDGES.iter().enumerate() {
                grads[4 + k] = (g[*b] * l[*a] + g[*a] * l[*b]) * 4.0;
            }
            QuadraturePoint {
                grads,
                weight: volume / 4.0,
            }
        });
        let (lambda, mu) = material.lame();
        Self {
            nodes,
            rest,
            points,
            volume,
            lambda,
            mu,
        }
    }

    /// The deformation gradient at Gauss point `q` for node displacements
    /// `u` (mm): `I + Σ_a u_a ⊗ ∇N_a`.
    #[inline]
    pub fn deformation_gradient(&self, q: usize, u: &[DVec3; NODES]) -> DMat3 {
        let g = &self.points[q].grads;
        (0..NODES).fold(DMat3::IDENTITY, |f, a| {
            let (p, c) = (u[a], g[a]);
            f + DMat3::from_cols(p * c.x, p * c.y, p * c.z)
        })
    }

    /// The rest stiffness block coupling nodes `a` and `b` (µN/mm), summed
    /// over the Gauss points (exact).
    pub fn stiffness(&self, a: usize, b: usize) -> DMat3 {
        self.points.iter().fold(DMat3::ZERO, |k, p| {
            k + stiffness_block(p.grads[a], p.grads[b], self.lambda, self.mu, p.weight)
        })
    }

    /// Adds Gauss point `q`'s share of the corotated stiffness
    /// `Σ_q R_q K^q_ab R_qᵀ` (to `k[10 a + b]`) and of the force offsets
    /// `f0_a = Σ_q Σ_b R_q K^q_ab (X_b − R_qᵀ X_b)` (µN; `f0[a]`), with its
    /// rotation `r`: summed over the points, the elastic force is
    /// `f_int = K_rot u − f0`.
    #[inline]
    fn corotate_point(&self, q: usize, r: DMat3, k: &mut [DMat3], f0: &mut [DVec3]) {
        let p = &self.points[q];
        let rt = r.transpose();
        let offset = self.rest.map(|x| x - rt * x);
        for a in 0..NODES {
            let mut f = DVec3::ZERO;
            for b in 0..NODES {
                let rk =
                    r * stiffness_block(p.grads[a], p.grads[b], self.lambda, self.mu, p.weight);
                k[NODES * a + b] += rk * rt;
                f += rk * offset[b];
            }
            f0[a] += f;
        }
    }

    /// The warped stiffness and force offsets (per Gauss point,
    /// [`Quadratic::corotate_point`]) at node displacements `u` (mm), with
    /// each Gauss point's rotation stiffness ([`add_twist`]) when `twist`
    /// is `Some(clamp)`: one signed SVD per Gauss point gives both.
    pub fn linearise(
        &self,
        u: &[DVec3; NODES],
        k: &mut [DMat3],
        f0: &mut [DVec3],
        twist: Option<bool>,
    ) {
        k.iter_mut().for_each(|b| *b = DMat3::ZERO);
        f0.iter_mut().for_each(|f| *f = DVec3::ZERO);
        for (q, p) in self.points.iter().enumerate() {
            let f = self.deformation_gradient(q, u);
            let Some(clamp) = twist else {
                self.corotate_point(q, rotation(f), k, f0);
                continue;
            };
            let svd = signed_svd(f);
            self.corotate_point(q, svd.0 * svd.2.transpose(), k, f0);
            add_twist(svd, &p.grads, p.weight, (self.lambda, self.mu), k, clamp);
        }
    }

    /// The elastic force on each node (µN) and the strain energy (µN·mm)
    /// at node displacements `u` (mm), one rotation per Gauss point: what
    /// [`Quadratic::elastic_force`] and [`Quadratic::energy`] give.
    pub fn force_and_energy(&self, u: &[DVec3; NODES]) -> ([DVec3; NODES], f64) {
        let mut out = [DVec3::ZERO; NODES];
        let mut energy = 0.0;
        for (q, p) in self.points.iter().enumerate() {
            let f = self.deformation_gradient(q, u);
            let r = rotation(f);
            energy += p.weight * rotated_energy_density(r, f, self.lambda, self.mu);
            self.add_point_force(q, r, f, &mut out);
        }
        (out, energy)
    }

    /// The element's strain energy (µN·mm) at node displacements `u` (mm).
    pub fn energy(&self, u: &[DVec3; NODES]) -> f64 {
        (0..4)
            .map(|q| {
                self.points[q].weight
                    * energy_density(self.deformation_gradient(q, u), self.lambda, self.mu)
            })
            .sum()
    }

    /// The elastic force on each node (µN), the energy's gradient:
    /// `Σ_q w_q P_q ∇N_a` with the stress `P = R (2μ ε + λ tr ε I)`.
    pub fn elastic_force(&self, u: &[DVec3; NODES]) -> [DVec3; NODES] {
        let mut out = [DVec3::ZERO; NODES];
        for q in 0..self.points.len() {
            let f = self.deformation_gradient(q, u);
            self.add_point_force(q, rotation(f), f, &mut out);
        }
        out
    }

    /// Adds Gauss point `q`'s share `w_q P_q ∇N_a` of the elastic force,
    /// at deformation gradient `f` with rotation `r`, to `out`.
    #[inline]
    fn add_point_force(&self, q: usize, r: DMat3, f: DMat3, out: &mut [DVec3; NODES]) {
        let p = &self.points[q];
        let d = r.transpose() * f - DMat3::IDENTITY;
        let e = (d + d.transpose()) * 0.5;
        let trace = e.x_axis.x + e.y_axis.y + e.z_axis.z;
        let stress = r
            * (e * (2.0 * self.mu) + DMat3::from_diagonal(DVec3::splat(self.lambda * trace)))
            * p.weight;
        for (o, g) in out.iter_mut().zip(&p.grads) {
            *o += stress * *g;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::element_checks::{
        assert_force_is_energy_gradient, assert_tangent_is_jacobian, force_jacobian,
        large_rotation, rotated_stretch, skewed_tetrahedron,
    };
    use voxflex_core::glam::DQuat;

    fn element() -> Quadratic {
        let mesh = skewed_tetrahedron();
        Quadratic::new(
            &mesh,
            0,
            [4, 5, 6, 7, 8, 9],
            &ElasticMaterial::new(1000.0, 0.3, 1e-6),
        )
    }

    #[test]
    fn shape_functions_interpolate_the_nodes_and_sum_to_one() {
        let e = element();
        let corners = [0, 1, 2, 3].map(|a| {
            let mut l = [0.0; 4];
            l[a] = 1.0;
            l
        });
        for (a, l) in corners.iter().enumerate() {
            let n = shape_functions(*l);
            for (b, v) in n.iter().enumerate() {
                assert_eq!(*v, f64::from(u8::from(a == b)), "corner {a} node {b}");
            }
        }
        for (k, [a, b]) in TET_EDGES.iter().enumerate() {
            let mut l = [0.0; 4];
            (l[*a], l[*b]) = (0.5, 0.5);
            let n = shape_functions(l);
            for (m, v) in n.iter().enumerate() {
                assert!((v - f64::from(u8::from(m == 4 + k))).abs() < 1e-15);
            }
        }
        // Gradients at each Gauss point reproduce linear and quadratic
        // fields: ∇(a·x) = a and ∇(x_0 x_1) = (x_1, x_0, 0).
        let a = DVec3::new(0.3, -1.2, 0.7);
        for (q, p) in e.points.iter().enumerate() {
            let mut l = [B; 4];
            l[q] = A;
            let x: DVec3 = (0..4).map(|c| e.rest[c] * l[c]).sum();
            let lin: DVec3 = (0..NODES).map(|n| p.grads[n] * a.dot(e.rest[n])).sum();
            assert!((lin - a).length() < 1e-12);
            let quad: DVec3 = (0..NODES)
                .map(|n| p.grads[n] * (e.rest[n].x * e.rest[n].y))
                .sum();
            assert!(
                (quad - DVec3::new(x.y, x.x, 0.0)).length() < 1e-12,
                "{quad} at {x}"
            );
        }
        let total: f64 = e.points.iter().map(|p| p.weight).sum();
        assert!((total - e.volume).abs() < 1e-12 && e.volume > 0.0);
    }

    #[test]
    fn the_elastic_force_is_the_gradient_of_the_energy() {
        // A large rotation, a stretch and a bend (a quadratic field).
        let e = element();
        let q = large_rotation();
        let u = e.rest.map(|x| {
            q * (DMat3::from_diagonal(DVec3::new(1.2, 0.9, 1.05)) * x
                + DVec3::new(0.0, 0.0, 0.1 * x.x * x.x))
                - x
        });
        let f = e.elastic_force(&u);
        let scale = f.iter().map(|v| v.length()).fold(0.0, f64::max);
        assert_force_is_energy_gradient(u, f, |u| e.energy(u));
        // K_rot u − f0 is the same force.
        let mut k = vec![DMat3::ZERO; NODES * NODES];
        let mut f0 = [DVec3::ZERO; NODES];
        e.linearise(&u, &mut k, &mut f0, None);
        for a in 0..NODES {
            let ku: DVec3 = (0..NODES).map(|b| k[NODES * a + b] * u[b]).sum();
            assert!(((ku - f0[a]) - f[a]).length() <= 1e-9 * scale, "node {a}");
        }
    }

    #[test]
    fn with_the_twist_part_the_tangent_is_the_forces_jacobian_in_tension() {
        let e = element();
        let m = rotated_stretch();
        let u = e.rest.map(|x| m * x - x);
        let mut k = vec![DMat3::ZERO; NODES * NODES];
        let mut f0 = [DVec3::ZERO; NODES];
        e.linearise(&u, &mut k, &mut f0, Some(true));
        let jac = force_jacobian(u, |u| e.elastic_force(u));
        assert_tangent_is_jacobian(&k, &jac, NODES);
    }

    #[test]
    fn a_rigid_rotation_produces_no_force_and_no_energy() {
        let e = element();
        let q = DMat3::from_quat(DQuat::from_axis_angle(
            DVec3::new(0.2, 1.0, 0.4).normalize(),
            std::f64::consts::FRAC_PI_2,
        ));
        let shift = DVec3::new(3.0, -1.0, 2.0);
        let u = e.rest.map(|x| q * x + shift - x);
        let stretched = e.rest.map(|x| x * 0.01);
        let scale = e
            .elastic_force(&stretched)
            .iter()
            .map(|v| v.length())
            .fold(0.0, f64::max);
        let worst = e
            .elastic_force(&u)
            .iter()
            .map(|v| v.length())
            .fold(0.0, f64::max);
        assert!(scale > 0.0 && worst <= 1e-9 * scale, "{worst} vs {scale}");
        assert!(e.energy(&u).abs() <= 1e-12 * e.energy(&stretched));
    }

    #[test]
    fn the_stiffness_is_symmetric_and_blind_to_rigid_motions() {
        let e = element();
        for a in 0..NODES {
            let t: DVec3 = (0..NODES)
                .map(|b| e.stiffness(a, b) * DVec3::new(1.0, 2.0, 3.0))
                .sum();
            assert!(t.length() < 1e-9);
            // An infinitesimal rotation ω × X.
            let w = DVec3::new(0.3, -0.2, 0.5);
            let r: DVec3 = (0..NODES)
                .map(|b| e.stiffness(a, b) * w.cross(e.rest[b]))
                .sum();
            assert!(r.length() < 1e-9, "{r}");
            for b in 0..NODES {
                let d = e.stiffness(a, b) - e.stiffness(b, a).transpose();
                assert!(d.to_cols_array().iter().all(|x| x.abs() < 1e-9));
            }
        }
    }
}
