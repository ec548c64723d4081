//! Accuracy and robustness tests of the corotational solver through the
//! shared mesh model (the same path the plugin's scenes take).

use crate::solver::{CorotationalFem, ElementKind, FemParams, SolverKind};
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::glam::{DMat3, DQuat, DVec3};
use voxflex_core::grid::Grid;
use voxflex_core::tet_mesh::TetMesh;
use voxflex_mesh::mesh_model::inversion::{inverted_tetrahedra, largest_edge_change};
use voxflex_mesh::mesh_model::{ElasticMaterial, MeshModel, cantilever};
use voxflex_mesh::proxy::uniform_proxy;

type Fem = MeshModel<CorotationalFem>;

/// The cantilever (`mesh_model::cantilever`) on this solver.
pub(crate) fn cantilever(r: usize, load: f64, params: FemParams) -> Fem {
    voxflex_mesh::mesh_model::cantilever::model::<CorotationalFem>(r, load, params)
}

/// Binding `id`'s displacements (mm) of its `n` points, mapped on the CPU.
pub(crate) fn map_on_cpu(
    m: &mut Fem,
    id: voxflex_core::deformation::BindingId,
    n: usize,
) -> [Vec<f32>; 3] {
    let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
    let target = voxflex_core::deformation::DisplacementTarget::Cpu {
        x: &mut x,
        y: &mut y,
        z: &mut z,
    };
    m.map(id, target).unwrap();
    [x, y, z]
}

pub(crate) fn static_params(tolerance: f64) -> FemParams {
    FemParams {
        solver: SolverKind::Static,
        cg_tolerance: tolerance,
        cg_max_iterations: Some(5000),
        ..FemParams::default()
    }
}

fn frame(dt: f64) -> FrameInfo {
    FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: dt,
    }
}

fn reference() -> serde_json::Value {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/reference/cantilever.json"
    );
    let text = std::fs::read_to_string(path).expect("tests/reference/cantilever.json");
    serde_json::from_str(&text).expect("reference JSON")
}

#[test]
fn cantilever_matches_an_independent_linear_solution_on_the_same_mesh() {
    let reference = reference();
    for level in reference["levels"].as_array().unwrap() {
        let r = level["r"].as_u64().unwrap() as usize;
        let Some(expected) = level.get("displacements").and_then(|d| d.as_array()) else {
            continue;
        };
        // Small deflection: the linear reference scales with the load, so
        // compare u / P at a load where rotations are negligible.
        let p = 1e-4;
        let mut m = cantilever(r, p, static_params(1e-12));
        m.step(frame(0.0)).unwrap();
        let mesh = m.mesh().unwrap().clone();
        let u = &m.state().unwrap().u;
        let mut worst = 0f64;
        let mut largest = 0f64;
        for (n, x) in mesh.nodes.iter().enumerate() {
            let e = &expected[cantilever::reference_node(*x, r)];
            let e = DVec3::new(
                e[0].as_f64().unwrap(),
                e[1].as_f64().unwrap(),
                e[2].as_f64().unwrap(),
            );
            worst = worst.max((u[n] / p - e).length());
            largest = largest.max(e.length());
        }
        assert!(
            worst <= 0.005 * largest,
            "r = {r}: largest deviation {worst:.3e} of {largest:.3e}"
        );
        assert!(largest > 1.0, "the reference deflects");
    }
}

#[test]
fn a_rigidly_rotated_rest_state_has_no_elastic_force() {
    let mesh = cantilever::mesh(2);
    let fem = Fem::with_mesh(
        mesh.clone(),
        vec![ElasticMaterial::new(1000.0, 0.3, 1e-6)],
        DVec3::ZERO,
        FemParams::default(),
    )
    .unwrap();
    let solver = fem.solver().unwrap();
    let q = DMat3::from_quat(DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2));
    let rotated: Vec<DVec3> = mesh.nodes.iter().map(|x| q * *x - *x).collect();
    let f = solver.elastic_forces(&rotated);
    // Against the forces of a 1 % stretch along x.
    let stretched: Vec<DVec3> = mesh
        .nodes
        .iter()
        .map(|x| DVec3::new(0.01 * x.x, 0.0, 0.0))
        .collect();
    let scale = solver
        .elastic_forces(&stretched)
        .iter()
        .map(|v| v.length())
        .fold(0.0, f64::max);
    let worst = f.iter().map(|v| v.length()).fold(0.0, f64::max);
    assert!(worst <= 1e-9 * scale, "{worst:.3e} against {scale:.3e}");
}

