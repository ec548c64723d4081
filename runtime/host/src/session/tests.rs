//! Unit tests of the session without plugins (the model, renderer and
//! GPU paths are driven through the real `.so` plugins in
//! `tests/tests/session.rs`).

use super::*;
use voxflex_core::glam::DVec3;

fn cpu() -> SessionDefaults {
    SessionDefaults {
        backend: BackendChoice::Cpu,
        ..SessionDefaults::default()
    }
}

/// The head phantom at 4 mm on the CPU with one default map seeded in the
/// brain, away from the ventricles (not grown): the ROI-editing tests'
/// common start.
pub(super) fn head_session_with_brain_roi() -> (Session, RoiId) {
    let mut s = Session::from_volume(
        SessionSource::Phantom {
            name: "head".into(),
            dims: [50, 60, 55],
        },
        cpu(),
    )
    .unwrap();
    let seed = Seed::World(DVec3::new(40.0, 0.0, 15.0));
    let id = s.add_roi(seed, GrowthParams::default()).unwrap();
    (s, id)
}

fn cube_session(n: usize) -> Session {
    Session::from_volume(
        SessionSource::Phantom {
            name: "cube".into(),
            dims: [n, n, n],
        },
        cpu(),
    )
    .unwrap()
}

#[test]
fn a_session_without_a_model_steps_nothing_and_shows_its_source() {
    let mut s = cube_session(12);
    let r = s.step().unwrap();
    assert_eq!(r.frame, 0);
    for stage in ["model", "map", "resample"] {
        let o = r.stage(stage).unwrap();
        assert!(!o.ran && o.why.contains("no model"), "{o:?}");
    }
    assert_eq!(s.frame(), 1);
    assert_eq!(s.versions(), Versions::default());
    let source = s.source().clone();
    assert_eq!(s.volume().unwrap(), &source);
    let m = s.metrics().unwrap();
    assert_eq!(m.frames, 1);
    assert_eq!(m.backend, "cpu");
    assert_eq!(m.stages["source"].runs, 1);
    assert_eq!(m.source_dims, [12, 12, 12]);
    for stage in ["model", "map", "resample", "render", "roi"] {
        assert!(m.stages_not_built.iter().any(|s| s == stage), "{stage}");
    }
}

#[test]
fn interacting_without_a_model_says_what_to_do() {
    let mut s = cube_session(8);
    let e = s.interact(&Interaction::Release).unwrap_err().to_string();
    assert!(e.contains("swap_model"), "{e}");
}

#[test]
fn an_unknown_phantom_or_plugin_is_one_clear_error() {
    let e = Session::from_volume(
        SessionSource::Phantom {
            name: "nope".into(),
            dims: [4, 4, 4],
        },
        cpu(),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("nope"), "{e}");
    let mut s = cube_session(8);
    let e = s.swap_model("no-such-plugin", "").unwrap_err().to_string();
    assert!(
        e.contains("no-such-plugin") && e.contains("not found"),
        "{e}"
    );
    assert!(
        s.metrics().unwrap().plugin.is_none(),
        "the failed swap left no model"
    );
}

