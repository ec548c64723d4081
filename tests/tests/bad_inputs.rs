//! Bad input through the real CLI: `validate` refuses what `run` refuses,
//! with the same message; non-finite voxels never reach an output; every
//! model treats a far grab and a carve of everything alike.

use std::path::Path;
use voxflex_integration_tests::{metrics, plugin_dir, repo_root, scene, text, voxflex};

/// The `error: …` line of a failed command, without `error: `.
fn error_line(o: &std::process::Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr);
    err.lines()
        .rev()
        .find_map(|l| l.strip_prefix("error: "))
        .unwrap_or_else(|| panic!("no `error:` line\n{}", text(o)))
        .to_owned()
}

const CHAINMAIL: &str = "materials = [{ range = [50, 200], constraint = 0.3 }]";
const FEM: &str = "proxy = { kind = \"uniform\", step = 2 }\nsolver = \"static\"\nmaterials = [{ range = [50, 200], youngs_modulus = 3000, poisson_ratio = 0.3 }]";
const SPRINGS: &str = "proxy = { kind = \"uniform\", step = 2 }\nintegrator = \"implicit\"\nmaterials = [{ range = [50, 200], youngs_modulus = 3000 }]";

/// A 12³ cube scene with `plugin` and `params`, then `extra` appended.
fn cube(plugin: &str, params: &str, extra: &str, out: &Path) -> String {
    format!(
        "{}\n{extra}\n",
        scene("cpu", "cube", 12, 2, plugin, params, out)
    )
}

/// Writes the scene `name.toml` in `dir`.
fn write(dir: &Path, name: &str, text: &str) -> String {
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, text).unwrap();
    file.to_str().unwrap().to_owned()
}

/// A 6×5×4 f32 NIfTI with a NaN, a +∞ and a −∞ voxel among values 0…119.
fn non_finite_nifti(path: &Path) {
    use voxflex_core::glam::DVec3;
    use voxflex_core::volume::{Volume, VoxelData};
    let mut values: Vec<f32> = (0..120).map(|v| v as f32).collect();
    values[7] = f32::NAN;
    values[50] = f32::INFINITY;
    values[90] = f32::NEG_INFINITY;
    let g = voxflex_core::grid::Grid::new([6, 5, 4], DVec3::ONE, DVec3::ZERO);
    let v = Volume::new(g, VoxelData::F32(values)).unwrap();
    voxflex_io::nifti::write_nifti(path, v.view()).unwrap();
}

