//! A session's ROI maps follow its backend: on the GPU they grow through
//! voxflex_opacity's GPU kernels, bit for bit the CPU's maps, stepwise and
//! to the end; `set_backend` re-grows them as far as before; a new volume
//! (the model moved) re-grows them on the GPU. Without an adapter these
//! skip, and fail under CI=true, as every GPU test.

use voxflex_core::glam::DVec3;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_integration_tests::plugin_dir;
use voxflex_opacity::{GrowthParams, Seed};
use voxflex_phantom::phantom;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::session::{Interaction, RoiId, Session, SessionDefaults};

const CHAINMAIL: &str = "materials = [{ range = [50, 200], constraint = 0.01 }]\n\
                         propagation_iterations = 40\n";

/// The 20³ cube phantom (5 mm voxels, −25 to 25 mm) with its x ≥ 0 half
/// at 150 and a deterministic ±6 texture on the cube, so the growth takes
/// many uneven steps.
fn textured_cube() -> Volume {
    let mut v = phantom("cube", [20, 20, 20]).unwrap();
    let grid = v.grid;
    let VoxelData::U8(d) = &mut v.data else {
        panic!("the cube phantom is u8")
    };
    for (l, x) in d.iter_mut().enumerate() {
        if *x == 0 {
            continue;
        }
        let [i, j, k] = grid.unlinear(l);
        let p = grid.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
        let base: i32 = if p.x >= 0.0 { 150 } else { 100 };
        *x = (base + (l * 7919 % 13) as i32 - 6) as u8;
    }
    v
}

fn session(backend: BackendChoice) -> Session {
    let defaults = SessionDefaults {
        backend,
        plugin_dirs: vec![plugin_dir(&["chainmail"])],
        ..SessionDefaults::default()
    };
    Session::from_volume(textured_cube(), defaults).unwrap()
}

/// A seed inside the 100 half of the cube, mm.
fn seed() -> Seed {
    Seed::World(DVec3::new(-12.5, 2.5, 2.5))
}

/// Asserts both sessions hold the same maps (values, boxes, steps,
/// convergence) for `ids`.
fn assert_same_maps(a: &Session, b: &Session, ids: &[RoiId], what: &str) {
    assert_eq!(a.rois(), b.rois(), "{what}: ROI infos");
    for &id in ids {
        assert_eq!(a.roi_map(id), b.roi_map(id), "{what}: map {}", id.0);
    }
}

/// One step at a time three times, then to the end on both backends: identical
/// maps at every stop, and the GPU map really changes between stops.
#[test]
fn gpu_roi_maps_equal_cpu_maps_stepwise_and_to_the_end() {
    if voxflex_runtime::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    let mut cpu = session(BackendChoice::Cpu);
    let mut gpu = session(BackendChoice::Gpu);
    assert_eq!(gpu.metrics().unwrap().backend, "gpu");
    let params = GrowthParams::default();
    let a = cpu.add_roi(seed(), params).unwrap();
    let b = gpu.add_roi(seed(), params).unwrap();
    assert_eq!(a, b);
    assert_same_maps(&cpu, &gpu, &[a], "seeded");
    let mut stops = vec![];
    for n in [1, 1, 1] {
        let rc = cpu.roi_step(a, n).unwrap();
        let rg = gpu.roi_step(a, n).unwrap();
        assert_eq!(rc, rg, "report of {n} steps");
        assert_same_maps(&cpu, &gpu, &[a], &format!("after {n} more steps"));
        stops.push(gpu.roi_map(a).unwrap().clone());
    }
    assert_eq!(gpu.rois()[0].steps, 3);
    let rc = cpu.roi_run_to_end(a).unwrap();
    let rg = gpu.roi_run_to_end(a).unwrap();
    assert_eq!(rc, rg, "report to the end");
    assert!(rg.converged && rg.steps > 0, "{rg:?}");
    assert_same_maps(&cpu, &gpu, &[a], "at the end");
    let end = &gpu.rois()[0];
    assert!(end.converged);
    stops.push(gpu.roi_map(a).unwrap().clone());
    for (k, w) in stops.windows(2).enumerate() {
        assert_ne!(w[0], w[1], "the map changes between stop {k} and the next");
    }
    // The 100 half of the cube (5 × 10 × 10 voxels), at most one layer
    // of the 150 half beyond it (the ±6 texture widens the seed's range).
    assert!(
        (5 * 10 * 10..=6 * 10 * 10).contains(&end.voxels_above_half),
        "{end:?}"
    );
    // Splitting the steps differently lands on the same map.
    let c = gpu.add_roi(seed(), params).unwrap();
    gpu.roi_step(c, 2).unwrap();
    gpu.roi_run_to_end(c).unwrap();
    assert_eq!(gpu.roi_map(c), gpu.roi_map(a));
    assert!(gpu.remove_roi(c) && gpu.remove_roi(a));
    assert!(gpu.rois().is_empty());
    assert!(gpu.roi_step(a, 1).is_err(), "a removed map is refused");
}

