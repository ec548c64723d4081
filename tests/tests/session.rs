//! The interactive `Session` through the real `.so` plugins: a worker
//! thread drives one session through open → ROI → a 10-call grab-drag →
//! cut → model swap → render, asserting on voxels and pixels; skips stay
//! skips; the CPU and GPU backends agree where an adapter exists.

use voxflex_core::glam::DVec3;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_integration_tests::plugin_dir;
use voxflex_opacity::{GrowthParams, Seed};
use voxflex_phantom::phantom;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::session::{Interaction, RenderParams, Session, SessionDefaults, StepReport};
use voxflex_runtime::visualise::RgbaImage;

const CHAINMAIL: &str = "materials = [{ range = [50, 200], constraint = 0.01 }]\n\
                         propagation_iterations = 40\n";
const FEM: &str = "proxy = { kind = \"uniform\", step = 2 }\n\
                   materials = [{ range = [50, 200], youngs_modulus = 3000 }]\n";
const RENDER: &str =
    "transfer_function = { points = [[0, 0, 0, 0, 0], [100, 1, 1, 1, 1], [150, 1, 1, 1, 1]] }\n";

/// The grabbed voxel centre on the cube's +x face, mm.
const GRAB: [f64; 3] = [22.5, 2.5, 2.5];

/// The 20³ cube phantom (5 mm voxels, the cube from −25 to 25 mm) with its
/// x ≥ 0 half at 150 instead of 100: two tissues an ROI can tell apart.
fn two_tone_cube() -> Volume {
    let mut v = phantom("cube", [20, 20, 20]).unwrap();
    let grid = v.grid;
    let VoxelData::U8(d) = &mut v.data else {
        panic!("the cube phantom is u8")
    };
    for (l, x) in d.iter_mut().enumerate() {
        let [i, j, k] = grid.unlinear(l);
        let p = grid.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
        if *x == 100 && p.x >= 0.0 {
            *x = 150;
        }
    }
    v
}

fn defaults(backend: BackendChoice) -> SessionDefaults {
    SessionDefaults {
        backend,
        plugin_dirs: vec![plugin_dir(&["chainmail", "corotational-fem", "raycast"])],
        ..SessionDefaults::default()
    }
}

/// The value of `v` at the voxel nearest world point `p` (mm); the
/// background (0) outside its grid.
fn value_at(v: &Volume, p: [f64; 3]) -> f32 {
    let f = v.grid.world_to_index(DVec3::from_array(p)).round();
    let idx = [f.x, f.y, f.z];
    if idx
        .iter()
        .zip(v.grid.dims)
        .any(|(&x, d)| !(x >= 0.0 && x < d as f64))
    {
        return 0.0;
    }
    v.get_f32(idx[0] as usize, idx[1] as usize, idx[2] as usize)
}

fn ran(r: &StepReport) -> Vec<&'static str> {
    r.stages.iter().filter(|s| s.ran).map(|s| s.stage).collect()
}

/// Steps until the model stops moving (at most `max` steps).
fn settle(s: &mut Session, max: usize) {
    for _ in 0..max {
        if !s.step().unwrap().ran("map") {
            return;
        }
    }
}

/// Drags the grabbed point from `from` by `by` mm in 10 calls, the target
/// moving each call, one step per call; every step re-maps and resamples.
fn drag(s: &mut Session, from: [f64; 3], by: f64) {
    for k in 1..=10 {
        let to = [from[0] + by * k as f64 / 10.0, from[1], from[2]];
        s.interact(&Interaction::Grab {
            point: GRAB,
            to,
            frames: 1,
        })
        .unwrap();
        let r = s.step().unwrap();
        assert!(
            r.ran("map") && r.ran("resample"),
            "drag call {k}: the model moved, so map and resample run: {r}"
        );
    }
}

