//! Tracked points and `step_model` of the `Session` through the real `.so`
//! plugins: tracked points follow a grab and agree with the map stage's
//! field, are bound again on a swapped model; `step_model` steps the model
//! alone and the next `step` maps and resamples what is due (skips stay
//! skips); a model's error says which call failed.

use voxflex_core::glam::DVec3;
use voxflex_integration_tests::plugin_dir;
use voxflex_phantom::phantom;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::session::{Interaction, ModelCall, Session, SessionDefaults, StepReport};

const CHAINMAIL: &str = "materials = [{ range = [50, 200], constraint = 0.01 }]\n\
                         propagation_iterations = 40\n";
const FEM: &str = "proxy = { kind = \"uniform\", step = 2 }\n\
                   materials = [{ range = [50, 200], youngs_modulus = 3000 }]\n\
                   solver = \"static\"\n";
const SPRINGS: &str = "proxy = { kind = \"uniform\", step = 2 }\n\
                       materials = [{ range = [50, 200], youngs_modulus = 3000 }]\n";

/// A voxel centre on the 20³ cube phantom's +x face (5 mm voxels, the
/// cube from −25 to 25 mm), mm.
const GRAB: [f64; 3] = [22.5, 2.5, 2.5];
/// A voxel centre on the opposite face, mm.
const FAR: [f64; 3] = [-22.5, 2.5, 2.5];

fn cube_session() -> Session {
    let defaults = SessionDefaults {
        backend: BackendChoice::Cpu,
        plugin_dirs: vec![plugin_dir(&[
            "chainmail",
            "corotational-fem",
            "mass-spring",
        ])],
        ..SessionDefaults::default()
    };
    Session::from_volume(phantom("cube", [20, 20, 20]).unwrap(), defaults).unwrap()
}

fn f32s(p: [f64; 3]) -> [f32; 3] {
    p.map(|x| x as f32)
}

fn grab_by(s: &mut Session, by: [f64; 3]) {
    let to = (DVec3::from_array(GRAB) + DVec3::from_array(by)).to_array();
    s.interact(&Interaction::Grab {
        point: GRAB,
        to,
        frames: 1,
    })
    .unwrap();
}

fn ran(r: &StepReport) -> Vec<&'static str> {
    r.stages.iter().filter(|s| s.ran).map(|s| s.stage).collect()
}

#[test]
fn tracked_points_follow_a_grab_and_agree_with_the_map_stage() {
    let mut s = cube_session();
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    let id = s.track_points(&[f32s(GRAB), f32s(FAR)]).unwrap();
    assert_eq!(s.tracked(), vec![id]);
    let rest = s.tracked_displacements(id).unwrap();
    assert_eq!(rest, vec![DVec3::ZERO; 2], "at rest before any step");
    grab_by(&mut s, [10.0, 0.0, 0.0]);
    for _ in 0..5 {
        s.step_model().unwrap();
    }
    let u = s.tracked_displacements(id).unwrap();
    assert!(
        (u[0] - DVec3::new(10.0, 0.0, 0.0)).length() < 1e-3,
        "the grabbed point went where it was dragged: {u:?}"
    );
    // The map stage's field at the same voxel centres holds the same.
    let [x, y, z] = s.displacement_field().unwrap();
    let grid = s.source().grid;
    for (p, d) in [GRAB, FAR].iter().zip(&u) {
        let i = grid.world_to_index(DVec3::from_array(*p)).round();
        let l = grid.linear(i.x as usize, i.y as usize, i.z as usize);
        let field = DVec3::new(x[l] as f64, y[l] as f64, z[l] as f64);
        assert!((field - *d).length() < 1e-4, "{p:?}: {field} vs {d}");
    }
    // Tracking did not consume what the pipeline has to resample.
    let r = s.step().unwrap();
    assert!(r.ran("resample"), "{r}");
    assert!(s.untrack(id));
    assert!(!s.untrack(id));
    let e = s.tracked_displacements(id).unwrap_err().to_string();
    assert!(e.contains("no tracked points"), "{e}");
}

