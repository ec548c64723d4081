//! CPU (rayon) vs GPU (WGSL, lavapipe in CI) on the same input: every
//! kernel of `shaders/chainmail/chainmail.wgsl` against its rayon twin.
//! Without an adapter these tests print SKIPPED, except under `CI=true`,
//! where a missing adapter fails them.

use crate::mapping;
use crate::model::ChainMail;
use crate::params::InteractionSpec;
use crate::tests::{grab, params, volume};
use std::sync::Arc;
use voxflex_core::gpu::{GpuService, GpuServiceExt, LimitedDevice};
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
    // Each side's current copy: the CPU's block propagation works in one
    // copy, the GPU's swaps two.
    let (a, b) = (cpu.state(), gpu.state());
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

/// Whole runs on the device — many iterations queued between read-backs,
/// the device building every next list — end where rayon's one-by-one
/// iterations end: the same iteration and sweep counts, visits, updates,
/// changed region, state, and rest; in both directions of the grab.
#[test]
fn gpu_runs_to_rest_match_rayon_in_both_directions() {
    let Some(gpu) = test_gpu() else { return };
    for by in [[-6.0, 5.0, 4.0], [6.0, -5.0, -4.0]] {
        let (mut cpu, mut gpu_model) = pair(gpu.clone(), "block = [8, 4, 4]");
        for m in [&mut cpu, &mut gpu_model] {
            grab(m, [18, 10, 8], by);
            m.start_deformation();
        }
        let (a, b) = (cpu.propagate(u64::MAX), gpu_model.propagate(u64::MAX));
        assert_eq!(a, b, "{by:?}: propagation iterations");
        assert!(a > 10, "{by:?}: the grab should take a while to propagate");
        assert_eq!(cpu.counts(), gpu_model.counts(), "{by:?}: counts");
        assert_eq!(cpu.take_dirty(), gpu_model.take_dirty(), "{by:?}: dirty");
        let (worst, keys) = compare(&cpu, &mut gpu_model);
        assert!(keys && worst <= 1e-5, "{by:?}: keys {keys}, {worst} mm");
        // Capped, then the rest: a run that stops with work pending hands
        // the pending list back.
        let (a, b) = (cpu.relax(7), gpu_model.relax(7));
        assert_eq!((a, cpu.at_rest()), (b, gpu_model.at_rest()), "{by:?}");
        // To rest: which sweep's largest move falls under the tolerance
        // hangs on f32 rounding, which differs between the two (fused
        // multiply-adds), so the counts agree to 1 %, not exactly (the
        // device against itself: `device_runs_equal_one_iteration_at_a_time`).
        let (a, b) = (cpu.relax(5000), gpu_model.relax(5000));
        assert!(a.abs_diff(b) * 100 <= a, "{by:?}: {a} against {b} sweeps");
        assert!(
            cpu.at_rest() && gpu_model.at_rest(),
            "{by:?}: rest after {a} sweeps"
        );
        assert_eq!(cpu.take_dirty(), gpu_model.take_dirty(), "{by:?}: dirty");
        // Both stopped where a sweep moved nothing by `rest_tolerance`; a
        // slowly converging sweep stops up to ~tolerance / (1 − rate) from
        // its fixed point, so two roundings of it end that far apart.
        let (worst, _) = compare(&cpu, &mut gpu_model);
        assert!(worst <= 1e-2, "{by:?}: after relaxation, {worst} mm");
        assert!(gpu_model.take_gpu_error().is_none());
    }
}

/// A model that propagated on the CPU (in one copy) and then moves to the
/// device — as the viewer's backend switch does — carries on as the CPU
/// model does: the blocks the CPU changed are synced into the device's
/// second copy first.
#[test]
fn a_model_moved_to_the_gpu_after_cpu_propagation_carries_on_alike() {
    let Some(gpu) = test_gpu() else { return };
    let v = phantom();
    let make = || ChainMail::new(v.view(), params("block = [8, 4, 4]", MATERIALS)).unwrap();
    let (mut cpu, mut moved) = (make(), make());
    for m in [&mut cpu, &mut moved] {
        grab(m, [18, 10, 8], [-4.0, 3.0, 2.0]);
        m.start_deformation();
        // Propagation only: relaxed blocks would be synced anyway.
        assert!(m.propagate(u64::MAX) > 10);
    }
    moved.use_gpu(gpu).unwrap();
    for m in [&mut cpu, &mut moved] {
        grab(m, [6, 4, 12], [3.0, -2.0, 4.0]);
        m.start_deformation();
    }
    let (a, b) = (cpu.propagate(u64::MAX), moved.propagate(u64::MAX));
    assert_eq!(a, b, "propagation iterations after the move");
    let (worst, keys) = compare(&cpu, &mut moved);
    assert!(keys && worst <= 1e-5, "keys {keys}, {worst} mm");
    assert!(moved.take_gpu_error().is_none());
}

