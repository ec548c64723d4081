//! The scripted grab drag the `drag` and `interactive` benchmarks share:
//! the head phantom scene opened in the headless viewer, then a grab on
//! the scalp of the axial slice dragged round a circle at 60 Hz, every
//! frame recorded.

use super::headless::{FRAME, Headless, screen_on};
use super::scene::head_scene;
use crate::open::OpenRequest;
use crate::protocol::StageTime;
use crate::slice_view::ClickMode;
use std::path::Path;
use std::time::{Duration, Instant};
use voxflex_core::glam::DVec3;
use voxflex_runtime::backend::BackendChoice;

/// How long to wait for the viewer's first images.
pub const PATIENCE: Duration = Duration::from_secs(300);

/// What one UI frame saw.
#[derive(Clone, Copy, Debug)]
pub struct FrameRecord {
    /// When the frame ran, since the press.
    pub at: Duration,
    /// Its UI-thread time.
    pub ui: Duration,
    /// Model steps reported so far.
    pub steps: u64,
    /// 3D images received so far.
    pub renders: u64,
    /// The last image's resolution scale and render time.
    pub render: Option<(f32, Duration)>,
    /// Voxels the last step's resample re-filled (0 when it did not run).
    pub refilled: u64,
}

/// A scripted drag's record.
#[derive(Debug)]
pub struct DragRun {
    /// The frame just before the press (its `at` is zero).
    pub before: FrameRecord,
    /// Every frame from the press to the release (inclusive).
    pub frames: Vec<FrameRecord>,
    /// The session's stage times at the press and after the release.
    pub stages: (Vec<StageTime>, Vec<StageTime>),
    /// The grabbed point, world mm.
    pub point: DVec3,
    /// The drag circle's radius, mm.
    pub radius_mm: f64,
}

/// Opens the built-in ChainMail head scene at `n`³ on the CPU in a
/// headless viewer whose 3D view is `render_px` pixels a side, and waits
/// for its first full-quality image at that size.
pub fn open_head(
    out: &Path,
    n: usize,
    render_px: u32,
    plugin_dirs: Vec<std::path::PathBuf>,
) -> anyhow::Result<Headless> {
    let scene = head_scene(out, n)?;
    let mut h = Headless::new(OpenRequest {
        input: Some(scene),
        backend: BackendChoice::Cpu,
        plugin_dirs,
        gpu: None,
        oblique: Default::default(),
    })?;
    h.wait_for("the session to open", PATIENCE, |a| a.opened().is_some())?;
    h.app.set_render_size(render_px);
    h.wait_for("the first full-quality image", PATIENCE, |a| {
        a.ready()
            && a.render_image()
                .0
                .is_some_and(|i| i.width == render_px && i.height == render_px)
    })?;
    Ok(h)
}

/// Period of the drag circle.
const PERIOD_S: f64 = 2.0;

/// Grabs the scalp on the +x side of the axial slice through the volume's
/// centre (44 % of the field of view out: fat and skin on the head
/// phantom) and drags it round a circle of 7.5 % of the field of view's
/// width for `seconds` at 60 Hz, one pointer move a frame, then lets go.
pub fn scripted_drag(h: &mut Headless, seconds: f64) -> anyhow::Result<DragRun> {
    let grid = h
        .app
        .opened()
        .map(|o| o.grid)
        .ok_or_else(|| anyhow::anyhow!("not open"))?;
    let size = grid.spacing * DVec3::from_array(grid.dims.map(|d| d as f64));
    let centre = grid.centre();
    let point = centre + DVec3::new(0.44 * size.x, 0.0, 0.0);
    let radius_mm = 0.075 * size.x;
    h.app.set_mode(ClickMode::Grab);
    h.frame();
    let slice = h.app.slices().map(|s| s[0].slice.clone());
    let (Some(slice), Some(rect)) = (slice, h.app.slice_rect(0)) else {
        anyhow::bail!("the axial slice is not drawn");
    };
    let at = |p: DVec3| screen_on(&slice, rect, p);
    h.event(egui::Event::PointerMoved(at(point)));
    h.frame();
    let stages_before = h.app.stages().to_vec();
    h.button(at(point), true);
    let start = Instant::now();
    let mut frames = vec![];
    let record = |h: &Headless, ui: Duration| FrameRecord {
        at: start.elapsed(),
        ui,
        steps: h.app.steps(),
        renders: h.app.render_image().1,
        render: h.app.render_timing(),
        refilled: h
            .app
            .last_step()
            .and_then(|r| r.stage("resample"))
            .map_or(0, |s| s.voxels),
    };
    let before = FrameRecord {
        at: Duration::ZERO,
        ..record(h, Duration::ZERO)
    };
    loop {
        let ui = h.frame();
        frames.push(record(h, ui));
        let t = start.elapsed().as_secs_f64();
        if t >= seconds {
            break;
        }
        let w = std::f64::consts::TAU * (t + FRAME.as_secs_f64()) / PERIOD_S;
        let offset = radius_mm * DVec3::new(w.sin(), 1.0 - w.cos(), 0.0);
        h.event(egui::Event::PointerMoved(at(point + offset)));
    }
    h.button(at(point), false);
    let ui = h.frame();
    frames.push(record(h, ui));
    let stages_after = h.app.stages().to_vec();
    Ok(DragRun {
        before,
        frames,
        stages: (stages_before, stages_after),
        point,
        radius_mm,
    })
}

/// Runs and wall time each stage added between two reports, by name.
pub fn stage_deltas(before: &[StageTime], after: &[StageTime]) -> Vec<StageTime> {
    after
        .iter()
        .map(|a| {
            let b = before.iter().find(|b| b.stage == a.stage);
            StageTime {
                stage: a.stage.clone(),
                runs: a.runs - b.map_or(0, |b| b.runs),
                wall_ms: a.wall_ms - b.map_or(0.0, |b| b.wall_ms),
            }
        })
        .filter(|d| d.runs > 0)
        .collect()
}
