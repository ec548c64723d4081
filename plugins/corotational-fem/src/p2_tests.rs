//! Quadratic (P2) tetrahedra through the whole model (issue 12): the
//! slender cantilever against beam theory where P1 locks, patch tests with
//! linear and quadratic fields, mirrored loads, the implicit steps settling
//! on the static answer, loads and masses moved onto the edge nodes, the
//! quadratic map, an octree proxy's hanging nodes, and the scene key.

use crate::edge_nodes::EdgeNodes;
use crate::front::{FRONT_LOAD, cantilever, front_point, timoshenko_tip, tip_displacement};
use crate::quadratic::shape_functions;
use crate::solver::{CorotationalFem, ElementKind, FemParams, SolverKind};
use voxflex_core::deformation::{DeformationModel, FrameInfo, RestPoints};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_mesh::mesh_model::edge_layer::TET_EDGES;
use voxflex_mesh::mesh_model::{
    Boundary, ElasticMaterial, MeshModel, MeshSolver, NodeState, largest_and_difference,
};
use voxflex_mesh::proxy::uniform_proxy;

type Fem = MeshModel<CorotationalFem>;

fn frame(dt: f64) -> FrameInfo {
    FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: dt,
    }
}

fn p2_static() -> FemParams {
    FemParams {
        element: ElementKind::P2,
        solver: SolverKind::Static,
        ..FemParams::default()
    }
}

#[test]
fn the_p2_cantilever_matches_beam_theory_where_p1_locks() {
    // 1,280 tetrahedra (cubes of 0.25 mm): P1 is a third too stiff.
    let p1 = front_point(ElementKind::P1, 0.25).unwrap();
    let p2 = front_point(ElementKind::P2, 0.25).unwrap();
    assert_eq!((p1.tetrahedra, p2.tetrahedra), (1280, 1280));
    assert!(p1.error < -0.10, "P1 locks: {p1:?}");
    // The clamped 3-D beam itself is ~0.8 % stiffer than Timoshenko's (its
    // clamp also holds the Poisson contraction); P2 converges to that
    // from above in stiffness.
    assert!(p2.error.abs() <= 0.012, "P2 within 1.2 %: {p2:?}");
    // 160 tetrahedra (cubes of 0.5 mm, one across the thickness).
    let p1 = front_point(ElementKind::P1, 0.5).unwrap();
    let p2 = front_point(ElementKind::P2, 0.5).unwrap();
    assert!(p1.error < -0.5, "{p1:?}");
    assert!(p2.error.abs() <= 0.025, "{p2:?}");
    assert!(timoshenko_tip(FRONT_LOAD) > 0.0);
}