#[test]
fn a_large_rotation_keeps_the_beam_length_where_linear_fem_grows_it() {
    // A heavy tip load bends the beam through a large angle: the
    // corotational beam keeps its axis length; the linear solution (the
    // response to a tiny load, where rotations are negligible, scaled up
    // to the same load) stretches it.
    let length = |m: &Fem, scale: f64| {
        let mesh = m.mesh().unwrap();
        let u = &m.state().unwrap().u;
        // The neutral axis y = z = 0.5 (a node line at r = 2).
        let mut edge: Vec<DVec3> = mesh
            .nodes
            .iter()
            .zip(u)
            .filter(|(x, _)| x.y == 0.5 && x.z == 0.5)
            .map(|(x, d)| *x + scale * *d)
            .collect();
        edge.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.z.total_cmp(&b.z)));
        edge.windows(2).map(|w| (w[1] - w[0]).length()).sum::<f64>()
    };
    let mut corotated = cantilever(2, 3.0, static_params(1e-10));
    corotated.step(frame(0.0)).unwrap();
    let mut linear = cantilever(2, 3e-4, static_params(1e-10));
    linear.step(frame(0.0)).unwrap();
    let (lc, ll) = (length(&corotated, 1.0), length(&linear, 1e4));
    let tip = |m: &Fem| {
        let mesh = m.mesh().unwrap();
        let u = &m.state().unwrap().u;
        mesh.nodes
            .iter()
            .zip(u)
            .filter(|(x, _)| x.x == 10.0)
            .map(|(_, d)| d.z)
            .sum::<f64>()
    };
    assert!(tip(&corotated) < -3.0, "the load bends the beam a lot");
    assert!((lc - 10.0).abs() < 0.1, "corotational length {lc}");
    assert!(ll > 10.5, "linear length {ll}");
}

