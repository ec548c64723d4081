//! Stability and consistency tests of the mass-spring solver through the
//! shared mesh model.

use crate::solver::{Integrator, MassSpring, SpringParams};
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::tet_mesh::TetMesh;
use voxflex_mesh::mesh_model::inversion::largest_edge_change;
use voxflex_mesh::mesh_model::{ElasticMaterial, MeshModel, MeshSolver};
use voxflex_mesh::proxy::uniform_proxy;

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
    let explicit = SpringParams {
        integrator: Integrator::Explicit,
        ..SpringParams::default()
    };
    let mut m = clamped(1.0, explicit.clone());
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
            ..explicit
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
    let volume = voxflex_phantom::phantom("rings", [33, 33, 33]).unwrap();
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

/// One-voxel objects at every offset inside a cell of 4 voxels, along each
/// axis, and one-voxel slabs at every offset: each keeps a proxy cell,
/// none is reported lost, and each resamples to its value after a shift
/// (`mesh_model::small_features`). The rule before (a cell takes its
/// centre voxel's label) refused to build a proxy for all but offset 2.
#[test]
fn one_voxel_objects_and_slabs_survive_at_every_offset() {
    let params = "proxy = { kind = \"uniform\", step = 4 }\n\
                  materials = [{ range = [50, 200], youngs_modulus = 3000 }]\n\
                  gravity = [0, 0, -9810]";
    voxflex_mesh::mesh_model::small_features::every_offset::<MassSpring>(params)
        .unwrap_or_else(|e| panic!("{e}"));
}

/// A block 30 × 30 × 15 mm (cells of 5 mm) clamped at its base; its top
/// corner node is grabbed 100 mm out and up, held, and released; then
/// `settle` frames pass. Returns the tetrahedra inverted at the end, the
/// most inverted after any frame, and the largest displacement left (mm).
fn grab_release(params: SpringParams, settle: usize) -> (f64, f64, f64) {
    let grid = Grid::new([7, 7, 4], DVec3::splat(5.0), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
    let material = ElasticMaterial::new(3000.0, 0.45, 1e-3);
    let mut m = Springs::with_mesh(mesh, vec![material], DVec3::ZERO, params).unwrap();
    m.interact("kind = \"fix\"\nmin = [-1, -1, -1]\nmax = [31, 31, 0.5]")
        .unwrap();
    m.interact("kind = \"grab\"\npoint = [30, 30, 15]\nby = [57.7, 57.7, 57.7]\nframes = 10")
        .unwrap();
    let dt = frame(1.0 / 30.0);
    for _ in 0..20 {
        m.step(dt).unwrap();
    }
    m.interact("kind = \"release\"").unwrap();
    for _ in 0..settle {
        m.step(dt).unwrap();
    }
    let notes = m.notes().unwrap();
    let left = m
        .state()
        .unwrap()
        .u
        .iter()
        .map(|u| u.length())
        .fold(0.0, f64::max);
    (
        notes["inverted_tetrahedra"],
        notes["inverted_tetrahedra_max"],
        left,
    )
}

/// Issue 12 (9): with the explicit integrator, springs alone leave a
/// released 100 mm grab tangled — an inverted tetrahedron has its rest
/// edge lengths, so nothing pushes it back — and the notes say so; the
/// volume springs untangle it, with both integrators, and the block
/// returns to rest.
#[test]
fn a_released_100_mm_grab_untangles_with_volume_springs() {
    for integrator in [Integrator::Explicit, Integrator::Implicit] {
        let springs_only = SpringParams {
            integrator,
            volume_stiffness: 0.0,
            ..SpringParams::default()
        };
        let (now, max, left) = grab_release(springs_only, 300);
        println!("{integrator:?}, springs only: {now} inverted, {max} at most, {left:.2} mm left");
        // The implicit step's numerical damping brings even springs alone
        // back; the explicit integrator keeps the tangle.
        if integrator == Integrator::Explicit {
            assert!(
                now > 0.0 && max >= now,
                "springs alone stay tangled ({now} inverted, {max} at most, {left} mm left)"
            );
        }
        let with_volume = SpringParams {
            integrator,
            volume_stiffness: 1.0,
            ..SpringParams::default()
        };
        let (now, max, left) = grab_release(with_volume, 300);
        println!(
            "{integrator:?} with volume springs: {now} inverted, {max} at most, {left:.2e} mm left"
        );
        assert_eq!(
            now, 0.0,
            "{integrator:?}: {now} still inverted ({max} at most)"
        );
        assert!(left < 0.1, "{integrator:?}: {left} mm left after settling");
    }
}

#[test]
fn volume_stiffness_is_checked_and_zero_means_no_volume_springs() {
    let (mesh, materials) = bar(1.0);
    let off = SpringParams {
        volume_stiffness: 0.0,
        ..SpringParams::default()
    };
    let s = MassSpring::new(&mesh, &materials, off).unwrap();
    assert!(s.volume_springs().corners.is_empty());
    assert_eq!(
        SpringParams::default().volume_stiffness,
        0.0,
        "off by default"
    );
    let on = SpringParams {
        volume_stiffness: 1.0,
        ..SpringParams::default()
    };
    let on = MassSpring::new(&mesh, &materials, on).unwrap();
    assert_eq!(on.volume_springs().corners.len(), mesh.tets.len());
    // k_v = κ E / V₀.
    let kv = on.volume_springs().k[0];
    assert!((kv * mesh.volume(0) - 1000.0).abs() < 1e-9 * 1000.0, "{kv}");
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let p = SpringParams {
            volume_stiffness: bad,
            ..SpringParams::default()
        };
        let e = MassSpring::new(&mesh, &materials, p).err().unwrap().0;
        assert!(e.contains("volume_stiffness"), "{e}");
    }
}