/// A click on a slice lands on the world point of the voxel shown there,
/// and that point maps back to the same pixel, on every axis.
#[test]
fn slice_pixels_map_to_world_points_and_back() {
    let volume = voxflex_phantom::phantom("ramp", [6, 5, 4]).unwrap();
    let mut s = Session::from_volume(volume.clone(), cpu()).unwrap();
    for (axis, index) in [
        (SliceAxis::Axial, 2),
        (SliceAxis::Coronal, 3),
        (SliceAxis::Sagittal, 1),
    ] {
        let img = s.slice(axis, index, None).unwrap();
        let (w, h) = axis.image_size(&volume.grid);
        assert_eq!((img.image.width, img.image.height), (w, h));
        for row in 0..h {
            for col in 0..w {
                let p = img.pixel_to_world(col, row).unwrap();
                assert_eq!(img.world_to_pixel(p), Some([col, row]), "{axis:?}");
                let v = volume.grid.world_to_index(p).round();
                let voxel = [v.x as usize, v.y as usize, v.z as usize];
                assert_eq!(img.pixel_to_voxel(col, row), Some(voxel));
                // The continuous mapping agrees at pixel centres and inverts.
                let q = img.point_to_world(col as f64, row as f64);
                assert!((q - p).length() < 1e-9, "{axis:?}");
                let [c, r] = img.world_to_point(q + DVec3::splat(0.0));
                assert!((c - col as f64).abs() < 1e-9 && (r - row as f64).abs() < 1e-9);
                // The same table as a seed click on that slice.
                let seed = Seed::Slice {
                    axis,
                    index,
                    pixel: [col, row],
                };
                assert_eq!(seed.resolve(&volume.grid).unwrap(), voxel);
                // The pixel shows that voxel's value through the window.
                let window = {
                    let (lo, hi) = volume.value_range();
                    Window {
                        level: 0.5 * (lo + hi),
                        width: (hi - lo).max(f32::MIN_POSITIVE),
                    }
                };
                let value = volume.get_f32(voxel[0], voxel[1], voxel[2]);
                assert_eq!(img.image.pixels[row * w + col], window.map(value));
            }
        }
        assert_eq!(img.pixel_to_world(w, 0), None);
        // A point on another slice has no pixel on this one.
        let elsewhere = img.pixel_to_voxel(0, 0).unwrap();
        let mut other = elsewhere;
        let a = axis.fixed_axis();
        other[a] = if other[a] == 0 { 1 } else { 0 };
        let p = volume.grid.index_to_world(DVec3::new(
            other[0] as f64,
            other[1] as f64,
            other[2] as f64,
        ));
        assert_eq!(img.world_to_pixel(p), None);
    }
    assert!(s.slice(SliceAxis::Axial, 4, None).is_err(), "index 4 of 4");
}

/// ROI maps step by step: `roi_step(a)` then `roi_step(b)` is the map of
/// a + b steps; running to the end converges; remove and list.
#[test]
fn roi_maps_grow_stepwise_to_the_end_and_are_removed() {
    let mut s = cube_session(16);
    let centre = s.source().grid.centre();
    let params = GrowthParams::default();
    let a = s.add_roi(Seed::World(centre), params).unwrap();
    let b = s.add_roi(Seed::World(centre), params).unwrap();
    assert_ne!(a, b);
    assert_eq!(s.rois().len(), 2);
    assert_eq!(s.rois()[0].steps, 0);
    s.roi_step(a, 2).unwrap();
    s.roi_step(a, 3).unwrap();
    s.roi_step(b, 5).unwrap();
    assert_eq!(s.roi_map(a), s.roi_map(b), "2 + 3 steps = 5 steps");
    assert_eq!(s.rois()[0].steps, 5);
    let before = s.rois()[0].voxels_above_half;
    let r = s.roi_run_to_end(a).unwrap();
    assert!(r.converged);
    let info = &s.rois()[0];
    assert!(info.converged && info.voxels_above_half >= before);
    // The cube's interior (value 100) is the region: n/2 voxels a side.
    assert_eq!(info.voxels_above_half, 8 * 8 * 8);
    assert!(s.remove_roi(b));
    assert!(!s.remove_roi(b));
    assert_eq!(s.rois().len(), 1);
    assert!(s.roi_step(b, 1).is_err());
    let m = s.metrics().unwrap();
    assert_eq!(m.stages["roi"].runs, 4);
    assert!(!m.stages_not_built.iter().any(|s| s == "roi"));
}

#[test]
fn a_session_moves_to_another_thread() {
    let s = cube_session(8);
    let frame = std::thread::spawn(move || {
        let mut s = s;
        s.step().unwrap();
        s.frame()
    })
    .join()
    .unwrap();
    assert_eq!(frame, 1);
}