/// Probe values after the drag and after the cut (the voxels the tests
/// assert on), and the final volume.
struct Driven {
    /// At 32.5 mm (beyond the cube's +x face), before any drag.
    beyond_before: f32,
    /// The same after dragging the face 15 mm out.
    beyond_after_drag: f32,
    /// At 27.5 mm (between the two halves after the cut and a further
    /// drag), before the cut.
    gap_before_cut: f32,
    /// The same after the cut and the further drag.
    gap_after_cut: f32,
    volume: Volume,
}

/// open → drag over 10 calls → cut across the dragged cube → drag on.
fn drive(s: &mut Session) -> Driven {
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    settle(s, 5);
    let beyond_before = value_at(s.volume().unwrap(), [32.5, 2.5, 2.5]);
    drag(s, GRAB, 15.0);
    settle(s, 20);
    let v = s.volume().unwrap();
    let beyond_after_drag = value_at(v, [32.5, 2.5, 2.5]);
    let gap_before_cut = value_at(v, [27.5, 2.5, 2.5]);
    // A plane across the dragged cube (current positions, mm), between
    // lattice nodes, then the +x part dragged 15 mm further.
    s.interact(&Interaction::Cut {
        polygon: vec![
            [20.0, -60.0, -60.0],
            [20.0, 60.0, -60.0],
            [20.0, 60.0, 60.0],
            [20.0, -60.0, 60.0],
        ],
    })
    .unwrap();
    s.step().unwrap();
    drag(s, [GRAB[0] + 15.0, GRAB[1], GRAB[2]], 15.0);
    settle(s, 20);
    let v = s.volume().unwrap().clone();
    Driven {
        beyond_before,
        beyond_after_drag,
        gap_before_cut,
        gap_after_cut: value_at(&v, [27.5, 2.5, 2.5]),
        volume: v,
    }
}

fn lit_pixels(img: &RgbaImage) -> usize {
    img.pixels
        .chunks(4)
        .filter(|p| p[..3].iter().any(|&c| c > 8))
        .count()
}

/// One session, moved into a worker thread, through open → add ROI →
/// grab-drag over 10 calls → cut → swap model → render, through the
/// chainmail, corotational-fem and raycast libraries.
#[test]
fn a_worker_thread_drives_one_session_end_to_end() {
    let session = Session::from_volume(two_tone_cube(), defaults(BackendChoice::Cpu)).unwrap();
    let worker = std::thread::spawn(move || {
        let mut s = session;
        // An ROI on the 100 half; the 150 half is not part of it.
        let roi = s
            .add_roi(
                Seed::World(DVec3::new(-12.5, 2.5, 2.5)),
                GrowthParams::default(),
            )
            .unwrap();
        s.roi_run_to_end(roi).unwrap();
        let info = s.rois()[0].clone();
        assert!(info.converged);
        assert_eq!(info.voxels_above_half, 5 * 10 * 10, "the x < 0 half");

        let d = drive(&mut s);
        assert_eq!(d.beyond_before, 0.0, "beyond the cube: background");
        assert_eq!(
            d.beyond_after_drag, 150.0,
            "the dragged face moved 15 mm out"
        );
        assert_eq!(d.gap_before_cut, 150.0, "the uncut cube holds together");
        assert_eq!(d.gap_after_cut, 0.0, "the cut opened a gap of background");
        // The ROI followed the volume: re-grown on each new one.
        assert!(s.metrics().unwrap().stages["roi"].runs > 2);

        // Swap the model: volume, output and ROI maps are kept until the
        // next step, which maps the new model (at rest) in full.
        let before_swap = s.volume().unwrap().clone();
        s.swap_model("corotational-fem", FEM).unwrap();
        assert_eq!(s.volume().unwrap(), &before_swap, "the output is kept");
        assert_eq!(s.rois().len(), 1, "the ROI map is kept");
        let r = s.step().unwrap();
        assert!(r.stage("map").unwrap().why.starts_with("first run"), "{r}");
        assert_eq!(ran(&r), ["model", "map", "resample", "roi"], "{r}");
        let m = s.metrics().unwrap();
        assert_eq!(m.plugin.as_ref().unwrap().name, "corotational-fem");
        assert!(
            m.stages["model"].notes.contains_key("proxy_tetrahedra"),
            "{m:?}"
        );
        // At rest, the new model shows the source again.
        let source = two_tone_cube();
        let v = s.volume().unwrap();
        for p in [[-12.5, 2.5, 2.5], [12.5, 2.5, 2.5], [32.5, 2.5, 2.5]] {
            assert_eq!(value_at(v, p), value_at(&source, p), "{p:?}");
        }

        // Render in memory: the ROI dims the 150 half.
        let camera = s.default_camera(48, 48).unwrap();
        let params = RenderParams {
            params_toml: RENDER.into(),
            ..RenderParams::default()
        };
        let with_roi = s.render(&camera, &params).unwrap();
        assert_eq!(with_roi.pixels.len(), 48 * 48 * 4);
        assert!(lit_pixels(&with_roi) > 48, "the cube is drawn");
        assert!(s.remove_roi(roi));
        let without = s.render(&camera, &params).unwrap();
        let differ = with_roi
            .pixels
            .chunks(4)
            .zip(without.pixels.chunks(4))
            .filter(|(a, b)| a != b)
            .count();
        assert!(differ > 20, "the ROI shows: {differ} pixels differ");
        let sum = |i: &RgbaImage| i.pixels.iter().map(|&c| c as u64).sum::<u64>();
        assert!(
            sum(&with_roi) < sum(&without),
            "the ROI fades what is outside it"
        );
        let m = s.metrics().unwrap();
        assert_eq!(m.stages["render"].runs, 2);
        assert!(m.stages_not_built.is_empty(), "{:?}", m.stages_not_built);
    });
    worker.join().expect("the worker thread");
}

