//! [`ViewerApp`]: the viewer's state on the UI thread — what the worker
//! sent last, the cursor, window and camera — and the layout: toolbar,
//! three slice views and the 3D view, the ROI and deformation panels.

use crate::backend_panel::BackendPanel;
use crate::file_menu::FileMenu;
use crate::gpu_image::GpuImage;
use crate::grab3d::Grab3d;
use crate::model_panel::ModelPanel;
use crate::open::OpenRequest;
use crate::orientation::normal_axis;
use crate::protocol::{AXES, Command, Opened, Reply, RoiRow, SliceFrame, StageTime, ViewRequest};
use crate::recent::{RecentFiles, default_store};
use crate::render_panel::RenderPanel;
use crate::roi_panel::RoiPanel;
use crate::screenshot::Screenshot;
use crate::slice_view::{ClickMode, SliceInput, slice_view};
use crate::tools::{carve_again, cut_quad, half_extent_mm, slice_normal};
use crate::view3d::view3d_texture;
use crate::window_level::{Preset, drag_window};
use crate::worker::Worker;
use egui::{ColorImage, Rect, TextureHandle, TextureId, TextureOptions};
use std::time::{Duration, Instant};
use voxflex_core::camera::Camera;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_runtime::session::{StepReport, Window};
use voxflex_runtime::visualise::RgbaImage;

mod files;

/// Idle time after the last drag before the 3D view renders at full quality.
const IDLE_AFTER: Duration = Duration::from_millis(200);
/// Smooth-scroll points per slice.
const WHEEL_POINTS_PER_SLICE: f32 = 20.0;
/// Messages kept for the status bar (the oldest are dropped).
const MAX_MESSAGES: usize = 100;
/// Pixels a side of the 3D image at full quality.
const RENDER_SIZE: u32 = 384;

/// A grab drag under way on a slice: the grabbed point (world mm) and the
/// last target sent.
#[derive(Clone, Copy, Debug)]
struct GrabDrag {
    point: DVec3,
    to: DVec3,
}

/// A cut line being drawn on slice view `view`: from `from` to `to`
/// (world mm).
#[derive(Clone, Copy, Debug)]
struct CutDrag {
    view: usize,
    from: DVec3,
    to: DVec3,
}

/// Carve brush radius range, mm.
const BRUSH_MM: std::ops::RangeInclusive<f64> = 1.0..=50.0;

/// Which panel the right-hand side shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SideTab {
    /// The ROI and deformation panels.
    MapsAndModel,
    /// The *Rendering* panel (transfer function, MIP, clip, crop).
    Rendering,
}

/// The viewer.
pub struct ViewerApp {
    worker: Worker,
    opened: Option<Opened>,
    cursor: DVec3,
    window: Window,
    preset: Preset,
    camera: Option<Camera>,
    mode: ClickMode,
    slices: Option<Box<[SliceFrame; 3]>>,
    cursor_value: f32,
    slice_tex: [Option<TextureHandle>; 3],
    slice_rects: [Option<Rect>; 3],
    render: Option<(RgbaImage, f32, Duration)>,
    renders: u64,
    render_tex: Option<TextureHandle>,
    /// The GPU path's 3D texture (with a wgpu renderer whose device the
    /// session shares).
    gpu_image: Option<GpuImage>,
    /// Scale and wall time of the last GPU-path image (`None` after a CPU one).
    gpu_render: Option<(f32, Duration)>,
    backend_panel: BackendPanel,
    rois: Vec<RoiRow>,
    roi_panel: RoiPanel,
    model_panel: ModelPanel,
    render_panel: RenderPanel,
    side_tab: SideTab,
    /// File → Save view as PNG's path.
    save_png_path: String,
    stages: Vec<StageTime>,
    last_step: Option<StepReport>,
    steps: u64,
    grab: Option<GrabDrag>,
    cut: Option<CutDrag>,
    /// Carve brush radius, mm.
    brush_mm: f64,
    /// Where the carve stroke last carved (world mm).
    last_carve: Option<DVec3>,
    /// The File menu: open, recent files, save paths and dialogs.
    files: FileMenu,
    /// What was asked to open at start (its backend and plugin folders
    /// serve every later open).
    req: OpenRequest,
    /// A grab on the 3D view under way.
    grab3d: Grab3d,
    /// Where the 3D image was drawn last frame.
    view3d_rect: Option<Rect>,
    last_drag: Option<Instant>,
    wheel: [f32; 3],
    sent: Option<ViewRequest>,
    messages: Vec<String>,
    frames: u64,
    screenshot: Screenshot,
    /// A map to seed and grow once the session is open (world mm).
    startup_seed: Option<DVec3>,
    /// Images received when the last ROI rows arrived.
    renders_at_rois: u64,
}

