//! A scene's results do not depend on how many worker threads ran it: the
//! shipped `chainmail-head.toml` scene (a grab, a fix, resampling and a
//! rendered image), with each of the three deformation models, run by the
//! CLI with `threads = 1` and `threads = 2`, writes the same volume, slices
//! and image byte for byte, and the same `metrics.json` apart from times.
//! (Parallel float sums are added in a fixed order,
//! `voxflex_core::ordered_reduce`; every other parallel loop writes
//! disjoint outputs.)

use std::path::Path;
use voxflex_integration_tests::*;

/// The shipped scene with `plugin`, the CPU backend, `threads` workers and
/// its outputs in `out`.
fn scene_text(plugin: &str, threads: usize, out: &str) -> String {
    let shipped = std::fs::read_to_string(repo_root().join("configs/chainmail-head.toml"))
        .expect("configs/chainmail-head.toml");
    let mut text = String::new();
    for line in shipped.lines() {
        let edited = if line.starts_with("plugin = \"chainmail\"") {
            format!("plugin = \"{plugin}\"")
        } else if line.starts_with("backend = ") {
            format!("backend = \"cpu\"\nthreads = {threads}")
        } else if line.starts_with("dir = ") {
            format!("dir = \"{out}\"")
        } else {
            line.to_owned()
        };
        text.push_str(&edited);
        text.push('\n');
    }
    assert!(
        text.contains(&format!("plugin = \"{plugin}\"")) && text.contains("threads = "),
        "the scene's plugin and backend lines moved: update this test"
    );
    text
}

/// `metrics.json` without the keys that are times (wall or CPU
/// milliseconds, timestamps) or the thread count itself.
fn results_only(v: &serde_json::Value) -> serde_json::Value {
    let timing = |k: &str| {
        k.ends_with("_ms")
            || k.contains("ms_per")
            || k.contains("time")
            || k.contains("started")
            || k.contains("threads")
            || k.contains("elapsed")
    };
    match v {
        serde_json::Value::Object(m) => serde_json::Value::Object(
            m.iter()
                .filter(|(k, _)| !timing(k))
                .map(|(k, v)| (k.clone(), results_only(v)))
                .collect(),
        ),
        serde_json::Value::Array(a) => a.iter().map(results_only).collect(),
        other => other.clone(),
    }
}

fn run(dir: &Path, plugin: &str, threads: usize) -> std::path::PathBuf {
    let out = format!("out_{plugin}_{threads}");
    let file = format!("{plugin}_{threads}.toml");
    std::fs::write(dir.join(&file), scene_text(plugin, threads, &out)).unwrap();
    let o = voxflex(&["run", &file], dir);
    assert!(
        o.status.success(),
        "{plugin}, {threads} threads: {}",
        text(&o)
    );
    dir.join(out)
}

#[test]
fn one_and_two_threads_write_the_same_results_for_every_model() {
    plugin_dir(&["chainmail", "corotational-fem", "mass-spring", "raycast"]);
    let tmp = tempfile::tempdir().unwrap();
    for plugin in ["chainmail", "corotational-fem", "mass-spring"] {
        let one = run(tmp.path(), plugin, 1);
        let two = run(tmp.path(), plugin, 2);
        let mut files: Vec<_> = std::fs::read_dir(&one)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            // metrics.json is compared below; `.voxflex-stamp` records
            // the scene text, whose `threads` line differs.
            .filter(|f| f != "metrics.json" && !f.starts_with('.'))
            .collect();
        files.sort();
        assert!(
            files.iter().any(|f| f.ends_with(".nii.gz")) && files.iter().any(|f| f == "render.png"),
            "{plugin}: {files:?}"
        );
        for f in &files {
            let (a, b) = (
                std::fs::read(one.join(f)).unwrap(),
                std::fs::read(two.join(f)).unwrap(),
            );
            assert!(a == b, "{plugin}: {f} differs between 1 and 2 threads");
        }
        assert_eq!(
            results_only(&metrics(&one)),
            results_only(&metrics(&two)),
            "{plugin}: metrics.json differs beyond its times"
        );
    }
}
