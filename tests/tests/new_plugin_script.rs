//! `scripts/new-plugin.sh NAME` (docs/PLUGINS.md's copy-and-rename recipe)
//! run on a scratch copy of the files it touches: the new crate, library,
//! plugin, types, shader folder and test carry the new name, nothing of the
//! template's names is left in them, the workspace lists the crate, and bad
//! or taken names are refused. Cheap: nothing is compiled (CI builds the
//! template itself, a workspace member, and its test loads it).

use std::path::Path;
use std::process::Command;
use voxflex_integration_tests::{repo_root, text};

/// Copies what the script reads into a scratch checkout.
fn scratch_checkout() -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let root = repo_root();
    let copy_tree = |rel: &str| {
        for entry in walk(&root.join(rel)) {
            let to = tmp.path().join(entry.strip_prefix(&root).unwrap());
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::copy(&entry, &to).unwrap();
        }
    };
    for rel in [
        "plugins/template",
        "shaders/template",
        "tests/tests/template_plugin.rs",
        "scripts/new-plugin.sh",
        "Cargo.toml",
        "runtime/wgsl-check/src/coverage.rs",
    ] {
        copy_tree(rel);
    }
    tmp
}

/// Every file under `p` (or `p` itself), skipping build output.
fn walk(p: &Path) -> Vec<std::path::PathBuf> {
    if p.is_file() {
        return vec![p.to_path_buf()];
    }
    let mut out = vec![];
    for e in std::fs::read_dir(p).unwrap() {
        let e = e.unwrap().path();
        if e.file_name().is_some_and(|n| n == "target") {
            continue;
        }
        out.extend(walk(&e));
    }
    out
}

fn new_plugin(root: &Path, name: &str) -> std::process::Output {
    Command::new("bash")
        .arg(root.join("scripts/new-plugin.sh"))
        .arg(name)
        .output()
        .expect("run bash")
}

fn read(root: &Path, rel: &str) -> String {
    std::fs::read_to_string(root.join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

#[test]
fn new_plugin_script_copies_the_template_under_the_new_names() {
    let tmp = scratch_checkout();
    let root = tmp.path();
    let o = new_plugin(root, "soft-ball");
    assert!(o.status.success(), "{}", text(&o));

    let manifest = read(root, "plugins/soft-ball/Cargo.toml");
    assert!(
        manifest.contains("name = \"voxflex-soft-ball\""),
        "{manifest}"
    );
    // The library cargo builds from that crate name is the file the host's
    // plugin search looks for when a scene says plugin = "soft-ball".
    assert_eq!(
        format!(
            "{}voxflex_soft_ball{}",
            std::env::consts::DLL_PREFIX,
            std::env::consts::DLL_SUFFIX
        ),
        voxflex_runtime::plugin_loader::library_file_name("soft-ball")
    );
    let lib = read(root, "plugins/soft-ball/src/lib.rs");
    assert!(
        lib.contains("const NAME: &'static str = \"soft-ball\";"),
        "{lib}"
    );
    assert!(
        lib.contains("impl DeformationPlugin for SoftBallField"),
        "{lib}"
    );
    assert!(
        lib.contains("export_deformation_plugin!(SoftBallField)"),
        "{lib}"
    );
    let model = read(root, "plugins/soft-ball/src/model.rs");
    assert!(
        model.contains("include_str!(\"../../../shaders/soft-ball/bulge.wgsl\")"),
        "the shader path was not renamed"
    );
    assert!(root.join("shaders/soft-ball/bulge.wgsl").is_file());
    let test = read(root, "tests/tests/soft_ball_plugin.rs");
    assert!(
        test.contains("const PLUGIN: &str = \"soft-ball\";"),
        "{test}"
    );
    assert!(test.contains("fn soft_ball_plugin_wgsl_field_matches_its_rayon_field"));

    // No name of the template is left in the copy (prose may still say
    // where it came from).
    let mut files = walk(&root.join("plugins/soft-ball"));
    files.extend(walk(&root.join("shaders/soft-ball")));
    files.push(root.join("tests/tests/soft_ball_plugin.rs"));
    for f in &files {
        let s = std::fs::read_to_string(f).unwrap();
        for old in [
            "voxflex-template",
            "voxflex_template",
            "\"template\"",
            "Template",
            "plugins/template",
            "shaders/template",
        ] {
            assert!(!s.contains(old), "{} still says {old}", f.display());
        }
    }

    // The workspace builds and lists it (members and default-members).
    let cargo = read(root, "Cargo.toml");
    assert_eq!(
        cargo.matches("\"plugins/soft-ball\",").count(),
        2,
        "{cargo}"
    );
    assert_eq!(cargo.matches("\"plugins/template\",").count(), 2, "{cargo}");
    // Its shader folder has an owner for the naga coverage guard.
    let owners = read(root, "runtime/wgsl-check/src/coverage.rs");
    assert!(
        owners.contains("(\"soft-ball\", \"plugins/soft-ball/src\"),"),
        "{owners}"
    );
    // The template itself is untouched.
    assert_eq!(
        read(root, "plugins/template/src/lib.rs"),
        read(&repo_root(), "plugins/template/src/lib.rs")
    );

    // The same name again is refused, and nothing is overwritten.
    let o = new_plugin(root, "soft-ball");
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("already exists"));
}

#[test]
fn new_plugin_script_refuses_bad_names() {
    let tmp = scratch_checkout();
    let root = tmp.path();
    for bad in [
        "Soft",
        "soft_ball",
        "-soft",
        "soft--ball",
        "../x",
        "9lives",
        "template",
    ] {
        let o = new_plugin(root, bad);
        assert_eq!(o.status.code(), Some(1), "{bad}: {}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.starts_with("error: "), "{bad}: {err}");
    }
    let o = new_plugin(root, "");
    assert_ne!(o.status.code(), Some(0), "{}", text(&o));
    // Nothing was created.
    let plugins: Vec<_> = std::fs::read_dir(root.join("plugins")).unwrap().collect();
    assert_eq!(plugins.len(), 1);
}
