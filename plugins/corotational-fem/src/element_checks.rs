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

/// A rotation (0.8 rad about a skew axis) after a stretch in every
/// direction (1.3, 1.1, 1.2): every twist eigenvalue of an element so
/// deformed is positive, so the exact tangent leaves none out.
pub(crate) fn rotated_stretch() -> DMat3 {
    let q = DMat3::from_quat(DQuat::from_axis_angle(
        DVec3::new(-0.4, 0.2, 1.0).normalize(),
        0.8,
    ));
    q * DMat3::from_diagonal(DVec3::new(1.3, 1.1, 1.2))
}

/// The force's Jacobian at nodal displacements `u` (mm) by central
/// differences (1e-6 mm): `N × N` blocks, block `(a, b)` at `N a + b`,
/// its column `c` the change of node `a`'s force per mm of node `b` along
/// axis `c` (µN/mm).
pub(crate) fn force_jacobian<const N: usize>(
    u: [DVec3; N],
    force: impl Fn(&[DVec3; N]) -> [DVec3; N],
) -> Vec<DMat3> {
    let eps = 1e-6;
    let mut jac = vec![DMat3::ZERO; N * N];
    for b in 0..N {
        for c in 0..3 {
            let (mut up, mut down) = (u, u);
            up[b][c] += eps;
            down[b][c] -= eps;
            let (fu, fd) = (force(&up), force(&down));
            for a in 0..N {
                *jac[N * a + b].col_mut(c) = (fu[a] - fd[a]) / (2.0 * eps);
            }
        }
    }
    jac
}

/// The largest absolute entry of `blocks`.
pub(crate) fn largest_entry(blocks: &[DMat3]) -> f64 {
    blocks
        .iter()
        .map(|m| m.abs().to_cols_array().iter().copied().fold(0.0, f64::max))
        .fold(0.0, f64::max)
}

/// Asserts that the tangent `k` (blocks `N a + b`) equals the force's
/// Jacobian `jac` ([`force_jacobian`]) entry by entry, to 1e-5 of `k`'s
/// largest entry.
pub(crate) fn assert_tangent_is_jacobian(k: &[DMat3], jac: &[DMat3], n: usize) {
    let scale = largest_entry(k);
    for (i, (column_block, got)) in jac.iter().zip(k).enumerate() {
        let (a, b) = (i / n, i % n);
        for c in 0..3 {
            let (column, got) = (column_block.col(c), got.col(c));
            assert!(
                (column - got).abs().max_element() <= 1e-5 * scale,
                "block {a}{b} column {c}: {column} vs {got}"
            );
        }
    }
}
