//! The viewer's benchmarks run end to end on tiny inputs and write their
//! tables, so they cannot rot: `voxflex-viewer --bench drag|interactive|open`
//! with a 32-voxel phantom, a 64² 3D view and a half-second drag. Nothing
//! here is timed against a figure (that is the benchmarks' job); the
//! checks are that each run succeeds, counts what it says it counts and
//! writes JSON and Markdown that agree. Needs the plugins built in
//! `target/<profile>/` (`cargo build`).

use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// Runs `voxflex-viewer --bench KIND` with the tiny settings into `out`
/// and returns its JSON report.
fn bench(kind: &str, out: &Path) -> Value {
    let plugins = voxflex_integration_tests::plugin_dir(&["chainmail", "raycast"]);
    let run = Command::new(env!("CARGO_BIN_EXE_voxflex-viewer"))
        .args(["--bench", kind, "--seconds", "0.5", "--size", "32"])
        .args(["--render-size", "64", "--out"])
        .arg(out)
        .env("VOXFLEX_PLUGIN_PATH", &plugins)
        .output()
        .expect("run voxflex-viewer");
    assert!(
        run.status.success(),
        "voxflex-viewer --bench {kind} failed: {}\n{}",
        run.status,
        String::from_utf8_lossy(&run.stderr)
    );
    let md = std::fs::read_to_string(out.join(format!("{kind}.md"))).expect("the Markdown table");
    assert!(md.contains("| figure | measured | requirement |"), "{md}");
    assert!(
        String::from_utf8_lossy(&run.stdout).contains("| figure |"),
        "the table is printed too"
    );
    let text = std::fs::read_to_string(out.join(format!("{kind}.json"))).expect("the JSON");
    let json: Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(json["bench"], kind);
    assert!(json["load_before"].is_array(), "{json}");
    json
}

#[test]
fn the_drag_bench_times_every_frame_of_the_drag() {
    let dir = tempfile::tempdir().unwrap();
    let json = bench("drag", dir.path());
    let f = &json["frame_ms"];
    // 0.5 s at 60 Hz: about 30 frames (fewer when the machine is slow).
    let count = f["count"].as_u64().unwrap();
    assert!((5..=40).contains(&count), "{json}");
    let [mean, p50, p99, worst] =
        ["mean_ms", "p50_ms", "p99_ms", "worst_ms"].map(|k| f[k].as_f64().unwrap());
    assert!(
        0.0 < p50 && p50 <= p99 && p99 <= worst && mean <= worst,
        "{json}"
    );
    assert!(
        json["steps"].as_u64().unwrap() >= 1,
        "the drag stepped the model: {json}"
    );
    assert_eq!(json["met"], worst <= 33.0);
}

#[test]
fn the_interactive_bench_counts_cycles_and_idle_renders() {
    let dir = tempfile::tempdir().unwrap();
    let json = bench("interactive", dir.path());
    assert!(json["cycles"].as_u64().unwrap() >= 1, "{json}");
    assert!(json["cycles_per_s"].as_f64().unwrap() > 0.0, "{json}");
    assert_eq!(json["idle_render_ms"]["count"], 5, "{json}");
    let stages: Vec<&str> = json["stages_while_dragging"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|s| s["stage"].as_str())
        .collect();
    for s in ["model", "resample", "render"] {
        assert!(stages.contains(&s), "stage {s} ran while dragging: {json}");
    }
}

#[test]
fn the_open_bench_writes_a_ct_like_file_and_times_its_first_image() {
    let dir = tempfile::tempdir().unwrap();
    let json = bench("open", dir.path());
    assert_eq!(json["dims"], serde_json::json!([32, 32, 8]));
    assert!(dir.path().join("ct-32x32x8.nii.gz").is_file());
    let first = json["first_image_s"].as_f64().unwrap();
    let opened = json["opened_at_ui_s"].as_f64().unwrap();
    assert!(0.0 < opened && opened <= first, "{json}");
    assert!(json["read_ms"].as_f64().unwrap() > 0.0, "{json}");
    assert!(json["render_px"].as_u64().unwrap() > 0, "{json}");
}