impl ViewerApp {
    /// Starts the worker on `req`; `ctx` is repainted whenever it replies.
    pub fn new(
        ctx: &egui::Context,
        req: OpenRequest,
        screenshot: Screenshot,
    ) -> anyhow::Result<Self> {
        let waker = ctx.clone();
        let worker = Worker::spawn(req.clone(), move || waker.request_repaint())?;
        Ok(Self {
            worker,
            opened: None,
            cursor: DVec3::ZERO,
            window: Window::CT_SOFT_TISSUE,
            preset: Preset::CtSoftTissue,
            camera: None,
            mode: ClickMode::Cursor,
            slices: None,
            cursor_value: f32::NAN,
            slice_tex: [None, None, None],
            slice_rects: [None; 3],
            render: None,
            renders: 0,
            render_tex: None,
            gpu_image: None,
            gpu_render: None,
            backend_panel: BackendPanel::default(),
            rois: vec![],
            roi_panel: RoiPanel::default(),
            model_panel: ModelPanel::default(),
            render_panel: RenderPanel::default(),
            side_tab: SideTab::MapsAndModel,
            save_png_path: "viewer-view.png".into(),
            stages: vec![],
            last_step: None,
            steps: 0,
            grab: None,
            cut: None,
            brush_mm: 8.0,
            last_carve: None,
            files: FileMenu::new(RecentFiles::load(default_store())),
            req,
            grab3d: Grab3d::default(),
            view3d_rect: None,
            last_drag: None,
            wheel: [0.0; 3],
            sent: None,
            messages: vec![],
            frames: 0,
            screenshot,
            startup_seed: None,
            renders_at_rois: 0,
        })
    }

    /// Seeds an ROI map at world point `p` (mm) and grows it to the end
    /// as soon as the session is open (`--seed-roi`).
    pub fn with_startup_seed(mut self, p: Option<DVec3>) -> Self {
        self.startup_seed = p;
        self
    }

    /// Draws the GPU path's 3D images through `g` (see
    /// [`GpuImage::share`]; the session must compute on its device).
    pub fn with_gpu_image(mut self, g: Option<GpuImage>) -> Self {
        self.gpu_image = g;
        self
    }

    /// The GPU path's texture, if the viewer has one.
    pub fn gpu_image(&self) -> Option<&GpuImage> {
        self.gpu_image.as_ref()
    }

    /// The texture the 3D view draws: the GPU path's while its images
    /// arrive, else the CPU image's.
    pub fn view3d_texture(&self) -> Option<TextureId> {
        let gpu = self.gpu_image.as_ref().and_then(GpuImage::texture_id);
        gpu.or(self.render_tex.as_ref().map(TextureHandle::id))
    }

    /// The *Backend* box (where the session computes, as last reported).
    pub fn backend_panel(&self) -> &BackendPanel {
        &self.backend_panel
    }

    /// Scale and wall time of the last 3D image, on either path.
    fn render_quality(&self) -> Option<(f32, Duration)> {
        let cpu = self.render.as_ref().map(|(_, s, w)| (*s, *w));
        self.gpu_render.or(cpu)
    }

