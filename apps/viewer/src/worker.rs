//! The worker thread: it owns the [`Session`], applies the UI's commands
//! in batches (a drag's stale targets dropped), and sends back slices, the
//! 3D image, ROI rows and stage times, so the UI thread never waits on the
//! pipeline.

use crate::adaptive::AdaptiveScale;
use crate::backend_panel::BackendStatus;
use crate::compose::compose_slice;
use crate::gpu_image::GpuFrame;
use crate::open::{
    OpenRequest, OpenedSession, deformation_models, deformation_schemas, first_camera, open,
    render_params,
};
use crate::orientation::normal_axis;
use crate::protocol::{AXES, Command, Opened, Reply, RoiRow, SliceFrame, StageTime, ViewRequest};
use crate::render_info::{render_info, sync_shown};
use crate::save_png::save_view_png;
use crate::scene_file::{SavedRender, SessionState, scene_text, write_atomic};
use anyhow::Context;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use voxflex_core::camera::Camera;
use voxflex_core::glam::DVec3;
use voxflex_runtime::gpu_context::WgpuService;
use voxflex_runtime::scene::Scene;
use voxflex_runtime::session::{
    GrowthReport, Interaction, RenderParams, RoiId, Seed, Session, StepReport,
};

/// The UI's handle on the worker thread.
pub struct Worker {
    tx: Sender<Command>,
    rx: Receiver<Reply>,
    handle: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts the worker, which opens `req`; `wake` is called after every
    /// batch of replies (e.g. to request a repaint).
    pub fn spawn(req: OpenRequest, wake: impl Fn() + Send + 'static) -> anyhow::Result<Self> {
        let (tx, commands) = channel();
        let (replies, rx) = channel();
        let handle = std::thread::Builder::new()
            .name("voxflex-session".into())
            .spawn(move || run(req, commands, replies, wake))
            .context("starting the session thread")?;
        Ok(Self {
            tx,
            rx,
            handle: Some(handle),
        })
    }

    /// Queues a command (ignored once the worker has stopped).
    pub fn send(&self, c: Command) {
        let _ = self.tx.send(c);
    }

