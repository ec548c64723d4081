//! The CLI end to end: the demo scene, outputs, metrics, up-to-date runs,
//! validation messages, plugin listing, and the plugin swap.

use voxflex_integration_tests::*;

fn twist(frames: u64) -> String {
    format!("field = \"twist\"\nangle_deg = 30\nramp_frames = {frames}")
}

#[test]
fn demo_scene_writes_slices_nifti_and_metrics() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let demo = repo_root().join("configs/demo.toml");
    let o = voxflex(
        &["run", demo.to_str().unwrap(), "--out", "demo"],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let out = tmp.path().join("demo");
    for f in [
        "axial.png",
        "coronal.png",
        "sagittal.png",
        "deformed.nii.gz",
        "metrics.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing\n{}", text(&o));
    }
    let m = metrics(&out);
    assert_eq!(m["plugin"]["name"], "affine");
    assert_eq!(m["up_to_date"], false);
    assert!(m["stages"]["resample"]["runs"].as_u64().unwrap() >= 1);
    assert!(m["stages"]["resample"]["wall_ms"].as_f64().unwrap() > 0.0);
    assert!(m["stages"]["resample"]["voxels_touched"].as_u64().unwrap() > 0);
    // The deformed volume reads back with the output grid of the metrics.
    let v = voxflex_io::read_volume(&out.join("deformed.nii.gz"), &Default::default()).unwrap();
    let dims: Vec<usize> = m["output_dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_u64().unwrap() as usize)
        .collect();
    assert_eq!(v.grid.dims.to_vec(), dims);
}

#[test]
fn converged_frames_skip_downstream_stages_and_a_second_run_reruns_nothing() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // Ramp over 2 frames, then 3 converged frames.
    std::fs::write(
        tmp.path().join("s.toml"),
        scene("cpu", "cube", 24, 5, "affine", &twist(2), &out),
    )
    .unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&out);
    assert_eq!(m["stages"]["model"]["runs"], 5);
    assert_eq!(m["stages"]["map"]["runs"], 2);
    assert_eq!(m["stages"]["map"]["skipped"], 3);
    assert_eq!(m["stages"]["resample"]["runs"], 2);
    assert_eq!(m["stages"]["resample"]["skipped"], 3);
    assert_eq!(m["stages"]["output"]["runs"], 1);

    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("up to date"),
        "{}",
        text(&o)
    );
    // metrics.json still reports the run that made the outputs.
    assert_eq!(metrics(&out), m);

    // Touching the scene makes it stale again.
    let text2 = std::fs::read_to_string(tmp.path().join("s.toml"))
        .unwrap()
        .replace("angle_deg = 30", "angle_deg = 31");
    std::fs::write(tmp.path().join("s.toml"), text2).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(metrics(&out)["up_to_date"], false);
}

/// Voxels of `<a>/deformed.nii.gz` and `<b>/deformed.nii.gz` (under `dir`)
/// that differ by more than one unit, and how many there are. Samples on
/// the edge of a moved structure may round the other way between two paths
/// that deform alike, so callers allow a few.
fn differing_voxels(dir: &std::path::Path, a: &str, b: &str) -> (usize, usize) {
    let read = |out: &str| {
        voxflex_io::read_volume(&dir.join(out).join("deformed.nii.gz"), &Default::default())
            .unwrap()
    };
    let (a, b) = (read(a), read(b));
    assert_eq!(a.grid, b.grid);
    let (a, b) = (a.view().data.to_f32_vec(), b.view().data.to_f32_vec());
    let differ = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (*x - *y).abs() > 1.0)
        .count();
    (differ, a.len())
}

