//! Quadratic tetrahedra (`element = "p2"`, issue 12) through the CLI and
//! the plugin's `.so`: a clamped cube phantom bent statically by a tip
//! traction with P1 and with P2 (P2 is less stiff in bending, so the two
//! resampled volumes differ and P2's notes count its Newton solve), the
//! same P2 scene on the GPU backend (lavapipe) giving the same volume, and
//! an unknown element refused naming the key.

use voxflex_integration_tests::{metrics, plugin_dir, text, voxflex};

fn scene(element: &str, backend: &str) -> String {
    format!(
        "[scene]\nname = \"p2\"\nbackend = \"{backend}\"\nframes = 1\n\
         [volume]\nsource = \"phantom:cube\"\ndims = [20, 20, 20]\n\
         [model]\nplugin = \"corotational-fem\"\n\
         [model.params]\nproxy = {{ kind = \"uniform\", step = 2 }}\n\
         materials = [{{ range = [50, 200], youngs_modulus = 3000 }}]\n\
         solver = \"static\"\nelement = \"{element}\"\n\
         [[interaction]]\nframe = 0\nkind = \"fix\"\nmin = [-40, -40, -40]\nmax = [-20, 40, 40]\n\
         [[interaction]]\nframe = 0\nkind = \"load\"\nmin = [20, -40, -40]\nmax = [40, 40, 40]\n\
         traction = [0, 0, -150]\n\
         [resample]\nbackground = 0\n\
         [output]\ndir = \"out\"\nnifti = \"deformed.nii.gz\"\n"
    )
}

fn run(dir: &std::path::Path, element: &str, backend: &str, out: &str) -> std::process::Output {
    std::fs::write(dir.join("s.toml"), scene(element, backend)).unwrap();
    voxflex(&["run", "s.toml", "--out", out, "--force"], dir)
}

#[test]
fn a_p2_scene_runs_through_the_cli_on_cpu_and_gpu_and_bends_unlike_p1() {
    plugin_dir(&["corotational-fem"]);
    let tmp = tempfile::tempdir().unwrap();
    let mut volumes = Vec::new();
    for element in ["p1", "p2"] {
        let o = run(tmp.path(), element, "cpu", element);
        assert!(o.status.success(), "{element}: {}", text(&o));
        let m = metrics(&tmp.path().join(element));
        let notes = &m["stages"]["model"]["notes"];
        assert!(notes["newton_iterations"].as_f64().unwrap() >= 1.0, "{m}");
        assert!(
            notes["newton_force_residual"].as_f64().unwrap() <= 1e-6,
            "{m}"
        );
        assert_eq!(notes["unconverged_solves"].as_f64(), Some(0.0), "{m}");
        volumes.push(std::fs::read(tmp.path().join(element).join("deformed.nii.gz")).unwrap());
    }
    assert_ne!(volumes[0], volumes[1], "P1 and P2 bend differently");

    if voxflex_runtime::gpu_context::testing::test_gpu().is_some() {
        let o = run(tmp.path(), "p2", "gpu", "g");
        assert!(o.status.success(), "{}", text(&o));
        let m = metrics(&tmp.path().join("g"));
        assert_eq!(m["backend"], "gpu", "{m}");
        let read = |d: &str| {
            voxflex_io::read_volume(
                &tmp.path().join(d).join("deformed.nii.gz"),
                &Default::default(),
            )
            .unwrap()
            .view()
            .data
            .to_f32_vec()
        };
        let (a, b) = (read("p2"), read("g"));
        let differ = a
            .iter()
            .zip(&b)
            .filter(|(x, y)| (*x - *y).abs() > 1.0)
            .count();
        assert!(
            differ * 1000 < a.len(),
            "{differ} of {} voxels differ",
            a.len()
        );
    }

    let o = run(tmp.path(), "p3", "cpu", "bad");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("`element` = \"p3\"") && err.contains("\"p2\""),
        "{}",
        text(&o)
    );
}