    /// The replies that arrived since the last call.
    pub fn poll(&self) -> Vec<Reply> {
        self.rx.try_iter().collect()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.tx.send(Command::Quit);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn run(req: OpenRequest, commands: Receiver<Command>, out: Sender<Reply>, wake: impl Fn()) {
    let mut state = open_or_report(&req, &out);
    wake();
    while let Ok(first) = commands.recv() {
        let mut batch = vec![first];
        batch.extend(commands.try_iter());
        if batch.iter().any(|c| matches!(c, Command::Quit)) {
            return;
        }
        // An Open replaces the session: the commands before it were for
        // the old one.
        if let Some(i) = batch.iter().rposition(|c| matches!(c, Command::Open(_))) {
            let rest = batch.split_off(i + 1);
            if let Some(Command::Open(req)) = batch.pop()
                && let Some(s) = open_or_report(&req, &out)
            {
                state = Some(s);
            }
            batch = rest;
        }
        if let Some(s) = &mut state {
            s.apply_batch(batch, &out);
        }
        wake();
    }
}

/// Opens `req`, or sends the error (naming the file and the reason).
fn open_or_report(req: &OpenRequest, out: &Sender<Reply>) -> Option<State> {
    match State::open(req, out) {
        Ok(s) => Some(s),
        Err(e) => {
            tracing::error!("{e:#}");
            let _ = out.send(Reply::Error(format!("{e:#}")));
            None
        }
    }
}

/// What changed in a batch, so only that is sent again.
#[derive(Default)]
struct Changes {
    view: bool,
    volume: bool,
    rois: bool,
    stepped: bool,
    /// The renderer was reconfigured.
    render: bool,
}

struct State {
    session: Session,
    view: Option<ViewRequest>,
    /// Camera and scale of the image last sent.
    rendered: Option<(Camera, f32)>,
    last_growth: HashMap<RoiId, (GrowthReport, Duration)>,
    model: Option<(String, String)>,
    render: RenderParams,
    /// The last renderer parameters that rendered (restored when new ones
    /// are refused).
    good_render: RenderParams,
    /// Reconfigures received in this batch, acknowledged after it.
    render_acks: Vec<u64>,
    /// The scene opened (the built-in one for a volume file): the base of
    /// a saved scene.
    scene: Scene,
    /// The volume file opened without a scene.
    volume_file: Option<PathBuf>,
    /// The 3D view's resolution while dragging.
    adaptive: AdaptiveScale,
    /// The UI's device, when shared: the 3D image then stays on it.
    shared: Option<Arc<WgpuService>>,
}

impl State {
    fn open(req: &OpenRequest, out: &Sender<Reply>) -> anyhow::Result<Self> {
        let mut opened = open(req)?;
        let render = render_params(&opened);
        let camera = first_camera(&mut opened)?;
        let OpenedSession {
            mut session,
            scene,
            title,
            scene_opened,
        } = opened;
        let volume_file = req.input.clone().filter(|_| !scene_opened);
        let models = deformation_models(&session, &scene);
        // A volume file has no model until one is chosen.
        let model = scene.model.as_ref().filter(|_| scene_opened).map(|m| {
            let params = scene.model_params_toml_for(&m.plugin).unwrap_or_default();
            (m.plugin.clone(), params)
        });
        let volume = session.volume()?;
        let (grid, value_range) = (volume.grid, volume.value_range());
        tracing::info!(%title, adapter = %session.adapter_name(), "opened");
        let _ = out.send(Reply::Opened(Box::new(Opened {
            title,
            grid,
            value_range,
            camera,
            models,
            schemas: deformation_schemas(&session),
            model: model.as_ref().map(|(n, _)| n.clone()),
            adapter: session.adapter_name(),
            path: req.input.clone(),
        })));
        let status = BackendStatus::of(&session, req.backend, req.gpu.as_ref());
        let _ = out.send(Reply::Backend(status));
        let _ = out.send(Reply::RenderInfo(Box::new(render_info(&session, &render)?)));
        Ok(Self {
            session,
            view: None,
            rendered: None,
            last_growth: HashMap::new(),
            model,
            good_render: render.clone(),
            render_acks: vec![],
            render,
            scene,
            volume_file,
            adaptive: AdaptiveScale::default(),
            shared: req.gpu.clone(),
        })
    }

    fn apply_batch(&mut self, batch: Vec<Command>, out: &Sender<Reply>) {
        let mut changes = Changes::default();
        let last_drag = batch
            .iter()
            .rposition(|c| matches!(c, Command::Drag { .. }));
        for (i, c) in batch.into_iter().enumerate() {
            // A drag's earlier targets in the same batch are stale.
            if matches!(c, Command::Drag { .. }) && Some(i) != last_drag {
                continue;
            }
            if let Err(e) = self.apply(c, &mut changes, out) {
                tracing::warn!("{e:#}");
                let _ = out.send(Reply::Error(format!("{e:#}")));
            }
        }
        if let Err(e) = self.publish(&changes, out) {
            tracing::warn!("{e:#}");
            let _ = out.send(Reply::Error(format!("{e:#}")));
            // Parameters the renderer refused give way to the last good ones.
            self.render = self.good_render.clone();
        }
        for seq in self.render_acks.drain(..) {
            let _ = out.send(Reply::RenderApplied(seq));
        }
    }

    fn apply(&mut self, c: Command, ch: &mut Changes, out: &Sender<Reply>) -> anyhow::Result<()> {
        let s = &mut self.session;
        match c {
            Command::View(v) => {
                ch.view = true;
                self.view = Some(v);
            }
            Command::AddRoi {
                seed,
                params,
                run_to_end,
            } => {
                let id = s.add_roi(Seed::World(DVec3::from_array(seed)), params)?;
                ch.rois = true;
                if run_to_end {
                    self.grow(id, ch, |s| s.roi_run_to_end(id))?;
                }
            }
            Command::RoiStep(id, n) => self.grow(id, ch, |s| s.roi_step(id, n))?,
            Command::RoiRunToEnd(id) => self.grow(id, ch, |s| s.roi_run_to_end(id))?,
            Command::RoiParams(id, p) => self.grow(id, ch, |s| s.set_roi_params(id, p))?,
            Command::RemoveRoi(id) => {
                s.remove_roi(id);
                self.last_growth.remove(&id);
                ch.rois = true;
            }
            Command::SaveRoi(id, path) => {
                s.write_roi_map(id, &path)?;
                let _ = out.send(Reply::Status(format!("wrote {}", path.display())));
            }
            Command::SwapModel { plugin, params } => {
                if let Err(e) = s.swap_model(&plugin, &params) {
                    let _ = out.send(Reply::ModelError(e.to_string()));
                    return Err(e.into());
                }
                self.model = Some((plugin.clone(), params));
                let _ = out.send(Reply::Model(plugin));
                self.step(ch, out)?;
            }
            Command::Drag { point, to } => {
                s.interact(&Interaction::Grab {
                    point,
                    to,
                    frames: 1,
                })?;
                self.step(ch, out)?;
            }
            Command::Cut { polygon } => {
                s.interact(&Interaction::Cut { polygon })?;
                self.step(ch, out)?;
            }
            Command::Carve { centre, radius } => {
                s.interact(&Interaction::CarveBall { centre, radius })?;
                self.step(ch, out)?;
            }
            Command::Release => {
                s.interact(&Interaction::Release)?;
                self.step(ch, out)?;
            }
            Command::Reset => {
                let (plugin, params) = self
                    .model
                    .clone()
                    .context("reset: no model to reset; choose one first")?;
                s.swap_model(&plugin, &params)?;
                self.step(ch, out)?;
            }
            Command::Step => self.step(ch, out)?,
            Command::SaveScene(path) => {
                let mut state = SessionState::of(s);
                state.render = self.view.as_ref().map(|v| SavedRender {
                    plugin: self.render.plugin.clone(),
                    params_toml: self.render.params_toml.clone(),
                    camera: v.camera,
                });
                let text = scene_text(&self.scene, self.volume_file.as_deref(), &state)?;
                write_atomic(&path, &text)?;
                let _ = out.send(Reply::Status(format!("wrote {}", path.display())));
            }
            Command::SaveVolume(path) => {
                voxflex_io::write_volume(&path, s.volume()?.view())
                    .with_context(|| format!("writing {}", path.display()))?;
                let _ = out.send(Reply::Status(format!("wrote {}", path.display())));
            }
            Command::SetBackend(choice) => match s.set_backend(choice) {
                Ok(_) => {
                    let status = BackendStatus::of(s, choice, self.shared.as_ref());
                    let _ = out.send(Reply::Backend(status));
                    // Maps re-grown, and the image is due on the new backend.
                    ch.rois = true;
                    self.rendered = None;
                }
                Err(e) => {
                    let _ = out.send(Reply::BackendError(format!("{choice}: {e}")));
                }
            },
            Command::RenderParams { seq, params_toml } => {
                self.render_acks.push(seq);
                self.render.params_toml = params_toml;
                ch.render = true;
            }
            Command::SaveViewPng(path) => {
                let view = self.view.as_ref().context("save view: no 3D view yet")?;
                save_view_png(s, &view.camera, &self.render, &path)?;
                let _ = out.send(Reply::Status(format!("wrote {}", path.display())));
            }
            Command::RoiAutoLambda(id) => {
                let t = Instant::now();
                let auto = s.roi_auto_lambda(id)?;
                self.last_growth.insert(id, (auto.report, t.elapsed()));
                ch.rois = true;
                let _ = out.send(Reply::Status(format!(
                    "map {}: auto λ = {} ({} trials)",
                    id.0,
                    auto.lambda,
                    auto.trials.len()
                )));
            }
            Command::RoiLimits(id, l) => self.grow(id, ch, |s| s.set_roi_limits(id, l))?,
            Command::Pick {
                camera,
                pixel,
                min_value,
            } => {
                let p = s.pick(&camera, pixel, min_value)?;
                let _ = out.send(Reply::Picked(p.map(|p| p.to_array())));
            }
            Command::Open(_) | Command::Quit => {}
        }
        Ok(())
    }

    fn grow(
        &mut self,
        id: RoiId,
        ch: &mut Changes,
        f: impl FnOnce(&mut Session) -> Result<GrowthReport, voxflex_runtime::pipeline::RunError>,
    ) -> anyhow::Result<()> {
        let t = Instant::now();
        let report = f(&mut self.session)?;
        self.last_growth.insert(id, (report, t.elapsed()));
        ch.rois = true;
        Ok(())
    }

    fn step(&mut self, ch: &mut Changes, out: &Sender<Reply>) -> anyhow::Result<()> {
        let report: StepReport = self.session.step()?;
        ch.stepped = true;
        ch.volume |= report.ran("resample");
        ch.rois |= report.ran("roi") || report.ran("resample");
        let _ = out.send(Reply::Step(report));
        Ok(())
    }

    fn publish(&mut self, ch: &Changes, out: &Sender<Reply>) -> anyhow::Result<()> {
        if ch.rois {
            let rows = self
                .session
                .rois()
                .into_iter()
                .map(|info| RoiRow {
                    last: self.last_growth.get(&info.id).copied(),
                    info,
                })
                .collect();
            let _ = out.send(Reply::Rois(rows));
        }
        let Some(view) = self.view.clone() else {
            return Ok(());
        };
        if ch.view || ch.volume || ch.rois {
            self.send_slices(&view, out)?;
        }
        let scale = if view.interacting {
            self.adaptive.scale()
        } else {
            1.0
        };
        let camera = scaled(&view.camera, scale);
        let shown_changed = sync_shown(&mut self.session, &view.hidden);
        let due = self.rendered != Some((camera, scale))
            || ch.volume
            || ch.rois
            || ch.render
            || shown_changed;
        if due {
            let t = Instant::now();
            let shared = self.shared.as_ref();
            let reply = match GpuFrame::render(&mut self.session, shared, &camera, &self.render)? {
                Some(frame) => Reply::GpuRender {
                    frame,
                    scale,
                    wall: t.elapsed(),
                },
                None => Reply::Render {
                    image: self.session.render(&camera, &self.render)?,
                    scale,
                    wall: t.elapsed(),
                },
            };
            self.good_render = self.render.clone();
            self.rendered = Some((camera, scale));
            if view.interacting {
                self.adaptive.observe(t.elapsed());
            }
            let _ = out.send(reply);
        }
        if ch.stepped || ch.rois || due {
            let _ = out.send(Reply::Stages(stage_times(&mut self.session)?));
        }
        Ok(())
    }

    fn send_slices(&mut self, view: &ViewRequest, out: &Sender<Reply>) -> anyhow::Result<()> {
        let volume = self.session.volume()?;
        let dims = volume.grid.dims;
        let [i, j, k] = view.cursor;
        let value = if i < dims[0] && j < dims[1] && k < dims[2] {
            volume.get_f32(i, j, k)
        } else {
            f32::NAN
        };
        let mut frames = Vec::with_capacity(3);
        for axis in AXES {
            let along = normal_axis(axis);
            let index = view.cursor[along].min(dims[along].saturating_sub(1));
            let slice = self.session.slice(axis, index, Some(view.window))?;
            let overlays: Vec<_> = view
                .overlays
                .iter()
                .filter_map(|(id, rgb)| self.session.roi_map(*id).map(|m| (m, *rgb)))
                .collect();
            let rgba = compose_slice(&slice, &overlays);
            frames.push(SliceFrame { slice, rgba });
        }
        let frames: [SliceFrame; 3] = frames
            .try_into()
            .map_err(|_| anyhow::anyhow!("three slices"))?;
        let _ = out.send(Reply::Slices(Box::new(frames), value));
        Ok(())
    }
}

/// `camera` at `scale` times its resolution (at least 1 pixel a side).
fn scaled(camera: &Camera, scale: f32) -> Camera {
    let px = |n: u32| ((n as f32 * scale).round() as u32).max(1);
    Camera {
        width: px(camera.width),
        height: px(camera.height),
        ..*camera
    }
}

fn stage_times(s: &mut Session) -> anyhow::Result<Vec<StageTime>> {
    Ok(s.metrics()?
        .stages
        .into_iter()
        .map(|(stage, m)| StageTime {
            stage,
            runs: m.runs,
            wall_ms: m.wall_ms,
        })
        .collect())
}