#[test]
fn chainmail_head_scene_runs_and_swaps_to_every_model_with_one_edit() {
    plugin_dir(&[
        "chainmail",
        "affine",
        "raycast",
        "corotational-fem",
        "mass-spring",
    ]);
    let tmp = tempfile::tempdir().unwrap();
    let scene_text =
        std::fs::read_to_string(repo_root().join("configs/chainmail-head.toml")).unwrap();
    std::fs::write(tmp.path().join("s.toml"), &scene_text).unwrap();
    let o = voxflex(&["run", "s.toml", "--out", "cm"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&tmp.path().join("cm"));
    assert_eq!(m["plugin"]["name"], "chainmail");
    assert!(m["stages"]["resample"]["runs"].as_u64().unwrap() >= 2);
    let cm = std::fs::read(tmp.path().join("cm/deformed.nii.gz")).unwrap();

    // Under `auto` a software adapter (lavapipe) counts as no GPU: rayon.
    assert_eq!(m["backend"], "cpu", "{}", m["backend_reason"]);

    // An explicit GPU backend runs the WGSL path (lavapipe in CI) and
    // deforms the head the same way, up to float rounding.
    if voxflex_runtime::gpu_context::testing::test_gpu().is_some() {
        let gpu = scene_text.replacen("backend = \"auto\"", "backend = \"gpu\"", 1);
        assert_ne!(gpu, scene_text);
        std::fs::write(tmp.path().join("s.toml"), &gpu).unwrap();
        let o = voxflex(&["run", "s.toml", "--out", "g"], tmp.path());
        assert!(o.status.success(), "{}", text(&o));
        let g = metrics(&tmp.path().join("g"));
        assert_eq!(g["backend"], "gpu", "{g}");
        assert_eq!(g["plugin"]["name"], "chainmail");
        // The device builds its own block lists: the same work, frame by
        // frame, as the rayon schedule.
        for note in [
            "propagation_iterations",
            "relaxation_sweeps",
            "repair_waves",
            "conflicting_constraints",
            "relaxation_blocks_per_frame_max",
        ] {
            let at = |m: &serde_json::Value| m["stages"]["model"]["notes"][note].clone();
            assert_eq!(at(&g), at(&m), "{note}");
            assert!(at(&m).is_number(), "{note}: {m}");
        }
        let (differ, of) = differing_voxels(tmp.path(), "cm", "g");
        // Samples on the edge of a moved structure may round the other way;
        // the deformation itself is the same.
        assert!(differ * 1000 < of, "{differ} of {of} voxels differ");
    }

    // The same scene, one line changed, for every other model.
    let mut volumes = vec![cm];
    for (plugin, out) in [
        ("affine", "af"),
        ("corotational-fem", "fem"),
        ("mass-spring", "ms"),
    ] {
        let swapped = scene_text.replacen(
            "plugin = \"chainmail\"",
            &format!("plugin = \"{plugin}\""),
            1,
        );
        assert_ne!(swapped, scene_text);
        std::fs::write(tmp.path().join("s.toml"), &swapped).unwrap();
        let o = voxflex(&["run", "s.toml", "--out", out], tmp.path());
        assert!(o.status.success(), "{plugin}: {}", text(&o));
        let m = metrics(&tmp.path().join(out));
        assert_eq!(m["plugin"]["name"], plugin);
        if plugin != "affine" {
            // The mesh models report their work through the plugin
            // boundary: every voxel bound, how many of them outside the
            // proxy, and the implicit solves' CG iterations.
            let notes = &m["stages"]["model"]["notes"];
            let voxels: u64 = m["source_dims"]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| d.as_u64().unwrap())
                .product();
            assert_eq!(notes["bound_points"].as_f64(), Some(voxels as f64), "{m}");
            let outside = notes["bound_points_outside_proxy"].as_f64().unwrap();
            assert!((0.0..voxels as f64).contains(&outside), "{m}");
            assert_eq!(
                notes["steps"].as_f64(),
                m["stages"]["model"]["runs"].as_f64(),
                "{m}"
            );
            assert!(notes["solver_iterations"].as_f64().unwrap() > 0.0, "{m}");
            assert!(notes["proxy_tetrahedra"].as_f64().unwrap() > 0.0, "{m}");
        }
        let v = std::fs::read(tmp.path().join(out).join("deformed.nii.gz")).unwrap();
        assert!(
            volumes.iter().all(|other| *other != v),
            "{plugin}: a different model must give a different volume"
        );
        volumes.push(v);
    }

    // The mesh models on the WGSL path (corotational FEM's PCG, the
    // implicit mass-spring's, and the map into device buffers, through the
    // plugin ABI's GPU service) deform the head as their rayon paths do.
    if voxflex_runtime::gpu_context::testing::test_gpu().is_some() {
        for (plugin, cpu_out) in [("corotational-fem", "fem"), ("mass-spring", "ms")] {
            let on_gpu = scene_text
                .replacen(
                    "plugin = \"chainmail\"",
                    &format!("plugin = \"{plugin}\""),
                    1,
                )
                .replacen("backend = \"auto\"", "backend = \"gpu\"", 1);
            std::fs::write(tmp.path().join("s.toml"), &on_gpu).unwrap();
            let gpu_out = format!("{cpu_out}-gpu");
            let o = voxflex(&["run", "s.toml", "--out", &gpu_out], tmp.path());
            assert!(o.status.success(), "{plugin}: {}", text(&o));
            assert_eq!(metrics(&tmp.path().join(&gpu_out))["backend"], "gpu");
            let (differ, of) = differing_voxels(tmp.path(), cpu_out, &gpu_out);
            assert!(
                differ * 1000 < of,
                "{plugin}: {differ} of {of} voxels differ"
            );
        }
    }
}