/// Table-driven: for each bad scene, `run` fails, and `validate` fails
/// first with the same message (`validate` may put the scene location in
/// front), and names the reason the case is about.
#[test]
fn validate_gives_every_error_run_gives() {
    plugin_dir(&[
        "affine",
        "chainmail",
        "corotational-fem",
        "mass-spring",
        "raycast",
    ]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    non_finite_nifti(&dir.join("nan.nii"));
    let out = dir.join("out");
    let twist = "field = \"twist\"\nangle_deg = 10";
    let render =
        |params: &str| format!("[render]\nwidth = 16\nheight = 16\n[render.params]\n{params}");
    let interaction = |body: &str| format!("[[interaction]]\nframe = 1\n{body}");
    let no_model = |extra: &str| {
        format!(
            "[scene]\nbackend = \"cpu\"\n[volume]\nsource = \"phantom:cube\"\ndims = [12, 12, 12]\n\
             [output]\ndir = \"{}\"\n{extra}\n",
            out.display()
        )
    };
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "affine param typo",
            cube("affine", "field = \"twist\"\nangel_deg = 10", "", &out),
            "angel_deg",
        ),
        (
            "chainmail param typo",
            cube(
                "chainmail",
                &format!("{CHAINMAIL}\nover_relaxtion = 1"),
                "",
                &out,
            ),
            "over_relaxtion",
        ),
        (
            "poisson ratio 0.6",
            cube(
                "corotational-fem",
                &FEM.replace("poisson_ratio = 0.3", "poisson_ratio = 0.6"),
                "",
                &out,
            ),
            "poisson_ratio` = 0.6",
        ),
        (
            "negative Young's modulus",
            cube(
                "mass-spring",
                &SPRINGS.replace("youngs_modulus = 3000", "youngs_modulus = -5"),
                "",
                &out,
            ),
            "youngs_modulus` = -5",
        ),
        (
            "render param typo",
            cube(
                "affine",
                twist,
                &render("shadng = { enabled = true }"),
                &out,
            ),
            "shadng",
        ),
        (
            "transfer function shift beyond f32",
            cube(
                "affine",
                twist,
                &render("transfer_function = { preset = \"ct-bone\", shift = 1e39 }"),
                &out,
            ),
            "transfer_function.shift",
        ),
        (
            "unknown render plugin",
            cube(
                "affine",
                twist,
                "[render]\nplugin = \"no-such-renderer\"",
                &out,
            ),
            "no-such-renderer",
        ),
        (
            "interaction typo",
            cube(
                "chainmail",
                CHAINMAIL,
                &interaction("kind = \"grab\"\npont = [0, 0, 0]\nby = [1, 0, 0]"),
                &out,
            ),
            "pont",
        ),
        (
            "unknown interaction kind",
            cube(
                "chainmail",
                CHAINMAIL,
                &interaction("kind = \"poke\""),
                &out,
            ),
            "poke",
        ),
        (
            "collinear cut polygon",
            cube(
                "chainmail",
                CHAINMAIL,
                &interaction("kind = \"cut\"\npolygon = [[0, 0, 0], [1, 1, 1], [3, 3, 3]]"),
                &out,
            ),
            "spans no area",
        ),
        (
            "unknown phantom",
            cube("affine", twist, "", &out).replace("phantom:cube", "phantom:skull"),
            "unknown phantom `skull`",
        ),
        (
            "roi seed outside the volume",
            no_model("[[roi]]\nseed = [500.0, 0.0, 0.0]"),
            "outside the volume",
        ),
        (
            "roi seed outside its intensity window",
            no_model("[[roi]]\nseed = [0.0, 0.0, 0.0]\nintensity = [-50, -10]"),
            "window",
        ),
        (
            "refused non-finite voxels",
            format!(
                "[scene]\nbackend = \"cpu\"\n[volume]\nsource = \"nan.nii\"\nnon_finite = \"refuse\"\n\
                 [output]\ndir = \"{}\"\n",
                out.display()
            ),
            "1 NaN, 1 +inf and 1 -inf",
        ),
    ];
    for (n, (what, text_of_scene, needle)) in cases.iter().enumerate() {
        let file = write(dir, &format!("bad{n}"), text_of_scene);
        let v = voxflex(&["validate", &file], dir);
        assert_eq!(v.status.code(), Some(1), "{what}: validate\n{}", text(&v));
        let r = voxflex(&["run", &file], dir);
        assert_eq!(r.status.code(), Some(1), "{what}: run\n{}", text(&r));
        let (v_err, r_err) = (error_line(&v), error_line(&r));
        assert!(
            v_err.ends_with(&r_err),
            "{what}: validate and run disagree\n  validate: {v_err}\n  run:      {r_err}"
        );
        assert!(v_err.contains(needle), "{what}: `{needle}` not in {v_err}");
        assert!(
            v_err.starts_with(&file),
            "{what}: the message names the scene file: {v_err}"
        );
    }
}

#[test]
fn validate_accepts_every_shipped_config() {
    plugin_dir(&["affine", "chainmail", "raycast"]);
    let root = repo_root();
    let mut seen = 0;
    for entry in std::fs::read_dir(root.join("configs")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let o = voxflex(&["validate", path.to_str().unwrap()], &root);
            assert!(o.status.success(), "{}: {}", path.display(), text(&o));
            seen += 1;
        }
    }
    assert!(seen >= 2, "configs/*.toml found: {seen}");
}