#[test]
fn tracked_points_are_bound_again_on_a_swapped_model() {
    let mut s = cube_session();
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    let id = s.track_points(&[f32s(GRAB)]).unwrap();
    grab_by(&mut s, [10.0, 0.0, 0.0]);
    s.step_model().unwrap();
    assert!(s.tracked_displacements(id).unwrap()[0].length() > 5.0);
    s.swap_model("corotational-fem", FEM).unwrap();
    assert_eq!(
        s.tracked_displacements(id).unwrap(),
        vec![DVec3::ZERO],
        "the same id on the new model, at rest"
    );
    grab_by(&mut s, [0.0, 0.0, -5.0]);
    s.step_model().unwrap();
    let u = s.tracked_displacements(id).unwrap()[0];
    assert!(
        u.z < -1.0 && u.is_finite(),
        "the FEM moved the tracked point: {u}"
    );
    // A swap the new model refuses keeps the old model and its bindings.
    assert!(s.swap_model("chainmail", "materials = 5").is_err());
    assert_eq!(s.tracked_displacements(id).unwrap()[0], u);
}

#[test]
fn step_model_steps_the_model_alone_and_the_next_step_maps_what_is_due() {
    let mut s = cube_session();
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    // A new model: the map is due in full whatever the model does.
    let r = s.step_model().unwrap();
    assert_eq!(ran(&r), ["model"], "{r}");
    assert_eq!(r.stages.len(), 1, "map and resample are not reported: {r}");
    assert_eq!(s.frame(), 1);
    assert_eq!(s.versions().map.version, 0);
    let m = s.metrics().unwrap();
    assert_eq!(m.stages["model"].runs, 1);
    assert!(
        !m.stages.contains_key("map") || (m.stages["map"].runs, m.stages["map"].skipped) == (0, 0),
        "step_model neither runs nor skips the map"
    );
    let r = s.step().unwrap();
    assert_eq!(ran(&r), ["model", "map", "resample"], "{r}");
    // At rest: a model step moves nothing, so the next step skips the rest.
    s.step_model().unwrap();
    let r = s.step().unwrap();
    assert_eq!(ran(&r), ["model"], "skips stay skips: {r}");
    // A grab stepped by step_model alone: the next step maps and resamples.
    grab_by(&mut s, [5.0, 0.0, 0.0]);
    let (model, map) = (s.versions().model, s.versions().map.version);
    s.step_model().unwrap();
    assert!(s.versions().model > model, "the model moved");
    assert_eq!(s.versions().map.version, map, "not mapped yet");
    let r = s.step().unwrap();
    assert!(r.ran("map") && r.ran("resample"), "{r}");
    assert_eq!(s.frame(), 6);
}

#[test]
fn a_model_error_says_which_call_failed() {
    let mut s = cube_session();
    let e = s.swap_model("chainmail", "materials = 5").unwrap_err();
    assert_eq!(e.model_call(), Some(ModelCall::Create), "{e}");
    assert!(e.to_string().contains("plugin `chainmail`"), "{e}");
    s.swap_model("chainmail", CHAINMAIL).unwrap();
    let e = s
        .interact(&Interaction::Toml("kind = \"no-such-kind\"".into()))
        .unwrap_err();
    assert_eq!(e.model_call(), Some(ModelCall::Interact), "{e}");
    let e = s.track_points(&[[f32::NAN, 0.0, 0.0]]).unwrap_err();
    assert_eq!(e.model_call(), Some(ModelCall::Bind), "{e}");
    assert!(s.tracked().is_empty(), "a refused set is not tracked");
}

/// The largest |a − b| over the three components of two displacement
/// fields, mm.
fn field_gap(a: &[Vec<f32>; 3], b: &[Vec<f32>; 3]) -> f32 {
    let mut gap = 0f32;
    for (ca, cb) in a.iter().zip(b) {
        assert_eq!(ca.len(), cb.len(), "the fields cover the same grid");
        for (x, y) in ca.iter().zip(cb) {
            gap = gap.max((x - y).abs());
        }
    }
    gap
}

