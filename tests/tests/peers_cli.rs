//! The CLI commands and options the side-by-side harness (`bench/peers/`)
//! relies on: `voxflex phantom`, `voxflex resample --export`,
//! `voxflex render --repeat` and the growth time of `voxflex roi`.

use voxflex_core::glam::DVec3;
use voxflex_integration_tests::*;
use voxflex_resample::accuracy::trilinear_f64;

#[test]
fn phantom_writes_the_volume_and_the_abdomen_labels() {
    let tmp = tempfile::tempdir().unwrap();
    let o = voxflex(
        &[
            "phantom", "abdomen", "--dims", "24,20,16", "--out", "a.nii", "--labels", "l.nii.gz",
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let a = voxflex_io::read_volume(&tmp.path().join("a.nii"), &Default::default()).unwrap();
    let l = voxflex_io::read_volume(&tmp.path().join("l.nii.gz"), &Default::default()).unwrap();
    assert_eq!(a.grid, l.grid);
    assert_eq!(a.grid.dims, [24, 20, 16]);
    let liver = (0..l.grid.len())
        .filter(|&i| {
            let [x, y, z] = l.grid.unlinear(i);
            l.get_f32(x, y, z) == 5.0
        })
        .count();
    assert!(liver > 0, "the liver (label 5) is there");

    // Labels exist for the abdomen only; bad names and extensions are refused.
    for (args, says) in [
        (
            vec!["phantom", "head", "--out", "h.nii", "--labels", "x.nii"],
            "only the abdomen",
        ),
        (vec!["phantom", "head", "--out", "h.png"], ".nii"),
        (vec!["phantom", "nope", "--out", "h.nii"], "nope"),
        (
            vec!["phantom", "head", "--dims", "4,4", "--out", "h.nii"],
            "three numbers",
        ),
    ] {
        let o = voxflex(&args, tmp.path());
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// The exported backward field is the map voxflex applied: sampling the
/// exported source trilinearly at X + d(X) gives voxflex's result at every
/// interior output voxel X (what SimpleITK is handed in the harness).
#[test]
fn resample_exports_the_exact_backward_field_of_its_result() {
    let tmp = tempfile::tempdir().unwrap();
    let o = voxflex(
        &[
            "resample",
            "phantom:head",
            "--dims",
            "24,24,20",
            "--field",
            "twist",
            "--angle-deg",
            "30",
            "--repeat",
            "2",
            "--export",
            "x",
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(stdout(&o).contains("resample: min "), "{}", text(&o));
    let dir = tmp.path().join("x");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("resample.json")).unwrap()).unwrap();
    assert_eq!(meta["resample_ms"].as_array().unwrap().len(), 2, "{meta}");
    assert_eq!(meta["output_grid"]["frame"], "LPS");
    let read = |f: &str| voxflex_io::read_volume(&dir.join(f), &Default::default()).unwrap();
    let (src, out) = (read("source.nii"), read("resampled.nii"));
    let d = [
        read("backward_x.nii"),
        read("backward_y.nii"),
        read("backward_z.nii"),
    ];
    assert_eq!(src.grid.dims, [24, 24, 20]);
    assert!(out.grid.dims[0] > 24, "the twist grows the output grid");
    let hi = DVec3::new(22.0, 22.0, 18.0);
    let (mut compared, mut worst) = (0, 0f64);
    for l in 0..out.grid.len() {
        let [i, j, k] = out.grid.unlinear(l);
        let x = out
            .grid
            .index_to_world(DVec3::new(i as f64, j as f64, k as f64));
        let u = DVec3::new(
            d[0].get_f32(i, j, k) as f64,
            d[1].get_f32(i, j, k) as f64,
            d[2].get_f32(i, j, k) as f64,
        );
        let r = src.grid.world_to_index(x + u);
        if r.cmplt(DVec3::ONE).any() || r.cmpgt(hi).any() {
            continue;
        }
        compared += 1;
        worst = worst.max((trilinear_f64(&src, r) - out.get_f32(i, j, k) as f64).abs());
    }
    assert!(compared > 2000, "{compared}");
    assert!(worst < 0.05, "max |Δ| {worst} HU over {compared} voxels");

    for args in [
        vec!["resample", "phantom:head", "--repeat", "0"],
        vec!["resample", "phantom:head", "--angle-deg", "500"],
    ] {
        let o = voxflex(&args, tmp.path());
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", text(&o));
        assert!(
            String::from_utf8_lossy(&o.stderr).contains("out of range"),
            "{}",
            text(&o)
        );
    }
}

#[test]
fn render_repeat_times_each_frame_and_roi_reports_its_growth_time() {
    plugin_dir(&["raycast"]);
    let tmp = tempfile::tempdir().unwrap();
    let o = voxflex(
        &[
            "render",
            "phantom:head",
            "--dims",
            "24,24,24",
            "--size",
            "32x32",
            "--backend",
            "cpu",
            "--repeat",
            "2",
            "--out",
            "r.png",
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let s = stdout(&o);
    let line = s
        .lines()
        .find(|l| l.starts_with("repeat frames (ms): "))
        .unwrap_or_else(|| panic!("{s}"));
    let times: Vec<f64> = line["repeat frames (ms): ".len()..]
        .split_whitespace()
        .map(|t| t.parse().unwrap())
        .collect();
    assert_eq!(times.len(), 2, "{line}");

    let o = voxflex(
        &[
            "roi",
            "phantom:abdomen",
            "--dims",
            "24,20,16",
            "--seed=-95,-10,30",
            "--lambda",
            "4",
            "--out",
            "m.nii",
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(stdout(&o).contains(" ms → "), "{}", text(&o));
}
