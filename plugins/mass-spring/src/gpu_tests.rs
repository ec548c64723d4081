//! CPU (rayon) vs GPU (WGSL, lavapipe in CI) on the same input: the
//! explicit sub-step kernels of `shaders/mass-spring/springs.wgsl` against
//! their rayon twins, and the map into device buffers. Without an adapter
//! these tests print SKIPPED, except under `CI=true`, where a missing
//! adapter fails them.

use crate::solver::{Integrator, MassSpring, SpringParams};
use std::sync::Arc;
use voxflex_core::deformation::{DeformationModel, DisplacementTarget, FrameInfo, RestPoints};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::grid::Grid;
use voxflex_mesh::mesh_model::parity::octree_parity;
use voxflex_mesh::mesh_model::{
    ElasticMaterial, MeshModel, device_difference, largest_and_difference,
};
use voxflex_mesh::proxy::uniform_proxy;

type Springs = MeshModel<MassSpring>;

fn test_gpu() -> Option<Arc<dyn GpuService>> {
    voxflex_runtime::gpu_context::testing::test_gpu().map(|g| g as Arc<dyn GpuService>)
}

/// A clamped two-material bar under gravity, grabbed at its tip.
fn bar(gpu: Option<Arc<dyn GpuService>>) -> Springs {
    let grid = Grid::new([9, 3, 3], DVec3::splat(0.5), DVec3::new(10.0, -3.0, 50.0));
    let mesh = uniform_proxy(&grid, 1, |v| Some(u16::from(v[0] >= 5))).unwrap();
    let materials = vec![
        ElasticMaterial::new(2000.0, 0.3, 1e-3),
        ElasticMaterial::new(8000.0, 0.3, 1e-3),
    ];
    let mut m = Springs::with_mesh(
        mesh,
        materials,
        DVec3::new(0.0, 0.0, -9810.0),
        SpringParams {
            integrator: Integrator::Explicit,
            ..SpringParams::default()
        },
    )
    .unwrap()
    .with_gpu(gpu);
    m.interact("kind = \"fix\"\nmin = [9.9, -3.1, 49.9]\nmax = [10.1, -1.9, 51.1]")
        .unwrap();
    m.interact("kind = \"grab\"\npoint = [14, -2.5, 51]\nby = [0.5, 0.3, 0.8]\nframes = 40")
        .unwrap();
    m
}

#[test]
fn gpu_sub_steps_match_rayon_after_100_frames() {
    let Some(gpu) = test_gpu() else { return };
    let mut cpu = bar(None);
    let mut dev = bar(Some(gpu.clone()));
    dev.use_gpu().unwrap();
    let frame = FrameInfo {
        frame: 0,
        frames: 100,
        dt_s: 1.0 / 120.0,
    };
    for f in 0..100 {
        cpu.step(frame).unwrap();
        dev.step(frame).unwrap();
        assert_eq!(
            cpu.last_solve().substeps,
            dev.last_solve().substeps,
            "frame {f}"
        );
    }
    let (a, b) = (&cpu.state().unwrap().u, &dev.state().unwrap().u);
    let (largest, worst) = largest_and_difference(a, b);
    assert!(largest > 0.1, "the bar moves ({largest} mm)");
    assert!(
        worst <= 1e-4 * largest,
        "GPU differs by {worst:.3e} of {largest:.3e} mm"
    );
    assert!(
        cpu.last_solve().substeps > 1,
        "the test covers sub-stepping"
    );

    // The map into device buffers equals the CPU map.
    let points: Vec<[f32; 3]> = (0..50)
        .map(|i| {
            [
                10.0 + 0.08 * i as f32,
                -2.7 + 0.01 * i as f32,
                50.3 + 0.005 * i as f32,
            ]
        })
        .collect();
    let (ic, id) = (
        cpu.bind(RestPoints::Points(&points)).unwrap(),
        dev.bind(RestPoints::Points(&points)).unwrap(),
    );
    let n = points.len();
    let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
    cpu.map(
        ic,
        DisplacementTarget::Cpu {
            x: &mut x,
            y: &mut y,
            z: &mut z,
        },
    )
    .unwrap();
    let bufs = [0, 1, 2].map(|_| gpu.create_buffer(4 * n as u64, "test out").unwrap());
    dev.map(
        id,
        DisplacementTarget::Gpu {
            x: bufs[0],
            y: bufs[1],
            z: bufs[2],
        },
    )
    .unwrap();
    let worst = device_difference(&*gpu, bufs, [&x, &y, &z]).unwrap();
    assert!(worst <= 1e-4 * largest as f32, "map differs by {worst}");
    for buf in bufs {
        gpu.destroy_buffer(buf);
    }
}