/// On the GPU path, tracked points and the map stage's field are read back
/// from the model's GPU state; both equal the CPU session's after the same
/// grab, for ChainMail and the FEM. Skips without an adapter (fails under
/// CI=true, as every GPU test).
#[test]
fn tracked_points_and_the_field_on_the_gpu_equal_the_cpu() {
    if voxflex_runtime::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    for (plugin, params, tolerance) in [
        ("chainmail", CHAINMAIL, 1e-4),
        ("corotational-fem", FEM, 2e-3),
    ] {
        let mut runs = vec![];
        for backend in [BackendChoice::Cpu, BackendChoice::Gpu] {
            let mut s = cube_session();
            s.set_backend(backend).unwrap();
            s.swap_model(plugin, params).unwrap();
            let id = s.track_points(&[f32s(GRAB), f32s(FAR)]).unwrap();
            grab_by(&mut s, [0.0, 0.0, -5.0]);
            for k in 0..3 {
                s.step_model()
                    .unwrap_or_else(|e| panic!("{plugin} on {backend:?}, step {k}: {e}"));
            }
            let tracked = s.tracked_displacements(id).unwrap();
            let field = s.displacement_field().unwrap();
            runs.push((s.metrics().unwrap().backend, tracked, field));
        }
        let [
            (cpu_backend, cpu_tracked, cpu_field),
            (gpu_backend, gpu_tracked, gpu_field),
        ] = <[_; 2]>::try_from(runs).unwrap();
        assert_eq!((cpu_backend.as_str(), gpu_backend.as_str()), ("cpu", "gpu"));
        assert!(
            cpu_tracked[0].length() > 3.0,
            "{plugin}: the grab moved the point"
        );
        for (c, g) in cpu_tracked.iter().zip(&gpu_tracked) {
            assert!(
                (*c - *g).length() < tolerance,
                "{plugin}: tracked {c} (cpu) vs {g} (gpu)"
            );
        }
        let gap = field_gap(&cpu_field, &gpu_field);
        assert!(
            gap < tolerance as f32,
            "{plugin}: fields differ by {gap} mm"
        );
    }
}

/// A static FEM body held by one grabbed node and nothing else, at rest
/// after the grab: every later frame asks for nothing new, so each converges
/// as it starts (no Newton iteration), for as long as the grab is held.
/// Before the solve kept a force scale across frames (`ForceScale`), the
/// second frame's rounding noise was its own scale and the step failed.
#[test]
fn a_held_static_grab_at_rest_stays_converged() {
    let mut s = cube_session();
    s.swap_model("corotational-fem", FEM).unwrap();
    grab_by(&mut s, [0.0, 0.0, -5.0]);
    s.step_model().unwrap();
    let first = s.model_notes().unwrap()["newton_iterations"];
    assert!(first >= 1.0, "the grab took Newton iterations: {first}");
    for k in 1..4 {
        s.step_model()
            .unwrap_or_else(|e| panic!("frame {k} of a held grab at rest: {e}"));
    }
    let notes = s.model_notes().unwrap();
    assert_eq!(notes["newton_iterations"], first, "{notes:?}");
    assert!(notes["newton_force_residual"] <= 1e-6, "{notes:?}");
}

/// Every model holds a grab at rest frame after frame without an error, and
/// the held point stays where it was dragged (the static FEM case above,
/// for ChainMail, the dynamic FEM and the implicit mass-spring).
#[test]
fn every_model_holds_a_grab_at_rest() {
    let dynamic = FEM.replace("static", "dynamic");
    for (plugin, params) in [
        ("chainmail", CHAINMAIL),
        ("corotational-fem", dynamic.as_str()),
        ("mass-spring", SPRINGS),
    ] {
        let mut s = cube_session();
        s.swap_model(plugin, params).unwrap();
        let id = s.track_points(&[f32s(GRAB)]).unwrap();
        grab_by(&mut s, [0.0, 0.0, -5.0]);
        for k in 0..6 {
            s.step_model()
                .unwrap_or_else(|e| panic!("{plugin}, frame {k} of a held grab: {e}"));
        }
        let u = s.tracked_displacements(id).unwrap()[0];
        assert!(
            (u - DVec3::new(0.0, 0.0, -5.0)).length() < 0.5,
            "{plugin}: the held point stays at the target: {u}"
        );
    }
}
