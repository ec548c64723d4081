//! A whole session on a device whose storage bindings are smaller than its
//! volume — issue 17's "a 512³ f32 volume must render and resample on a
//! device with 128 MiB bindings", scaled down: a 32 × 32 × 96 head (384
//! KiB of f32 per array) on a device that binds at most 128 KiB. The
//! `affine` model writes its displacement arrays in slabs of points, the
//! resampler reads its source in z-slabs, an ROI map grows with only its
//! working box's planes of the values bound (the box cut to the 14 planes
//! one binding holds, where it would have taken 17), and the ray caster renders
//! the deformed volume in z-slabs; every stage's result agrees with the
//! CPU session's within its CPU/GPU tolerance. Skips without an adapter
//! (fails under CI=true, as every GPU test).

use voxflex_integration_tests::session_on;
use voxflex_opacity::{GrowthParams, Seed};
use voxflex_phantom::phantom;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::gpu_context::testing::test_gpu_with_binding_limit;
use voxflex_runtime::session::{RenderParams, Session};

/// The head phantom's size: small planes, many of them, so that every
/// stage's slab (the ray caster's is 11 planes of the deformed volume)
/// fits the binding while the volume does not.
const DIMS: [usize; 3] = [32, 32, 96];
/// The device's pretended binding limit, bytes.
const BINDING: u64 = 128 << 10;
const TWIST: &str = "field = \"twist\"\naxis = \"z\"\nangle_deg = 35\n";

fn session(
    backend: BackendChoice,
    gpu: Option<std::sync::Arc<voxflex_runtime::gpu_context::WgpuService>>,
) -> Session {
    let volume = phantom("head", DIMS).unwrap();
    assert!(
        volume.grid.len() as u64 * 4 > 2 * BINDING,
        "the volume must exceed one binding"
    );
    session_on(volume, backend, gpu, &["affine", "raycast"])
}

#[test]
fn a_session_above_one_binding_runs_on_the_gpu_as_on_the_cpu() {
    let Some(gpu) = test_gpu_with_binding_limit(BINDING) else {
        return;
    };
    let mut cpu = session(BackendChoice::Cpu, None);
    let mut small = session(BackendChoice::Gpu, Some(gpu));
    assert_eq!(small.metrics().unwrap().backend, "gpu");
    for s in [&mut cpu, &mut small] {
        s.swap_model("affine", TWIST).unwrap();
        s.step().unwrap();
    }
    // The deformed volumes: the same sampling mesh, the fields equal to
    // rounding, so only voxel centres on a face may change owner.
    let (a, b) = (
        cpu.volume().unwrap().data.as_slice().to_f32_vec(),
        small.volume().unwrap().data.as_slice().to_f32_vec(),
    );
    assert_eq!(a.len(), b.len());
    let differ = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (*x - *y).abs() > 1e-2)
        .count();
    assert!(
        differ * 1000 < a.len(),
        "{differ} of {} voxels differ",
        a.len()
    );
    let moved = a
        .iter()
        .zip(phantom("head", DIMS).unwrap().data.as_slice().to_f32_vec());
    assert!(
        moved.filter(|(x, y)| (*x - y).abs() > 1.0).count() > 1000,
        "the twist moves the head"
    );

    // An ROI map seeded in the head's middle, bounded to an 8 mm ball so
    // its working box spans a few of the 96 planes.
    let params = GrowthParams::default();
    let seed = Seed::Voxel([24, 23, 48]);
    let limits = voxflex_opacity::GrowthLimits {
        max_distance_mm: Some(8.0),
        ..Default::default()
    };
    let mut ids = vec![];
    for s in [&mut cpu, &mut small] {
        let id = s.add_roi(seed, params).unwrap();
        s.set_roi_limits(id, limits).unwrap();
        let report = s.roi_run_to_end(id).unwrap();
        assert!(report.converged, "{report:?}");
        ids.push(id);
    }
    let map = cpu.roi_map(ids[0]).unwrap();
    assert!(
        map.values.iter().filter(|&&q| q >= 32768).count() > 20,
        "the ROI grows"
    );
    assert_eq!(cpu.roi_map(ids[0]), small.roi_map(ids[1]), "ROI maps");

    // The rendered image of the deformed head.
    let params = RenderParams {
        plugin: "raycast".into(),
        params_toml: "transfer_function = { preset = \"ct-bone\" }\n".into(),
    };
    let camera = cpu.default_camera(64, 64).unwrap();
    let on_cpu = cpu.render(&camera, &params).unwrap();
    let on_gpu = small.render(&camera, &params).unwrap();
    let lit = on_gpu.pixels.chunks(4).filter(|p| p[3] > 0).count();
    assert!(lit > 200, "the head shows: {lit} pixels");
    let d = on_cpu
        .pixels
        .iter()
        .zip(&on_gpu.pixels)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap();
    assert!(d <= 2, "GPU vs CPU render: largest difference {d}");
}
