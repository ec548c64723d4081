//! The coverage guard: every WGSL file under `shaders/` belongs to a
//! directory listed in `SHADER_OWNERS`, and each listed owner has a test
//! that validates that directory with a `ShaderSet` and calls `finish()`
//! (which fails for any file of the directory it did not validate).

use std::path::Path;

use voxflex_wgsl_check::{SHADER_OWNERS, shader_files, shaders_dir};

fn repo_root() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|x| x == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn every_shader_directory_has_an_owner() {
    let files = shader_files(&shaders_dir());
    assert!(
        !files.is_empty(),
        "no WGSL under {}",
        shaders_dir().display()
    );
    let unowned: Vec<&String> = files
        .iter()
        .filter(|f| {
            let dir = f.split('/').next().unwrap_or("");
            !f.contains('/') || !SHADER_OWNERS.iter().any(|(d, _)| *d == dir)
        })
        .collect();
    assert!(
        unowned.is_empty(),
        "WGSL files no test validates: {unowned:?}. Put each shader in a subdirectory of \
         shaders/ listed in voxflex_wgsl_check::SHADER_OWNERS, and validate it in the owning \
         module's shader test (ShaderSet::new(\"<dir>\") … finish())"
    );
}

#[test]
fn every_owner_validates_its_directory() {
    for (dir, owner) in SHADER_OWNERS {
        let shaders = shaders_dir().join(dir);
        assert!(
            !shader_files(&shaders).is_empty(),
            "SHADER_OWNERS lists shaders/{dir}/, which holds no WGSL; remove the entry"
        );
        let src = repo_root().join(owner);
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        let call = format!("ShaderSet::new(\"{dir}\")");
        let tested = files.iter().any(|f| {
            let text = std::fs::read_to_string(f).unwrap();
            text.contains(&call) && text.contains(".finish()")
        });
        assert!(
            tested,
            "no Rust file under {owner} builds {call} and calls finish(); the owner of \
             shaders/{dir}/ must validate it (see voxflex_wgsl_check::SHADER_OWNERS)"
        );
    }
}
