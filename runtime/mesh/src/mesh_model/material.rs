//! Linear-elastic materials of a proxy's tetrahedra, in the mm-g-s units
//! the mesh solvers compute in (stress in Pa, density in g/mm³, force in
//! µN = g·mm/s²).

use super::params::MaterialSpec;
use crate::tet_mesh::TetMesh;

/// kg/m³ → g/mm³.
const KG_PER_M3: f64 = 1e-6;

/// One material as the solvers use it.
#[derive(Clone, Debug, PartialEq)]
pub struct ElasticMaterial {
    /// Name, if the scene gave one.
    pub name: Option<String>,
    /// Young's modulus, Pa.
    pub youngs_modulus: f64,
    /// Poisson ratio.
    pub poisson_ratio: f64,
    /// Density, g/mm³.
    pub density: f64,
}

impl ElasticMaterial {
    /// Converts a scene material.
    pub fn from_spec(m: &MaterialSpec) -> Self {
        Self {
            name: m.name.clone(),
            youngs_modulus: m.youngs_modulus,
            poisson_ratio: m.poisson_ratio,
            density: m.density * KG_PER_M3,
        }
    }

    /// A material from its moduli (Pa) and density (g/mm³), for tests and
    /// programs that build models directly.
    pub fn new(youngs_modulus: f64, poisson_ratio: f64, density: f64) -> Self {
        Self {
            name: None,
            youngs_modulus,
            poisson_ratio,
            density,
        }
    }

    /// Lamé parameters `(λ, μ)`, Pa.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        let mu = e / (2.0 * (1.0 + nu));
        let lambda = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
        (lambda, mu)
    }
}

/// Lumped nodal masses (g): a quarter of each tetrahedron's mass to each
/// of its corners, `materials[labels[t]]` giving its density.
pub fn lumped_masses(mesh: &TetMesh, materials: &[ElasticMaterial]) -> Vec<f64> {
    let mut m = vec![0.0; mesh.nodes.len()];
    for (t, tet) in mesh.tets.iter().enumerate() {
        let share = materials[mesh.labels[t] as usize].density * mesh.volume(t) / 4.0;
        for &n in tet {
            m[n as usize] += share;
        }
    }
    m
}
