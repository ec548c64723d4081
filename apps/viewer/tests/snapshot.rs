//! The main layout drawn by egui's wgpu renderer (lavapipe in CI) matches
//! `tests/snapshots/main_layout.png`, the built-in head phantom as it
//! opens: toolbar, three slices with crosshair and LPS labels, the 3D view
//! and both panels. The status bar and the stage-time table (wall times)
//! are masked. Skips without a GPU adapter unless `CI=true`.
//! `UPDATE_SNAPSHOTS=1 cargo test -p voxflex-viewer --test snapshot`
//! rewrites the snapshot after an intended change.

use egui::{Pos2, Rect};
use egui_kittest::kittest::Queryable;
use egui_kittest::{Harness, SnapshotOptions};
use std::time::{Duration, Instant};
use voxflex_runtime::backend::{BackendChoice, resolve};
use voxflex_viewer::app::ViewerApp;
use voxflex_viewer::open::OpenRequest;
use voxflex_viewer::screenshot::Screenshot;

const SIZE: [f32; 2] = [1280.0, 860.0];

#[test]
fn the_main_layout_matches_its_snapshot() {
    if resolve(BackendChoice::Gpu).is_err() {
        assert!(
            std::env::var("CI").is_err(),
            "CI=true but no GPU adapter (install lavapipe)"
        );
        eprintln!("skipped: no GPU adapter for egui's renderer");
        return;
    }
    let plugins = voxflex_integration_tests::plugin_dir(&["chainmail"]);
    let req = OpenRequest {
        input: None,
        backend: BackendChoice::Cpu,
        plugin_dirs: vec![plugins],
        gpu: None,
        oblique: Default::default(),
    };
    let app = ViewerApp::new(&egui::Context::default(), req, Screenshot::new(None, None))
        .expect("start the viewer");
    let mut h = Harness::builder()
        .with_size(SIZE)
        .wgpu()
        .build_ui_state(|ui, app: &mut ViewerApp| app.show(ui), app);
    let t = Instant::now();
    while !h.state().ready() {
        assert!(
            t.elapsed() < Duration::from_secs(120),
            "{:?}",
            h.state().messages()
        );
        h.step();
        std::thread::sleep(Duration::from_millis(10));
    }
    h.run_steps(2);
    // Wall times differ run to run: the status bar (with the backend box,
    // whose combo box frame reaches its top edge) and the stage table.
    let stage = h.get_by_label("stage").rect();
    h.mask(Rect::from_min_max(
        stage.min,
        Pos2::new(SIZE[0], stage.min.y + 120.0),
    ));
    h.mask(Rect::from_min_max(
        Pos2::new(0.0, SIZE[1] - 32.0),
        Pos2::from(SIZE),
    ));
    h.snapshot_options("main_layout", &SnapshotOptions::new().max_failed_pixels(10));
}