/// A model that did not move re-runs nothing downstream: after the first
/// step (which maps and resamples what there is), steps without an
/// interaction skip map, resample and the ROI maps, and the metrics count
/// the skips.
#[test]
fn an_unmoved_model_reruns_nothing_downstream() {
    let mut s = Session::from_volume(two_tone_cube(), defaults(BackendChoice::Cpu)).unwrap();
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    let roi = s
        .add_roi(
            Seed::World(DVec3::new(-12.5, 2.5, 2.5)),
            GrowthParams::default(),
        )
        .unwrap();
    s.roi_step(roi, 3).unwrap();
    let first = s.step().unwrap();
    assert_eq!(ran(&first), ["model", "map", "resample", "roi"], "{first}");
    let v = s.versions();
    for _ in 0..3 {
        let r = s.step().unwrap();
        assert_eq!(ran(&r), ["model"], "{r}");
        assert!(r.stage("map").unwrap().why.contains("unchanged"), "{r}");
    }
    assert_eq!(s.versions(), v, "no version moved");
    assert_eq!(
        s.rois()[0].steps,
        3,
        "re-grown as far as before, no further"
    );
    let m = s.metrics().unwrap();
    assert_eq!((m.stages["map"].runs, m.stages["map"].skipped), (1, 3));
    assert_eq!(m.stages["resample"].skipped, 3);
    assert_eq!(m.stages["roi"].skipped, 3);
    assert_eq!(m.frames, 4);
    // An interaction moves it again: everything downstream re-runs.
    s.interact(&Interaction::Grab {
        point: GRAB,
        to: [GRAB[0] + 5.0, GRAB[1], GRAB[2]],
        frames: 1,
    })
    .unwrap();
    let r = s.step().unwrap();
    assert_eq!(ran(&r), ["model", "map", "resample", "roi"], "{r}");
}

