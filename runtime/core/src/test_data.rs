//! Where the real test volumes live, for test suites of every crate.
//!
//! The folder (see its README) holds small real CT/MRI volumes. It is found
//! through the environment variable `VOXFLEX_TEST_DATA`, or else at
//! `shared/data` beside the repository (`<repo>/../shared/data`). The product
//! itself never needs it: demos run on built-in phantoms.

use std::path::PathBuf;

/// Environment variable that names the test-data folder.
pub const ENV_VAR: &str = "VOXFLEX_TEST_DATA";

/// The default folder: `<repository>/../shared/data`.
pub fn default_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"))
}

/// The test-data folder, if it exists.
///
/// When it does not: with `CI=true` in the environment this **panics** (a CI
/// run must not silently skip real-data tests); otherwise it prints a loud
/// `SKIPPED: …` line on stderr and returns `None`, so the caller returns:
///
/// ```no_run
/// let Some(dir) = voxflex_core::test_data::dir() else { return };
/// let _ct = dir.join("ct_skull_64.nii.gz");
/// ```
pub fn dir() -> Option<PathBuf> {
    let dir = std::env::var_os(ENV_VAR)
        .map(PathBuf::from)
        .unwrap_or_else(default_dir);
    if dir.is_dir() {
        return Some(dir);
    }
    let ci = std::env::var("CI").is_ok_and(|v| v.eq_ignore_ascii_case("true") || v == "1");
    if ci {
        panic!(
            "test data folder {} is missing and CI=true: set {ENV_VAR} to the folder holding \
             the real volumes (see shared/data/README.md)",
            dir.display()
        );
    }
    eprintln!(
        "SKIPPED: test data folder {} not found; set {ENV_VAR} to run the real-data tests",
        dir.display()
    );
    None
}
