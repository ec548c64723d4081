//! Shared helpers of the integration tests: where the built binary and
//! plugin libraries are, and how to run the CLI.
//!
//! The tests drive what users run: `target/<profile>/voxflex` and the
//! `target/<profile>/libvoxflex_*.so` plugins. `cargo test` does not build
//! `cdylib` crates nothing depends on, so build the workspace first
//! (`scripts/test.sh` does: `cargo build --workspace` then `cargo test`).

#![warn(missing_docs)]

mod field_parity;
pub use field_parity::{FieldParity, assert_field_parity, field_parity, field_plugin_on_gpu};

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository root.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// `target/<profile>`: the directory holding this test binary's `deps/`.
pub fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let deps = exe.parent().expect("deps dir");
    deps.parent().expect("profile dir").to_path_buf()
}

/// The built `voxflex` binary.
pub fn voxflex_bin() -> PathBuf {
    let p = target_dir().join(format!("voxflex{}", std::env::consts::EXE_SUFFIX));
    assert!(
        p.is_file(),
        "{} is missing: build the workspace first (`cargo build --workspace`, or scripts/test.sh)",
        p.display()
    );
    p
}

/// The test-only plugins (`tests/fixtures/*-plugin`).
pub const FIXTURES: [&str; 2] = ["ripple", "mismatched"];

/// `target/<profile>/test-plugins`: the test fixtures under their plugin
/// file names. Cargo builds a fixture as `libfixture_voxflex_<name>.so`,
/// which the plugin search never matches, so `voxflex plugins` run from
/// `target/<profile>/` never lists one; the tests put this directory on
/// `VOXFLEX_PLUGIN_PATH`.
pub fn fixture_dir() -> PathBuf {
    target_dir().join("test-plugins")
}

/// Copies the built fixture `name` into [`fixture_dir`] under its plugin
/// file name (atomically: concurrent tests may load it meanwhile).
fn stage_fixture(name: &str) -> PathBuf {
    let built = target_dir().join(format!(
        "{}fixture_voxflex_{}{}",
        std::env::consts::DLL_PREFIX,
        name.replace('-', "_"),
        std::env::consts::DLL_SUFFIX
    ));
    assert!(
        built.is_file(),
        "{} is missing: build the test fixtures first (`cargo build --workspace`, or \
         scripts/test.sh)",
        built.display()
    );
    // A build from before the fixtures were renamed left them where the
    // plugin search finds them; such a stale copy must not be listed or win.
    let _ = std::fs::remove_file(
        target_dir().join(voxflex_runtime::plugin_loader::library_file_name(name)),
    );
    let dir = fixture_dir();
    std::fs::create_dir_all(&dir).expect("create target/<profile>/test-plugins");
    let staged = dir.join(voxflex_runtime::plugin_loader::library_file_name(name));
    let same = |a: &Path, b: &Path| std::fs::read(a).ok() == std::fs::read(b).ok();
    if !staged.is_file() || !same(&built, &staged) {
        let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
        std::fs::copy(&built, &tmp).expect("copy a fixture");
        std::fs::rename(&tmp, &staged).expect("stage a fixture");
    }
    dir
}

/// The directory of the built plugins, checking that `names` are there
/// (test fixtures among `names` are staged into [`fixture_dir`]).
pub fn plugin_dir(names: &[&str]) -> PathBuf {
    let dir = target_dir();
    for n in names {
        if FIXTURES.contains(n) {
            stage_fixture(n);
            continue;
        }
        let f = dir.join(voxflex_runtime::plugin_loader::library_file_name(n));
        assert!(
            f.is_file(),
            "{} is missing: build the plugins first (`cargo build --workspace`, or scripts/test.sh)",
            f.display()
        );
    }
    dir
}

/// The directory holding the staged test fixtures `names`.
pub fn fixture_plugin_dir(names: &[&str]) -> PathBuf {
    for n in names {
        stage_fixture(n);
    }
    fixture_dir()
}

/// `VOXFLEX_PLUGIN_PATH` of the tests: the staged fixtures, then the built
/// plugins.
pub fn test_plugin_path() -> std::ffi::OsString {
    std::env::join_paths([fixture_dir(), target_dir()]).expect("plugin path")
}

/// Runs `voxflex args…` in `cwd` with the built plugins and the test
/// fixtures on the search path.
pub fn voxflex(args: &[&str], cwd: &Path) -> Output {
    Command::new(voxflex_bin())
        .args(args)
        .current_dir(cwd)
        .env("VOXFLEX_PLUGIN_PATH", test_plugin_path())
        .env_remove("RUST_LOG")
        .output()
        .expect("run voxflex")
}