/// What `voxflex plugins` lists, the session lists; a refused interaction
/// names the plugin.
#[test]
fn plugins_are_listed_and_refusals_name_the_plugin() {
    let mut s = Session::from_volume(two_tone_cube(), defaults(BackendChoice::Cpu)).unwrap();
    let listed = s.plugins();
    for name in ["chainmail", "corotational-fem", "raycast"] {
        assert!(
            listed.plugins.iter().any(|l| l.plugin.name == name),
            "{name} listed"
        );
    }
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    let e = s
        .interact(&Interaction::Toml("kind = \"pinch\"\n".into()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("chainmail") && e.contains("pinch"), "{e}");
    let e = s.swap_model("raycast", "").unwrap_err().to_string();
    assert!(e.contains("renderer") && e.contains("deformation"), "{e}");
}

/// The same drag and cut on the GPU gives the voxels the CPU gives, and
/// `set_backend` names the adapter. Without an adapter this skips (and
/// fails under CI=true, as every GPU test).
#[test]
fn the_gpu_session_agrees_with_the_cpu_session() {
    let Some(gpu) = voxflex_runtime::gpu_context::testing::test_gpu() else {
        return;
    };
    let mut cpu = Session::from_volume(two_tone_cube(), defaults(BackendChoice::Cpu)).unwrap();
    let mut on_gpu = Session::from_volume(two_tone_cube(), defaults(BackendChoice::Cpu)).unwrap();
    assert_eq!(
        on_gpu.set_backend(BackendChoice::Gpu).unwrap(),
        gpu.info().name
    );
    assert_eq!(on_gpu.metrics().unwrap().backend, "gpu");
    let a = drive(&mut cpu);
    let b = drive(&mut on_gpu);
    assert_eq!(
        (a.beyond_after_drag, a.gap_after_cut),
        (b.beyond_after_drag, b.gap_after_cut)
    );
    assert_eq!(a.volume.grid, b.volume.grid);
    let (VoxelData::F32(x), VoxelData::F32(y)) = (&a.volume.data, &b.volume.data) else {
        panic!("resampled volumes are f32")
    };
    let off = x
        .iter()
        .zip(y)
        .filter(|(p, q)| (*p - *q).abs() > 1.0)
        .count();
    assert!(
        off * 1000 <= x.len(),
        "{off} of {} voxels differ by more than 1",
        x.len()
    );
    assert_eq!(on_gpu.set_backend(BackendChoice::Cpu).unwrap(), "cpu");
}

/// `Session::open` on a scene file: the scene's model and settings, and
/// interactions at any time — here a carve and a load the scene never
/// scripted — through the corotational-fem library.
#[test]
fn an_opened_scene_takes_unscripted_carves_and_loads() {
    let dir = plugin_dir(&["corotational-fem"]);
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("s.toml");
    std::fs::write(
        &path,
        format!(
            "[scene]\nname = \"open\"\nbackend = \"cpu\"\nframes = 5\nplugin_dirs = [\"{}\"]\n\
             [volume]\nsource = \"phantom:cube\"\ndims = [20, 20, 20]\n\
             [model]\nplugin = \"corotational-fem\"\n[model.params]\n{FEM}\
             [resample]\nbackground = 0\n",
            dir.display()
        ),
    )
    .unwrap();
    let scene = voxflex_runtime::scene::Scene::load(&path).unwrap();
    let mut s = Session::open(&scene).unwrap();
    let m = s.metrics().unwrap();
    assert_eq!(
        (m.scene.as_str(), m.frames, m.backend.as_str()),
        ("open", 5, "cpu")
    );
    assert_eq!(m.stages_not_built, ["render", "roi"]);
    s.step().unwrap();
    let centre = [2.5, 2.5, 2.5];
    assert_eq!(value_at(s.volume().unwrap(), centre), 100.0);
    s.interact(&Interaction::CarveBall {
        centre,
        radius: 11.0,
    })
    .unwrap();
    let r = s.step().unwrap();
    assert!(r.ran("resample"), "{r}");
    assert_eq!(value_at(s.volume().unwrap(), centre), 0.0, "carved");
    assert_eq!(value_at(s.volume().unwrap(), [17.5, 2.5, 2.5]), 100.0);
    // A load on the +x face (the −x face fixed) sets the model moving.
    let before = s.versions();
    assert_eq!(before.model, 0, "the carve moved nothing: {before:?}");
    s.interact(&Interaction::Fix {
        min: [-30.0, -30.0, -30.0],
        max: [-20.0, 30.0, 30.0],
    })
    .unwrap();
    s.interact(&Interaction::Load {
        min: [20.0, -30.0, -30.0],
        max: [30.0, 30.0, 30.0],
        force: [5.0, 0.0, 0.0],
        frames: 1,
    })
    .unwrap();
    let r = s.step().unwrap();
    assert!(r.ran("map") && r.ran("resample"), "{r}");
    assert_eq!(s.versions().model, 1, "{:?}", s.versions());
}

/// The session records what its model received, at the model's frames, and
/// starts over with a new model.
#[test]
fn the_session_records_the_interactions_its_model_received() {
    let mut s = Session::from_volume(two_tone_cube(), defaults(BackendChoice::Cpu)).unwrap();
    assert!(s.interactions_so_far().is_empty());
    assert_eq!(s.model_frames(), None);
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    s.step().unwrap();
    drag(&mut s, GRAB, 5.0);
    s.interact(&Interaction::Release).unwrap();
    s.step().unwrap();
    let got = s.interactions_so_far();
    assert_eq!(got.len(), 11);
    // One grab before each of frames 1..=10, the release before frame 11.
    let frames: Vec<u64> = got.iter().map(|a| a.frame).collect();
    assert_eq!(frames, (1..=11).collect::<Vec<_>>());
    assert!(got[9].toml.contains("kind = \"grab\"") && got[9].toml.contains("27.5"));
    assert!(got[10].toml.contains("release"));
    assert_eq!(s.model_frames(), Some(12));
    let (plugin, params) = s.model_params().unwrap();
    assert_eq!((plugin.as_str(), params.as_str()), ("chainmail", CHAINMAIL));
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    assert!(
        s.interactions_so_far().is_empty(),
        "a new model starts over"
    );
    assert_eq!(s.model_frames(), Some(0));
}

/// Mass-spring on the same proxy as [`FEM`].
const SPRINGS: &str = "proxy = { kind = \"uniform\", step = 2 }\n\
                       integrator = \"implicit\"\n\
                       materials = [{ range = [50, 200], youngs_modulus = 3000 }]\n";

/// A drag re-sends the grab with the pressed point and a new target each
/// call; every model takes the element or node whose *rest* position is
/// nearest the point, so the same one all along. [`GRAB`] is a voxel
/// centre (a ChainMail element) and a node of the step-2 proxy, so the
/// point tracked there is the grabbed one: it ends at the last target.
/// Taken by its position *now*, a mesh model would let go of nothing and
/// take a second node once the first had moved past a neighbour's rest,
/// leaving the first held behind at an earlier target.
#[test]
fn a_drag_keeps_the_element_or_node_it_first_took_in_every_model() {
    let by = 20.0;
    for (model, params) in [
        ("chainmail", CHAINMAIL),
        ("corotational-fem", FEM),
        ("mass-spring", SPRINGS),
    ] {
        let mut s = Session::from_volume(
            two_tone_cube(),
            SessionDefaults {
                plugin_dirs: vec![plugin_dir(&[model])],
                ..defaults(BackendChoice::Cpu)
            },
        )
        .unwrap();
        s.swap_model(model, params).unwrap();
        let id = s.track_points(&[GRAB.map(|x| x as f32)]).unwrap();
        drag(&mut s, GRAB, by);
        let u = s.tracked_displacements(id).unwrap()[0];
        assert!(
            (u - DVec3::new(by, 0.0, 0.0)).length() < 0.05,
            "{model}: the grabbed point moved {u} mm, not the drag's {by} mm along x"
        );
    }
}