/// On the GPU the ROI maps hold GPU buffers (their growths and one upload
/// of the volume): removing the maps frees every one, and moving to the
/// CPU keeps the maps. Skips without an adapter (fails under CI=true).
#[test]
fn gpu_roi_maps_free_their_buffers() {
    if crate::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    let mut s = cube_session(16);
    s.set_backend(BackendChoice::Gpu).unwrap();
    let live = |s: &Session| s.resolved.gpu.as_ref().unwrap().stats().live_buffers;
    let base = live(&s);
    let centre = s.source().grid.centre();
    let params = GrowthParams::default();
    let a = s.add_roi(Seed::World(centre), params).unwrap();
    let one = live(&s);
    assert!(one > base, "a GPU map holds buffers ({base} → {one})");
    let b = s.add_roi(Seed::World(centre), params).unwrap();
    let two = live(&s);
    assert!(two > one, "a second map holds its own ({one} → {two})");
    s.roi_step(a, 3).unwrap();
    s.roi_run_to_end(b).unwrap();
    assert_eq!(live(&s), two, "stepping allocates nothing that stays");
    assert!(s.remove_roi(b));
    assert_eq!(live(&s), one, "removing a map frees its buffers");
    assert!(s.remove_roi(a));
    assert_eq!(live(&s), base, "the last map frees the volume's upload too");
    assert!(s.roi_values.is_none());
    let a = s.add_roi(Seed::World(centre), params).unwrap();
    s.roi_step(a, 3).unwrap();
    let map = s.roi_map(a).unwrap().clone();
    s.set_backend(BackendChoice::Cpu).unwrap();
    assert!(s.roi_values.is_none() && s.gpu.is_none());
    assert_eq!(s.roi_map(a), Some(&map));
    assert_eq!(s.rois()[0].steps, 3);
}

#[test]
fn tracked_points_and_the_displacement_field_need_a_model() {
    let mut s = cube_session(8);
    let e = s.track_points(&[[0.0, 0.0, 0.0]]).unwrap_err().to_string();
    assert!(
        e.contains("need a model") && e.contains("swap_model"),
        "{e}"
    );
    assert!(s.tracked().is_empty());
    let e = s.tracked_displacements(TrackId(0)).unwrap_err().to_string();
    assert!(e.contains("no tracked points 0"), "{e}");
    assert!(!s.untrack(TrackId(0)));
    let e = s.displacement_field().unwrap_err().to_string();
    assert!(e.contains("swap_model"), "{e}");
    let e = s.track_points(&[]).unwrap_err().to_string();
    assert!(e.contains("no points"), "{e}");
}

#[test]
fn step_model_without_a_model_steps_nothing() {
    let mut s = cube_session(8);
    let r = s.step_model().unwrap();
    assert_eq!(r.frame, 0);
    assert_eq!(r.stages.len(), 1, "{r}");
    let o = r.stage("model").unwrap();
    assert!(!o.ran && o.why.contains("no model"), "{o:?}");
    assert_eq!(s.frame(), 1);
    assert_eq!(s.versions(), Versions::default());
}

#[test]
fn new_roi_params_regrow_the_map_as_far_and_bad_ones_change_nothing() {
    let mut s = cube_session(16);
    let centre = s.source().grid.centre();
    let id = s
        .add_roi(Seed::World(centre), GrowthParams::default())
        .unwrap();
    s.roi_step(id, 3).unwrap();
    let before = s.roi_map(id).unwrap().clone();
    let bad = GrowthParams {
        lambda: -1.0,
        ..GrowthParams::default()
    };
    let e = s.set_roi_params(id, bad).unwrap_err().to_string();
    assert!(e.contains("-1"), "{e}");
    assert_eq!(s.roi_map(id), Some(&before));
    let raised = GrowthParams {
        o_min: 0.2,
        ..GrowthParams::default()
    };
    let r = s.set_roi_params(id, raised).unwrap();
    assert_eq!(r.steps, 3, "grown as far as before");
    let info = &s.rois()[0];
    assert_eq!((info.params, info.steps), (raised, 3));
    let map = s.roi_map(id).unwrap();
    assert_eq!(map.outside, voxflex_core::opacity_map::to_fixed(0.2));
    assert_ne!(map, &before);
    assert!(s.set_roi_params(RoiId(99), raised).is_err());
}