#[test]
fn gpu_implicit_steps_and_octree_proxies_match_rayon() {
    let Some(gpu) = test_gpu() else { return };
    let implicit = |gpu: Option<Arc<dyn GpuService>>| {
        let grid = Grid::new([9, 3, 3], DVec3::splat(0.5), DVec3::ZERO);
        let mesh = uniform_proxy(&grid, 1, |v| Some(u16::from(v[0] >= 5))).unwrap();
        let materials = vec![
            ElasticMaterial::new(2000.0, 0.3, 1e-3),
            ElasticMaterial::new(8000.0, 0.3, 1e-3),
        ];
        let params = SpringParams {
            integrator: Integrator::Implicit,
            cg_tolerance: 1e-6,
            ..SpringParams::default()
        };
        let mut m = Springs::with_mesh(mesh, materials, DVec3::new(0.0, 0.0, -9810.0), params)
            .unwrap()
            .with_gpu(gpu);
        m.interact("kind = \"fix\"\nmin = [-0.1, -0.1, -0.1]\nmax = [0.1, 1.1, 1.1]")
            .unwrap();
        m.interact("kind = \"grab\"\npoint = [4, 0.5, 1]\nby = [0.3, 0.2, 0.5]\nframes = 40")
            .unwrap();
        m
    };
    let (mut cpu, mut dev) = (implicit(None), implicit(Some(gpu.clone())));
    dev.use_gpu().unwrap();
    let frame = FrameInfo {
        frame: 0,
        frames: 100,
        dt_s: 1.0 / 60.0,
    };
    for _ in 0..100 {
        cpu.step(frame).unwrap();
        dev.step(frame).unwrap();
    }
    let (a, b) = (&cpu.state().unwrap().u, &dev.state().unwrap().u);
    let (largest, worst) = largest_and_difference(a, b);
    assert!(largest > 0.1 && dev.last_solve().iterations > 0);
    assert!(
        worst <= 1e-4 * largest,
        "GPU differs by {worst:.3e} of {largest:.3e} mm"
    );

    // An octree proxy: the explicit sub-steps tie the hanging nodes on the
    // device as the CPU does.
    let volume = voxflex_phantom::phantom("rings", [33, 33, 33]).unwrap();
    let p = octree_parity::<MassSpring>(
        volume.view(),
        gpu,
        "proxy = { kind = \"octree\", max_cell = 8 }\n\
         materials = [{ name = \"soft\", range = [50, 150], youngs_modulus = 2000 }, \
                      { name = \"hard\", range = [150, 256], youngs_modulus = 20000 }]\n\
         gravity = [0, 0, -9810]\nintegrator = \"explicit\"",
        &["kind = \"fix\"\nmaterial = \"hard\""],
        frame,
        10,
    )
    .unwrap();
    assert!(p.hanging > 0, "the test needs hanging nodes");
    assert!(
        p.largest > 1e-3,
        "gravity moves the soft half ({} mm)",
        p.largest
    );
    assert!(
        p.worst <= 1e-4 * p.largest,
        "octree: GPU differs by {:.3e} of {:.3e} mm",
        p.worst,
        p.largest
    );
    assert!(
        p.worst_tie < 1e-6,
        "hanging nodes off by {:.3e} mm",
        p.worst_tie
    );
}

/// The volume springs' WGSL twin (`tet_forces`): a block squashed through
/// itself (every tetrahedron inverted; `tests::squashed_block`) recovers
/// on the device as on the CPU, within 1e-4 of the largest displacement
/// after the first frame and at the end, and both end with no tetrahedron
/// inverted.
#[test]
fn gpu_volume_springs_untangle_as_rayon_does() {
    let Some(gpu) = test_gpu() else { return };
    let params = SpringParams {
        integrator: Integrator::Explicit,
        volume_stiffness: 1.0,
        ..SpringParams::default()
    };
    let (mut cpu, mut dev) = (
        crate::tests::squashed_block(params.clone(), None),
        crate::tests::squashed_block(params, Some(gpu)),
    );
    dev.use_gpu().unwrap();
    assert!(!cpu.solver().unwrap().volume_springs().k.is_empty());
    let frame = FrameInfo {
        frame: 0,
        frames: 200,
        dt_s: 0.01,
    };
    for f in 0..200 {
        cpu.step(frame).unwrap();
        dev.step(frame).unwrap();
        if f == 0 {
            let (a, b) = (&cpu.state().unwrap().u, &dev.state().unwrap().u);
            let (largest, worst) = largest_and_difference(a, b);
            assert!(
                worst <= 1e-4 * largest,
                "first frame: GPU differs by {worst:.3e} of {largest:.3e} mm"
            );
        }
    }
    let inverted = |m: &mut Springs| m.notes().unwrap()["inverted_tetrahedra"];
    assert_eq!(inverted(&mut cpu), 0.0, "the CPU run untangles");
    assert_eq!(inverted(&mut dev), 0.0, "the GPU run untangles");
    let (a, b) = (&cpu.state().unwrap().u, &dev.state().unwrap().u);
    let (largest, worst) = largest_and_difference(a, b);
    assert!(
        worst <= 1e-4 * largest,
        "GPU differs by {worst:.3e} of {largest:.3e} mm"
    );
}