/// The device's lists come in another order than the host's ascending
/// ones; a launch's result must not depend on it. A run of many
/// iterations (lists built on the device) against the same model stepped
/// one iteration at a time (each list read back, sorted, written again):
/// bit-identical states and equal counts, through propagation and
/// relaxation to rest.
#[test]
fn device_runs_equal_one_iteration_at_a_time() {
    let Some(gpu) = test_gpu() else { return };
    let (_, mut batched) = pair(gpu.clone(), "block = [8, 4, 4]");
    let (_, mut stepped) = pair(gpu, "block = [8, 4, 4]");
    for m in [&mut batched, &mut stepped] {
        grab(m, [18, 10, 8], [-6.0, 5.0, 4.0]);
        m.start_deformation();
    }
    let runs = batched.propagate(u64::MAX);
    let mut steps = 0;
    while stepped.propagate(1) == 1 {
        steps += 1;
    }
    assert_eq!(runs, steps, "propagation iterations");
    let sweeps = batched.relax(5000);
    let mut steps = 0;
    while !stepped.at_rest() && steps < 5000 {
        steps += stepped.relax(1);
    }
    assert_eq!(sweeps, steps, "relaxation sweeps to rest");
    assert_eq!(batched.counts(), stepped.counts());
    assert_eq!(batched.take_dirty(), stepped.take_dirty());
    batched.pull().unwrap();
    stepped.pull().unwrap();
    let (a, b) = (batched.state(), stepped.state());
    assert_eq!(a.cur, b.cur);
    for n in 0..batched.lattice().len() {
        assert_eq!(a.get(a.cur, n), b.get(b.cur, n), "element {n}");
        assert_eq!(a.key(a.cur, n), b.key(b.cur, n), "element {n}");
    }
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
        let (a, b) = (cpu.step_stats(), gpu_model.step_stats());
        // The largest move is f32 arithmetic on both sides: equal to rounding.
        let same = |s: crate::model::FrameStats| crate::model::FrameStats {
            ms: 0.0,
            max_move: (s.max_move * 1e5).round(),
            ..s
        };
        assert_eq!(same(a), same(b), "frame {frame}");
        assert_eq!(cpu.take_dirty(), gpu_model.take_dirty(), "frame {frame}");
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

/// Lists longer than the device's workgroup limit fold into rows of that
/// limit (the kernels find their slot without `num_workgroups`): the same
/// frames as rayon with a limit of 7 workgroups per dimension.
#[test]
fn launches_fold_past_the_workgroup_limit() {
    let Some(gpu) = test_gpu() else { return };
    let few: Arc<dyn GpuService> = Arc::new(LimitedDevice::workgroups(gpu, 7));
    let (mut cpu, mut gpu_model) = pair(
        few,
        "block = [4, 4, 4]\npropagation_iterations = 6\nrelaxation_iterations = 4",
    );
    for m in [&mut cpu, &mut gpu_model] {
        grab(m, [18, 10, 8], [-6.0, 5.0, 4.0]);
    }
    for frame in 0..4 {
        let (a, b) = (cpu.step_stats(), gpu_model.step_stats());
        assert_eq!(
            (a.propagation_blocks, a.relaxation_blocks, a.sweeps),
            (b.propagation_blocks, b.relaxation_blocks, b.sweeps),
            "frame {frame}"
        );
        assert!(
            a.propagation_blocks > 7 * 3,
            "frame {frame}: lists must fold"
        );
        let (worst, _) = compare(&cpu, &mut gpu_model);
        assert!(worst <= 1e-5, "frame {frame}: {worst} mm");
    }
    assert!(gpu_model.take_gpu_error().is_none());
}