/// cpu → gpu → cpu keeps every map as far as it had grown, and stepping on
/// after each move equals stepping on a session that never moved.
#[test]
fn set_backend_cpu_gpu_cpu_keeps_the_roi_maps() {
    if voxflex_runtime::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    let params = GrowthParams::default();
    let mut moved = session(BackendChoice::Cpu);
    let mut stayed = session(BackendChoice::Cpu);
    let mut ids = vec![];
    for s in [&mut moved, &mut stayed] {
        let stepped = s.add_roi(seed(), params).unwrap();
        let ended = s
            .add_roi(Seed::World(DVec3::new(12.5, -2.5, 2.5)), params)
            .unwrap();
        s.roi_step(stepped, 4).unwrap();
        s.roi_run_to_end(ended).unwrap();
        ids = vec![stepped, ended];
    }
    assert_same_maps(&moved, &stayed, &ids, "before moving");
    assert_ne!(moved.set_backend(BackendChoice::Gpu).unwrap(), "cpu");
    assert_eq!(moved.metrics().unwrap().backend, "gpu");
    assert_same_maps(&moved, &stayed, &ids, "moved to the GPU");
    for s in [&mut moved, &mut stayed] {
        s.roi_step(ids[0], 3).unwrap();
    }
    assert_same_maps(&moved, &stayed, &ids, "3 more steps on the GPU");
    assert_eq!(moved.set_backend(BackendChoice::Cpu).unwrap(), "cpu");
    assert_same_maps(&moved, &stayed, &ids, "moved back to the CPU");
    for s in [&mut moved, &mut stayed] {
        s.roi_run_to_end(ids[0]).unwrap();
    }
    assert_same_maps(&moved, &stayed, &ids, "to the end on the CPU");
    assert!(moved.rois().iter().all(|r| r.converged));
}

/// The model moves the volume: the GPU session re-grows its maps on the
/// new volume (to the end, as they were run), equal to maps grown on the
/// CPU over that same volume.
#[test]
fn a_new_volume_regrows_the_gpu_maps_as_the_cpu_would() {
    if voxflex_runtime::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    let mut gpu = session(BackendChoice::Gpu);
    gpu.swap_model("chainmail", CHAINMAIL).unwrap();
    let params = GrowthParams::default();
    let stepped = gpu.add_roi(seed(), params).unwrap();
    let ended = gpu
        .add_roi(Seed::World(DVec3::new(12.5, -2.5, 2.5)), params)
        .unwrap();
    gpu.roi_step(stepped, 5).unwrap();
    gpu.roi_run_to_end(ended).unwrap();
    let before = gpu.roi_map(ended).unwrap().clone();
    for k in 1..=3 {
        gpu.interact(&Interaction::Grab {
            point: [22.5, 2.5, 2.5],
            to: [22.5 + 3.0 * k as f64, 2.5, 2.5],
            frames: 1,
        })
        .unwrap();
        let r = gpu.step().unwrap();
        assert!(r.ran("roi"), "the volume moved, so the maps re-grow: {r}");
    }
    assert_ne!(
        gpu.roi_map(ended).unwrap(),
        &before,
        "the dragged face moves the map"
    );
    let volume = gpu.volume().unwrap().clone();
    let mut cpu = Session::from_volume(
        volume,
        SessionDefaults {
            backend: BackendChoice::Cpu,
            ..SessionDefaults::default()
        },
    )
    .unwrap();
    let s = cpu.add_roi(seed(), params).unwrap();
    let e = cpu
        .add_roi(Seed::World(DVec3::new(12.5, -2.5, 2.5)), params)
        .unwrap();
    cpu.roi_step(s, 5).unwrap();
    cpu.roi_run_to_end(e).unwrap();
    assert_eq!((s, e), (stepped, ended));
    assert_same_maps(&cpu, &gpu, &[stepped, ended], "re-grown on the new volume");
}