#[test]
fn swap_plugins_by_editing_only_the_scene() {
    plugin_dir(&["affine", "ripple"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let a = scene(
        "cpu",
        "head",
        32,
        1,
        "affine",
        "field = \"bend\"\nangle_deg = 20",
        &out,
    );
    std::fs::write(tmp.path().join("s.toml"), &a).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(metrics(&out)["plugin"]["name"], "affine");
    let first = std::fs::read(out.join("deformed.nii.gz")).unwrap();

    let b = a
        .replace("plugin = \"affine\"", "plugin = \"ripple\"")
        .replace("field = \"bend\"\nangle_deg = 20", "amplitude_mm = 2.0");
    std::fs::write(tmp.path().join("s.toml"), &b).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(metrics(&out)["plugin"]["name"], "ripple");
    assert_ne!(
        std::fs::read(out.join("deformed.nii.gz")).unwrap(),
        first,
        "a different model must give a different volume"
    );
}

#[test]
fn validate_accepts_the_demo_and_names_misspelt_keys() {
    plugin_dir(&["affine"]);
    let root = repo_root();
    let o = voxflex(&["validate", "configs/demo.toml"], &root);
    assert!(o.status.success(), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("configs/demo.toml: ok"));

    let tmp = tempfile::tempdir().unwrap();
    let bad = std::fs::read_to_string(root.join("configs/demo.toml"))
        .unwrap()
        .replace("frames = 8", "frams = 8");
    std::fs::write(tmp.path().join("bad.toml"), bad).unwrap();
    let o = voxflex(&["validate", "bad.toml"], tmp.path());
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("bad.toml:")
            && err.contains("unknown key `frams` in [scene]; did you mean `frames`?"),
        "{}",
        text(&o)
    );
    assert_eq!(err.lines().count(), 1, "one line: {err}");
}

#[test]
fn plugin_errors_are_one_clear_line() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // Unknown plugin.
    std::fs::write(
        tmp.path().join("s.toml"),
        scene("cpu", "cube", 8, 1, "warp-drive", "", &out),
    )
    .unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert_eq!(o.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("plugin `warp-drive` not found"),
        "{}",
        text(&o)
    );
    // Bad plugin parameter: the plugin names its key.
    std::fs::write(
        tmp.path().join("s.toml"),
        scene(
            "cpu",
            "cube",
            8,
            1,
            "affine",
            "field = \"twist\"\nangel_deg = 3",
            &out,
        ),
    )
    .unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("plugin `affine`") && err.contains("angel_deg"),
        "{}",
        text(&o)
    );
}

#[test]
fn abi_mismatch_is_refused_naming_the_file_and_both_versions() {
    let built = fixture_plugin_dir(&["mismatched"]);
    let tmp = tempfile::tempdir().unwrap();
    let lib = voxflex_runtime::plugin_loader::library_file_name("mismatched");
    std::fs::copy(built.join(&lib), tmp.path().join(&lib)).unwrap();
    let out = tmp.path().join("out");
    let s = scene("cpu", "cube", 8, 1, "mismatched", "", &out).replace(
        "frames = 1",
        &format!("frames = 1\nplugin_dirs = [\"{}\"]", tmp.path().display()),
    );
    std::fs::write(tmp.path().join("s.toml"), s).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    let host = voxflex_abi::ABI_VERSION;
    assert!(
        err.contains(&tmp.path().join(&lib).display().to_string()),
        "{err}"
    );
    assert!(
        err.contains(&format!("plugin was built for ABI v{}", host + 1))
            && err.contains(&format!("this host speaks ABI v{host}")),
        "{err}"
    );
    // `plugins` lists it as refused instead of failing.
    let o = voxflex(
        &["plugins", "--dir", tmp.path().to_str().unwrap()],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("(refused)"),
        "{}",
        text(&o)
    );
}