    /// Mutable access to the ROI panel (its growth constants, styles and
    /// save folder).
    pub fn roi_panel_mut(&mut self) -> &mut RoiPanel {
        &mut self.roi_panel
    }

    /// The deformation panel (its parameter form).
    pub fn model_panel(&self) -> &ModelPanel {
        &self.model_panel
    }

    /// Mutable access to the deformation panel (its parameter form).
    pub fn model_panel_mut(&mut self) -> &mut ModelPanel {
        &mut self.model_panel
    }

    /// The *Rendering* panel (transfer function and render options).
    pub fn render_panel(&self) -> &RenderPanel {
        &self.render_panel
    }

    /// Mutable access to the *Rendering* panel.
    pub fn render_panel_mut(&mut self) -> &mut RenderPanel {
        &mut self.render_panel
    }

    /// Queues a command to the session.
    pub fn send(&self, c: Command) {
        self.worker.send(c);
    }

    /// What was opened, once the worker opened it.
    pub fn opened(&self) -> Option<&Opened> {
        self.opened.as_ref()
    }

    /// The ROI maps as last reported.
    pub fn rois(&self) -> &[RoiRow] {
        &self.rois
    }

    /// The last 3D image received in memory (`None` while the GPU path
    /// draws from its texture) and how many images have been received.
    pub fn render_image(&self) -> (Option<&RgbaImage>, u64) {
        (self.render.as_ref().map(|(i, _, _)| i), self.renders)
    }

    /// The last 3D image's resolution scale (1 = full) and render wall
    /// time, as the worker reported (benchmarks).
    pub fn render_timing(&self) -> Option<(f32, Duration)> {
        self.render.as_ref().map(|(_, s, w)| (*s, *w))
    }

    /// What the session's last step re-ran, and why (benchmarks).
    pub fn last_step(&self) -> Option<&StepReport> {
        self.last_step.as_ref()
    }

    /// The session's per-stage times as last reported (benchmarks).
    pub fn stages(&self) -> &[StageTime] {
        &self.stages
    }

    /// Sets the 3D view's full-quality size, pixels a side (once the
    /// session is open; benchmarks).
    pub fn set_render_size(&mut self, px: u32) {
        if let Some(c) = &mut self.camera {
            (c.width, c.height) = (px, px);
        }
    }

    /// The slices last received, in axial, coronal, sagittal order.
    pub fn slices(&self) -> Option<&[SliceFrame; 3]> {
        self.slices.as_deref()
    }

    /// Where slice view `n` was drawn last frame (screen points).
    pub fn slice_rect(&self, n: usize) -> Option<Rect> {
        self.slice_rects.get(n).copied().flatten()
    }

    /// The cursor, world mm.
    pub fn cursor(&self) -> DVec3 {
        self.cursor
    }

    /// The current volume's value at the cursor voxel, as last reported.
    pub fn cursor_value(&self) -> f32 {
        self.cursor_value
    }

    /// The model in use, as last reported.
    pub fn model(&self) -> Option<&str> {
        self.model_panel.current.as_deref()
    }

    /// Steps the session reported so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The errors and status lines received, oldest first.
    pub fn messages(&self) -> &[String] {
        &self.messages
    }

    /// Sets what a primary click or drag on a slice does.
    pub fn set_mode(&mut self, mode: ClickMode) {
        self.mode = mode;
    }

    /// True once the slices and a full-quality 3D image are shown (and,
    /// with a startup seed, its map converged and rendered).
    pub fn ready(&self) -> bool {
        let seeded = self.startup_seed.is_none()
            || (self.rois.iter().all(|r| r.info.converged)
                && !self.rois.is_empty()
                && self.renders > self.renders_at_rois);
        seeded && self.slices.is_some() && self.render_quality().is_some_and(|(s, _)| s >= 1.0)
    }