/// A map grown again (here: the same parameters set again) starts in the
/// box of the region it had, so it never moves its field, and grows the
/// same map.
#[test]
fn a_regrowth_starts_in_the_last_region_and_grows_the_same_map() {
    let (mut s, id) = head_session_with_brain_roi();
    let first = s.roi_run_to_end(id).unwrap();
    assert!(first.regrows > 0, "from the seed, the box moves: {first:?}");
    let map = s.roi_map(id).unwrap().clone();
    let params = s.rois()[0].params;
    let again = s.set_roi_params(id, params).unwrap();
    assert!(again.converged, "{again:?}");
    assert_eq!(
        again.regrows, 0,
        "the last region's box holds it: {again:?}"
    );
    assert_eq!(s.roi_map(id).unwrap(), &map);
}

#[test]
fn a_roi_map_is_written_as_a_volume_and_drawn_over_slices() {
    let mut s = cube_session(16);
    let grid = s.source().grid;
    let id = s
        .add_roi(Seed::World(grid.centre()), GrowthParams::default())
        .unwrap();
    s.roi_run_to_end(id).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("roi.nii");
    s.write_roi_map(id, &path).unwrap();
    let back = voxflex_io::read_volume(&path, &Default::default()).unwrap();
    assert_eq!(back.grid.dims, grid.dims);
    let at = |i, j, k| back.get_f32(i, j, k);
    assert!(at(8, 8, 8) >= 0.5, "the seed's cube is in the map");
    assert!(at(0, 0, 0) < 0.5, "the background is not");
    assert!(s.write_roi_map(RoiId(7), &path).is_err());

    let slice = s.slice(SliceAxis::Axial, 8, None).unwrap();
    let overlay = slice.overlay(s.roi_map(id).unwrap());
    assert_eq!(overlay.len(), 16 * 16);
    assert!(overlay[8 * 16 + 8] >= 0.5 && overlay[0] < 0.5);
    let coronal = s.slice(SliceAxis::Coronal, 8, None).unwrap();
    let o = coronal.overlay(s.roi_map(id).unwrap());
    // Row 0 is the top (k = 15): background.
    assert!(o[8] < 0.5 && o[8 * 16 + 8] >= 0.5);
}

#[test]
fn a_session_opens_a_volume_file_or_names_it_in_its_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cube.nii");
    let cube = voxflex_phantom::phantom("cube", [6, 5, 4]).unwrap();
    voxflex_io::write_volume(&path, cube.view()).unwrap();
    let s = Session::from_volume(SessionSource::File(path.clone()), cpu()).unwrap();
    assert_eq!(s.source().grid.dims, [6, 5, 4]);
    let missing = dir.path().join("missing.nii");
    let e = Session::from_volume(SessionSource::File(missing), cpu())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("missing.nii"), "{e}");
}

/// The source histogram counts every finite voxel once, agrees with
/// `voxflex info`'s 64-bin histogram, and refuses 0 bins.
#[test]
fn the_histogram_counts_the_source_values_like_volume_stats() {
    let s = cube_session(16);
    let stats = voxflex_core::stats::VolumeStats::compute(s.source().view());
    let h = s.histogram(stats.histogram.counts.len()).unwrap();
    assert_eq!(h, stats.histogram);
    let h = s.histogram(4).unwrap();
    assert_eq!((h.min, h.max), (stats.min, stats.max));
    assert_eq!(h.counts.iter().sum::<u64>(), 16 * 16 * 16);
    // The cube (8³ voxels at the top value) fills the last bin.
    assert_eq!(h.counts[3], 8 * 8 * 8);
    let e = s.histogram(0).unwrap_err().to_string();
    assert!(e.contains("0 bins"), "{e}");
    assert!(s.histogram(MAX_HISTOGRAM_BINS + 1).is_err());
}

/// A hidden map stays in the session but is not handed to the renderer;
/// an unknown map is an error.
#[test]
fn a_hidden_roi_map_is_kept_but_not_shown() {
    let mut s = cube_session(12);
    let centre = s.source().grid.centre();
    let a = s
        .add_roi(Seed::World(centre), GrowthParams::default())
        .unwrap();
    assert!(s.roi_shown(a));
    s.set_roi_shown(a, false).unwrap();
    assert!(!s.roi_shown(a));
    assert_eq!(s.rois().len(), 1);
    s.set_roi_shown(a, true).unwrap();
    assert!(s.roi_shown(a));
    s.remove_roi(a);
    assert!(s.set_roi_shown(a, false).is_err());
    assert!(!s.roi_shown(a));
}
