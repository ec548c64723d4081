//! Which test validates each file under `shaders/`, and the check that
//! nothing there goes unvalidated.
//!
//! The unit is a subdirectory of `shaders/` (`shaders/resample/`, …): one
//! Rust module ships all its files and one test of that module builds a
//! [`ShaderSet`] for it, validates every source the module compiles and
//! calls [`ShaderSet::finish`], which fails when a file of the directory is
//! part of no validated source. [`SHADER_OWNERS`] names the owner of each
//! directory; the guard test of this crate (`tests/coverage.rs`) fails when
//! a directory with WGSL is missing from it or its owner has no such test.

use std::path::{Path, PathBuf};

use crate::shader::Shader;
use crate::validate::validate;

/// Each subdirectory of `shaders/` and the source directory (relative to
/// the repository root) of the Rust module that ships its shaders and
/// validates them with a [`ShaderSet`] of that name.
pub const SHADER_OWNERS: &[(&str, &str)] = &[
    ("resample", "runtime/resample/src"),
    ("opacity", "runtime/opacity/src"),
    ("fluid", "runtime/fluid/src"),
    ("barycentric", "runtime/mesh/src/barycentric"),
    ("mesh-model", "runtime/mesh/src/mesh_model"),
    ("affine", "plugins/affine/src"),
    ("raycast", "plugins/raycast/src"),
    ("chainmail", "plugins/chainmail/src"),
    ("mass-spring", "plugins/mass-spring/src"),
    ("template", "plugins/template/src"),
    ("viewer", "apps/viewer/src"),
];

/// The repository's `shaders/` directory.
pub fn shaders_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shaders")
}

/// Every `.wgsl` file under `dir` (recursively), as paths relative to
/// `dir` with `/` separators, sorted.
pub fn shader_files(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
        let entries =
            std::fs::read_dir(dir).unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        for entry in entries {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                walk(root, &path, out);
            } else if path.extension().is_some_and(|x| x == "wgsl") {
                let rel = path.strip_prefix(root).expect("under the root");
                let parts: Vec<_> = rel.iter().map(|p| p.to_string_lossy()).collect();
                out.push(parts.join("/"));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// The files of `shaders/<dir>/` (relative to `shaders/`) whose text is
/// part of none of `sources`.
pub fn uncovered_files<'a>(dir: &str, sources: impl IntoIterator<Item = &'a str>) -> Vec<String> {
    let sources: Vec<&str> = sources.into_iter().collect();
    let root = shaders_dir().join(dir);
    shader_files(&root)
        .into_iter()
        .filter(|f| {
            let path = root.join(f);
            let text = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
            let text = text.trim();
            !sources.iter().any(|s| s.contains(text))
        })
        .map(|f| format!("{dir}/{f}"))
        .collect()
}

/// The shaders one module's test validated, for the check that they cover
/// every file of the module's `shaders/` subdirectory.
#[derive(Debug)]
pub struct ShaderSet {
    dir: &'static str,
    shaders: Vec<Shader>,
}

impl ShaderSet {
    /// An empty set for the files of `shaders/<dir>/`; `dir` must be listed
    /// in [`SHADER_OWNERS`].
    #[track_caller]
    pub fn new(dir: &'static str) -> Self {
        assert!(
            SHADER_OWNERS.iter().any(|(d, _)| *d == dir),
            "shaders/{dir}/ is not listed in voxflex_wgsl_check::SHADER_OWNERS"
        );
        Self {
            dir,
            shaders: Vec::new(),
        }
    }

    /// Validates one full source as the module compiles it (see
    /// [`crate::validate`]; panics with naga's diagnostic) and keeps it.
    #[track_caller]
    pub fn validate(&mut self, name: &str, source: &str) -> &Shader {
        let shader = validate(name, source);
        self.shaders.push(shader);
        self.shaders.last().expect("just pushed")
    }

    /// Panics listing the files of `shaders/<dir>/` that no validated
    /// source contains, and when nothing was validated.
    #[track_caller]
    pub fn finish(self) {
        assert!(
            !self.shaders.is_empty(),
            "the ShaderSet for shaders/{}/ validated nothing",
            self.dir
        );
        let missing = uncovered_files(self.dir, self.shaders.iter().map(|s| s.source()));
        assert!(
            missing.is_empty(),
            "these shaders are part of no source this test validated: {missing:?}; validate \
             every source the module compiles (through the function that assembles it)"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_left_out_of_every_source_is_reported() {
        let dir = shaders_dir().join("resample");
        let common = std::fs::read_to_string(dir.join("common.wgsl")).unwrap();
        let clear = std::fs::read_to_string(dir.join("clear.wgsl")).unwrap();
        let sources = [format!("{common}\n{clear}")];
        let missing = uncovered_files("resample", sources.iter().map(String::as_str));
        assert!(
            missing.contains(&"resample/raster.wgsl".to_owned()),
            "{missing:?}"
        );
        assert!(!missing.contains(&"resample/common.wgsl".to_owned()));
        assert!(!missing.contains(&"resample/clear.wgsl".to_owned()));
    }

    #[test]
    #[should_panic(expected = "part of no source this test validated")]
    fn finish_fails_when_a_file_is_not_validated() {
        let mut set = ShaderSet::new("raycast");
        set.validate("noop", "@compute @workgroup_size(1) fn main() {}");
        set.finish();
    }

    #[test]
    #[should_panic(expected = "not listed in voxflex_wgsl_check::SHADER_OWNERS")]
    fn unknown_directories_are_refused() {
        ShaderSet::new("no-such-dir");
    }
}
