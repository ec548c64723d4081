//! `--bench open`: a CT-like volume file (512 × 512 × 133 int16, gzipped
//! NIfTI) from the open request to the first rendered 3D frame at the UI,
//! split into its stages (issue 15: ≤ 2 s on 2 cores).

use super::BenchOptions;
use super::headless::Headless;
use super::report::{Report, verdict};
use super::scene::{ct_dims, ct_volume};
use super::script::PATIENCE;
use crate::open::OpenRequest;
use serde_json::json;
use std::time::{Duration, Instant};
use voxflex_runtime::backend::BackendChoice;

/// The time allowed from the open request to the first 3D frame, s.
pub const REQUIRED_S: f64 = 2.0;

/// When the UI first saw each milestone, since the open request.
#[derive(Default, Debug)]
struct Milestones {
    opened: Option<Duration>,
    slices: Option<Duration>,
    render: Option<Duration>,
}

/// Runs the benchmark and returns its report.
pub fn run(opts: &BenchOptions) -> anyhow::Result<Report> {
    let dims = ct_dims(opts.size.unwrap_or(512));
    let input = ct_volume(&opts.out, dims)?;
    let bytes = std::fs::metadata(&input).map_or(0, |m| m.len());
    let mut report = Report::new(
        "open",
        &format!(
            "A CT-like head ({}×{}×{} int16 HU, gzipped NIfTI of {:.1} MB: `{}`) opened in the \
             headless viewer on the CPU: time from the open request to the first 3D image at the \
             UI (full quality, the viewer's default size), and where it went.",
            dims[0],
            dims[1],
            dims[2],
            bytes as f64 / 1e6,
            input.display()
        ),
    );
    let t0 = Instant::now();
    let mut h = Headless::new(OpenRequest {
        input: Some(input.clone()),
        backend: BackendChoice::Cpu,
        plugin_dirs: opts.plugin_dirs.clone(),
        gpu: None,
        oblique: Default::default(),
    })?;
    let mut m = Milestones::default();
    h.wait_for("the first 3D image", PATIENCE, |a| {
        let now = t0.elapsed();
        let note = |slot: &mut Option<Duration>, seen: bool| {
            if seen && slot.is_none() {
                *slot = Some(now);
            }
        };
        note(&mut m.opened, a.opened().is_some());
        note(&mut m.slices, a.slices().is_some());
        note(&mut m.render, a.render_image().1 > 0);
        m.render.is_some()
    })?;
    let first = m.render.unwrap_or_else(|| t0.elapsed());
    // The stage times come in the same batch as the image.
    h.wait_for("the stage times", PATIENCE, |a| {
        a.stages().iter().any(|s| s.stage == "render")
    })?;
    let stage_ms = |name: &str| {
        h.app
            .stages()
            .iter()
            .find(|s| s.stage == name)
            .map(|s| s.wall_ms)
    };
    let read_ms = stage_ms("source");
    let render_ms = stage_ms("render");
    let resample_ms = stage_ms("resample");
    let (scale, wall) = h.app.render_timing().unwrap_or((0.0, Duration::ZERO));
    let px = h.app.render_image().0.map_or(0, |i| i.width);
    let ok = first.as_secs_f64() <= REQUIRED_S;
    report.row(
        "open request → first 3D image at the UI",
        format!("{:.3} s", first.as_secs_f64()),
        &format!("≤ {REQUIRED_S} s: {}", verdict(ok)),
    );
    let ms = |x: Option<f64>| x.map_or("not run".into(), |v| format!("{v:.0} ms"));
    let at = |x: Option<Duration>| {
        x.map_or("never".into(), |d| {
            format!("{:.0} ms", d.as_secs_f64() * 1e3)
        })
    };
    report.row("read + decode the file (`source` stage)", ms(read_ms), "");
    report.row(
        "session open at the UI (read, plugins listed, first camera)",
        at(m.opened),
        "",
    );
    report.row("first slices at the UI", at(m.slices), "");
    report.row(
        "first resample",
        resample_ms.map_or("not run: a volume file opens with no model".into(), |v| {
            format!("{v:.0} ms")
        }),
        "",
    );
    report.row(
        &format!("first render ({px}², scale {scale})"),
        format!("{:.0} ms", wall.as_secs_f64() * 1e3),
        "",
    );
    report.field("dims", json!(dims));
    report.field("file_bytes", json!(bytes));
    report.field("first_image_s", json!(first.as_secs_f64()));
    report.field("required_s", json!(REQUIRED_S));
    report.field("met", json!(ok));
    report.field("read_ms", json!(read_ms));
    report.field("resample_ms", json!(resample_ms));
    report.field("render_ms", json!(render_ms));
    report.field("render_px", json!(px));
    let secs = |x: Option<Duration>| x.map(|d| d.as_secs_f64());
    report.field("opened_at_ui_s", json!(secs(m.opened)));
    report.field("slices_at_ui_s", json!(secs(m.slices)));
    Ok(report)
}
