//! Stability and consistency tests of the mass-spring solver through the
//! shared mesh model.

use crate::solver::{Integrator, MassSpring, SpringParams};
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::mesh_model::{ElasticMaterial, MeshModel, MeshSolver};
use voxflex_core::proxy::uniform_proxy;
use voxflex_core::tet_mesh::TetMesh;

type Springs = MeshModel<MassSpring>;

/// A bar [0, 4] × [0, 1] × [0, 1] mm with cells of 0.5 mm; material 1
/// (stiffer by `ratio`) in x ≥ 2.
fn bar(ratio: f64) -> (TetMesh, Vec<ElasticMaterial>) {
    let grid = Grid::new([9, 3, 3], DVec3::splat(0.5), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |v| Some(u16::from(v[0] >= 5))).unwrap();
    let soft = ElasticMaterial::new(1000.0, 0.3, 1e-3);
    let stiff = ElasticMaterial::new(1000.0 * ratio, 0.3, 1e-3);
    (mesh, vec![soft, stiff])
}

fn clamped(ratio: f64, params: SpringParams) -> Springs {
    let (mesh, materials) = bar(ratio);
    let mut m = Springs::with_mesh(mesh, materials, DVec3::new(0.0, 0.0, -9810.0), params).unwrap();
    m.interact("kind = \"fix\"\nmin = [-0.1, -0.1, -0.1]\nmax = [0.1, 1.1, 1.1]")
        .unwrap();
    m
}

fn frame(dt: f64) -> FrameInfo {
    FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: dt,
    }
}

#[test]
fn a_step_far_above_the_stable_limit_is_sub_stepped_or_refused() {
    let mut m = clamped(1.0, SpringParams::default());
    let stable = m.solver().unwrap().stable_dt();
    m.step(frame(10.0 * stable)).unwrap();
    let report = m.last_solve();
    assert!(report.substeps >= 10, "{report:?}");
    assert!(m.state().unwrap().u.iter().all(|u| u.is_finite()));
    // The same step with a cap of 5 sub-steps is refused, saying why.
    let mut capped = clamped(
        1.0,
        SpringParams {
            max_substeps: 5,
            ..SpringParams::default()
        },
    );
    let e = capped.step(frame(10.0 * stable)).unwrap_err().0;
    assert!(e.contains("max_substeps") && e.contains("implicit"), "{e}");
}

#[test]
fn explicit_and_implicit_come_to_the_same_rest_under_gravity() {
    let settle = |integrator: Integrator, dt: f64, frames: usize| {
        let mut m = clamped(
            1.0,
            SpringParams {
                integrator,
                damping_ratio: 0.5,
                mass_damping: 50.0,
                cg_tolerance: 1e-10,
                ..SpringParams::default()
            },
        );
        for _ in 0..frames {
            m.step(frame(dt)).unwrap();
        }
        m.state().unwrap().u.clone()
    };
    let explicit = settle(Integrator::Explicit, 0.005, 200);
    let implicit = settle(Integrator::Implicit, 0.005, 200);
    let sag = explicit.iter().map(|u| -u.z).fold(0.0, f64::max);
    assert!(sag > 1e-3, "gravity bends the bar ({sag} mm)");
    let worst = explicit
        .iter()
        .zip(&implicit)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0, f64::max);
    assert!(
        worst < 0.01 * sag,
        "explicit and implicit differ by {worst} of {sag}"
    );
}

#[test]
fn a_translation_stores_no_force_and_springs_follow_the_material() {
    let (mesh, materials) = bar(1.0);
    let s = MassSpring::new(&mesh, &materials, SpringParams::default()).unwrap();
    let springs = s.springs();
    // Every tetrahedron edge is one spring, once.
    let mut edges = std::collections::HashSet::new();
    for t in &mesh.tets {
        for a in 0..4 {
            for b in a + 1..4 {
                edges.insert([t[a].min(t[b]), t[a].max(t[b])]);
            }
        }
    }
    assert_eq!(springs.ends.len(), edges.len());
    // Σ k L² = 6 E Σ V (each tetrahedron's E V on each of its 6 edges).
    let total: f64 = springs
        .k
        .iter()
        .zip(&springs.rest)
        .map(|(k, l)| k * l * l)
        .sum();
    let volume: f64 = (0..mesh.tets.len()).map(|t| mesh.volume(t)).sum();
    assert!((total - 6.0 * 1000.0 * volume).abs() < 1e-9 * total);
}

#[test]
fn stiffness_ratios_of_a_million_and_random_grabs_stay_finite() {
    // Implicit: the explicit limit of a 10⁶-times stiffer part would need
    // ~1000 sub-steps per frame.
    let mut m = clamped(
        1e6,
        SpringParams {
            integrator: Integrator::Implicit,
            ..SpringParams::default()
        },
    );
    let mut seed = 17u64;
    let mut rand = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for step in 0..10_000 {
        if step % 50 == 0 {
            let p = [4.0 * rand(), rand(), rand()];
            let by = [rand() - 0.5, rand() - 0.5, rand() - 0.5].map(|v| 2.0 * v);
            m.interact(&format!(
                "kind = \"grab\"\npoint = {p:?}\nby = {by:?}\nframes = 10"
            ))
            .unwrap();
        }
        if step % 500 == 499 {
            m.interact("kind = \"release\"").unwrap();
        }
        m.step(frame(1.0 / 60.0)).unwrap();
    }
    assert!(m.state().unwrap().u.iter().all(|u| u.is_finite()));
}

#[test]
fn an_octree_proxy_runs_explicit_and_implicit_with_hanging_nodes_tied() {
    use voxflex_core::deformation::ExecutionBackend;
    let volume = voxflex_core::phantom::phantom("rings", [33, 33, 33]).unwrap();
    for integrator in ["explicit", "implicit"] {
        let toml = format!(
            "proxy = {{ kind = \"octree\", max_cell = 8 }}\n\
             materials = [{{ name = \"soft\", range = [50, 150], youngs_modulus = 2000 }},\n\
                          {{ name = \"hard\", range = [150, 256], youngs_modulus = 20000 }}]\n\
             integrator = \"{integrator}\"\ngravity = [0, 0, -9810]"
        );
        let mut m = Springs::from_toml(&toml).unwrap();
        m.init(volume.view(), ExecutionBackend::Cpu).unwrap();
        m.interact("kind = \"fix\"\nmaterial = \"hard\"").unwrap();
        for _ in 0..5 {
            m.step(frame(1.0 / 30.0)).unwrap();
        }
        let u = &m.state().unwrap().u;
        assert!(u.iter().all(|v| v.is_finite()), "{integrator}");
        assert!(
            u.iter().any(|v| v.z < -1e-3),
            "{integrator}: gravity moves the soft half"
        );
        assert!(!m.hanging().is_empty());
        for h in m.hanging() {
            let tied: DVec3 = h
                .masters
                .iter()
                .map(|&(n, w)| w as f64 * u[n as usize])
                .sum();
            assert!(
                (u[h.node as usize] - tied).length() < 1e-4,
                "{integrator}: node {}",
                h.node
            );
        }
    }
}