/// The stdout of a finished command, as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// stdout + stderr of a finished command, for assertion messages.
pub fn text(o: &Output) -> String {
    format!(
        "status {:?}\n--- stdout\n{}\n--- stderr\n{}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Reads `metrics.json` from a run's output directory.
pub fn metrics(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("metrics.json")).expect("metrics.json written");
    serde_json::from_str(&text).expect("metrics.json is JSON")
}

/// A small scene on `phantom:<phantom>` with `plugin` and its params table body.
pub fn scene(
    backend: &str,
    phantom: &str,
    dims: usize,
    frames: u64,
    plugin: &str,
    params: &str,
    out: &Path,
) -> String {
    format!(
        r#"[scene]
name = "test"
backend = "{backend}"
frames = {frames}

[volume]
source = "phantom:{phantom}"
dims = [{dims}, {dims}, {dims}]

[model]
plugin = "{plugin}"

[model.params]
{params}

[output]
dir = "{}"
nifti = "deformed.nii.gz"
"#,
        out.display()
    )
}

/// Runs a GPU-vs-CPU parity check (from a `parity` module of voxflex-core)
/// on the shared test device; prints SKIPPED without an adapter, except
/// under `CI=true`, where a missing adapter fails.
pub fn run_parity(check: fn(&dyn voxflex_core::gpu::GpuService) -> Result<(), String>) {
    let Some(gpu) = voxflex_runtime::gpu_context::testing::test_gpu() else {
        return;
    };
    if let Err(e) = check(gpu.as_ref()) {
        panic!(
            "{} on {}",
            e,
            voxflex_core::gpu::GpuService::adapter_description(gpu.as_ref())
        );
    }
}

/// The value of the run's f32 output volume `o/deformed.nii.gz` (in `dir`)
/// at the voxel nearest each world point (mm).
pub fn output_values(dir: &Path, points: &[[f64; 3]]) -> Vec<f32> {
    let v = voxflex_io::read_volume(&dir.join("o/deformed.nii.gz"), &Default::default())
        .expect("the run's output volume");
    let voxflex_core::volume::VoxelSlice::F32(s) = v.data.as_slice() else {
        panic!("unexpected output type {:?}", v.scalar_type());
    };
    points
        .iter()
        .map(|&p| {
            let i = v
                .grid
                .world_to_index(voxflex_core::glam::DVec3::from_array(p))
                .round();
            s[v.grid.linear(i.x as usize, i.y as usize, i.z as usize)]
        })
        .collect()
}

/// A session on `volume` with the built plugins `plugins` on its search
/// path, computing on `backend` — on `gpu` when given (a device such as
/// the viewer's, or a test view of one with a smaller binding limit).
pub fn session_on(
    volume: voxflex_core::volume::Volume,
    backend: voxflex_runtime::backend::BackendChoice,
    gpu: Option<std::sync::Arc<voxflex_runtime::gpu_context::WgpuService>>,
    plugins: &[&str],
) -> voxflex_runtime::session::Session {
    let defaults = voxflex_runtime::session::SessionDefaults {
        backend,
        plugin_dirs: vec![plugin_dir(plugins)],
        gpu,
        ..Default::default()
    };
    voxflex_runtime::session::Session::from_volume(volume, defaults).expect("a session")
}

/// A linear function of LPS position (mm): what an oblique file's voxels
/// hold in the oblique-header tests, reproduced exactly by trilinear
/// interpolation wherever it is resampled.
pub fn oblique_ramp(p: [f64; 3]) -> f64 {
    p[0] + 2.0 * p[1] + 3.0 * p[2] + 50.0
}

/// A 6 × 5 × 4 float NRRD whose i and j axes are turned by 30° about z
/// (1 mm voxels, origin (10, 20, 30) mm, LPS), holding [`oblique_ramp`].
pub fn write_oblique_nrrd(dir: &std::path::Path) {
    let (s, c) = 30f64.to_radians().sin_cos();
    let mut values = Vec::new();
    for k in 0..4 {
        for j in 0..5 {
            for i in 0..6 {
                let (i, j, k) = (i as f64, j as f64, k as f64);
                let p = [10.0 + c * i - s * j, 20.0 + s * i + c * j, 30.0 + k];
                values.push(format!("{}", oblique_ramp(p) as f32));
            }
        }
    }
    let nrrd = format!(
        "NRRD0004\ntype: float\ndimension: 3\nspace: left-posterior-superior\n\
         sizes: 6 5 4\nspace directions: ({c},{s},0) ({},{c},0) (0,0,1)\n\
         space origin: (10,20,30)\nencoding: ascii\n\n{}\n",
        -s,
        values.join(" ")
    );
    std::fs::write(dir.join("oblique.nrrd"), nrrd).unwrap();
}
