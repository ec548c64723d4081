//! CPU (rayon) vs GPU (WGSL, lavapipe in CI) on the same input: the PCG of
//! `shaders/mesh-model/pcg.wgsl` (sparse mat-vec, reductions, updates)
//! against the rayon PCG, through whole implicit steps. Without an adapter
//! these tests print SKIPPED, except under `CI=true`, where a missing
//! adapter fails them.

use crate::solver::{CorotationalFem, ElementKind, FemParams, SolverKind};
use std::sync::Arc;
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::grid::Grid;
use voxflex_mesh::mesh_model::parity::octree_parity;
use voxflex_mesh::mesh_model::{
    ElasticMaterial, MeshModel, device_difference, largest_and_difference,
};
use voxflex_mesh::proxy::uniform_proxy;

type Fem = MeshModel<CorotationalFem>;

fn test_gpu() -> Option<Arc<dyn GpuService>> {
    voxflex_runtime::gpu_context::testing::test_gpu().map(|g| g as Arc<dyn GpuService>)
}

/// A clamped two-material bar under gravity with a grab on its tip.
fn bar(gpu: Option<Arc<dyn GpuService>>, solver: SolverKind, element: ElementKind) -> Fem {
    let grid = Grid::new([13, 4, 4], DVec3::splat(1.0), DVec3::new(-20.0, 5.0, 40.0));
    let mesh = uniform_proxy(&grid, 1, |v| Some(u16::from(v[0] >= 6))).unwrap();
    let materials = vec![
        ElasticMaterial::new(3000.0, 0.45, 1e-3),
        ElasticMaterial::new(30000.0, 0.3, 1e-3),
    ];
    let params = FemParams {
        element,
        solver,
        cg_tolerance: 1e-6,
        cg_max_iterations: Some(400),
        ..FemParams::default()
    };
    let mut m = Fem::with_mesh(mesh, materials, DVec3::new(0.0, 0.0, -9810.0), params)
        .unwrap()
        .with_gpu(gpu);
    m.interact("kind = \"fix\"\nmin = [-20.1, 4.9, 39.9]\nmax = [-19.9, 8.1, 43.1]")
        .unwrap();
    m.interact("kind = \"grab\"\npoint = [-8, 8, 43]\nby = [1, 2, 3]\nframes = 50")
        .unwrap();
    m
}

fn compare(solver: SolverKind, frames: usize) {
    compare_elements(solver, ElementKind::P1, frames);
}

fn compare_elements(solver: SolverKind, element: ElementKind, frames: usize) {
    let Some(gpu) = test_gpu() else { return };
    let mut cpu = bar(None, solver, element);
    let mut dev = bar(Some(gpu), solver, element);
    dev.use_gpu().unwrap();
    let frame = FrameInfo {
        frame: 0,
        frames: frames as u64,
        dt_s: 1.0 / 30.0,
    };
    for _ in 0..frames {
        cpu.step(frame).unwrap();
        dev.step(frame).unwrap();
    }
    assert!(dev.last_solve().iterations > 0, "the GPU solved");
    let (a, b) = (&cpu.state().unwrap().u, &dev.state().unwrap().u);
    let (largest, worst) = largest_and_difference(a, b);
    assert!(largest > 0.1, "the bar moves ({largest} mm)");
    assert!(
        worst <= 1e-4 * largest,
        "{solver:?} {element:?}: GPU differs by {worst:.3e} of {largest:.3e} mm"
    );
    if element == ElementKind::P2 {
        // The mid-edge nodes too.
        let full = |m: &Fem| m.solver().unwrap().edge_nodes().unwrap().state.u.clone();
        let (largest, worst) = largest_and_difference(&full(&cpu), &full(&dev));
        assert!(
            worst <= 1e-4 * largest,
            "{solver:?} P2 edge nodes: GPU differs by {worst:.3e} of {largest:.3e} mm"
        );
    }
}

#[test]
fn gpu_p2_implicit_steps_match_rayon() {
    compare_elements(SolverKind::Dynamic, ElementKind::P2, 30);
}

#[test]
fn gpu_p2_static_solves_match_rayon() {
    compare_elements(SolverKind::Static, ElementKind::P2, 2);
}

#[test]
fn gpu_implicit_steps_match_rayon_after_100_steps() {
    compare(SolverKind::Dynamic, 100);
}

#[test]
fn gpu_static_solves_match_rayon() {
    compare(SolverKind::Static, 3);
}

#[test]
fn gpu_solves_on_an_octree_proxy_with_hanging_nodes_match_rayon() {
    let Some(gpu) = test_gpu() else { return };
    let volume = voxflex_phantom::phantom("rings", [33, 33, 33]).unwrap();
    let p = octree_parity::<CorotationalFem>(
        volume.view(),
        gpu,
        "proxy = { kind = \"octree\", max_cell = 8 }\n\
         materials = [{ name = \"soft\", range = [50, 150], youngs_modulus = 2000, density = 1000 },\n\
                      { name = \"hard\", range = [150, 256], youngs_modulus = 20000, density = 1000 }]\n\
         solver = \"dynamic\"\ncg_tolerance = 1e-6\ncg_max_iterations = 400",
        &[
            "kind = \"fix\"\nmaterial = \"hard\"",
            "kind = \"grab\"\npoint = [-40, 0, 0]\nby = [-4, 2, 1]\nframes = 10",
        ],
        FrameInfo {
            frame: 0,
            frames: 10,
            dt_s: 1.0 / 30.0,
        },
        10,
    )
    .unwrap();
    assert!(p.hanging > 0, "the test needs hanging nodes");
    assert!(
        p.largest > 1.0,
        "the grab moves the soft half ({} mm)",
        p.largest
    );
    assert!(
        p.worst <= 1e-4 * p.largest,
        "GPU differs by {:.3e} of {:.3e} mm",
        p.worst,
        p.largest
    );
    // The hanging nodes follow their masters on the GPU path too.
    assert!(
        p.worst_tie < 1e-9,
        "hanging nodes off by {:.3e} mm",
        p.worst_tie
    );
}