#[test]
fn plugins_lists_name_kind_version_abi_capabilities_path() {
    let dir = plugin_dir(&["affine"]);
    let o = voxflex(&["plugins"], &repo_root());
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    let line = out
        .lines()
        .find(|l| l.starts_with("affine "))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        line.contains("deformation")
            && line.contains(env!("CARGO_PKG_VERSION"))
            && line.contains(&format!("v{}", voxflex_abi::ABI_VERSION)),
        "{line}"
    );
    assert!(
        line.contains("cpu, gpu") && line.contains(&dir.display().to_string()),
        "{line}"
    );
}

#[test]
fn info_describes_phantoms_and_refuses_hostile_headers() {
    let tmp = tempfile::tempdir().unwrap();
    let o = voxflex(&["info", "phantom:head", "--dims", "32,32,32"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("32") && out.contains("-1000"), "{out}");

    // A NIfTI file cut in half: one line naming the file.
    let v = voxflex_phantom::phantom("cube", [16, 16, 16]).unwrap();
    let p = tmp.path().join("v.nii.gz");
    voxflex_io::write_volume(&p, v.view()).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let o = voxflex(&["info", p.to_str().unwrap()], tmp.path());
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("v.nii.gz") && err.lines().count() == 1,
        "{err}"
    );
}

