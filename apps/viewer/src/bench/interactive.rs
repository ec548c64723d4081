//! `--bench interactive`: the interactive loop — completed deform +
//! resample + render cycles per second during a scripted grab drag with
//! adaptive quality (the 3D view at ¼–½ resolution while dragging), and
//! the full-quality render once idle (issue 15: ≥ 10 cycles/s at 512² on
//! 2 cores, 128³ head phantom, ChainMail on the CPU).

use super::BenchOptions;
use super::headless::Headless;
use super::report::{Report, verdict};
use super::script::{DragRun, FrameRecord, PATIENCE, open_head, scripted_drag, stage_deltas};
use super::stats::Stats;
use serde_json::json;
use std::time::Duration;

/// Cycles per second the interactive loop must reach.
pub const REQUIRED_HZ: f64 = 10.0;
/// Full-quality renders timed once idle.
const IDLE_RENDERS: usize = 5;

/// The frames at which a 3D image arrived at the UI that shows a model
/// step newer than the previous counted image's: each one a completed
/// deform + resample + render cycle.
pub fn cycle_frames(drag: &DragRun) -> Vec<FrameRecord> {
    let (mut steps, mut renders) = (drag.before.steps, drag.before.renders);
    let mut cycles = vec![];
    for f in &drag.frames {
        if f.renders > renders && f.steps > steps {
            cycles.push(*f);
            steps = f.steps;
        }
        renders = f.renders;
    }
    cycles
}

/// The median (upper middle) of `v`, if any.
fn median(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

/// Runs the benchmark and returns its report.
pub fn run(opts: &BenchOptions) -> anyhow::Result<Report> {
    let n = opts.size.unwrap_or(128);
    let px = opts.render_size;
    let mut report = Report::new(
        "interactive",
        &format!(
            "Completed deform + resample + render cycles (a 3D image showing a new model step \
             arriving at the UI) during a {:.1} s scripted grab drag on the {n}³ head phantom, \
             ChainMail on the CPU, 3D view {px}² rendered at an adaptive ¼–½ of that while \
             dragging; then the full-quality {px}² render once idle (median of {IDLE_RENDERS}).",
            opts.seconds,
        ),
    );
    let mut h = open_head(&opts.out, n, px, opts.plugin_dirs.clone())?;
    let drag = scripted_drag(&mut h, opts.seconds)?;
    let frames = cycle_frames(&drag);
    let cycles: Vec<Duration> = frames.iter().map(|f| f.at).collect();
    let span = drag.frames.last().map_or(Duration::ZERO, |f| f.at);
    let hz = cycles.len() as f64 / span.as_secs_f64().max(1e-9);
    let gaps: Vec<Duration> = cycles.windows(2).map(|w| w[1] - w[0]).collect();
    let per_stage = stage_deltas(&drag.stages.0, &drag.stages.1);
    let refilled = median(frames.iter().map(|f| f.refilled as f64).collect());
    let scales = frames
        .iter()
        .filter_map(|f| f.render.map(|(s, _)| s as f64));
    let scale = median(scales.collect());
    let voxels = h.app.opened().map_or(0, |o| o.grid.len()) as f64;
    let idle = idle_renders(&mut h)?;
    let idle_stats = Stats::of(&idle);
    report.row(
        "cycles per second while dragging",
        format!(
            "{hz:.2} ({} cycles in {:.2} s)",
            cycles.len(),
            span.as_secs_f64()
        ),
        &format!("≥ {REQUIRED_HZ}: {}", verdict(hz >= REQUIRED_HZ)),
    );
    if let Some(g) = Stats::of(&gaps) {
        report.row(
            "time between cycles (p50 / worst)",
            format!("{:.0} / {:.0} ms", g.p50_ms, g.worst_ms),
            "",
        );
        report.field("cycle_gap_ms", g.json());
    }
    if let (Some(r), Some(sc)) = (refilled, scale) {
        report.row(
            "per cycle: voxels re-filled (median) / 3D scale (median)",
            format!(
                "{r:.0} ({:.0} % of the volume) / {sc:.3} ({:.0}²)",
                100.0 * r / voxels.max(1.0),
                sc * px as f64
            ),
            "",
        );
        report.field("refilled_voxels_median", json!(r));
        report.field("drag_scale_median", json!(sc));
    }
    for d in &per_stage {
        report.row(
            &format!("stage `{}` while dragging", d.stage),
            format!(
                "{:.1} ms per run ({} runs)",
                d.wall_ms / d.runs as f64,
                d.runs
            ),
            "",
        );
    }
    if let Some(s) = idle_stats {
        report.row(
            &format!("idle full-quality render, {px}²"),
            format!(
                "{:.1} ms (median of {}; worst {:.1})",
                s.p50_ms, s.count, s.worst_ms
            ),
            "reported",
        );
        report.field("idle_render_ms", s.json());
    }
    report.field("phantom_dims", json!([n, n, n]));
    report.field("render_px", json!(px));
    report.field("seconds", json!(opts.seconds));
    report.field("cycles", json!(cycles.len()));
    report.field("cycles_per_s", json!(hz));
    report.field("required_per_s", json!(REQUIRED_HZ));
    report.field("met", json!(hz >= REQUIRED_HZ));
    report.field(
        "stages_while_dragging",
        json!(
            per_stage
                .iter()
                .map(|d| json!({"stage": d.stage, "runs": d.runs, "wall_ms": d.wall_ms}))
                .collect::<Vec<_>>()
        ),
    );
    Ok(report)
}

/// Once the drag's last image is in, orbits the 3D view a little
/// [`IDLE_RENDERS`] times, each time waiting for the full-quality image
/// that follows the half-resolution ones, and returns those renders'
/// times as the worker measured them.
fn idle_renders(h: &mut Headless) -> anyhow::Result<Vec<Duration>> {
    let full = |a: &crate::app::ViewerApp| a.render_timing().is_some_and(|(s, _)| s >= 1.0);
    h.wait_for("the full-quality image after the drag", PATIENCE, full)?;
    // The 3D view fills the lower right quarter: right of the sagittal
    // slice (lower left), below the coronal one (upper right).
    let (Some(coronal), Some(sagittal)) = (h.app.slice_rect(1), h.app.slice_rect(2)) else {
        anyhow::bail!("the slices are not drawn");
    };
    let centre = egui::pos2(coronal.center().x, sagittal.center().y);
    let mut walls = vec![];
    for _ in 0..IDLE_RENDERS {
        let renders = h.app.render_image().1;
        h.button(centre, true);
        h.frame();
        // Past egui's click distance (6 points): a drag, not a click.
        for dx in [10.0, 20.0] {
            h.event(egui::Event::PointerMoved(centre + egui::vec2(dx, 0.0)));
            h.frame();
        }
        h.button(centre + egui::vec2(20.0, 0.0), false);
        // Past the viewer's idle delay the full-quality view is sent; no
        // half-resolution image follows the first full one after it.
        let released = std::time::Instant::now();
        while released.elapsed() < Duration::from_millis(300) {
            h.frame();
        }
        h.wait_for("a full-quality image after an orbit", PATIENCE, |a| {
            a.render_image().1 > renders && full(a)
        })?;
        walls.extend(h.app.render_timing().map(|(_, w)| w));
    }
    Ok(walls)
}