/// A box of 2 × 1 × 1 mm in cubes of 0.5 mm (40 tetrahedra), P2, with
/// every node on its surface driven to `field` (mm, of the rest position)
/// and the interior solved statically; returns the worst difference of
/// the interior nodes from `field` and the field's largest value there.
fn patch(field: impl Fn(DVec3) -> DVec3) -> (f64, f64) {
    let grid = Grid::new([5, 3, 3], DVec3::splat(0.5), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
    let material = ElasticMaterial::new(1000.0, 0.3, 1e-6);
    let params = FemParams {
        cg_tolerance: 1e-12,
        cg_max_iterations: Some(10_000),
        static_tolerance: 1e-9,
        ..p2_static()
    };
    let mut fem = CorotationalFem::new(&mesh, &[material], params).unwrap();
    let layer = fem.edge_nodes().unwrap();
    let mut rest = mesh.nodes.clone();
    rest.extend(
        layer
            .edges
            .iter()
            .map(|[a, b]| (mesh.nodes[*a as usize] + mesh.nodes[*b as usize]) * 0.5),
    );
    let n = rest.len();
    let on_surface = |x: DVec3| {
        [x.x, x.y, x.z]
            .iter()
            .zip([2.0, 1.0, 1.0])
            .any(|(c, hi)| c.abs() < 1e-9 || (c - hi).abs() < 1e-9)
    };
    let mut bc = Boundary::new(n);
    let mut interior = Vec::new();
    for (i, x) in rest.iter().enumerate() {
        if on_surface(*x) {
            bc.driven.push((i as u32, field(*x)));
        } else {
            interior.push(i);
        }
    }
    // Interior edge nodes as well as the centre corners.
    assert!(interior.len() > 10, "{}", interior.len());
    let mut state = NodeState::at_rest(n);
    fem.step_nodes(0.0, &bc, &mut state).unwrap();
    interior.iter().fold((0.0, 0.0), |(worst, largest), &i| {
        let want = field(rest[i]);
        (
            f64::max(worst, (state.u[i] - want).length()),
            f64::max(largest, want.length()),
        )
    })
}

#[test]
fn a_p2_patch_reproduces_linear_and_quadratic_fields() {
    // A homogeneous deformation (rotation and stretch, 1 %) is an
    // equilibrium of the corotated material at any size.
    let eps = 1e-2;
    let (worst, largest) = patch(|x| {
        DVec3::new(
            0.3 * x.x - 0.2 * x.y + 0.1,
            0.5 * x.z + 0.1 * x.x,
            -0.4 * x.y + 0.2,
        ) * eps
    });
    assert!(
        worst <= 1e-7 * largest,
        "linear: {worst:.2e} of {largest:.2e}"
    );
    // Harmonic and divergence-free: in linear elasticity its stress is
    // divergence-free, so it needs no body force, but no linear element
    // can represent it. Small (1e-5), where the corotated material is
    // linear to ~1e-5.
    let eps = 1e-5;
    let (worst, largest) = patch(|x| {
        DVec3::new(
            x.x * x.x - 2.0 * x.y * x.y + x.z * x.z,
            -2.0 * x.x * x.y + x.x * x.z,
            x.x * x.y,
        ) * eps
    });
    assert!(largest > 0.0);
    assert!(
        worst <= 1e-4 * largest,
        "quadratic: {worst:.2e} of {largest:.2e}"
    );
}

#[test]
fn mirrored_loads_give_mirrored_p2_tips() {
    // A large deflection (about half the length): Newton with the exact
    // tangent, per Gauss point, and the line search. Two cells across the
    // thickness: the five-tetrahedra pattern is mirror-symmetric in z.
    let h = 0.25;
    let tight = FemParams {
        cg_tolerance: 1e-10,
        static_tolerance: 1e-10,
        ..p2_static()
    };
    let mut down = cantilever(h, 0.5, tight.clone()).unwrap();
    down.step(frame(0.0)).unwrap();
    let mut up = cantilever(h, -0.5, tight).unwrap();
    up.step(frame(0.0)).unwrap();
    let (a, b) = (tip_displacement(&down), tip_displacement(&up));
    assert!(-a.z > 1.0, "a large deflection ({a})");
    assert!(
        (a - DVec3::new(b.x, b.y, -b.z)).length() <= 1e-5 * a.length(),
        "down {a}, up {b}"
    );
    let notes = down.notes().unwrap();
    assert!(notes["newton_force_residual"] <= 1e-10, "{notes:?}");
    assert_eq!(notes["unconverged_solves"], 0.0, "{notes:?}");
}

#[test]
fn p2_implicit_steps_settle_on_the_static_answer() {
    let (h, p) = (0.5, 0.01);
    let mut st = cantilever(h, p, p2_static()).unwrap();
    st.step(frame(0.0)).unwrap();
    let dynamic = FemParams {
        solver: SolverKind::Dynamic,
        mass_damping: 50.0,
        ..p2_static()
    };
    let mut dy = cantilever(h, p, dynamic).unwrap();
    for _ in 0..40 {
        dy.step(frame(1.0 / 30.0)).unwrap();
    }
    let (a, b) = (tip_displacement(&st).z, tip_displacement(&dy).z);
    assert!(a < -0.1, "{a}");
    assert!((a - b).abs() <= 1e-3 * a.abs(), "static {a}, dynamic {b}");
    // The edge nodes too.
    let full = |m: &Fem| m.solver().unwrap().edge_nodes().unwrap().state.u.clone();
    let (largest, worst) = largest_and_difference(&full(&st), &full(&dy));
    assert!(worst <= 2e-3 * largest, "{worst} of {largest}");
}

#[test]
fn loads_and_masses_move_onto_the_edge_nodes_conserving_their_totals() {
    let grid = Grid::new([3, 2, 2], DVec3::splat(1.0), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
    let material = ElasticMaterial::new(1000.0, 0.3, 2e-3);
    let layer = EdgeNodes::new(&mesh, std::slice::from_ref(&material));
    let mass: f64 = layer.masses.iter().sum();
    assert!((mass - 2e-3 * 2.0).abs() < 1e-15, "{mass}");
    assert!(layer.masses.iter().all(|m| *m > 0.0));
    // The model's linear forces: gravity as lumped masses and a traction
    // on the face x = 2.
    let g = DVec3::new(0.0, 0.0, -9810.0);
    let mut bc = Boundary::new(mesh.nodes.len());
    let linear = voxflex_mesh::mesh_model::lumped_masses(&mesh, std::slice::from_ref(&material));
    for (f, m) in bc.force.iter_mut().zip(&linear) {
        *f = *m * g;
    }
    bc.gravity = g;
    bc.faces = voxflex_mesh::mesh_model::boundary::traction_faces(
        &mesh,
        DVec3::new(1.99, -1.0, -1.0),
        DVec3::new(2.01, 2.0, 2.0),
        DVec3::new(0.0, 3.0, 0.0),
    );
    assert_eq!(bc.faces.len(), 2);
    for (face, force) in &bc.faces {
        for &c in face {
            bc.force[c as usize] += *force / 3.0;
        }
    }
    let full = layer.boundary(&bc);
    let total = |f: &[DVec3]| f.iter().copied().sum::<DVec3>();
    assert!((total(&full.force) - total(&bc.force)).length() < 1e-9);
    // The loaded face's corners keep only their gravity.
    let nc = mesh.nodes.len();
    for (face, _) in &bc.faces {
        for &c in face {
            let want = layer.masses[c as usize] * g;
            assert!((full.force[c as usize] - want).length() < 1e-9);
        }
    }
    // Its five edges (two triangles) share the 3 µN × 1 mm².
    let traction: DVec3 = (nc..full.force.len())
        .map(|n| full.force[n] - layer.masses[n] * g)
        .sum();
    assert!(
        (traction - DVec3::new(0.0, 3.0, 0.0)).length() < 1e-12,
        "{traction}"
    );
}

#[test]
fn a_bent_p2_beam_maps_its_volume_quadratically() {
    let mut m = cantilever(0.5, 0.05, p2_static()).unwrap();
    m.step(frame(0.0)).unwrap();
    let mesh = m.mesh().unwrap().clone();
    let full = m.solver().unwrap().edge_nodes().unwrap().state.u.clone();
    let tet_edges = m.solver().unwrap().edge_nodes().unwrap().tet_edges.clone();
    let nc = mesh.nodes.len();
    // Points inside a few tetrahedra at known barycentric coordinates.
    let mut points = Vec::new();
    let mut want = Vec::new();
    for t in (0..mesh.tets.len()).step_by(7) {
        let l = [0.1, 0.2, 0.3, 0.4];
        let x: DVec3 = (0..4)
            .map(|a| mesh.nodes[mesh.tets[t][a] as usize] * l[a])
            .sum();
        let n = shape_functions(l);
        let mut u: DVec3 = (0..4).map(|a| full[mesh.tets[t][a] as usize] * n[a]).sum();
        for k in 0..6 {
            u += full[nc + tet_edges[t][k] as usize] * n[4 + k];
        }
        points.push(x.as_vec3().to_array());
        want.push(u);
    }
    let id = m.bind(RestPoints::Points(&points)).unwrap();
    let [x, y, z] = crate::tests::map_on_cpu(&mut m, id, points.len());
    let mut worst = 0f64;
    let mut linear_miss = 0f64;
    for (i, w) in want.iter().enumerate() {
        let got = DVec3::new(x[i] as f64, y[i] as f64, z[i] as f64);
        worst = worst.max((got - *w).length());
        let t = (0..mesh.tets.len()).step_by(7).nth(i).unwrap();
        let l = [0.1, 0.2, 0.3, 0.4];
        let lin: DVec3 = (0..4).map(|a| full[mesh.tets[t][a] as usize] * l[a]).sum();
        linear_miss = linear_miss.max((lin - *w).length());
    }
    let largest = want.iter().map(|u| u.length()).fold(0.0, f64::max);
    assert!(largest > 0.5, "{largest}");
    // f32 map and 16-bit weights.
    assert!(worst <= 1e-4 * largest, "{worst} of {largest}");
    assert!(
        linear_miss > 100.0 * worst,
        "the quadratic part matters ({linear_miss})"
    );
    let _ = TET_EDGES;
}

#[test]
fn an_octree_proxy_runs_p2_with_its_edge_nodes_tied() {
    use voxflex_core::deformation::ExecutionBackend;
    let volume = voxflex_phantom::phantom("rings", [33, 33, 33]).unwrap();
    let toml = "proxy = { kind = \"octree\", max_cell = 8 }\n\
         materials = [{ name = \"soft\", range = [50, 150], youngs_modulus = 2000 },\n\
                      { name = \"hard\", range = [150, 256], youngs_modulus = 200000 }]\n\
         solver = \"static\"\nelement = \"p2\"";
    let mut m = Fem::from_toml(toml).unwrap();
    m.init(volume.view(), ExecutionBackend::Cpu).unwrap();
    assert!(!m.hanging().is_empty(), "the octree has hanging nodes");
    m.interact("kind = \"fix\"\nmaterial = \"hard\"").unwrap();
    m.interact("kind = \"grab\"\npoint = [-40, 0, 0]\nby = [-5, 0, 0]")
        .unwrap();
    assert!(m.step(frame(0.0)).unwrap().changed);
    let u = &m.state().unwrap().u;
    assert!(u.iter().all(|v| v.is_finite()));
    assert!(
        u.iter().any(|v| v.length() > 1.0),
        "the grab moves the soft half"
    );
    for h in m.hanging() {
        let tied: DVec3 = h
            .masters
            .iter()
            .map(|&(n, w)| w as f64 * u[n as usize])
            .sum();
        assert!((u[h.node as usize] - tied).length() < 1e-9);
    }
}

#[test]
fn the_element_key_takes_p1_or_p2_and_names_itself_otherwise() {
    let scene = |e: &str| {
        format!(
            "proxy = {{ kind = \"uniform\", step = 4 }}\nmaterials = [{{ range = [0, 1], \
             youngs_modulus = 1000 }}]\nelement = \"{e}\""
        )
    };
    assert!(Fem::from_toml(&scene("p1")).is_ok());
    assert!(Fem::from_toml(&scene("p2")).is_ok());
    let e = Fem::from_toml(&scene("p3")).err().unwrap().0;
    assert!(
        e.contains("element = \"p3\"") && e.contains("\"p2\""),
        "{e}"
    );
}
