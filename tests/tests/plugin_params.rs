//! The parameter schema every plugin declares through the ABI, through the
//! CLI and the built `.so` plugins: `voxflex plugins --params NAME` prints
//! each key with its type, unit, range and default; `voxflex validate`
//! reports every problem of a parameter table at once, against it.

use std::path::Path;
use voxflex_integration_tests::{scene, text, voxflex};

fn params_of(name: &str) -> String {
    let o = voxflex(&["plugins", "--params", name], Path::new("."));
    assert!(o.status.success(), "{}", text(&o));
    String::from_utf8(o.stdout).unwrap()
}

/// The row of `key` (trimmed of its indentation) in a printed table.
fn row<'a>(table: &'a str, key: &str) -> &'a str {
    table
        .lines()
        .find(|l| l.split_whitespace().next() == Some(key))
        .unwrap_or_else(|| panic!("no `{key}` row in:\n{table}"))
}

#[test]
fn every_shipped_plugin_prints_its_keys_with_types_units_ranges_and_defaults() {
    let fem = params_of("corotational-fem");
    assert!(fem.contains("[model.params]"), "{fem}");
    let e = row(&fem, "youngs_modulus");
    assert!(
        e.contains("number") && e.contains("Pa") && e.contains("required"),
        "{e}"
    );
    let element = row(&fem, "element");
    assert!(
        element.contains("\"p1\" | \"p2\"") && element.contains("\"p1\""),
        "{element}"
    );
    assert!(row(&fem, "static_tolerance").contains("0 ..= 1"), "{fem}");
    let chainmail = params_of("chainmail");
    assert!(
        row(&chainmail, "constraint").contains("number | [number; 3]"),
        "{chainmail}"
    );
    assert!(
        row(&chainmail, "downsample").contains("1 ..= 64"),
        "{chainmail}"
    );
    let springs = params_of("mass-spring");
    assert!(
        row(&springs, "integrator").contains("\"implicit\""),
        "{springs}"
    );
    let raycast = params_of("raycast");
    assert!(raycast.contains("[render.params]"), "{raycast}");
    assert!(
        row(&raycast, "sample_distance").contains("voxels"),
        "{raycast}"
    );
    for name in ["affine", "template"] {
        let t = params_of(name);
        assert!(row(&t, "ramp_frames").contains(">= 1"), "{name}: {t}");
    }
}

#[test]
fn an_unknown_plugin_is_one_clear_error() {
    let o = voxflex(&["plugins", "--params", "no-such-model"], Path::new("."));
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("no-such-model"), "{err}");
}

#[test]
fn validate_reports_every_problem_of_a_parameter_table_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let params = "materials = [{ range = [50, 200], youngs_modulus = -3000 }]\n\
                  element = \"p3\"\nstatic_tolerence = 1e-6\nsubsteps = 0\n\
                  proxy = { kind = \"uniform\", step = 0 }";
    let file = dir.path().join("s.toml");
    std::fs::write(
        &file,
        scene(
            "cpu",
            "cube",
            12,
            1,
            "corotational-fem",
            params,
            &dir.path().join("out"),
        ),
    )
    .unwrap();
    let o = voxflex(&["validate", file.to_str().unwrap()], dir.path());
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    for needle in [
        "s.toml:",
        "plugin `corotational-fem` parameters",
        "`materials[0].youngs_modulus` = -3000 Pa is below its minimum 0 Pa",
        "`element` = \"p3\" is not one of \"p1\" | \"p2\"",
        "unknown key `static_tolerence`: did you mean `static_tolerance`?",
        "`substeps` = 0 is below its minimum 1",
        "`proxy.step` = 0 voxels is below its minimum 1 voxels",
        "voxflex plugins --params corotational-fem",
    ] {
        assert!(err.contains(needle), "missing {needle:?} in:\n{err}");
    }
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error")).count(),
        1,
        "one error: {err}"
    );
}