#[test]
fn inverted_elements_recover_without_nan() {
    // A block squashed through itself along z (z → −0.2 z: every element
    // inside out, the flip along its shortest axis), then let go: it
    // returns to rest.
    let h = 0.5;
    let grid = Grid::new([5, 5, 5], DVec3::splat(h), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
    let params = FemParams {
        solver: SolverKind::Dynamic,
        substeps: 4,
        mass_damping: 5.0,
        ..FemParams::default()
    };
    let mut m = Fem::with_mesh(
        mesh.clone(),
        vec![ElasticMaterial::new(5000.0, 0.3, 1e-6)],
        DVec3::ZERO,
        params,
    )
    .unwrap();
    let inverted: Vec<DVec3> = mesh
        .nodes
        .iter()
        .map(|x| DVec3::new(0.0, 0.0, -1.2 * x.z))
        .collect();
    m.set_displacements(&inverted).unwrap();
    let inverted_count = (0..mesh.tets.len())
        .filter(|&t| {
            let x = mesh.tets[t].map(|n| mesh.nodes[n as usize] + inverted[n as usize]);
            voxflex_core::tet_mesh::signed_volume(x) < 0.0
        })
        .count();
    assert_eq!(
        inverted_count,
        mesh.tets.len(),
        "every element starts inverted"
    );
    for _ in 0..400 {
        m.step(frame(0.01)).unwrap();
    }
    let u = &m.state().unwrap().u;
    assert!(u.iter().all(|v| v.is_finite()));
    let still_inverted = inverted_tetrahedra(&mesh, u);
    assert_eq!(still_inverted, 0, "elements still inverted");
    // Back at rest up to a rigid motion: every edge has its rest length.
    let (edge, change) = largest_edge_change(&mesh, u).unwrap();
    assert!(
        change < 0.02,
        "edge {edge:?} off its rest length by {change:.3}"
    );
}

#[test]
fn stiffness_ratios_slivers_and_random_grabs_stay_finite() {
    // A 4 × 2 × 2 block whose far half is 10⁶ times stiffer, with one cell
    // squeezed to a sliver layer (0.01 of the others' thickness).
    let mut nodes = Vec::new();
    let xs = [0.0, 1.0, 2.0, 2.01, 3.0];
    let index = |i: usize, j: usize, k: usize| (i + 5 * (j + 3 * k)) as u32;
    for k in 0..3 {
        for j in 0..3 {
            for &x in &xs {
                nodes.push(DVec3::new(x, j as f64, k as f64));
            }
        }
    }
    let mut tets = Vec::new();
    let mut labels = Vec::new();
    for k in 0..2 {
        for j in 0..2 {
            for i in 0..4 {
                let corner = |c: u8| {
                    index(
                        i + (c & 1) as usize,
                        j + ((c >> 1) & 1) as usize,
                        k + (c >> 2) as usize,
                    )
                };
                let pattern = voxflex_resample::sampling_mesh::CELL_TETS[(i + j + k) & 1];
                for t in pattern {
                    tets.push(t.map(corner));
                    labels.push(u16::from(i >= 2));
                }
            }
        }
    }
    let mesh = TetMesh::new("sliver block", nodes, tets, labels).unwrap();
    let materials = vec![
        ElasticMaterial::new(1000.0, 0.45, 1e-6),
        ElasticMaterial::new(1e9, 0.3, 1e-6),
    ];
    let mut m = Fem::with_mesh(mesh, materials, DVec3::ZERO, FemParams::default()).unwrap();
    m.interact("kind = \"fix\"\nmin = [-0.1, -0.1, -0.1]\nmax = [0.1, 2.1, 2.1]")
        .unwrap();
    let mut seed = 5u64;
    let mut rand = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for step in 0..10_000 {
        if step % 40 == 0 {
            let p = [3.0 * rand(), 2.0 * rand(), 2.0 * rand()];
            let by = [rand() - 0.5, rand() - 0.5, rand() - 0.5].map(|v| 3.0 * v);
            m.interact(&format!(
                "kind = \"grab\"\npoint = {p:?}\nby = {by:?}\nframes = 8"
            ))
            .unwrap();
        }
        if step % 400 == 399 {
            m.interact("kind = \"release\"").unwrap();
        }
        m.step(frame(1.0 / 60.0)).unwrap();
    }
    let u = &m.state().unwrap().u;
    assert!(u.iter().all(|v| v.is_finite()));
}

/// Before `init`, `interact` is a dry run (what `voxflex validate` uses):
/// the shared parser refuses a bad interaction, a good one is accepted
/// and nothing is applied (a grab after `init` still finds no earlier one).
#[test]
fn interact_before_init_only_validates() {
    let mut m = Fem::from_toml(
        "materials = [{ range = [50, 150], youngs_modulus = 2000 }]\nsolver = \"static\"",
    )
    .unwrap();
    let e = m.interact("kind = \"poke\"").unwrap_err().0;
    assert!(e.contains("poke") && e.contains("grab"), "{e}");
    m.interact("kind = \"carve\"\ncentre = [0, 0, 0]\nradius = 1000")
        .unwrap();
    let volume = voxflex_phantom::phantom("cube", [8, 8, 8]).unwrap();
    m.init(
        volume.view(),
        voxflex_core::deformation::ExecutionBackend::Cpu,
    )
    .unwrap();
    assert!(
        m.notes().unwrap()["proxy_tetrahedra"] > 0.0,
        "the dry-run carve of everything removed nothing"
    );
}

#[test]
fn an_octree_proxy_from_a_volume_runs_with_hanging_nodes_tied_and_exports_vtu() {
    use voxflex_core::deformation::ExecutionBackend;
    let volume = voxflex_phantom::phantom("rings", [33, 33, 33]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let vtu = dir.path().join("ring.vtu");
    let toml = format!(
        "proxy = {{ kind = \"octree\", max_cell = 8 }}\n\
         materials = [{{ name = \"soft\", range = [50, 150], youngs_modulus = 2000 }},\n\
                      {{ name = \"hard\", range = [150, 256], youngs_modulus = 200000 }}]\n\
         solver = \"static\"\nvtu = {:?}",
        vtu.to_str().unwrap()
    );
    let mut m = Fem::from_toml(&toml).unwrap();
    m.init(volume.view(), ExecutionBackend::Cpu).unwrap();
    m.interact("kind = \"fix\"\nmaterial = \"hard\"").unwrap();
    m.interact("kind = \"grab\"\npoint = [-40, 0, 0]\nby = [-5, 0, 0]")
        .unwrap();
    assert!(m.step(frame(0.0)).unwrap().changed);
    let mesh = m.mesh().unwrap();
    let u = &m.state().unwrap().u;
    assert!(u.iter().all(|v| v.is_finite()));
    assert!(
        u.iter().any(|v| v.length() > 1.0),
        "the grab moves the soft half"
    );
    // The proxy has level changes; its hanging nodes follow their masters.
    assert!(!m.hanging().is_empty(), "the test needs hanging nodes");
    for h in m.hanging() {
        let tied: DVec3 = h
            .masters
            .iter()
            .map(|&(n, w)| w as f64 * u[n as usize])
            .sum();
        assert!(
            (u[h.node as usize] - tied).length() < 1e-6,
            "node {}",
            h.node
        );
    }
    let text = std::fs::read_to_string(&vtu).unwrap();
    assert!(
        text.contains("<VTKFile")
            && text.contains(&format!("NumberOfPoints=\"{}\"", mesh.nodes.len()))
    );
}

#[test]
fn a_cut_separates_the_proxy_and_opens_in_the_sampling_mesh() {
    a_cut_separates_the_proxy_and_opens_in_the_sampling_mesh_with(ElementKind::P1);
}

/// The same with quadratic elements: the solver and its edge nodes are
/// rebuilt on the changed mesh.
#[test]
fn a_cut_separates_the_proxy_and_opens_in_the_sampling_mesh_with_p2() {
    a_cut_separates_the_proxy_and_opens_in_the_sampling_mesh_with(ElementKind::P2);
}

fn a_cut_separates_the_proxy_and_opens_in_the_sampling_mesh_with(element: ElementKind) {
    use voxflex_core::deformation::RestPoints;
    // The cantilever, cut through at x = 5; a pull on the free half moves
    // it away while the clamped half stays.
    let mut m = cantilever(
        2,
        0.0,
        FemParams {
            element,
            ..static_params(1e-10)
        },
    );
    let grid = Grid::new([21, 3, 3], DVec3::splat(0.5), DVec3::ZERO);
    let id = m.bind(RestPoints::Lattice(grid)).unwrap();
    assert!(
        !m.removed_tetrahedra(id, &mut []).unwrap(),
        "nothing removed yet"
    );
    let nodes = m.mesh().unwrap().nodes.len();
    m.interact(
        "kind = \"cut\"\npolygon = [[5.1, -1, -1], [5.1, 2, -1], [5.1, 2, 2], [5.1, -1, 2]]",
    )
    .unwrap();
    assert!(m.mesh().unwrap().nodes.len() > nodes, "nodes duplicated");
    m.interact("kind = \"grab\"\npoint = [10, 0.5, 0.5]\nby = [2, 0, 0]")
        .unwrap();
    m.step(frame(0.0)).unwrap();
    let mesh = m.mesh().unwrap();
    let u = &m.state().unwrap().u;
    for (x, d) in mesh.nodes.iter().zip(u) {
        if x.x < 5.0 {
            assert!(d.length() < 1e-6, "the clamped half stays: {x} moved {d}");
        } else if x.x > 5.5 {
            // Held by one node only, the free half may also turn a little.
            assert!(
                (d.x - 2.0).abs() < 0.1,
                "the free half follows the grab: {x} moved {d}"
            );
        }
    }
    // The resampler's mask: the sampling tetrahedra across x = 5.1.
    assert!(m.removed_tetrahedra(id, &mut []).unwrap());
    let mut bits = vec![0u8; 20 * 2 * 2];
    assert!(m.removed_tetrahedra(id, &mut bits).unwrap());
    for (cell, b) in bits.iter().enumerate() {
        let i = cell % 20;
        assert_eq!(*b != 0, i == 10, "cell {cell} (x index {i}): bits {b:#b}");
    }
    assert!(
        !m.removed_tetrahedra(id, &mut bits).unwrap(),
        "reported once"
    );
    let n = grid.len();
    let [x, _, _] = map_on_cpu(&mut m, id, n);
    assert!((x[grid.linear(20, 1, 1)] - 2.0).abs() < 0.1);
    assert!(x[grid.linear(0, 1, 1)].abs() < 1e-6);
}

/// A cut through the inside of proxy cells is voxel-sharp: every voxel
/// centre of a cut cell follows the piece of its own side of the plane,
/// not the side of the tetrahedron that carried it (bound anew, note
/// `cut_voxels_rebound`; none left across), for planes at three places in
/// the cells, either side of a node plane.
#[test]
fn a_cut_inside_proxy_cells_moves_every_voxel_centre_with_its_own_side() {
    use voxflex_core::deformation::RestPoints;
    for plane in [5.15, 5.35, 4.85] {
        let mut m = cantilever(2, 0.0, static_params(1e-10));
        // Voxel centres 0.1 mm apart in the proxy's 0.5 mm cells.
        let grid = Grid::new([101, 11, 11], DVec3::splat(0.1), DVec3::ZERO);
        let id = m.bind(RestPoints::Lattice(grid)).unwrap();
        m.interact(&format!(
            "kind = \"cut\"\npolygon = [[{plane}, -1, -1], [{plane}, 2, -1], [{plane}, 2, 2], \
             [{plane}, -1, 2]]"
        ))
        .unwrap();
        m.interact("kind = \"grab\"\npoint = [10, 0.5, 0.5]\nby = [2, 0, 0]")
            .unwrap();
        m.step(frame(0.0)).unwrap();
        let notes = m.notes().unwrap();
        assert!(notes["cut_voxels_rebound"] > 0.0, "{plane}: {notes:?}");
        assert_eq!(notes["cut_voxels_across"], 0.0, "{plane}");
        let [x, _, _] = map_on_cpu(&mut m, id, grid.len());
        for (l, ux) in x.iter().enumerate() {
            let px = grid.unlinear(l)[0] as f64 * 0.1;
            if px < plane {
                assert!(ux.abs() < 1e-5, "{plane}: the point at x = {px} moved {ux}");
            } else {
                assert!(
                    (ux - 2.0).abs() < 0.1,
                    "{plane}: the point at x = {px} moved {ux}, not with the free half"
                );
            }
        }
    }
}

#[test]
fn a_carve_removes_tissue_rebinds_its_points_and_opens_in_the_sampling_mesh() {
    a_carve_removes_tissue_rebinds_its_points_and_opens_in_the_sampling_mesh_with(ElementKind::P1);
}

/// The same with quadratic elements: the solver and its edge nodes are
/// rebuilt on the changed mesh.
#[test]
fn a_carve_removes_tissue_rebinds_its_points_and_opens_in_the_sampling_mesh_with_p2() {
    a_carve_removes_tissue_rebinds_its_points_and_opens_in_the_sampling_mesh_with(ElementKind::P2);
}

fn a_carve_removes_tissue_rebinds_its_points_and_opens_in_the_sampling_mesh_with(
    element: ElementKind,
) {
    use voxflex_core::deformation::RestPoints;
    use voxflex_mesh::mesh_model::cantilever::tip_deflection;
    let load = 1e-3;
    let tip = |m: &Fem| tip_deflection(m.mesh().unwrap(), &m.state().unwrap().u);
    let mut whole = cantilever(
        2,
        load,
        FemParams {
            element,
            ..static_params(1e-10)
        },
    );
    whole.step(frame(0.0)).unwrap();
    // The top half of the beam's middle carved away: thinner there, the
    // tip sags more under the same load.
    let mut m = cantilever(
        2,
        load,
        FemParams {
            element,
            ..static_params(1e-10)
        },
    );
    let grid = Grid::new([21, 3, 3], DVec3::splat(0.5), DVec3::ZERO);
    let id = m.bind(RestPoints::Lattice(grid)).unwrap();
    let outside = m.notes().unwrap()["bound_points_outside_proxy"];
    let (nodes, tets) = {
        let mesh = m.mesh().unwrap();
        (mesh.nodes.len(), mesh.tets.len())
    };
    m.interact("kind = \"carve\"\nmin = [3, -1, 0.6]\nmax = [7, 2, 2]")
        .unwrap();
    let mesh = m.mesh().unwrap();
    assert!(mesh.tets.len() < tets && mesh.nodes.len() < nodes);
    for t in 0..mesh.tets.len() {
        let c = mesh.corners(t).iter().sum::<DVec3>() * 0.25;
        assert!(
            !(c.x >= 3.0 && c.x <= 7.0 && c.z >= 0.6),
            "tetrahedron {t} at {c} should be gone"
        );
    }
    // The lattice points on the carved top face now lie outside the proxy.
    assert!(m.notes().unwrap()["bound_points_outside_proxy"] > outside);
    m.step(frame(0.0)).unwrap();
    assert!(
        tip(&m) < 1.5 * tip(&whole) && tip(&whole) < 0.0,
        "carved {} vs whole {}",
        tip(&m),
        tip(&whole)
    );
    // The resampler's mask: every sampling cell at a lattice point in the
    // box (x 3..7 mm = i 6..14, z 1 mm = k 2), none elsewhere.
    let mut bits = vec![0u8; 20 * 2 * 2];
    assert!(m.removed_tetrahedra(id, &mut bits).unwrap());
    for (cell, b) in bits.iter().enumerate() {
        let (i, k) = (cell % 20, cell / 40);
        assert_eq!(
            *b != 0,
            (5..=14).contains(&i) && k == 1,
            "cell {cell} (x {i}, z {k}): bits {b:#b}"
        );
    }
    // Every point maps, those of removed tetrahedra with their neighbours.
    let n = grid.len();
    let [x, y, z] = map_on_cpu(&mut m, id, n);
    assert!(x.iter().chain(&y).chain(&z).all(|v| v.is_finite()));
    let top = grid.linear(10, 1, 2); // (5, 0.5, 1) mm: carved away
    let below = grid.linear(10, 1, 1); // (5, 0.5, 0.5) mm: kept
    assert!((z[top] - z[below]).abs() < 1e-3 * z[below].abs().max(1e-9) + 1e-9);
    // A carve of the whole beam is refused; one that misses is a no-op.
    let e = m
        .interact("kind = \"carve\"\ncentre = [5, 0.5, 0.5]\nradius = 100")
        .unwrap_err()
        .0;
    assert!(e.contains("whole proxy"), "{e}");
    let before = m.mesh().unwrap().tets.len();
    m.interact("kind = \"carve\"\ncentre = [50, 0, 0]\nradius = 1")
        .unwrap();
    assert_eq!(m.mesh().unwrap().tets.len(), before);
}

#[test]
fn a_mesh_file_proxy_maps_its_tags_to_materials_and_hostile_files_are_refused() {
    use voxflex_core::deformation::ExecutionBackend;
    let dir = tempfile::tempdir().unwrap();
    // Two tetrahedra of a unit cube's corner, tagged 7 and 9 (TetGen).
    let node = "5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n";
    let ele = "2 4 1\n1 1 2 3 4 7\n2 2 3 4 5 9\n";
    std::fs::write(dir.path().join("m.node"), node).unwrap();
    std::fs::write(dir.path().join("m.ele"), ele).unwrap();
    let volume = voxflex_phantom::phantom("cube", [8, 8, 8]).unwrap();
    let scene = |materials: &str| {
        format!(
            "proxy = {{ kind = \"file\", path = {:?} }}\nmaterials = [{materials}]\nsolver = \"static\"",
            dir.path().join("m.node").to_str().unwrap()
        )
    };
    let both = "{ label = 7, youngs_modulus = 1000 }, { label = 9, youngs_modulus = 5000 }";
    let mut m = Fem::from_toml(&scene(both)).unwrap();
    m.init(volume.view(), ExecutionBackend::Cpu).unwrap();
    let mesh = m.mesh().unwrap();
    assert_eq!(mesh.tets.len(), 2);
    let mut labels = mesh.labels.clone();
    labels.sort_unstable();
    assert_eq!(labels, vec![0, 1], "tags 7 and 9 became materials 0 and 1");

    let mut m = Fem::from_toml(&scene("{ label = 7, youngs_modulus = 1000 }")).unwrap();
    let e = m.init(volume.view(), ExecutionBackend::Cpu).unwrap_err().0;
    assert!(
        e.contains("tagged 9") && e.contains("label = 9") && e.contains("m.node"),
        "{e}"
    );

    std::fs::write(
        dir.path().join("m.node"),
        node.replace("5 1 1 1", "5 1 nan 1"),
    )
    .unwrap();
    let mut m = Fem::from_toml(&scene(both)).unwrap();
    let e = m.init(volume.view(), ExecutionBackend::Cpu).unwrap_err().0;
    assert!(e.contains("m.node") && e.contains("finite"), "{e}");
}

#[test]
fn notes_count_points_bound_outside_the_proxy_and_the_solver_work() {
    use voxflex_core::deformation::RestPoints;
    let mut fem = cantilever(1, 0.01, static_params(1e-9));
    let notes = fem.notes().unwrap();
    assert_eq!(notes["steps"], 0.0);
    assert_eq!(notes["bound_points"], 0.0);
    // Two points inside the 10 × 1 × 1 beam, three outside it.
    let points = [
        [5.0, 0.5, 0.5],
        [0.1, 0.1, 0.9],
        [-3.0, 0.5, 0.5],
        [5.0, 2.0, 0.5],
        [11.0, -1.0, 4.0],
    ];
    fem.bind(RestPoints::Points(&points)).unwrap();
    fem.step(frame(0.01)).unwrap();
    fem.step(frame(0.01)).unwrap();
    let notes = fem.notes().unwrap();
    assert_eq!(notes["bound_points"], 5.0);
    assert_eq!(notes["bound_points_outside_proxy"], 3.0);
    assert_eq!(notes["steps"], 2.0);
    assert!(notes["solver_iterations"] > 0.0, "{notes:?}");
    assert!(notes["last_residual"] <= 1e-9, "{notes:?}");
    assert_eq!(notes["proxy_tetrahedra"], 50.0);
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
    voxflex_mesh::mesh_model::small_features::every_offset::<CorotationalFem>(params)
        .unwrap_or_else(|e| panic!("{e}"));
}

/// With no `proxy` key the proxy's nodes lie the solver's
/// `MeshSolver::DEFAULT_NODE_SPACING` voxels apart whatever the element: P1 on uniform cells of that many voxels,
/// P2 (a node mid-edge) on cells twice that size.
#[test]
fn the_default_proxy_keeps_the_node_spacing_of_each_element() {
    use voxflex_core::deformation::ExecutionBackend;
    use voxflex_mesh::mesh_model::MeshSolver;
    const DEFAULT_NODE_SPACING: usize = <CorotationalFem as MeshSolver>::DEFAULT_NODE_SPACING;
    let volume = voxflex_phantom::phantom("cube", [33, 33, 33]).unwrap();
    let tetrahedra = |params: &str| {
        let mut m = Fem::from_toml(&format!(
            "materials = [{{ range = [50, 150], youngs_modulus = 2000 }}]\n{params}"
        ))
        .unwrap();
        m.init(volume.view(), ExecutionBackend::Cpu).unwrap();
        m.notes().unwrap()["proxy_tetrahedra"]
    };
    let step = |s: usize| format!("proxy = {{ kind = \"uniform\", step = {s} }}\n");
    for (element, cells_per_spacing) in [("p1", 1), ("p2", 2)] {
        let by_default = tetrahedra(&format!("element = \"{element}\""));
        let explicit = tetrahedra(&format!(
            "{}element = \"{element}\"",
            step(cells_per_spacing * DEFAULT_NODE_SPACING)
        ));
        let other = tetrahedra(&format!(
            "{}element = \"{element}\"",
            step(cells_per_spacing * (DEFAULT_NODE_SPACING - 1).max(1))
        ));
        assert_eq!(by_default, explicit, "{element}");
        assert_ne!(
            by_default, other,
            "{element}: the cube must tell the steps apart"
        );
    }
    // The element's own default follows the same rule.
    let default_step = match FemParams::default().element {
        ElementKind::P1 => DEFAULT_NODE_SPACING,
        ElementKind::P2 => 2 * DEFAULT_NODE_SPACING,
    };
    assert_eq!(tetrahedra(""), tetrahedra(&step(default_step)));
}

/// A static large-deflection solve whose vectors are long enough for the
/// parallel dot products (9,100 nodes) gives the same displacements, bit
/// for bit, on 1, 2 and 3 threads: the CG's reductions do not depend on
/// how the threads share the work (they did before the fixed-chunk
/// `pcg::dot`: iteration totals differed by 1–3 between runs).
#[test]
fn a_static_solve_is_the_same_on_any_thread_count() {
    let solve = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut m = cantilever(9, 0.5, static_params(1e-8));
            m.step(frame(0.0)).unwrap();
            let u: Vec<[u64; 3]> = m
                .state()
                .unwrap()
                .u
                .iter()
                .map(|d| d.to_array().map(f64::to_bits))
                .collect();
            u
        })
    };
    let one = solve(1);
    assert!(
        one.len() > 8192,
        "{} nodes: not the parallel path",
        one.len()
    );
    for threads in [2, 3] {
        assert!(solve(threads) == one, "{threads} threads moved a node");
    }
}