/// A free block 2 × 2 × 2 mm (cells of 0.5 mm) squashed through itself
/// along z (`z → −0.2 z`: every tetrahedron inside out), as the
/// corotational FEM's inversion test starts; `gpu` for the GPU twin.
pub(crate) fn squashed_block(
    params: SpringParams,
    gpu: Option<std::sync::Arc<dyn voxflex_core::gpu::GpuService>>,
) -> Springs {
    let grid = Grid::new([5, 5, 5], DVec3::splat(0.5), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
    let material = ElasticMaterial::new(5000.0, 0.3, 1e-3);
    let inverted: Vec<DVec3> = mesh
        .nodes
        .iter()
        .map(|x| DVec3::new(0.0, 0.0, -1.2 * x.z))
        .collect();
    let mut m = Springs::with_mesh(mesh, vec![material], DVec3::ZERO, params)
        .unwrap()
        .with_gpu(gpu);
    m.set_displacements(&inverted).unwrap();
    m
}

/// The squashed block: springs alone spring back to its mirror image —
/// every tetrahedron stays inverted, the notes count them all — while the
/// volume springs bring it back to rest (every edge within 2 % of its rest
/// length, no tetrahedron inverted), explicit and implicit.
#[test]
fn a_block_squashed_through_itself_recovers_only_with_volume_springs() {
    for integrator in [Integrator::Explicit, Integrator::Implicit] {
        let run = |volume_stiffness: f64| {
            let params = SpringParams {
                integrator,
                volume_stiffness,
                ..SpringParams::default()
            };
            let mut m = squashed_block(params, None);
            for _ in 0..200 {
                m.step(frame(0.01)).unwrap();
            }
            m
        };
        let mut springs_only = run(0.0);
        let tets = springs_only.mesh().unwrap().tets.len() as f64;
        let notes = springs_only.notes().unwrap();
        assert_eq!(
            notes["inverted_tetrahedra"], tets,
            "{integrator:?}: springs alone keep the mirror image"
        );
        let mut m = run(1.0);
        assert_eq!(
            m.notes().unwrap()["inverted_tetrahedra"],
            0.0,
            "{integrator:?}"
        );
        let mesh = m.mesh().unwrap().clone();
        let u = &m.state().unwrap().u;
        let (edge, change) = largest_edge_change(&mesh, u).unwrap();
        assert!(
            change < 0.02,
            "{integrator:?}: edge {edge:?} off its rest length by {change:.3}"
        );
    }
}

/// The connected pieces of `mesh` (tetrahedra joined through shared
/// nodes): each node's piece, numbered by its smallest node.
fn pieces(mesh: &TetMesh) -> Vec<usize> {
    let mut parent: Vec<usize> = (0..mesh.nodes.len()).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for t in &mesh.tets {
        for &n in &t[1..] {
            let (a, b) = (
                root(&mut parent, t[0] as usize),
                root(&mut parent, n as usize),
            );
            parent[a.max(b)] = a.min(b);
        }
    }
    (0..parent.len()).map(|n| root(&mut parent, n)).collect()
}

/// Cut inside the proxy's cells, at three places and with the polygon
/// wound both ways: the bar falls in two pieces, and once the right piece
/// is moved every voxel centre (a lattice binding) and every tracked point
/// (a point binding) moves with the piece of its own side of the plane,
/// none with the tetrahedron that carried it across.
#[test]
fn a_cut_inside_cells_moves_voxels_and_tracked_points_with_their_own_side() {
    use voxflex_core::deformation::{DisplacementTarget, RestPoints};
    let map = |m: &mut Springs, id, n: usize| {
        let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
        let target = DisplacementTarget::Cpu {
            x: &mut x,
            y: &mut y,
            z: &mut z,
        };
        m.map(id, target).unwrap();
        x
    };
    for plane in [1.85, 2.15, 2.35] {
        for wound in [false, true] {
            let (mesh, materials) = bar(1.0);
            let mut m =
                Springs::with_mesh(mesh, materials, DVec3::ZERO, SpringParams::default()).unwrap();
            let grid = Grid::new([41, 11, 11], DVec3::splat(0.1), DVec3::ZERO);
            let lattice = m.bind(RestPoints::Lattice(grid)).unwrap();
            let tracked: Vec<[f32; 3]> = (0..40)
                .map(|i| [0.05 + 0.1 * i as f32, 0.37, 0.61])
                .collect();
            let points = m.bind(RestPoints::Points(&tracked)).unwrap();
            let mut corners = [
                [plane, -1.0, -1.0],
                [plane, 2.0, -1.0],
                [plane, 2.0, 2.0],
                [plane, -1.0, 2.0],
            ];
            if wound {
                corners.reverse();
            }
            m.interact(&format!("kind = \"cut\"\npolygon = {corners:?}"))
                .unwrap();
            let mesh = m.mesh().unwrap().clone();
            let piece = pieces(&mesh);
            let right = piece[(0..mesh.nodes.len())
                .max_by(|&a, &b| mesh.nodes[a].x.total_cmp(&mesh.nodes[b].x))
                .unwrap()];
            assert_ne!(piece[0], right, "{plane}: the cut separates the bar");
            let u: Vec<DVec3> = piece
                .iter()
                .map(|&p| if p == right { DVec3::X } else { DVec3::ZERO })
                .collect();
            m.set_displacements(&u).unwrap();
            let notes = m.notes().unwrap();
            assert!(
                notes["cut_voxels_rebound"] > 0.0,
                "{plane} {wound}: {notes:?}"
            );
            assert_eq!(notes["cut_voxels_across"], 0.0, "{plane} {wound}");
            let ux = map(&mut m, lattice, grid.len());
            for (l, ux) in ux.iter().enumerate() {
                let x = grid.unlinear(l)[0] as f64 * 0.1;
                let want = if x > plane { 1.0 } else { 0.0 };
                assert!(
                    (ux - want).abs() < 1e-4,
                    "{plane} {wound}: voxel at x = {x} moved {ux}"
                );
            }
            let ux = map(&mut m, points, tracked.len());
            for (p, ux) in tracked.iter().zip(ux) {
                let want = if f64::from(p[0]) > plane { 1.0 } else { 0.0 };
                assert!(
                    (ux - want).abs() < 1e-4,
                    "{plane} {wound}: point {p:?} moved {ux}"
                );
            }
        }
    }
}