    fn receive(&mut self, ctx: &egui::Context) {
        for reply in self.worker.poll() {
            match reply {
                Reply::Opened(o) => self.on_opened(*o),
                Reply::Slices(s, value) => {
                    self.cursor_value = value;
                    for (n, f) in s.iter().enumerate() {
                        let img = &f.slice.image;
                        let color =
                            ColorImage::from_rgba_unmultiplied([img.width, img.height], &f.rgba);
                        upload(
                            ctx,
                            &mut self.slice_tex[n],
                            &format!("slice-{n}"),
                            color,
                            TextureOptions::NEAREST,
                        );
                    }
                    self.slices = Some(s);
                }
                Reply::Render { image, scale, wall } => {
                    let size = [image.width as usize, image.height as usize];
                    let color = ColorImage::from_rgba_unmultiplied(size, &image.pixels);
                    upload(
                        ctx,
                        &mut self.render_tex,
                        "render",
                        color,
                        TextureOptions::LINEAR,
                    );
                    self.render = Some((image, scale, wall));
                    self.renders += 1;
                    self.gpu_render = None;
                    if let Some(g) = &mut self.gpu_image {
                        g.set_stale();
                    }
                }
                Reply::GpuRender { frame, scale, wall } => {
                    match self.gpu_image.as_mut().map(|g| g.show(&frame)) {
                        Some(Ok(())) => {
                            // The image is on the GPU only; no stale CPU copy.
                            self.render = None;
                            self.gpu_render = Some((scale, wall));
                            self.renders += 1;
                        }
                        Some(Err(e)) => self.messages.push(format!("error: {e}")),
                        None => self
                            .messages
                            .push("error: a GPU image arrived without a wgpu renderer".into()),
                    }
                }
                Reply::Backend(b) => {
                    self.model_panel.adapter = b
                        .computing
                        .as_ref()
                        .map_or("cpu".into(), |a| a.name.clone());
                    self.backend_panel.on_status(b);
                }
                Reply::BackendError(e) => self.backend_panel.on_error(e),
                Reply::Rois(r) => {
                    self.rois = r;
                    self.renders_at_rois = self.renders;
                }
                Reply::Model(m) => self.model_panel.set_current(m),
                Reply::ModelError(e) => self.model_panel.model_error(&e),
                Reply::Step(r) => {
                    self.steps += 1;
                    self.last_step = Some(r);
                }
                Reply::Stages(s) => self.stages = s,
                Reply::Error(e) => self.messages.push(format!("error: {e}")),
                Reply::Status(s) => self.messages.push(s),
                Reply::RenderInfo(i) => self.render_panel.on_info(*i),
                Reply::RenderApplied(seq) => self.render_panel.applied(seq),
                Reply::Picked(p) => self.on_picked(p),
            }
        }
        let extra = self.messages.len().saturating_sub(MAX_MESSAGES);
        self.messages.drain(..extra);
    }

    fn on_opened(&mut self, o: Opened) {
        self.forget_session();
        if let Some(p) = &o.path
            && let Err(e) = self.files.recent.push(p)
        {
            self.messages
                .push(format!("error: updating the recent files: {e}"));
        }
        self.cursor = o.grid.centre();
        self.preset = Preset::default_for(o.value_range);
        self.window = self.preset.window(o.value_range);
        self.camera = Some(Camera {
            width: RENDER_SIZE,
            height: RENDER_SIZE,
            ..o.camera
        });
        self.model_panel.models = o.models.clone();
        self.model_panel.schemas = o.schemas.clone();
        self.model_panel.adapter = o.adapter.clone();
        if let Some(m) = &o.model {
            self.model_panel.params = o
                .models
                .iter()
                .find(|(n, _)| n == m)
                .map(|(_, p)| p.clone())
                .unwrap_or_default();
            self.model_panel.set_current(m.clone());
        }
        if let Some(p) = self.startup_seed {
            self.cursor = p;
            self.worker.send(Command::AddRoi {
                seed: p.to_array(),
                params: self.roi_panel.params,
                run_to_end: true,
            });
        }
        self.opened = Some(o);
    }

