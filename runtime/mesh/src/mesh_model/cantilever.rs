//! The cantilever reference problem of `tests/reference/cantilever.json`,
//! shared by the mesh plugins' accuracy tests and benchmarks: the box
//! [0, 10] × [0, 1] × [0, 1] mm meshed with cells of 1/r mm (five
//! tetrahedra each, the mirrored pattern), clamped at x = 0 and loaded by a
//! traction in −z on the face x = 10.

use super::MeshSolver;
use super::material::ElasticMaterial;
use super::model::MeshModel;
use crate::deformation::DeformationModel;
use crate::grid::Grid;
use crate::proxy::uniform_proxy;
use crate::tet_mesh::TetMesh;
use glam::DVec3;

/// The mesh at refinement level `r` (10 r × r × r cells).
pub fn mesh(r: usize) -> TetMesh {
    let h = 1.0 / r as f64;
    let grid = Grid::new([10 * r + 1, r + 1, r + 1], DVec3::splat(h), DVec3::ZERO);
    uniform_proxy(&grid, 1, |_| Some(0)).expect("the cantilever mesh")
}

/// The reference's index of the node at `p` (mm): x fastest over the
/// (10 r + 1) × (r + 1) × (r + 1) nodes.
pub fn reference_node(p: DVec3, r: usize) -> usize {
    let [i, j, k] = [p.x, p.y, p.z].map(|c| (c * r as f64).round() as usize);
    i + (10 * r + 1) * (j + (r + 1) * k)
}

/// A model of level `r` with solver `S`, E = 1000 Pa, ν = 0.3, clamped at
/// x = 0, with a traction of `load` Pa in −z on the face x = 10.
pub fn model<S: MeshSolver>(r: usize, load: f64, params: S::Params) -> MeshModel<S> {
    let material = ElasticMaterial::new(1000.0, 0.3, 1e-6);
    let mut m = MeshModel::<S>::with_mesh(mesh(r), vec![material], DVec3::ZERO, params)
        .expect("the cantilever model");
    m.interact("kind = \"fix\"\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, 1.01, 1.01]")
        .expect("clamp");
    m.interact(&format!(
        "kind = \"load\"\nmin = [9.99, -0.01, -0.01]\nmax = [10.01, 1.01, 1.01]\ntraction = [0, 0, {}]",
        -load
    ))
    .expect("tip load");
    m
}

/// The mean u_z (mm) of the nodes on the face x = 10.
pub fn tip_deflection(mesh: &TetMesh, u: &[DVec3]) -> f64 {
    let tip: Vec<f64> = mesh
        .nodes
        .iter()
        .zip(u)
        .filter(|(x, _)| (x.x - 10.0).abs() < 1e-9)
        .map(|(_, d)| d.z)
        .collect();
    tip.iter().sum::<f64>() / tip.len().max(1) as f64
}