/// A carve on the GPU backend: the solver is rebuilt on the device, the
/// binding (uploaded before the carve) is uploaded again for the smaller
/// mesh, and the device map still equals the rayon map afterwards.
#[test]
fn a_carve_on_the_gpu_backend_rebuilds_the_device_map() {
    carve_on_the_gpu_backend(ElementKind::P1);
}

/// The same with quadratic elements, whose map (corners plus the mid-edge
/// layer) runs on the CPU and goes up to the device buffers.
#[test]
fn a_carve_on_the_gpu_backend_with_p2_maps_like_rayon() {
    carve_on_the_gpu_backend(ElementKind::P2);
}

fn carve_on_the_gpu_backend(element: ElementKind) {
    use voxflex_core::deformation::{DisplacementTarget, RestPoints};
    let Some(gpu) = test_gpu() else { return };
    let mut cpu = bar(None, SolverKind::Dynamic, element);
    let mut dev = bar(Some(gpu.clone()), SolverKind::Dynamic, element);
    dev.use_gpu().unwrap();
    let grid = Grid::new([25, 7, 7], DVec3::splat(0.5), DVec3::new(-20.0, 5.0, 40.0));
    let (ic, id) = (
        cpu.bind(RestPoints::Lattice(grid)).unwrap(),
        dev.bind(RestPoints::Lattice(grid)).unwrap(),
    );
    let n = grid.len();
    let bufs = [0, 1, 2].map(|_| gpu.create_buffer(4 * n as u64, "test out").unwrap());
    let frame = FrameInfo {
        frame: 0,
        frames: 20,
        dt_s: 1.0 / 30.0,
    };
    let run = |cpu: &mut Fem, dev: &mut Fem, frames: usize| {
        let target = DisplacementTarget::Gpu {
            x: bufs[0],
            y: bufs[1],
            z: bufs[2],
        };
        for _ in 0..frames {
            cpu.step(frame).unwrap();
            dev.step(frame).unwrap();
        }
        let [x, y, z] = crate::tests::map_on_cpu(cpu, ic, n);
        dev.map(id, target).unwrap();
        let largest = x
            .iter()
            .chain(&y)
            .chain(&z)
            .fold(0f32, |m, v| m.max(v.abs()));
        assert!(largest > 0.1, "the bar moves ({largest} mm)");
        let worst = device_difference(&*gpu, bufs, [&x, &y, &z]).unwrap();
        assert!(
            worst <= 1e-4 * largest,
            "map differs by {worst} of {largest}"
        );
    };
    run(&mut cpu, &mut dev, 5);
    let carve = "kind = \"carve\"\ncentre = [-12, 6.5, 41.5]\nradius = 1.6";
    let tets = dev.mesh().unwrap().tets.len();
    cpu.interact(carve).unwrap();
    dev.interact(carve).unwrap();
    assert!(
        dev.mesh().unwrap().tets.len() < tets,
        "the carve removes tissue"
    );
    run(&mut cpu, &mut dev, 10);
    for buf in bufs {
        gpu.destroy_buffer(buf);
    }
}

#[test]
fn gpu_unconverged_solves_are_counted_like_rayons() {
    // The same capped implicit step (3 CG iterations) on both paths: each
    // counts one unconverged solve, and the worst residuals agree.
    let Some(gpu) = test_gpu() else { return };
    let capped = |gpu: Option<Arc<dyn GpuService>>| {
        let grid = Grid::new([13, 4, 4], DVec3::splat(1.0), DVec3::new(-20.0, 5.0, 40.0));
        let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
        let params = FemParams {
            cg_max_iterations: Some(3),
            ..FemParams::default()
        };
        let material = ElasticMaterial::new(3000.0, 0.45, 1e-3);
        let mut m = Fem::with_mesh(mesh, vec![material], DVec3::new(0.0, 0.0, -9810.0), params)
            .unwrap()
            .with_gpu(gpu);
        m.interact("kind = \"fix\"\nmin = [-20.1, 4.9, 39.9]\nmax = [-19.9, 8.1, 43.1]")
            .unwrap();
        m
    };
    let mut cpu = capped(None);
    let mut dev = capped(Some(gpu));
    dev.use_gpu().unwrap();
    let frame = FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: 1.0 / 30.0,
    };
    cpu.step(frame).unwrap();
    dev.step(frame).unwrap();
    let (a, b) = (cpu.notes().unwrap(), dev.notes().unwrap());
    assert_eq!(a["unconverged_solves"], 1.0, "{a:?}");
    assert_eq!(b["unconverged_solves"], 1.0, "{b:?}");
    let (ra, rb) = (a["worst_residual"], b["worst_residual"]);
    assert!(ra > 1e-6 && (ra - rb).abs() <= 1e-3 * ra, "{ra} vs {rb}");
}