    /// The cursor's voxel index (clamped into the grid).
    fn cursor_voxel(&self, o: &Opened) -> [usize; 3] {
        let f = o.grid.world_to_index(self.cursor).round();
        let mut v = [0; 3];
        for (a, x) in v.iter_mut().enumerate() {
            *x = (f[a].max(0.0) as usize).min(o.grid.dims[a].saturating_sub(1));
        }
        v
    }

    fn interacting(&self) -> bool {
        self.last_drag.is_some_and(|t| t.elapsed() < IDLE_AFTER)
    }

    /// Sends the view when it changed since the last one sent.
    fn sync_view(&mut self) {
        let (Some(o), Some(camera)) = (&self.opened, self.camera) else {
            return;
        };
        let view = ViewRequest {
            cursor: self.cursor_voxel(o),
            window: self.window,
            camera,
            interacting: self.interacting(),
            overlays: self.roi_panel.overlays(&self.rois),
            hidden: self.roi_panel.hidden(),
        };
        if self.sent.as_ref() != Some(&view) {
            self.sent = Some(view.clone());
            self.worker.send(Command::View(view));
        }
    }

    /// Draws the whole viewer into `ui` (the eframe app and the UI tests).
    pub fn show(&mut self, ui: &mut egui::Ui) {
        let ctx = ui.ctx().clone();
        self.receive(&ctx);
        self.on_files(&ctx);
        self.frames += 1;
        egui::Panel::top("toolbar").show(ui, |ui| self.toolbar(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.status(ui));
        egui::Panel::right("panels")
            .default_size(330.0)
            .show(ui, |ui| {
                ui.horizontal(|ui| {
                    let tab = &mut self.side_tab;
                    ui.selectable_value(tab, SideTab::MapsAndModel, "Maps & model");
                    ui.selectable_value(tab, SideTab::Rendering, "Rendering");
                });
                egui::ScrollArea::vertical().show(ui, |ui| {
                    if self.side_tab == SideTab::Rendering {
                        self.render_panel.ui(ui);
                        return;
                    }
                    for c in self.roi_panel.ui(ui, &self.rois) {
                        self.worker.send(c);
                    }
                    ui.separator();
                    let cmds = self
                        .model_panel
                        .ui(ui, &self.stages, self.last_step.as_ref());
                    for c in cmds {
                        self.worker.send(c);
                    }
                });
            });
        egui::CentralPanel::default().show(ui, |ui| self.views(ui));
        if let Some(c) = self.render_panel.take_command() {
            self.worker.send(c);
        }
        self.sync_view();
        if self.interacting() {
            ctx.request_repaint_after(IDLE_AFTER);
        }
    }

    /// Frames drawn so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    fn toolbar(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let title = self
                .opened
                .as_ref()
                .map_or("opening…".into(), |o| o.title.clone());
            ui.menu_button("File", |ui| self.file_menu(ui));
            ui.strong(title);
            ui.separator();
            ui.selectable_value(&mut self.mode, ClickMode::Cursor, "Cursor");
            ui.selectable_value(&mut self.mode, ClickMode::SeedRoi, "Seed ROI");
            ui.selectable_value(&mut self.mode, ClickMode::Grab, "Grab");
            ui.selectable_value(&mut self.mode, ClickMode::Cut, "Cut");
            ui.selectable_value(&mut self.mode, ClickMode::Carve, "Carve");
            if self.mode == ClickMode::Carve {
                ui.add(
                    egui::Slider::new(&mut self.brush_mm, BRUSH_MM)
                        .suffix(" mm")
                        .text("brush"),
                );
            }
            ui.separator();
            let before = self.preset;
            egui::ComboBox::from_label("Window")
                .selected_text(self.preset.name())
                .show_ui(ui, |ui| {
                    for p in Preset::ALL {
                        ui.selectable_value(&mut self.preset, p, p.name());
                    }
                });
            if self.preset != before
                && let Some(o) = &self.opened
            {
                self.window = self.preset.window(o.value_range);
            }
            ui.label(format!(
                "L {:.0} W {:.0}",
                self.window.level, self.window.width
            ));
        });
    }

    /// File → Open…, Open recent, Save scene / Save volume.
    fn file_menu(&mut self, ui: &mut egui::Ui) {
        for a in self.files.ui(ui) {
            self.on_file_action(a);
        }
        if let Some(c) = crate::save_png::menu_item(ui, &mut self.save_png_path) {
            self.worker.send(c);
            ui.close();
        }
    }

    fn status(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            if let Some(c) = self.backend_panel.ui(ui) {
                self.worker.send(c);
            }
            if let Some((scale, wall)) = self.render_quality() {
                ui.label(format!(
                    "3D: {:.0} % res, {:.0} ms",
                    scale * 100.0,
                    wall.as_secs_f64() * 1e3
                ));
            }
            let c = self.cursor;
            ui.label(format!(
                "cursor ({:.1}, {:.1}, {:.1}) mm, value {:.1}",
                c.x, c.y, c.z, self.cursor_value
            ));
            if let Some(m) = self.messages.last() {
                ui.label(m);
            }
        });
    }

    fn views(&mut self, ui: &mut egui::Ui) {
        let full = ui.available_rect_before_wrap();
        let half = full.size() / 2.0;
        let cells = [
            Rect::from_min_size(full.min, half),
            Rect::from_min_size(full.min + egui::vec2(half.x, 0.0), half),
            Rect::from_min_size(full.min + egui::vec2(0.0, half.y), half),
            Rect::from_min_size(full.min + half, half),
        ];
        for n in 0..3 {
            let cell = cells[n].shrink(2.0);
            let mut child =
                ui.new_child(egui::UiBuilder::new().max_rect(cell).id_salt(("slice", n)));
            let input = match (&self.slices, &self.slice_tex[n]) {
                (Some(s), Some(tex)) => slice_view(
                    &mut child,
                    &s[n],
                    tex,
                    self.cursor,
                    self.mode,
                    self.brush_mm,
                ),
                _ => {
                    child.label("loading…");
                    SliceInput::default()
                }
            };
            self.slice_rects[n] = input.rect;
            self.on_slice_input(n, input);
        }
        let cell = cells[3].shrink(2.0);
        let mut child = ui.new_child(egui::UiBuilder::new().max_rect(cell).id_salt("3d"));
        if let Some(camera) = self.camera {
            let avail = child.available_rect_before_wrap();
            let tex = self.view3d_texture();
            let (c, dragging) = view3d_texture(&mut child, tex, &camera);
            let (c, dragging) = self.grab_on_3d(&mut child, avail, camera, (c, dragging));
            if dragging {
                self.last_drag = Some(Instant::now());
            }
            self.camera = Some(c);
        }
    }

    fn on_slice_input(&mut self, n: usize, input: SliceInput) {
        if input.dragging {
            self.last_drag = Some(Instant::now());
        }
        if let (Some(p), Some(o)) = (input.cursor, &self.opened) {
            self.cursor = clamp_to_grid(&o.grid, p);
        }
        if let Some(seed) = input.seed {
            self.worker.send(Command::AddRoi {
                seed: seed.to_array(),
                params: self.roi_panel.params,
                run_to_end: false,
            });
        }
        match self.mode {
            ClickMode::Cut => self.on_cut(n, &input),
            ClickMode::Carve => self.on_carve(&input),
            _ => self.on_grab(&input),
        }
        self.on_slice_wheel_and_window(n, &input);
    }

    /// A cut line: sent as the quad through it across the volume when the
    /// drag ends.
    fn on_cut(&mut self, n: usize, input: &SliceInput) {
        if let Some(from) = input.grab_start {
            self.cut = Some(CutDrag {
                view: n,
                from,
                to: from,
            });
        }
        if let (Some(to), Some(c)) = (input.grab_to, &mut self.cut) {
            c.to = to;
        }
        if !input.drag_end {
            return;
        }
        let (Some(c), Some(slices), Some(o)) = (self.cut.take(), &self.slices, &self.opened) else {
            return;
        };
        if (c.to - c.from).length() < 1e-3 {
            return;
        }
        let normal = slice_normal(&slices[c.view]);
        let polygon = cut_quad(c.from, c.to, normal, half_extent_mm(&o.grid));
        self.worker.send(Command::Cut { polygon });
    }

    /// A carve click or stroke: a ball at the click, and along the drag
    /// every half radius.
    fn on_carve(&mut self, input: &SliceInput) {
        if input.grab_start.is_some() {
            self.last_carve = None;
        }
        let at = input.carve_click.or(input.grab_to);
        if let Some(p) = at
            && (input.carve_click.is_some() || carve_again(self.last_carve, p, self.brush_mm))
        {
            self.last_carve = Some(p);
            self.worker.send(Command::Carve {
                centre: p.to_array(),
                radius: self.brush_mm,
            });
        }
        if input.drag_end {
            self.last_carve = None;
        }
    }

    fn on_grab(&mut self, input: &SliceInput) {
        if let Some(point) = input.grab_start {
            self.grab = Some(GrabDrag { point, to: point });
        }
        if let (Some(to), Some(g)) = (input.grab_to, &mut self.grab)
            && (to - g.to).length() > 1e-3
        {
            g.to = to;
            self.worker.send(Command::Drag {
                point: g.point.to_array(),
                to: to.to_array(),
            });
        }
    }

    fn on_slice_wheel_and_window(&mut self, n: usize, input: &SliceInput) {
        if let Some(d) = input.window_drag {
            self.window = drag_window(self.window, d.x, d.y);
        }
        self.wheel[n] += input.wheel;
        let slices = (self.wheel[n] / WHEEL_POINTS_PER_SLICE).trunc();
        if slices != 0.0 {
            self.wheel[n] -= slices * WHEEL_POINTS_PER_SLICE;
            if let Some(o) = &self.opened {
                let axis = normal_axis(AXES[n]);
                let mut c = self.cursor.to_array();
                let spacing = o.grid.spacing.to_array()[axis];
                c[axis] += slices as f64 * spacing;
                self.cursor = clamp_to_grid(&o.grid, DVec3::from_array(c));
            }
        }
    }
}

/// World point `p` (mm) moved into the box of `grid`'s voxel centres.
fn clamp_to_grid(grid: &Grid, p: DVec3) -> DVec3 {
    let f = grid.world_to_index(p);
    let top = DVec3::new(
        grid.dims[0] as f64 - 1.0,
        grid.dims[1] as f64 - 1.0,
        grid.dims[2] as f64 - 1.0,
    );
    grid.index_to_world(f.clamp(DVec3::ZERO, top.max(DVec3::ZERO)))
}

fn upload(
    ctx: &egui::Context,
    slot: &mut Option<TextureHandle>,
    name: &str,
    image: ColorImage,
    opts: TextureOptions,
) {
    match slot {
        Some(t) => t.set(image, opts),
        None => *slot = Some(ctx.load_texture(name, image, opts)),
    }
}

impl eframe::App for ViewerApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.show(ui);
        let ready = self.ready() || self.messages.iter().any(|m| m.starts_with("error"));
        let ctx = ui.ctx().clone();
        if let Some(r) = self.screenshot.on_frame(&ctx, self.frames, ready) {
            match r {
                Ok(()) => tracing::info!("screenshot done"),
                Err(e) => tracing::error!("{e}"),
            }
        }
    }
}
