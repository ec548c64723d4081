//! `voxflex bench --stress` through the CLI (issue 13): a few hundred frames
//! of randomized scenes per deformation model, each plugin loaded from its
//! shared library. No call may panic and no frame may go non-finite without
//! the model's error; the JSON figures must add up.

use voxflex_integration_tests::{plugin_dir, text, voxflex};

#[test]
fn stress_runs_every_model_without_panics_or_silent_non_finite_frames() {
    plugin_dir(&["chainmail", "mass-spring", "corotational-fem", "affine"]);
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("stress.json");
    let (scenes, frames) = (8u64, 13u64);
    let o = voxflex(
        &[
            "bench",
            "--stress",
            "--stress-scenes",
            &scenes.to_string(),
            "--stress-frames",
            &frames.to_string(),
            "--json",
            json.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let mut total = 0;
    for model in ["chainmail", "mass-spring", "corotational-fem", "affine"] {
        let m = &v[model];
        let n = |k: &str| m[k].as_u64().unwrap_or_else(|| panic!("{model}.{k}: {m}"));
        assert_eq!(n("panics"), 0, "{model}: {stdout}");
        assert_eq!(n("silent_non_finite"), 0, "{model}: {stdout}");
        assert_eq!(n("scenes"), scenes, "{model}");
        assert!(n("frames") <= scenes * frames, "{model}");
        assert!(n("frames") > 0, "{model}: no frame ran: {stdout}");
        assert!(m["worst_growth"].as_f64().unwrap().is_finite(), "{model}");
        assert!(stdout.contains(model), "{stdout}");
        total += n("frames");
    }
    assert!(total >= 300, "only {total} frames ran: {stdout}");
}
