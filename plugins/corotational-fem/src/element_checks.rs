//! Checks both element kinds share (tests only): one skewed tetrahedron,
//! and the force against central differences of the energy.

use voxflex_core::glam::{DMat3, DQuat, DVec3};
use voxflex_core::tet_mesh::TetMesh;

/// One skewed tetrahedron (mm), positively oriented, of region 0.
pub(crate) fn skewed_tetrahedron() -> TetMesh {
    let nodes = vec![
        DVec3::new(0.1, 0.0, 0.2),
        DVec3::new(2.0, 0.3, 0.0),
        DVec3::new(0.4, 1.7, 0.1),
        DVec3::new(0.2, 0.5, 1.9),
    ];
    TetMesh::new("one", nodes, vec![[0, 1, 2, 3]], vec![0]).unwrap()
}

/// A large rotation (1.1 rad about a skew axis).
pub(crate) fn large_rotation() -> DMat3 {
    DMat3::from_quat(DQuat::from_axis_angle(
        DVec3::new(0.3, -0.5, 1.0).normalize(),
        1.1,
    ))
}

/// Asserts that `force` (µN per node) is the gradient of `energy` (µJ) at
/// the nodal displacements `u` (mm), component by component, by central
/// differences (1e-6 mm), to 1e-6 of the largest nodal force.
pub(crate) fn assert_force_is_energy_gradient<const N: usize>(
    u: [DVec3; N],
    force: [DVec3; N],
    energy: impl Fn(&[DVec3; N]) -> f64,
) {
    let scale = force.iter().map(|v| v.length()).fold(0.0, f64::max);
    let eps = 1e-6;
    for a in 0..N {
        for c in 0..3 {
            let (mut up, mut down) = (u, u);
            up[a][c] += eps;
            down[a][c] -= eps;
            let grad = (energy(&up) - energy(&down)) / (2.0 * eps);
            assert!(
                (grad - force[a][c]).abs() <= 1e-6 * scale,
                "node {a} axis {c}: {grad} vs {}",
                force[a][c]
            );
        }
    }
}