/// A session offered a device (as the viewer offers eframe's) computes on
/// it — its kernels run there, not on a device of its own — on `gpu` and
/// after `set_backend`; `auto` refuses a software adapter and stays on the
/// CPU.
#[test]
fn an_offered_device_is_the_one_the_session_computes_on() {
    let Some(offered) = voxflex_runtime::gpu_context::testing::test_gpu() else {
        return;
    };
    let defaults = |backend| SessionDefaults {
        backend,
        plugin_dirs: vec![plugin_dir(&["chainmail"])],
        gpu: Some(offered.clone()),
        ..SessionDefaults::default()
    };
    let mut s = Session::from_volume(textured_cube(), defaults(BackendChoice::Gpu)).unwrap();
    assert_eq!(s.adapter_name(), offered.info().name);
    let before = offered.stats().dispatches;
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    s.interact(&Interaction::Grab {
        point: [22.5, 2.5, 2.5],
        to: [27.5, 2.5, 2.5],
        frames: 1,
    })
    .unwrap();
    s.step().unwrap();
    assert!(
        offered.stats().dispatches > before,
        "the session's kernels ran on the offered device"
    );
    s.set_backend(BackendChoice::Cpu).unwrap();
    s.set_backend(BackendChoice::Gpu).unwrap();
    let before = offered.stats().dispatches;
    s.step().unwrap();
    s.add_roi(seed(), GrowthParams::default()).unwrap();
    assert!(
        offered.stats().dispatches > before,
        "and again after set_backend"
    );
    let auto = Session::from_volume(textured_cube(), defaults(BackendChoice::Auto)).unwrap();
    if offered.info().software {
        assert_eq!(
            auto.adapter_name(),
            "cpu",
            "auto refuses a software adapter"
        );
    } else {
        assert_eq!(auto.adapter_name(), offered.info().name);
    }
}

/// A bounded map (intensity window and distance) on the GPU, over its own
/// upload of the bounded values, and its automatic λ (written from the
/// scan on the CPU on either backend): the CPU's maps and λ, bit for bit.
#[test]
fn bounded_and_auto_lambda_maps_on_the_gpu_equal_the_cpus() {
    if voxflex_runtime::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    let mut cpu = session(BackendChoice::Cpu);
    let mut gpu = session(BackendChoice::Gpu);
    let limits = voxflex_opacity::GrowthLimits {
        intensity: Some([80.0, 120.0]),
        max_distance_mm: Some(30.0),
    };
    let mut unbounded = 0;
    for s in [&mut cpu, &mut gpu] {
        let id = s.add_roi(seed(), GrowthParams::default()).unwrap();
        s.roi_run_to_end(id).unwrap();
        unbounded = s.rois()[0].voxels_above_half;
        s.set_roi_limits(id, limits).unwrap();
    }
    assert!(
        cpu.rois()[0].voxels_above_half < unbounded,
        "the bounds hold the map in"
    );
    assert_same_maps(&cpu, &gpu, &[RoiId(0)], "bounded");
    let (a, b) = (
        cpu.roi_auto_lambda(RoiId(0)).unwrap(),
        gpu.roi_auto_lambda(RoiId(0)).unwrap(),
    );
    assert_eq!(a, b);
    assert_same_maps(&cpu, &gpu, &[RoiId(0)], "auto λ, bounded");
}

/// A switch the model cannot make (ChainMail's sequential algorithm runs
/// on the CPU only) fails naming the backend the session stays on, and
/// leaves it there whole: its model steps, and its ROI maps hold what they
/// had grown and grow on as on a session that never tried.
#[test]
fn a_failed_set_backend_leaves_the_session_whole_on_its_backend() {
    if voxflex_runtime::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    let params = GrowthParams::default();
    let sequential = format!("{CHAINMAIL}algorithm = \"sequential\"\n");
    let mut tried = session(BackendChoice::Cpu);
    let mut stayed = session(BackendChoice::Cpu);
    let mut ids = vec![];
    for s in [&mut tried, &mut stayed] {
        s.swap_model("chainmail", &sequential).unwrap();
        let id = s.add_roi(seed(), params).unwrap();
        s.roi_step(id, 3).unwrap();
        ids = vec![id];
    }
    let e = tried
        .set_backend(BackendChoice::Gpu)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("CPU only") && e.contains("stays on `cpu`"),
        "{e}"
    );
    assert_eq!(tried.adapter_name(), "cpu");
    assert_eq!(tried.metrics().unwrap().backend, "cpu");
    assert_same_maps(&tried, &stayed, &ids, "after the failed switch");
    for s in [&mut tried, &mut stayed] {
        s.step().unwrap();
        s.roi_step(ids[0], 2).unwrap();
    }
    assert_same_maps(&tried, &stayed, &ids, "stepped on");
    assert!(
        tried.metrics().unwrap().plugin.is_some(),
        "the model is kept"
    );
}
