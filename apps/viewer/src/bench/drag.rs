//! `--bench drag`: the UI thread's time per frame while a simulation
//! runs — a scripted grab drag on the head phantom, each frame's update
//! timed on the UI thread (issue 15: never over 33 ms).

use super::BenchOptions;
use super::report::{Report, verdict};
use super::script::{open_head, scripted_drag};
use super::stats::Stats;
use serde_json::json;
use std::time::Duration;

/// The UI thread's budget per frame (30 frames/s), ms.
pub const BUDGET_MS: f64 = 33.0;

/// Runs the benchmark and returns its report.
pub fn run(opts: &BenchOptions) -> anyhow::Result<Report> {
    let n = opts.size.unwrap_or(128);
    let mut report = Report::new(
        "drag",
        &format!(
            "UI-thread time of every frame (the app's update and egui's tessellation, headless, \
             60 Hz) during a {:.1} s scripted grab drag on the {n}³ head phantom, ChainMail on \
             the CPU, 3D view {px}² (an adaptive ¼–½ of that while dragging).",
            opts.seconds,
            px = opts.render_size,
        ),
    );
    let mut h = open_head(&opts.out, n, opts.render_size, opts.plugin_dirs.clone())?;
    let drag = scripted_drag(&mut h, opts.seconds)?;
    let ui: Vec<Duration> = drag.frames.iter().map(|f| f.ui).collect();
    let stats = Stats::of(&ui).ok_or_else(|| anyhow::anyhow!("the drag drew no frame"))?;
    let over = ui
        .iter()
        .filter(|d| d.as_secs_f64() * 1e3 > BUDGET_MS)
        .count();
    let last = drag.frames.last().copied().unwrap_or(drag.before);
    let steps = last.steps - drag.before.steps;
    let renders = last.renders - drag.before.renders;
    let ok = stats.worst_ms <= BUDGET_MS;
    report.row("frames", stats.count.to_string(), "");
    report.row(
        "mean / p50",
        format!("{:.2} / {:.2} ms", stats.mean_ms, stats.p50_ms),
        "",
    );
    report.row(
        "p99",
        format!("{:.2} ms", stats.p99_ms),
        &format!("≤ {BUDGET_MS} ms: {}", verdict(stats.p99_ms <= BUDGET_MS)),
    );
    report.row(
        "worst",
        format!("{:.2} ms", stats.worst_ms),
        &format!("≤ {BUDGET_MS} ms: {}", verdict(ok)),
    );
    report.row(&format!("frames over {BUDGET_MS} ms"), over.to_string(), "");
    report.row(
        "model steps / 3D images during the drag",
        format!("{steps} / {renders}"),
        "",
    );
    report.field("phantom_dims", json!([n, n, n]));
    report.field("render_px", json!(opts.render_size));
    report.field("seconds", json!(opts.seconds));
    report.field("frame_ms", stats.json());
    report.field("frames_over_budget", json!(over));
    report.field("budget_ms", json!(BUDGET_MS));
    report.field("met", json!(ok));
    report.field("steps", json!(steps));
    report.field("renders", json!(renders));
    report.field("grab_point_mm", json!(drag.point.to_array()));
    report.field("drag_radius_mm", json!(drag.radius_mm));
    Ok(report)
}