/// A header that permutes and reverses its axes is read into the LPS grid:
/// the axes follow the world, not the file's storage order.
#[test]
fn info_applies_header_orientation() {
    let tmp = tempfile::tempdir().unwrap();
    // i runs superior (2 mm), j towards the patient's right (LPS −x,
    // 1 mm), k posterior (LPS +y, 3 mm): 2 × 3 × 4 voxels.
    let values: Vec<String> = (0..24).map(|v| v.to_string()).collect();
    let nrrd = format!(
        "NRRD0004\ntype: uchar\ndimension: 3\nspace: left-posterior-superior\n\
         sizes: 2 3 4\nspace directions: (0,0,2) (-1,0,0) (0,3,0)\n\
         space origin: (10,20,30)\nencoding: ascii\n\n{}\n",
        values.join(" ")
    );
    std::fs::write(tmp.path().join("turned.nrrd"), nrrd).unwrap();
    let o = voxflex(&["--log", "info", "info", "turned.nrrd"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    assert!(out.contains("3 × 4 × 2 voxels"), "{out}");
    assert!(out.contains("spacing   1 × 3 × 2 mm"), "{out}");
    // j runs towards −x, so grid voxel 0 is the file's last j, 2 × 1 mm
    // further along −x than the header's origin.
    assert!(out.contains("origin    (8, 20, 30) mm"), "{out}");
    assert!(out.contains("i→+z, j→−x, k→+y"), "{out}");
}

/// An oblique header is placed along its closest axes by default, with a
/// warning that names the angle and the option; with `--oblique linear`
/// (CLI) or `[volume] oblique = "linear"` (scene) it is resampled onto the
/// axis-aligned grid that holds it, every voxel where the header puts it.
#[test]
fn oblique_headers_are_resampled_where_the_header_puts_them_on_request() {
    plugin_dir(&[]);
    let tmp = tempfile::tempdir().unwrap();
    write_oblique_nrrd(tmp.path());
    let o = voxflex(&["info", "oblique.nrrd"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    assert!(out.contains("6 × 5 × 4 voxels"), "{out}");
    assert!(
        out.contains("oblique by 30.00°") && out.contains("--oblique linear"),
        "{out}"
    );
    // The corners span 5 cos 30° + 4 sin 30° = 6.33 mm along x and
    // 5 sin 30° + 4 cos 30° = 5.96 mm along y: 8 × 7 voxel centres.
    let o = voxflex(&["info", "oblique.nrrd", "--oblique", "linear"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    assert!(
        out.contains("8 × 7 × 4 voxels") && !out.contains("WARN"),
        "{out}"
    );
    let o = voxflex(&["info", "oblique.nrrd", "--oblique", "cubic"], tmp.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("closest-axes"), "{}", text(&o));

    let out_dir = tmp.path().join("out");
    std::fs::write(
        tmp.path().join("s.toml"),
        format!(
            "[scene]\nname = \"oblique\"\nbackend = \"cpu\"\n\n[volume]\n\
             source = \"oblique.nrrd\"\noblique = \"linear\"\n\n[output]\ndir = \"{}\"\n\
             nifti = \"copy.nii.gz\"\n",
            out_dir.display()
        ),
    )
    .unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let v = voxflex_io::read_volume(&out_dir.join("copy.nii.gz"), &Default::default()).unwrap();
    assert_eq!(v.grid.dims, [8, 7, 4]);
    let (s, c) = 30f64.to_radians().sin_cos();
    let values = v.data.as_slice().to_f32_vec();
    let mut inside = 0;
    for (l, value) in values.into_iter().enumerate() {
        let p = v.grid.index_to_world(voxflex_core::glam::DVec3::from_array(
            v.grid.unlinear(l).map(|x| x as f64),
        ));
        // The header's inverse: world → file index.
        let (dx, dy) = (p.x - 10.0, p.y - 20.0);
        let (i, j, k) = (c * dx + s * dy, -s * dx + c * dy, p.z - 30.0);
        if i > 1e-6 && i < 5.0 - 1e-6 && j > 1e-6 && j < 4.0 - 1e-6 && (0.0..=3.0).contains(&k) {
            inside += 1;
            let want = oblique_ramp(p.to_array());
            assert!((value as f64 - want).abs() < 1e-3, "{p}: {value} vs {want}");
        }
    }
    assert!(inside >= 60, "{inside} voxels inside");
    assert_eq!(metrics(&out_dir)["warnings"].as_array().unwrap().len(), 0);

    // The default placement's warning reaches metrics.json too.
    let scene = std::fs::read_to_string(tmp.path().join("s.toml")).unwrap();
    std::fs::write(
        tmp.path().join("s.toml"),
        scene.replace("oblique = \"linear\"\n", ""),
    )
    .unwrap();
    let o = voxflex(&["run", "s.toml", "--force"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let warnings = metrics(&out_dir)["warnings"].to_string();
    assert!(warnings.contains("oblique by 30.00°"), "{warnings}");
}

#[test]
fn a_cpu_only_plugin_runs_on_the_cpu_under_auto_and_is_refused_under_gpu() {
    plugin_dir(&["ripple"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let s = scene("auto", "cube", 16, 1, "ripple", "amplitude_mm = 1.0", &out);
    std::fs::write(tmp.path().join("s.toml"), &s).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&out);
    assert_eq!(m["backend"], "cpu");
    let reason = m["backend_reason"].as_str().unwrap();
    assert!(reason.contains("computes on the CPU only"), "{reason}");
    // Refused before any GPU work, whether or not an adapter exists.
    let s = s.replacen("backend = \"auto\"", "backend = \"gpu\"", 1);
    std::fs::write(tmp.path().join("s.toml"), &s).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(!o.status.success());
    assert!(
        text(&o).contains("plugin `ripple` has no GPU path; use backend = \"cpu\" or \"auto\""),
        "{}",
        text(&o)
    );
}

#[test]
fn scripted_interactions_reach_the_model_at_their_frame() {
    plugin_dir(&["ripple"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let s = format!(
        "{}\n[[interaction]]\nframe = 3\namplitude_mm = 4.0\n",
        scene("cpu", "cube", 16, 5, "ripple", "amplitude_mm = 1.0", &out)
    );
    std::fs::write(tmp.path().join("s.toml"), s).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&out);
    // Frame 0 maps the initial ripple, frame 3 the new amplitude; the rest skip.
    assert_eq!(m["stages"]["map"]["runs"], 2, "{m}");
    assert_eq!(m["stages"]["resample"]["runs"], 2, "{m}");
    assert_eq!(m["stages"]["resample"]["skipped"], 3, "{m}");

    // A bad interaction key is named by the plugin.
    let s = format!(
        "{}\n[[interaction]]\nframe = 1\namplitude = 4.0\n",
        scene("cpu", "cube", 16, 2, "ripple", "", &out)
    );
    std::fs::write(tmp.path().join("s.toml"), s).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("unknown field `amplitude`"),
        "{}",
        text(&o)
    );
}

#[test]
fn roi_maps_grow_from_a_seed_and_stages_nobody_asked_for_are_not_built() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // Seed in the brain of the head phantom (world centre is inside it).
    let s = format!(
        "{}\n[[roi]]\nname = \"brain\"\nseed = [0.0, 0.0, 0.0]\nwrite = true\n",
        scene(
            "cpu",
            "head",
            40,
            1,
            "affine",
            "field = \"twist\"\nangle_deg = 10",
            &out
        )
    );
    std::fs::write(tmp.path().join("s.toml"), s).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&out);
    assert_eq!(m["stages"]["roi"]["runs"], 1, "{m}");
    assert!(
        m["stages"]["roi"]["notes"]["useful_fraction"]
            .as_f64()
            .unwrap()
            > 0.5,
        "{m}"
    );
    let nb: Vec<&str> = m["stages_not_built"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(nb.contains(&"render") && !nb.contains(&"roi"), "{m}");
    let map = voxflex_io::read_volume(&out.join("roi_brain.nii.gz"), &Default::default()).unwrap();
    let v = map.data.as_slice().to_f32_vec();
    let inside = v.iter().filter(|&&q| q > 0.5 * 65535.0).count();
    assert!(
        inside > 1000,
        "the brain map holds only {inside} voxels above 0.5"
    );

    // A scene with neither [[roi]] nor [render] builds neither.
    std::fs::write(
        tmp.path().join("t.toml"),
        scene(
            "cpu",
            "cube",
            8,
            1,
            "affine",
            "field = \"twist\"",
            &tmp.path().join("o2"),
        ),
    )
    .unwrap();
    let o = voxflex(&["run", "t.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&tmp.path().join("o2"));
    let nb: Vec<&str> = m["stages_not_built"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(nb.contains(&"render") && nb.contains(&"roi"), "{m}");
}

/// A ChainMail cut reaches the resampler: pulled apart, the two halves of
/// a cube leave background in the gap, where the uncut cube stays solid.
/// A carve through the mesh plugins' `.so` files: the proxy loses the
/// tetrahedra in the ball, the resampled volume shows the hole, and the
/// notes count the smaller proxy.
#[test]
fn mesh_models_carve_a_hole_through_the_plugin_boundary() {
    plugin_dir(&["corotational-fem", "mass-spring"]);
    let tmp = tempfile::tempdir().unwrap();
    for plugin in ["corotational-fem", "mass-spring"] {
        let run = |carve: bool| {
            let carve_table = if carve {
                "[[interaction]]\nframe = 0\nkind = \"carve\"\ncentre = [2.5, 2.5, 2.5]\nradius = 11\n"
            } else {
                ""
            };
            let scene_text = format!(
                "[scene]\nname = \"carve\"\nbackend = \"cpu\"\nframes = 2\n\
                 [volume]\nsource = \"phantom:cube\"\ndims = [20, 20, 20]\n\
                 [model]\nplugin = \"{plugin}\"\n\
                 [model.params]\nproxy = {{ kind = \"uniform\", step = 2 }}\n\
                 materials = [{{ range = [50, 200], youngs_modulus = 3000 }}]\n\
                 {carve_table}\
                 [resample]\nbackground = 0\n\
                 [output]\ndir = \"out\"\nnifti = \"deformed.nii.gz\"\n"
            );
            std::fs::write(tmp.path().join("s.toml"), &scene_text).unwrap();
            let o = voxflex(&["run", "s.toml", "--out", "o", "--force"], tmp.path());
            assert!(o.status.success(), "{plugin}: {}", text(&o));
            let at = output_values(tmp.path(), &[[2.5, 2.5, 2.5], [17.5, 2.5, 2.5]]);
            let m = metrics(&tmp.path().join("o"));
            let tets = m["stages"]["model"]["notes"]["proxy_tetrahedra"]
                .as_f64()
                .unwrap();
            (at[0], at[1], tets)
        };
        let (centre, beside, whole) = run(false);
        assert_eq!((centre, beside), (100.0, 100.0), "{plugin}: the cube");
        let (centre, beside, carved) = run(true);
        assert_eq!(centre, 0.0, "{plugin}: the carved ball is background");
        assert_eq!(beside, 100.0, "{plugin}: tissue beside the ball stays");
        assert!(carved < whole, "{plugin}: {carved} of {whole} tetrahedra");
    }
}

/// Output piped into a reader that goes away ends the process without a
/// panic (the default SIGPIPE action, as for other Unix tools).
#[test]
fn output_into_a_closed_pipe_ends_quietly() {
    use std::process::{Command, Stdio};
    let mut child = Command::new(voxflex_bin())
        .args(["info", "phantom:head", "--dims", "48,48,48"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked"), "{err}");
    assert_ne!(o.status.code(), Some(101), "{err}");
}

#[test]
fn a_chainmail_cut_opens_a_gap_in_the_resampled_volume() {
    plugin_dir(&["chainmail"]);
    let tmp = tempfile::tempdir().unwrap();
    let value_in_gap = |cut: bool| {
        let cut_table = if cut {
            "[[interaction]]\nframe = 0\nkind = \"cut\"\n\
             polygon = [[0, -60, -60], [0, 60, -60], [0, 60, 60], [0, -60, 60]]\n"
        } else {
            ""
        };
        let scene_text = format!(
            "[scene]\nname = \"cut\"\nbackend = \"cpu\"\nframes = 3\n\
             [volume]\nsource = \"phantom:cube\"\ndims = [20, 20, 20]\n\
             [model]\nplugin = \"chainmail\"\n\
             [model.params]\nmaterials = [{{ range = [50, 200], constraint = 0.01 }}]\n\
             propagation_iterations = 40\n\
             {cut_table}\
             [[interaction]]\nframe = 0\nkind = \"grab\"\npoint = [22.5, 2.5, 2.5]\nby = [15, 0, 0]\n\
             [resample]\nbackground = 0\n\
             [output]\ndir = \"out\"\nnifti = \"deformed.nii.gz\"\n"
        );
        std::fs::write(tmp.path().join("s.toml"), &scene_text).unwrap();
        let o = voxflex(&["run", "s.toml", "--out", "o", "--force"], tmp.path());
        assert!(o.status.success(), "{}", text(&o));
        output_values(tmp.path(), &[[7.5, 2.5, 2.5]])[0]
    };
    assert_eq!(value_in_gap(false), 100.0, "the uncut cube moves as one");
    assert_eq!(value_in_gap(true), 0.0, "the cut opens a gap of background");
}

#[test]
fn warnings_of_plugins_land_in_metrics_whatever_the_log_filter() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // The affine field ignores a grab, loudly.
    let s = format!(
        "{}\n[[interaction]]\nframe = 1\nkind = \"grab\"\npoint = [0, 0, 0]\nby = [1, 0, 0]\n",
        scene("cpu", "cube", 16, 3, "affine", &twist(2), &out)
    );
    std::fs::write(tmp.path().join("s.toml"), s).unwrap();
    let o = voxflex(&["--log", "error", "run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        !String::from_utf8_lossy(&o.stderr).contains("takes no interactions"),
        "--log error hides it on the terminal\n{}",
        text(&o)
    );
    let m = metrics(&out);
    let warnings = m["warnings"].as_array().expect("a warnings list");
    assert_eq!(warnings.len(), 1, "{m}");
    let w = warnings[0].as_str().unwrap();
    assert!(
        w.contains("affine") && w.contains("takes no interactions"),
        "{w}"
    );
    // A clean run has an empty list.
    std::fs::write(
        tmp.path().join("s.toml"),
        scene("cpu", "cube", 16, 3, "affine", &twist(2), &out),
    )
    .unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(metrics(&out)["warnings"], serde_json::json!([]));
}

/// `lambda = "auto"` and the growth bounds on the labelled abdomen: the λ
/// used, its trials and what stopped each map reach `metrics.json`; the
/// one-off `voxflex roi` takes `--lambda auto` and refuses bad values
/// naming the option.
#[test]
fn roi_auto_lambda_and_bounds_reach_the_notes_and_the_cli() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let s = format!(
        "{}\n[[roi]]\nname = \"liver\"\nseed = [-95.0, -10.0, 30.0]\n\
         [[roi]]\nname = \"near\"\nseed = [-95.0, -10.0, 30.0]\nlambda = 30\nmax_distance_mm = 25\n",
        scene(
            "cpu",
            "abdomen",
            48,
            1,
            "affine",
            "field = \"twist\"\nangle_deg = 5",
            &out
        )
    );
    std::fs::write(tmp.path().join("s.toml"), s).unwrap();
    let o = voxflex(&["run", "s.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&out);
    let maps = &m["stages"]["roi"]["notes"]["maps"];
    let liver = &maps["liver"];
    let lambda = liver["lambda"].as_f64().unwrap();
    assert!((1.0..=32.0).contains(&lambda) && lambda < 30.0, "{m}");
    assert!(
        !liver["lambda_auto_trials"].as_array().unwrap().is_empty(),
        "{m}"
    );
    assert_eq!(liver["stopped_by"], "converged", "{m}");
    assert_eq!(liver["made_by"], "lambda scan", "{m}");
    let near = &maps["near"];
    assert_eq!(near["made_by"], "growth", "{m}");
    assert_eq!(near["lambda"].as_f64(), Some(30.0), "{m}");
    assert!(
        near["stopped_by"]
            .as_str()
            .unwrap()
            .contains("max_distance_mm"),
        "{m}"
    );

    let o = voxflex(
        &[
            "roi",
            "phantom:abdomen",
            "--dims",
            "48,48,48",
            "--seed",
            "-95,-10,30",
            "--lambda",
            "auto",
            "--out",
            "l.nii.gz",
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("(auto)"),
        "{}",
        text(&o)
    );
    for (opt, val) in [
        ("--lambda", "soon"),
        ("--intensity", "200,100"),
        ("--max-distance-mm", "-3"),
    ] {
        let o = voxflex(
            &[
                "roi",
                "phantom:abdomen",
                "--dims",
                "24,24,24",
                "--seed",
                "-95,-10,30",
                opt,
                val,
                "--out",
                "x.nii.gz",
            ],
            tmp.path(),
        );
        assert!(!o.status.success(), "{opt} {val}: {}", text(&o));
        let key = opt.trim_start_matches("--").replace('-', "_");
        let err = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(err.contains(&key) || err.contains(opt), "{opt}: {err}");
    }
}

/// A legitimate large bend of a thin beam needs an output grid more than 8×
/// the source's voxels: refused by default with a message naming the scene
/// key `[resample] max_output_factor` and its value, accepted once the key
/// is raised; the interpolation key reaches the resampler (the two modes
/// give different volumes).
#[test]
fn a_large_bend_needs_the_max_output_factor_key() {
    use voxflex_core::glam::DVec3;
    use voxflex_core::grid::Grid;
    use voxflex_core::volume::{Volume, VoxelData};
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    // A 4 × 4 × 128 mm beam (1 mm voxels) with a ramp along it.
    let grid = Grid::new([4, 4, 128], DVec3::ONE, DVec3::ZERO);
    let values = (0..grid.len())
        .map(|l| {
            let [i, j, k] = grid.unlinear(l);
            (10 * k + 3 * i + j) as i16 + if (i + j + k) % 3 == 0 { 100 } else { 0 }
        })
        .collect();
    let beam = Volume::new(grid, VoxelData::I16(values)).unwrap();
    voxflex_io::write_volume(&tmp.path().join("beam.nii"), beam.view()).unwrap();
    let write = |name: &str, resample: &str| {
        let text = format!(
            r#"[scene]
backend = "cpu"

[volume]
source = "beam.nii"

[model]
plugin = "affine"
[model.params]
field = "bend"
axis = "z"
towards = "x"
angle_deg = 270

[resample]
background = -1000
{resample}

[output]
dir = "{name}"
slices = []
nifti = "deformed.nii"
"#
        );
        std::fs::write(tmp.path().join(format!("{name}.toml")), text).unwrap();
    };
    write("default", "");
    let o = voxflex(&["run", "default.toml"], tmp.path());
    assert!(
        !o.status.success(),
        "the bend fit the default limit\n{}",
        text(&o)
    );
    let msg = text(&o);
    assert!(
        msg.contains("`[resample] max_output_factor` = 8")
            && msg.contains("raise `[resample] max_output_factor`"),
        "{msg}"
    );

    write("raised", "max_output_factor = 40");
    let o = voxflex(&["run", "raised.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let m = metrics(&tmp.path().join("raised"));
    let dims: Vec<u64> = m["output_dims"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d.as_u64().unwrap())
        .collect();
    let voxels: u64 = dims.iter().product();
    assert!(
        voxels > 8 * grid.len() as u64,
        "output {dims:?} is within the default limit"
    );

    write(
        "tetrahedral",
        "max_output_factor = 40\ninterpolation = \"tetrahedral\"",
    );
    let o = voxflex(&["run", "tetrahedral.toml"], tmp.path());
    assert!(o.status.success(), "{}", text(&o));
    let read = |name: &str| {
        voxflex_io::read_volume(
            &tmp.path().join(name).join("deformed.nii"),
            &Default::default(),
        )
        .unwrap()
    };
    let (tri, tet) = (read("raised"), read("tetrahedral"));
    assert_eq!(tri.grid.dims, tet.grid.dims);
    let differ = (0..tri.grid.len())
        .filter(|&l| tri.data.as_slice().get_f32(l) != tet.data.as_slice().get_f32(l))
        .count();
    assert!(
        differ > 0,
        "interpolation = \"tetrahedral\" changed nothing"
    );

    write("bad", "max_output_factor = 0");
    let o = voxflex(&["validate", "bad.toml"], tmp.path());
    assert!(!o.status.success());
    assert!(
        text(&o).contains("bad.toml:17:1: `[resample] max_output_factor` = 0"),
        "{}",
        text(&o)
    );
}