/// A source with NaN and ±∞ voxels: replaced with a warning by default
/// (the outputs are finite and the default window is the finite range),
/// refused with the counts on request.
#[test]
fn non_finite_source_voxels_are_replaced_with_a_warning_or_refused() {
    plugin_dir(&["affine"]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    non_finite_nifti(&dir.join("nan.nii"));
    for model in [
        "",
        "[model]\nplugin = \"affine\"\n[model.params]\nfield = \"twist\"\nangle_deg = 5\n[resample]\nbackground = -7\n",
    ] {
        let out = dir.join(if model.is_empty() { "plain" } else { "model" });
        let file = write(
            dir,
            "replace",
            &format!(
                "[scene]\nbackend = \"cpu\"\n[volume]\nsource = \"nan.nii\"\n{model}\
                 [output]\ndir = \"{}\"\nnifti = \"out.nii\"\n",
                out.display()
            ),
        );
        let o = voxflex(&["run", &file], dir);
        assert!(o.status.success(), "{}", text(&o));
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(
            stderr.contains("1 NaN, 1 +inf and 1 -inf voxels replaced"),
            "{}",
            text(&o)
        );
        let m = metrics(&out);
        let warnings = m["warnings"].to_string();
        assert!(warnings.contains("1 NaN, 1 +inf and 1 -inf"), "{warnings}");
        // Read the raw file back without the policy's help: every voxel
        // finite, within the source's finite range (or the background).
        let written = voxflex_io::nifti::read_nifti(
            &out.join("out.nii"),
            &voxflex_io::ReadOptions::default(),
        )
        .unwrap();
        let values = written.data.as_slice().to_f32_vec();
        assert!(
            values.iter().all(|v| v.is_finite()),
            "a non-finite voxel was written"
        );
        let lo = if model.is_empty() { 0.0 } else { -7.0 };
        assert!(
            values.iter().all(|&v| (lo..=119.0).contains(&v)),
            "values outside [{lo}, 119]"
        );
    }
    let file = write(
        dir,
        "refuse",
        &format!(
            "[scene]\nbackend = \"cpu\"\n[volume]\nsource = \"nan.nii\"\nnon_finite = \"refuse\"\n\
             [output]\ndir = \"{}\"\n",
            dir.join("refused").display()
        ),
    );
    let o = voxflex(&["run", &file], dir);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let e = error_line(&o);
    assert!(e.contains("nan.nii") && e.contains("non_finite"), "{e}");
    // `info` reads with the default policy: finite statistics.
    let o = voxflex(&["info", "nan.nii"], dir);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("119"),
        "{}",
        text(&o)
    );
}

/// A grab 500 mm outside a 12³ cube: every model with grabs warns with the
/// distance and counts it in its notes (metrics.json).
#[test]
fn a_far_grab_warns_and_reaches_metrics_in_every_model() {
    let models = [
        ("chainmail", CHAINMAIL),
        ("corotational-fem", FEM),
        ("mass-spring", SPRINGS),
    ];
    plugin_dir(&["chainmail", "corotational-fem", "mass-spring"]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    for (plugin, params) in models {
        for (name, point, far) in [("far", 500.0, true), ("near", 20.0, false)] {
            let out = dir.join(format!("{plugin}-{name}"));
            let grab = format!(
                "[[interaction]]\nframe = 0\nkind = \"fix\"\nmin = [-6, -6, -6]\nmax = [6, 6, 6]\n\
                 [[interaction]]\nframe = 0\nkind = \"grab\"\npoint = [{point:?}, 0.0, 0.0]\nby = [1.0, 0.0, 0.0]"
            );
            let file = write(
                dir,
                &format!("{plugin}-{name}"),
                &cube(plugin, params, &grab, &out),
            );
            let o = voxflex(&["run", &file], dir);
            assert!(o.status.success(), "{plugin} {name}: {}", text(&o));
            let m = metrics(&out);
            let notes = &m["stages"]["model"]["notes"];
            if far {
                assert_eq!(notes["grabs_far_from_body"], 1.0, "{plugin}: {notes}");
                let d = notes["grab_far_max_mm"].as_f64().unwrap();
                assert!(d > 400.0 && d < 500.0, "{plugin}: distance {d}");
                assert!(
                    m["warnings"].to_string().contains("from the body"),
                    "{plugin}: {}",
                    m["warnings"]
                );
            } else {
                assert!(
                    notes.get("grabs_far_from_body").is_none(),
                    "{plugin}: {notes}"
                );
            }
        }
    }
}

/// A carve of the whole body: refused by every model, naming the carve.
#[test]
fn carving_everything_is_refused_by_every_model() {
    plugin_dir(&["chainmail", "corotational-fem", "mass-spring"]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let carve = "[[interaction]]\nframe = 0\nkind = \"carve\"\nmin = [-500, -500, -500]\nmax = [500, 500, 500]";
    for (plugin, params) in [
        ("chainmail", CHAINMAIL),
        ("corotational-fem", FEM),
        ("mass-spring", SPRINGS),
    ] {
        let out = dir.join(plugin);
        let file = write(dir, plugin, &cube(plugin, params, carve, &out));
        let o = voxflex(&["run", &file], dir);
        assert_eq!(o.status.code(), Some(1), "{plugin}: {}", text(&o));
        let e = error_line(&o);
        assert!(
            e.contains("carve") && e.contains("carve a smaller region"),
            "{plugin}: {e}"
        );
    }
}
