//! What the viewer's headless UI tests share: the built plugins, a viewer
//! on the built-in phantom, and waiting for the worker.

#![allow(dead_code)] // each test binary uses its own subset

use egui_kittest::Harness;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use voxflex_runtime::backend::BackendChoice;
use voxflex_viewer::app::ViewerApp;
use voxflex_viewer::open::OpenRequest;
use voxflex_viewer::screenshot::Screenshot;

/// How long a test waits for the worker before failing.
pub const PATIENCE: Duration = Duration::from_secs(120);

/// `target/<profile>`, where the plugins are built (checked: `names`).
pub fn plugin_dir(names: &[&str]) -> PathBuf {
    voxflex_integration_tests::plugin_dir(names)
}

/// The viewer on the built-in phantom (CPU, its own device), with the
/// plugins `names` and File → Open recent kept in `store` (`None`: no
/// file — the tests never touch the user's list); not yet waited for.
pub fn phantom_viewer(names: &[&str], store: Option<PathBuf>) -> Harness<'static, ViewerApp> {
    let req = OpenRequest {
        input: None,
        backend: BackendChoice::Cpu,
        plugin_dirs: vec![plugin_dir(names)],
        gpu: None,
        oblique: Default::default(),
    };
    let app = ViewerApp::new(&egui::Context::default(), req, Screenshot::new(None, None))
        .expect("start the viewer")
        .with_recent_store(store);
    Harness::builder()
        .with_size([1280.0, 860.0])
        .build_ui_state(|ui, app: &mut ViewerApp| app.show(ui), app)
}

/// Steps frames until `done` holds (failing after [`PATIENCE`], with the
/// viewer's messages).
pub fn wait(h: &mut Harness<'static, ViewerApp>, what: &str, done: impl Fn(&ViewerApp) -> bool) {
    let t = Instant::now();
    while !done(h.state()) {
        assert!(
            t.elapsed() < PATIENCE,
            "timed out waiting for {what}; viewer messages: {:?}",
            h.state().messages()
        );
        h.step();
        std::thread::sleep(Duration::from_millis(10));
    }
    h.step();
}

/// Waits until the viewer has said "wrote …" `count` times (the worker
/// finished that many saves).
pub fn wait_for_writes(h: &mut Harness<'static, ViewerApp>, count: usize) {
    wait(h, &format!("{count} files written"), |a| {
        a.messages()
            .iter()
            .filter(|m| m.starts_with("wrote"))
            .count()
            == count
    });
}

/// Runs `voxflex run scene --out out` (in `cwd`, with the built plugins)
/// and fails with its output and `context` (the saved scene's text) unless
/// it succeeds.
pub fn run_saved_scene(scene: &Path, out: &Path, cwd: &Path, context: &str) {
    let (scene, out) = (scene.to_string_lossy(), out.to_string_lossy());
    let run = voxflex_integration_tests::voxflex(&["run", &scene, "--out", &out], cwd);
    assert!(
        run.status.success(),
        "voxflex run {scene}: {}\n{context}",
        voxflex_integration_tests::text(&run)
    );
}
