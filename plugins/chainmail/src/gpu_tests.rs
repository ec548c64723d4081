//! CPU (rayon) vs GPU (WGSL, lavapipe in CI) on the same input: every
//! kernel of `shaders/chainmail/chainmail.wgsl` against its rayon twin.
//! Without an adapter these tests print SKIPPED, except under `CI=true`,
//! where a missing adapter fails them.

use crate::mapping;
use crate::model::ChainMail;
use crate::params::InteractionSpec;
use crate::tests::{grab, params, volume};
use std::sync::Arc;
use voxflex_core::gpu::{GpuService, GpuServiceExt};
use voxflex_core::volume::Volume;

fn test_gpu() -> Option<Arc<dyn GpuService>> {
    voxflex_runtime::gpu_context::testing::test_gpu().map(|g| g as Arc<dyn GpuService>)
}

/// Two materials with holes, odd `nx` (padding slots) and 1 mm voxels.
fn phantom() -> Volume {
    volume([37, 21, 17], |i, j, k| {
        let r2 = (i as i64 - 26).pow(2) + (j as i64 - 10).pow(2) + (k as i64 - 8).pow(2);
        if (i * 7 + j * 3 + k) % 89 == 0 {
            0
        } else if r2 < 30 {
            200
        } else {
            100
        }
    })
}

const MATERIALS: &str = "{ range = [50, 150], constraint = 0.2, elastic = 0.7 }, \
    { name = \"hard\", range = [150, 256], constraint = [0.05, 0.1, 0.02], elastic = 1.0 }";

/// A CPU and a GPU model of the phantom with the same interactions: a
/// fixed box, a cut, and a grab.
fn pair(gpu: Arc<dyn GpuService>, extra: &str) -> (ChainMail, ChainMail) {
    let v = phantom();
    let make = || {
        let mut m = ChainMail::new(v.view(), params(extra, MATERIALS)).unwrap();
        m.interact(
            &InteractionSpec::from_toml("kind = \"fix\"\nmin = [30, 0, 0]\nmax = [36, 4, 16]")
                .unwrap(),
        )
        .unwrap();
        m.interact(
            &InteractionSpec::from_toml(
                "kind = \"cut\"\npolygon = [[12.5, 8, -1], [12.5, 21, -1], [12.5, 21, 17], [12.5, 8, 17]]",
            )
            .unwrap(),
        )
        .unwrap();
        m
    };
    let (cpu, mut gpu_model) = (make(), make());
    gpu_model.use_gpu(gpu).unwrap();
    (cpu, gpu_model)
}

/// Largest displacement difference (mm; 1 mm voxels, so also in voxels)
/// and whether all keys are equal.
fn compare(cpu: &ChainMail, gpu: &mut ChainMail) -> (f32, bool) {
    gpu.pull().unwrap();
    let (a, b) = (cpu.state(), gpu.state());
    assert_eq!(a.cur, b.cur);
    let lat = cpu.lattice();
    let mut worst = 0f32;
    let mut keys = true;
    for n in (0..lat.len()).filter(|&n| lat.present(n)) {
        let (ua, ub) = (a.get(a.cur, n), b.get(b.cur, n));
        for k in 0..3 {
            worst = worst.max((ua[k] - ub[k]).abs());
        }
        keys &= a.key(a.cur, n) == b.key(b.cur, n);
    }
    (worst, keys)
}

#[test]
fn gpu_propagation_and_relaxation_match_rayon_iteration_by_iteration() {
    let Some(gpu) = test_gpu() else { return };
    let (mut cpu, mut gpu_model) = pair(gpu, "block = [8, 4, 4]");
    for m in [&mut cpu, &mut gpu_model] {
        grab(m, [3, 15, 9], [-6.0, 5.0, 4.0]);
        m.start_deformation();
    }
    let mut iterations = 0;
    while iterations < 200 && !(cpu.at_rest() && gpu_model.at_rest()) {
        let (a, b) = (cpu.propagate(1), gpu_model.propagate(1));
        assert_eq!(a, b, "iteration {iterations}: one model stopped first");
        iterations += 1;
        if iterations % 5 == 0 {
            let (worst, keys) = compare(&cpu, &mut gpu_model);
            assert!(keys, "iteration {iterations}: keys differ");
            assert!(
                worst <= 1e-5,
                "iteration {iterations}: displacements differ by {worst} mm"
            );
        }
        if a == 0 {
            break;
        }
    }
    assert!(iterations > 10, "the grab should take a while to propagate");
    let (worst, keys) = compare(&cpu, &mut gpu_model);
    assert!(
        keys && worst <= 1e-5,
        "after propagation: keys {keys}, {worst} mm"
    );
    assert!(cpu.counts().updates > 1000);
    assert_eq!(cpu.counts().updates, gpu_model.counts().updates);
    assert_eq!(cpu.counts().visits, gpu_model.counts().visits);
    for sweep in 0..30 {
        cpu.relax(1);
        gpu_model.relax(1);
        let (worst, _) = compare(&cpu, &mut gpu_model);
        assert!(
            worst <= 1e-5,
            "relaxation sweep {sweep}: displacements differ by {worst} mm"
        );
    }
    assert!(gpu_model.take_gpu_error().is_none());
}

#[test]
fn gpu_frames_and_identity_map_match_rayon() {
    let Some(gpu) = test_gpu() else { return };
    let (mut cpu, mut gpu_model) = pair(
        gpu.clone(),
        "propagation_iterations = 6\nrelaxation_iterations = 4",
    );
    for m in [&mut cpu, &mut gpu_model] {
        let p = m.lattice().world([20, 2, 3]).to_array();
        m.interact(&InteractionSpec::Grab {
            point: p,
            by: Some([3.0, -2.0, 2.0]),
            to: None,
            path: None,
            frames: 3,
        })
        .unwrap();
    }
    for frame in 0..8 {
        assert_eq!(cpu.step(), gpu_model.step(), "frame {frame}");
        let (worst, _) = compare(&cpu, &mut gpu_model);
        assert!(
            worst <= 1e-5,
            "frame {frame}: displacements differ by {worst} mm"
        );
    }
    // The identity map, in voxel order, from the GPU's buffer.
    let lat = cpu.lattice();
    let voxels: usize = lat.dims.iter().product();
    let out = [0, 1, 2].map(|_| gpu.create_buffer(4 * voxels as u64, "map test").unwrap());
    gpu_model.map_identity_gpu(out).unwrap();
    let mut want = [vec![0f32; voxels], vec![0f32; voxels], vec![0f32; voxels]];
    let [wx, wy, wz] = &mut want;
    mapping::copy_identity(lat, cpu.state(), [wx, wy, wz]);
    for (id, w) in out.iter().zip(&want) {
        let mut got = vec![0f32; voxels];
        gpu.download(*id, &mut got).unwrap();
        let worst = got
            .iter()
            .zip(w)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(worst <= 1e-5, "identity map differs by {worst} mm");
        gpu.destroy_buffer(*id);
    }
    assert!(
        want[0].iter().any(|&v| v != 0.0),
        "the grab moved something"
    );
}

#[test]
fn the_gpu_path_refuses_what_it_cannot_run() {
    let Some(gpu) = test_gpu() else { return };
    let v = phantom();
    for extra in ["algorithm = \"sequential\"", "schedule = \"frontier\""] {
        let mut m = ChainMail::new(v.view(), params(extra, MATERIALS)).unwrap();
        let e = m.use_gpu(gpu.clone()).unwrap_err().to_string();
        assert!(
            e.contains("CPU only") && e.contains("backend = \"cpu\""),
            "{e}"
        );
    }
}
