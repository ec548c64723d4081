//! [`Session`]: the pipeline as an object a front end drives —
//!
//! ```text
//! source → model (+ interactions) → map → resample → roi → render → output
//! ```
//!
//! A session owns the loaded plugins, the source volume, the backend, the
//! stage [`Versions`] and the per-stage metrics. [`Session::interact`]
//! hands the model an interaction at any time; [`Session::step`] advances
//! the model one frame and re-runs only the stages whose input version
//! moved (a model that did not move re-runs nothing downstream) and says
//! what ran and why ([`StepReport`]). [`Session::render`] and
//! [`Session::slice`] make images in memory; ROI maps are grown stepwise
//! ([`Session::add_roi`], [`Session::roi_step`]) on the session's backend
//! (CPU or GPU) and shown by `render`.
//! A scene run ([`crate::pipeline::run_scene`]) is a loop over a session
//! that writes files; `voxflex bench` times the same stages.
//!
//! Tracked points ([`Session::track_points`], see `tracked.rs`) read the
//! displacement of chosen world points (landmarks, sensors, a bench's
//! probes) on demand, and [`Session::step_model`] advances the model alone,
//! leaving map and resample due for the next [`Session::step`]: `voxflex
//! bench --fronts` and `--stress` drive models this way. A model's error
//! says which call failed ([`ModelCall`], [`RunError::model_call`]).
//!
//! A session is [`Send`]: one thread at a time drives it, any thread may.
//!
//! ```no_run
//! use voxflex_core::glam::DVec3;
//! use voxflex_io::png::SliceAxis;
//! use voxflex_opacity::{GrowthParams, Seed};
//! use voxflex_runtime::backend::BackendChoice;
//! use voxflex_runtime::session::{
//!     Interaction, RenderParams, Session, SessionDefaults, SessionSource,
//! };
//!
//! // A 20³ cube phantom (100 mm field, the cube from −25 to 25 mm).
//! let cube = SessionSource::Phantom { name: "cube".into(), dims: [20, 20, 20] };
//! let cpu = SessionDefaults { backend: BackendChoice::Cpu, ..Default::default() };
//! let mut s = Session::from_volume(cube, cpu)?;
//! s.swap_model("chainmail", "materials = [{ range = [50, 200], constraint = 0.01 }]")?;
//! let roi = s.add_roi(Seed::World(DVec3::new(-12.5, 2.5, 2.5)), GrowthParams::default())?;
//! s.roi_run_to_end(roi)?;
//! // Drag the +x face 15 mm out over 10 calls, the target moving each call.
//! for k in 1..=10 {
//!     let to = [22.5 + 1.5 * k as f64, 2.5, 2.5];
//!     s.interact(&Interaction::Grab { point: [22.5, 2.5, 2.5], to, frames: 1 })?;
//!     println!("{}", s.step()?); // what re-ran and why
//! }
//! let camera = s.default_camera(256, 256)?;
//! let image = s.render(&camera, &RenderParams::default())?; // RGBA8, in memory
//! let slice = s.slice(SliceAxis::Axial, 10, None)?;
//! let click_mm = slice.pixel_to_world(5, 7);
//! println!("{}×{} px, click at {click_mm:?}", image.width, image.height);
//! println!("{}", s.metrics()?.to_json());
//! # Ok::<(), voxflex_runtime::pipeline::RunError>(())
//! ```

mod actuation;
mod defaults;
mod histogram;
mod interaction;
mod model_call;
mod model_stage;
mod pick;
mod plugins;
mod render;
mod report;
mod roi;
mod roi_auto;
mod roi_edit;
mod roi_visibility;
mod slice;
mod tracked;
mod versions;

pub use defaults::SessionDefaults;
pub use histogram::MAX_HISTOGRAM_BINS;
pub use interaction::Interaction;
pub use model_call::ModelCall;
pub use model_stage::AppliedInteraction;
pub use plugins::ScenePlugins;
pub use report::{StageOutcome, StepReport};
pub use roi::{RoiId, RoiInfo};
pub use roi_auto::AutoLambdaReport;
pub use slice::SliceImage;
pub use tracked::TrackId;
pub use versions::{StageVersion, Versions};
// The types a front end passes to and gets from a session, so that it
// needs the host (and voxflex-core) only.
pub use voxflex_core::opacity_map::OpacityMap;
pub use voxflex_core::slice_axis::SliceAxis;
pub use voxflex_core::stats::Histogram;
pub use voxflex_io::png::{GrayImage, Window};
pub use voxflex_opacity::{GrowthLimits, GrowthParams, GrowthReport, MAX_SEED_RADIUS, Seed};

use crate::backend::{self, BackendChoice, ResolvedBackend};
use crate::gpu_context::WgpuService;
use crate::metrics::{PluginReport, RunMetrics};
use crate::pipeline::{RunError, load_source};
use crate::plugin_loader::{self, LoadedPlugin, PluginListing};
use crate::scene::{CameraSettings, RenderSettings, Scene};
use crate::visualise::{RenderStage, camera_for};
use model_stage::{Displacements, ModelStage, ResampleStage, refilled_region};
use roi::{RoiDevice, SessionRoi};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use voxflex_abi::host_side::HostServices;
use voxflex_core::camera::Camera;
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend, FrameInfo, ModelNotes};
use voxflex_core::gpu::{BufferId, GpuService};
use voxflex_core::interaction::InteractionSpec;
use voxflex_core::shared_volume::SharedVolume;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_io::png::render_slice;
use voxflex_opacity::GpuOpacityVolume;
use voxflex_phantom::phantom;
use voxflex_resample::ResampleParams;

/// What a session starts from: a volume in memory or a built-in phantom.
#[derive(Clone, Debug)]
pub enum SessionSource {
    /// A volume already loaded.
    Volume(Volume),
    /// A volume file (NIfTI, MetaImage, NRRD; the format from its name),
    /// read with the default limits.
    File(PathBuf),
    /// A phantom (`head`, `cube`, … as `phantom:<name>` in scenes) of
    /// `dims` voxels.
    Phantom {
        /// Phantom name.
        name: String,
        /// Voxels along x, y, z.
        dims: [usize; 3],
    },
}

impl From<Volume> for SessionSource {
    fn from(v: Volume) -> Self {
        SessionSource::Volume(v)
    }
}

/// Which renderer plugin [`Session::render`] uses and its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderParams {
    /// Renderer plugin name (default `raycast`).
    pub plugin: String,
    /// Its parameters as TOML text (a scene's `[render.params]` table).
    pub params_toml: String,
}

impl Default for RenderParams {
    fn default() -> Self {
        Self {
            plugin: "raycast".into(),
            params_toml: String::new(),
        }
    }
}

/// The renderer a session built, with what it was built from.
struct RendererSlot {
    plugin: LoadedPlugin,
    params_toml: String,
    stage: RenderStage,
}

/// The pipeline as an object; see the module docs.
pub struct Session {
    /// Prefix of error messages (the scene file, or `session`).
    context: String,
    plugin_dirs: Vec<PathBuf>,
    threads: usize,
    choice: BackendChoice,
    resolved: ResolvedBackend,
    /// The device a front end offered ([`SessionDefaults::gpu`]).
    offered_gpu: Option<Arc<WgpuService>>,
    gpu: Option<Arc<dyn GpuService>>,
    services: Arc<HostServices>,
    /// The loaded volume, never changed; shared with the renderer while
    /// nothing deforms it (no copy, see `RenderVolume::Shared`).
    source: Arc<Volume>,
    /// The next frame the model steps.
    frame: u64,
    frames: u64,
    dt_s: f64,
    /// True when `metrics.frames` counts steps (sessions without a scene).
    counts_frames: bool,
    model: Option<ModelStage>,
    displacements: Option<Displacements>,
    resample: Option<ResampleStage>,
    resample_params: ResampleParams,
    wait_for_gpu: bool,
    renderer: Option<RendererSlot>,
    /// The image buffer of [`Self::render_to_gpu`] and its size in bytes.
    gpu_image: Option<(BufferId, u64)>,
    rois: Vec<SessionRoi>,
    next_roi: u64,
    /// Tracked point sets, bound on every model (see `tracked.rs`).
    tracked: Vec<tracked::TrackedSet>,
    /// The scene's actuators and effectors, bound on the model.
    actuation: Option<crate::actuation::stage::ActuationStage>,
    next_track: u64,
    /// The current volume uploaded for the ROI maps growing on the GPU,
    /// with the resample version it holds (0: the source); `None` on the
    /// CPU or without GPU ROI maps.
    roi_values: Option<(u64, GpuOpacityVolume)>,
    versions: Versions,
    /// Source region (mm) the model moved since the last resample.
    dirty: DirtyRegion,
    /// Output region (mm) re-filled since the last render.
    render_dirty: DirtyRegion,
    /// The resampled volume read back, at the resample version it holds.
    resampled: Option<(u64, Volume)>,
    /// Interaction time not yet counted in the model stage.
    pending_interaction: Duration,
    /// A cut or carve since the last map: the mask must be asked again
    /// even when the model reports no motion.
    topology_changed: bool,
    metrics: RunMetrics,
    opened: Instant,
}

/// A session moves between threads (the viewer's worker, a test's spawn).
const _: fn() = || {
    fn assert_send<T: Send>() {}
    assert_send::<Session>();
};

/// What [`Session::open_loaded`] and [`Session::from_volume`] settle
/// before a session exists; [`Session::assemble`] builds it from this.
struct Opening {
    context: String,
    plugin_dirs: Vec<PathBuf>,
    threads: usize,
    choice: BackendChoice,
    resolved: ResolvedBackend,
    offered_gpu: Option<Arc<WgpuService>>,
    source: Volume,
    /// Wall time of loading (or generating) the source.
    source_wall: Duration,
    frames: u64,
    dt_s: f64,
    counts_frames: bool,
    resample_params: ResampleParams,
    wait_for_gpu: bool,
    metrics: RunMetrics,
    opened: Instant,
}

fn configure_threads(threads: usize) {
    if threads > 0 {
        // Only the first call in a process takes effect; later ones share it.
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global();
    }
}

fn plugin_report(p: &LoadedPlugin) -> PluginReport {
    PluginReport {
        name: p.name.clone(),
        version: p.version.clone(),
        path: p.path.display().to_string(),
    }
}

fn backend_name(b: ExecutionBackend) -> String {
    match b {
        ExecutionBackend::Cpu => "cpu".into(),
        ExecutionBackend::Gpu => "gpu".into(),
    }
}

/// True for a deformation plugin that declares no GPU path.
fn cpu_only(p: &LoadedPlugin) -> bool {
    p.deformation.is_some() && p.capabilities & voxflex_abi::ffi::CAPABILITY_GPU == 0
}

/// The resolved choice for a model plugin: a CPU-only plugin takes the
/// CPU under `auto` and refuses an explicit `gpu`.
fn choice_for(
    context: &str,
    choice: BackendChoice,
    model: Option<&LoadedPlugin>,
) -> Result<BackendChoice, RunError> {
    match (choice, model.filter(|p| cpu_only(p))) {
        (BackendChoice::Gpu, Some(p)) => Err(RunError::Other(format!(
            "{context}: backend = \"gpu\", but plugin `{}` has no GPU path; use backend = \"cpu\" or \"auto\"",
            p.name
        ))),
        (BackendChoice::Auto, Some(_)) => Ok(BackendChoice::Cpu),
        (c, _) => Ok(c),
    }
}

impl Session {
    /// Opens a scene: loads the plugins it names, resolves its backend,
    /// loads its source and builds the stages it asks for (see
    /// [`Self::open_loaded`]).
    pub fn open(scene: &Scene) -> Result<Self, RunError> {
        let plugins = ScenePlugins::load(scene)?;
        Self::open_loaded(scene, &plugins)
    }

    /// [`Self::open`] with the scene's plugins already loaded. Stages the
    /// scene does not ask for are not built (and listed in
    /// `metrics.stages_not_built`); the GPU is not initialised for a CPU
    /// scene or one with nothing to compute.
    pub fn open_loaded(scene: &Scene, plugins: &ScenePlugins) -> Result<Self, RunError> {
        Self::open_loaded_on(scene, plugins, None)
    }

    /// [`Self::open`] computing on `gpu` — a device a front end opened
    /// (the viewer's eframe device) — instead of opening one, as
    /// [`SessionDefaults::gpu`] does for [`Self::from_volume`]: the scene's
    /// `gpu` takes it, `auto` takes it when it is a hardware adapter, and
    /// [`Self::set_backend`] uses it later.
    pub fn open_on(scene: &Scene, gpu: Option<Arc<WgpuService>>) -> Result<Self, RunError> {
        let plugins = ScenePlugins::load(scene)?;
        Self::open_loaded_on(scene, &plugins, gpu)
    }

    fn open_loaded_on(
        scene: &Scene,
        plugins: &ScenePlugins,
        gpu: Option<Arc<WgpuService>>,
    ) -> Result<Self, RunError> {
        let opened = Instant::now();
        let context = scene.path.display().to_string();
        configure_threads(scene.settings.threads);
        let choice = choice_for(&context, scene.settings.backend, plugins.model.as_ref())?;
        let mut resolved =
            if scene.model.is_some() || scene.render.is_some() || !scene.rois.is_empty() {
                backend::resolve_on(choice, gpu.as_ref())?
            } else {
                // Nothing to compute: never initialise a GPU.
                backend::resolve(BackendChoice::Cpu)?
            };
        if let (BackendChoice::Auto, Some(p)) = (
            scene.settings.backend,
            plugins.model.as_ref().filter(|p| cpu_only(p)),
        ) {
            resolved.reason = format!(
                "backend = \"auto\": plugin `{}` computes on the CPU only, so rayon on the CPU",
                p.name
            );
        }
        let metrics = RunMetrics {
            scene: scene.settings.name.clone(),
            voxflex_version: env!("CARGO_PKG_VERSION").into(),
            frames: scene.settings.frames,
            plugin: plugins.model.as_ref().map(plugin_report),
            backend: backend_name(resolved.backend),
            backend_reason: resolved.reason.clone(),
            ..Default::default()
        };
        // Stage: source.
        let t = Instant::now();
        let source = load_source(scene)?;
        let source_wall = t.elapsed();

        let background = scene
            .resample
            .as_ref()
            .and_then(|r| r.background)
            .unwrap_or_else(|| source.value_range().0);
        let params = ResampleParams {
            background,
            ..ResampleParams::default()
        };
        let resample_params = match &scene.resample {
            Some(r) => r.apply(params),
            None => params,
        };
        let mut session = Session::assemble(Opening {
            context,
            plugin_dirs: scene.plugin_dirs(),
            threads: scene.settings.threads,
            choice: scene.settings.backend,
            resolved,
            offered_gpu: gpu,
            source,
            source_wall,
            frames: scene.settings.frames,
            dt_s: scene.settings.dt_s,
            counts_frames: false,
            resample_params,
            wait_for_gpu: false,
            metrics,
            opened,
        });
        match (&scene.model, &plugins.model) {
            (Some(_), Some(p)) => session.build_model(p, &scene.model_params_toml())?,
            _ => {
                session.metrics.stages_not_built =
                    vec!["model".into(), "map".into(), "resample".into()]
            }
        }
        session.build_actuation(scene, plugins)?;
        match (&scene.render, &plugins.renderer) {
            (Some(_), Some(p)) => session.build_renderer(p, &scene.render_params_toml())?,
            _ => session.metrics.stages_not_built.push("render".into()),
        }
        if scene.rois.is_empty() {
            session.metrics.stages_not_built.push("roi".into());
        }
        // The first step maps from whatever the model reports.
        session.dirty = DirtyRegion::None;
        Ok(session)
    }

    /// A session on a volume in memory or a phantom, with no model (add
    /// one with [`Self::swap_model`]), no renderer (built by the first
    /// [`Self::render`]) and no ROI maps.
    pub fn from_volume(
        source: impl Into<SessionSource>,
        defaults: SessionDefaults,
    ) -> Result<Self, RunError> {
        let opened = Instant::now();
        configure_threads(defaults.threads);
        let t = Instant::now();
        let source = match source.into() {
            SessionSource::Volume(v) => v,
            SessionSource::File(path) => voxflex_io::read_volume(&path, &defaults.read)?,
            SessionSource::Phantom { name, dims } => phantom(&name, dims)
                .map_err(|e| RunError::Other(format!("session: phantom `{name}`: {e}")))?,
        };
        let source_wall = t.elapsed();
        let resolved = backend::resolve_on(defaults.backend, defaults.gpu.as_ref())?;
        let metrics = RunMetrics {
            scene: "session".into(),
            voxflex_version: env!("CARGO_PKG_VERSION").into(),
            backend: backend_name(resolved.backend),
            backend_reason: resolved.reason.clone(),
            stages_not_built: ["model", "map", "resample", "render", "roi"]
                .map(String::from)
                .to_vec(),
            ..Default::default()
        };
        let resample_params = ResampleParams {
            background: defaults
                .background
                .unwrap_or_else(|| source.value_range().0),
            ..defaults.resample
        };
        Ok(Session::assemble(Opening {
            context: "session".into(),
            plugin_dirs: defaults.plugin_dirs,
            threads: defaults.threads,
            choice: defaults.backend,
            resolved,
            offered_gpu: defaults.gpu,
            source,
            source_wall,
            frames: defaults.frames,
            dt_s: defaults.dt_s,
            counts_frames: true,
            resample_params,
            wait_for_gpu: defaults.wait_for_gpu,
            metrics,
            opened,
        }))
    }

    /// A session at frame 0 on `o.source`: the source stage's run recorded,
    /// the GPU service and host services from `o.resolved`, no model,
    /// renderer, ROI maps or tracked points, every stage due.
    fn assemble(o: Opening) -> Self {
        let mut metrics = o.metrics;
        metrics
            .stage("source")
            .record_run(o.source_wall, o.source.grid.len() as u64);
        metrics.source_dims = o.source.grid.dims;
        metrics.output_dims = o.source.grid.dims;
        let gpu = o.resolved.gpu_service();
        Session {
            context: o.context,
            plugin_dirs: o.plugin_dirs,
            threads: o.threads,
            choice: o.choice,
            services: HostServices::new(gpu.clone(), rayon::current_num_threads()),
            resolved: o.resolved,
            offered_gpu: o.offered_gpu,
            gpu,
            source: Arc::new(o.source),
            frame: 0,
            frames: o.frames,
            dt_s: o.dt_s,
            counts_frames: o.counts_frames,
            model: None,
            displacements: None,
            resample: None,
            resample_params: o.resample_params,
            wait_for_gpu: o.wait_for_gpu,
            renderer: None,
            gpu_image: None,
            rois: vec![],
            next_roi: 0,
            tracked: vec![],
            actuation: None,
            next_track: 0,
            roi_values: None,
            versions: Versions::default(),
            dirty: DirtyRegion::None,
            render_dirty: DirtyRegion::All,
            resampled: None,
            pending_interaction: Duration::ZERO,
            topology_changed: false,
            metrics,
            opened: o.opened,
        }
    }

    fn built(&mut self, stages: &[&str]) {
        self.metrics
            .stages_not_built
            .retain(|s| !stages.contains(&s.as_str()));
    }

    /// Builds the model stage (and the map and resample stages the first
    /// time) with `plugin`, the tracked points bound on it; the next step
    /// maps in full.
    fn build_model(&mut self, plugin: &LoadedPlugin, params_toml: &str) -> Result<(), RunError> {
        let mut stage = ModelStage::new(
            &self.context,
            plugin,
            params_toml,
            self.services.clone(),
            &self.source,
            self.resolved.backend,
        )?;
        for set in &self.tracked {
            tracked::bind(&mut stage, set)?;
        }
        if let Some(a) = &mut self.actuation {
            a.bind(stage.model.as_mut())?;
        }
        if self.displacements.is_none() {
            self.displacements = Some(Displacements::new(
                &self.source,
                self.resolved.backend,
                &self.gpu,
            )?);
        }
        if self.resample.is_none() {
            self.resample = Some(ResampleStage::new(self.resample_params));
        }
        self.model = Some(stage);
        self.metrics.plugin = Some(plugin_report(plugin));
        self.versions.map.invalidate();
        self.dirty = DirtyRegion::All;
        self.built(&["model", "map", "resample"]);
        Ok(())
    }

    fn build_renderer(&mut self, plugin: &LoadedPlugin, params_toml: &str) -> Result<(), RunError> {
        let stage = RenderStage::new(
            &self.context,
            plugin,
            params_toml,
            self.services.clone(),
            self.resolved.backend,
        )?;
        self.renderer = Some(RendererSlot {
            plugin: plugin.clone(),
            params_toml: params_toml.to_owned(),
            stage,
        });
        self.render_dirty = DirtyRegion::All;
        self.built(&["render"]);
        Ok(())
    }

    fn load_plugin(&self, name: &str) -> Result<LoadedPlugin, RunError> {
        Ok(plugin_loader::load_by_name(
            name,
            &plugin_loader::search_path(&self.plugin_dirs),
        )?)
    }

    /// Hands the model an interaction; it takes effect at the next
    /// [`Self::step`]. Any time, as often as wanted (a drag is a grab sent
    /// again with a new target each call). Errors when there is no model
    /// or the model refuses it (the message names the plugin).
    pub fn interact(&mut self, interaction: &Interaction) -> Result<(), RunError> {
        let t = Instant::now();
        let m = self.model.as_mut().ok_or_else(|| {
            RunError::Other(format!(
                "{}: an interaction needs a model; call swap_model first",
                self.context
            ))
        })?;
        let text = interaction.to_toml();
        m.model
            .interact(&text)
            .map_err(ModelCall::Interact.failed())?;
        let kind = InteractionSpec::from_toml(&text).map(|s| s.kind());
        self.topology_changed |= matches!(kind, Ok("cut" | "carve"));
        m.received.push(AppliedInteraction {
            frame: m.frame,
            toml: text,
        });
        self.pending_interaction += t.elapsed();
        Ok(())
    }

    /// Advances the model one frame and re-runs the stages whose input
    /// moved: map when the model changed (or a cut or carve changed its
    /// topology, moved or not), resample when the map did, the
    /// session's ROI maps when the volume did. A model that did not move
    /// re-runs nothing downstream. Returns what ran and why.
    pub fn step(&mut self) -> Result<StepReport, RunError> {
        let mut report = StepReport {
            frame: self.frame,
            stages: vec![],
        };
        if self.model.is_some() {
            report.stages.push(self.model_stage()?);
            report.stages.push(self.map_stage()?);
            report.stages.push(self.resample_stage()?);
        } else {
            for stage in ["model", "map", "resample"] {
                report.push(
                    stage,
                    false,
                    "not built: the session has no model".into(),
                    Duration::ZERO,
                    0,
                );
            }
        }
        if !self.rois.is_empty() {
            report.stages.push(self.roi_stage()?);
        }
        self.advance_frame();
        Ok(report)
    }

    /// Advances the model alone one frame — the interactions handed over
    /// since the last step, then the model stage — and leaves the map,
    /// resample and ROI stages due: the next [`Self::step`] runs whichever
    /// its [`Versions`] say (what the model moved is mapped and resampled
    /// then; a model that did not move re-runs nothing, as ever). For a
    /// caller that reads the model through tracked points
    /// ([`Self::track_points`]) and looks at no volume (benches, sensors):
    /// nothing is mapped or re-sampled. Counts a frame like `step`; the
    /// report holds the model stage only (not built without a model).
    pub fn step_model(&mut self) -> Result<StepReport, RunError> {
        let mut report = StepReport {
            frame: self.frame,
            stages: vec![],
        };
        if self.model.is_some() {
            report.stages.push(self.model_stage()?);
        } else {
            report.push(
                "model",
                false,
                "not built: the session has no model".into(),
                Duration::ZERO,
                0,
            );
        }
        self.advance_frame();
        Ok(report)
    }

    /// One frame stepped (by `step` or `step_model`).
    fn advance_frame(&mut self) {
        self.frame += 1;
        if self.counts_frames {
            self.metrics.frames = self.frame;
        }
    }

    /// Stage model: steps the model one frame (its own clock) with the
    /// interactions handed over since the last step; a new model version
    /// when it moved.
    fn model_stage(&mut self) -> Result<StageOutcome, RunError> {
        let m = self.model.as_mut().ok_or_else(no_model)?;
        let t = Instant::now();
        let frame = FrameInfo {
            frame: m.frame,
            frames: self.frames,
            dt_s: self.dt_s,
        };
        if let Some(a) = &mut self.actuation {
            a.before_step(m.model.as_mut(), frame)?;
        }
        let mut outcome = m.model.step(frame).map_err(ModelCall::Step.failed())?;
        if let Some(a) = &mut self.actuation {
            outcome.changed |= a.after_step(m.model.as_mut(), frame)?;
        }
        m.frame += 1;
        let wall = t.elapsed() + std::mem::take(&mut self.pending_interaction);
        self.metrics.stage("model").record_run(wall, 0);
        let why = if outcome.changed {
            self.versions.model += 1;
            format!("stepped; the model moved (version {})", self.versions.model)
        } else {
            "stepped; the model did not move".to_string()
        };
        Ok(ran("model", why, wall, 0))
    }

    /// Stage map: the model's displacements at the sampling mesh's
    /// vertices, and its removed tetrahedra, when the model moved — or
    /// when a cut or carve changed its topology without moving it.
    fn map_stage(&mut self) -> Result<StageOutcome, RunError> {
        let input = self.versions.model;
        let due = self.versions.map.is_due(input);
        let topology = std::mem::take(&mut self.topology_changed);
        let why = if !due && topology {
            "a cut or carve changed the model's topology".to_string()
        } else {
            self.versions.map.reason("model", input)
        };
        if !(due || topology) {
            self.metrics.stage("map").skipped += 1;
            return Ok(skipped("map", why));
        }
        let (Some(m), Some(disp)) = (self.model.as_mut(), self.displacements.as_mut()) else {
            return Err(no_model());
        };
        let t = Instant::now();
        self.dirty = self.dirty.union(m.model.dirty_region());
        m.map(disp)?;
        m.update_mask()?;
        self.versions.map.ran_on(input);
        let wall = t.elapsed();
        let points = self.source.grid.len() as u64;
        self.metrics.stage("map").record_run(wall, points);
        Ok(ran("map", why, wall, points))
    }

    /// Stage resample: the source re-sampled under the mapped
    /// displacements over the dirty region, when the map moved.
    fn resample_stage(&mut self) -> Result<StageOutcome, RunError> {
        let input = self.versions.map.version;
        let why = self.versions.resample.reason("map", input);
        if !self.versions.resample.is_due(input) {
            self.metrics.stage("resample").skipped += 1;
            return Ok(skipped("resample", why));
        }
        let (Some(m), Some(disp), Some(res)) = (
            self.model.as_ref(),
            self.displacements.as_ref(),
            self.resample.as_mut(),
        ) else {
            return Err(no_model());
        };
        let t = Instant::now();
        let mask = m.mask.as_ref().map(|(mask, _)| mask);
        let r = res.run(
            &self.source,
            disp,
            mask,
            &self.gpu,
            self.dirty,
            self.wait_for_gpu,
        )?;
        self.dirty = DirtyRegion::None;
        self.versions.resample.ran_on(input);
        let wall = t.elapsed();
        self.metrics
            .stage("resample")
            .record_run(wall, r.voxels_touched);
        let output_grid = res.resampler.output_grid();
        self.render_dirty = self.render_dirty.union(refilled_region(&r, output_grid));
        if let Some(g) = output_grid {
            self.metrics.output_dims = g.dims;
        }
        // Displacements (3 × f32) plus the resampler's own scratch.
        self.metrics.resample_extra_bytes_per_voxel =
            12.0 + res.resampler.scratch_bytes() as f64 / self.source.grid.len().max(1) as f64;
        let why = format!("{why}; {} voxels re-filled", r.voxels_touched);
        Ok(ran("resample", why, wall, r.voxels_touched))
    }

    /// Stage roi: the session's maps re-grown (as far as they had grown)
    /// on a new volume.
    fn roi_stage(&mut self) -> Result<StageOutcome, RunError> {
        let input = self.versions.resample.version;
        let why = self.versions.roi.reason("resample", input);
        if !self.versions.roi.is_due(input) {
            self.metrics.stage("roi").skipped += 1;
            return Ok(skipped("roi", why));
        }
        let t = Instant::now();
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let (rois, volume, device) = self.roi_parts();
        let mut visits = 0;
        for r in rois {
            visits += r.regrow(volume, device)?.visits;
        }
        self.versions.roi.ran_on(input);
        let wall = t.elapsed();
        self.metrics.stage("roi").record_run(wall, visits);
        Ok(ran("roi", format!("{why}; maps re-grown"), wall, visits))
    }

    /// Replaces the model with an instance of `plugin` (its parameters as
    /// TOML text), initialised on the source volume at rest; its frames
    /// count from 0 (`FrameInfo::frame` is the model's own clock). The volume,
    /// the resampled output, the ROI maps and the renderer are kept; the
    /// next [`Self::step`] maps and resamples in full. Under `auto` a
    /// CPU-only plugin moves a GPU session to the CPU (as
    /// [`Self::set_backend`]); under `gpu` it is refused.
    pub fn swap_model(&mut self, plugin: &str, params_toml: &str) -> Result<(), RunError> {
        let p = self.load_plugin(plugin)?;
        let choice = choice_for(&self.context, self.choice, Some(&p))?;
        if choice != self.choice && self.resolved.backend == ExecutionBackend::Gpu {
            // Drop the old model first: its GPU buffers live in the old context.
            self.model = None;
            self.rebuild_backend(BackendChoice::Cpu)?;
        }
        let old = self.model.take();
        if let Err(e) = self.build_model(&p, params_toml) {
            self.model = old;
            return Err(e);
        }
        Ok(())
    }

    /// Moves every stage to another backend (`cpu`, `gpu` or `auto`) and
    /// returns the adapter computing now (`cpu` for the CPU path). The
    /// model is rebuilt on the source at rest with the same plugin and
    /// parameters (a plugin's state cannot move between backends); the
    /// resampled volume is kept, the ROI maps are re-grown on the new
    /// backend as far as they had grown, and the next step maps and
    /// resamples in full. When a stage cannot be built on the new backend
    /// (a model the device cannot hold, a CPU-only setting), every stage
    /// is built again on the backend the session ran on and the error says
    /// so: a failed switch leaves the session as a successful switch back
    /// would (model at rest, ROI maps as far as they had grown).
    pub fn set_backend(&mut self, choice: BackendChoice) -> Result<String, RunError> {
        let model = self.model.as_ref().map(|m| m.plugin.clone());
        let resolved_choice = choice_for(&self.context, choice, model.as_ref())?;
        // Keep the current output: the new resampler has none yet.
        self.ensure_volume()?;
        let resolved = backend::resolve_on(resolved_choice, self.offered_gpu.as_ref())?;
        let previous = self.resolved.clone();
        let stages = self.stage_specs();
        if let Err(e) = self.move_to(resolved, &stages) {
            let was = backend_name(previous.backend);
            return Err(match self.move_to(previous, &stages) {
                Ok(()) => RunError::Other(format!(
                    "moving to backend `{choice}`: {e}; the session stays on `{was}`"
                )),
                Err(back) => RunError::Other(format!(
                    "moving to backend `{choice}`: {e}; moving back to `{was}` failed too: {back}"
                )),
            });
        }
        self.choice = choice;
        Ok(self.adapter_name())
    }

    /// The adapter computing now: the GPU's name, or `cpu`.
    pub fn adapter_name(&self) -> String {
        match &self.resolved.gpu {
            Some(g) => g.info().name,
            None => "cpu".into(),
        }
    }

    /// Moves every stage to `choice` (see [`Self::set_backend`]), without
    /// a way back: for a switch that cannot fail to resolve (the CPU).
    fn rebuild_backend(&mut self, choice: BackendChoice) -> Result<(), RunError> {
        self.ensure_volume()?;
        let resolved = backend::resolve_on(choice, self.offered_gpu.as_ref())?;
        let stages = self.stage_specs();
        self.move_to(resolved, &stages)
    }

    /// The plugin and parameters of the model and the renderer, to build
    /// them again.
    fn stage_specs(&self) -> StageSpecs {
        StageSpecs {
            model: self
                .model
                .as_ref()
                .map(|m| (m.plugin.clone(), m.params_toml.clone())),
            renderer: self
                .renderer
                .as_ref()
                .map(|r| (r.plugin.clone(), r.params_toml.clone())),
        }
    }

    /// Drops every stage's state on the current backend and builds
    /// `stages` on `resolved`; the ROI maps follow.
    fn move_to(&mut self, resolved: ResolvedBackend, stages: &StageSpecs) -> Result<(), RunError> {
        // Their buffers live in the old context: dropped before it.
        self.model = None;
        self.renderer = None;
        self.release_gpu();
        self.displacements = None;
        self.resample = None;
        self.gpu = resolved.gpu_service();
        self.services = HostServices::new(self.gpu.clone(), rayon::current_num_threads());
        self.metrics.backend = backend_name(resolved.backend);
        self.metrics.backend_reason = resolved.reason.clone();
        self.resolved = resolved;
        if let Some((p, params)) = &stages.model {
            self.build_model(p, params)?;
        }
        if let Some((p, params)) = &stages.renderer {
            self.build_renderer(p, params)?;
        }
        // The ROI maps re-grown on the new backend as far as before.
        self.follow_rois()
    }

    /// Re-grows on the session's backend, as far as before, every ROI map
    /// whose growth was released or lives on the other backend.
    fn follow_rois(&mut self) -> Result<(), RunError> {
        if self.rois.is_empty() {
            return Ok(());
        }
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let (rois, volume, device) = self.roi_parts();
        for r in rois {
            r.follow(volume, device)?;
        }
        Ok(())
    }

    /// Uploads the current volume for the ROI maps when the session
    /// computes on the GPU and the copy there is missing or older (after
    /// [`Self::ensure_volume`]); nothing on the CPU.
    fn ensure_roi_values(&mut self) -> Result<(), RunError> {
        let Some(gpu) = &self.gpu else {
            return Ok(());
        };
        let at = self.resampled.as_ref().map_or(0, |(v, _)| *v);
        match self.roi_values {
            Some((held, _)) if held == at => return Ok(()),
            Some((_, old)) => {
                old.release(gpu.as_ref());
                self.roi_values = None;
            }
            None => {}
        }
        let values =
            GpuOpacityVolume::upload(gpu.as_ref(), self.volume_ref().view()).map_err(roi_err)?;
        self.roi_values = Some((at, values));
        Ok(())
    }

    /// Frees the ROI maps' upload of the volume once no map grows on the GPU.
    fn release_unused_roi_values(&mut self) {
        if self.rois.iter().any(SessionRoi::on_gpu) {
            return;
        }
        if let (Some((_, values)), Some(gpu)) = (self.roi_values.take(), &self.gpu) {
            values.release(gpu.as_ref());
        }
    }

    /// The ROI maps, the volume they grow on and where they grow (the
    /// GPU only once [`Self::ensure_roi_values`] uploaded the volume).
    fn roi_parts(&mut self) -> (&mut [SessionRoi], &Volume, RoiDevice<'_>) {
        let volume = match &self.resampled {
            Some((_, v)) => v,
            None => self.source.as_ref(),
        };
        let device = match (&self.gpu, &self.roi_values) {
            (Some(gpu), Some((_, values))) => RoiDevice::Gpu {
                gpu: gpu.as_ref(),
                values,
            },
            _ => RoiDevice::Cpu,
        };
        (&mut self.rois, volume, device)
    }

    fn release_gpu(&mut self) {
        let gpu = self.gpu.as_deref();
        for r in &mut self.rois {
            if r.on_gpu() {
                r.release(gpu);
            }
        }
        if let (Some((_, values)), Some(gpu)) = (self.roi_values.take(), gpu) {
            values.release(gpu);
        }
        if let Some(d) = &self.displacements {
            d.release(&self.gpu);
        }
        if let (Some(r), Some(gpu)) = (self.resample.as_mut(), &self.gpu) {
            r.resampler.release_gpu(gpu.as_ref());
        }
        if let (Some((id, _)), Some(gpu)) = (self.gpu_image.take(), &self.gpu) {
            gpu.destroy_buffer(id);
        }
    }

    /// Reads the resampled volume back when the cached copy is older than
    /// the resample stage's output.
    fn ensure_volume(&mut self) -> Result<(), RunError> {
        let v = self.versions.resample.version;
        if v == 0 || self.resampled.as_ref().is_some_and(|(at, _)| *at == v) {
            return Ok(());
        }
        let (Some(res), Some(disp)) = (&self.resample, &self.displacements) else {
            return Ok(());
        };
        let out = res.read_back(disp, &self.gpu)?;
        let volume = Volume::new(out.grid, VoxelData::F32(out.values))
            .map_err(|e| RunError::Other(e.to_string()))?;
        self.resampled = Some((v, volume));
        Ok(())
    }

    /// The volume as it stands, after [`Self::ensure_volume`].
    fn volume_ref(&self) -> &Volume {
        match &self.resampled {
            Some((_, v)) => v,
            None => self.source.as_ref(),
        }
    }

    /// The current volume: the last resampled output (f32, on the output
    /// grid, world mm), or the source before any resample or without a
    /// model.
    pub fn volume(&mut self) -> Result<&Volume, RunError> {
        self.ensure_volume()?;
        Ok(self.volume_ref())
    }

    /// The map stage's displacement field: one displacement per source
    /// voxel (x fastest, on the source grid), mm, world axes, as x, y and z
    /// arrays — read back from the GPU when the session computes there.
    /// Runs the map stage first when it is due (the model moved, or a cut
    /// or carve changed its topology, since the last map: every voxel
    /// centre mapped and the removed tetrahedra asked for), so the next
    /// [`Self::step`] does not map again but resamples what moved. Errors
    /// without a model, or with the model's [`ModelCall::Map`] or
    /// [`ModelCall::RemovedTetrahedra`] error.
    pub fn displacement_field(&mut self) -> Result<[Vec<f32>; 3], RunError> {
        if self.model.is_none() {
            return Err(no_model());
        }
        if self.versions.map.is_due(self.versions.model) || self.topology_changed {
            self.map_stage()?;
        }
        let n = self.source.grid.len();
        let disp = self.displacements.as_ref().ok_or_else(no_model)?;
        disp.to_cpu(n, &self.gpu)
    }

    /// The source volume, as loaded.
    pub fn source(&self) -> &Volume {
        &self.source
    }

    /// The stage versions.
    pub fn versions(&self) -> Versions {
        self.versions
    }

    /// The interactions the current model received so far (since
    /// [`Self::swap_model`] built it), in order, each with the frame of the
    /// model's clock it came before: a scene with these as
    /// `[[interaction]]` tables and [`Self::model_frames`] frames makes
    /// `voxflex run` step the model through the same inputs. Empty without
    /// a model.
    pub fn interactions_so_far(&self) -> Vec<AppliedInteraction> {
        self.model
            .as_ref()
            .map(|m| m.received.clone())
            .unwrap_or_default()
    }

    /// Frames the current model has stepped (its own clock; `None`
    /// without a model).
    pub fn model_frames(&self) -> Option<u64> {
        self.model.as_ref().map(|m| m.frame)
    }

    /// The current model's plugin name and parameters (TOML text).
    pub fn model_params(&self) -> Option<(String, String)> {
        self.model
            .as_ref()
            .map(|m| (m.plugin.name.clone(), m.params_toml.clone()))
    }

    /// The next frame the model steps (the number of steps so far).
    pub fn frame(&self) -> u64 {
        self.frame
    }

    /// The camera of a `[render]` table with default camera settings
    /// (looking at the current volume's centre from its front, the whole
    /// volume in view), `width` × `height` pixels.
    pub fn default_camera(&mut self, width: u32, height: u32) -> Result<Camera, RunError> {
        self.ensure_volume()?;
        let settings = RenderSettings {
            plugin: String::new(),
            width,
            height,
            camera: CameraSettings::default(),
            turntable: 0,
            file: String::new(),
            params: Default::default(),
        };
        Ok(camera_for(&settings, &self.volume_ref().grid, 0.0))
    }

    /// Slice `index` (voxel index along `axis`) of the current volume as an
    /// 8-bit image, one pixel per voxel, through `window` (default: the
    /// volume's value range), with the pixel ↔ world mapping for clicks.
    pub fn slice(
        &mut self,
        axis: SliceAxis,
        index: usize,
        window: Option<Window>,
    ) -> Result<SliceImage, RunError> {
        self.ensure_volume()?;
        let volume = self.volume_ref();
        let window = window.unwrap_or_else(|| {
            let (lo, hi) = volume.value_range();
            Window {
                level: 0.5 * (lo + hi),
                width: (hi - lo).max(f32::MIN_POSITIVE),
            }
        });
        let image = render_slice(volume.view(), axis, index, window)
            .map_err(|e| RunError::Other(format!("{}: slice: {e}", self.context)))?;
        Ok(SliceImage {
            image,
            axis,
            index,
            grid: volume.grid,
        })
    }

    /// Seeds an ROI map on the current volume (no step yet; see
    /// [`Self::roi_step`]) on the session's backend: the CPU, or the GPU
    /// over one upload of the current volume shared by every map. The map
    /// is re-grown as far again whenever the volume or the backend
    /// changes, and shown by [`Self::render`].
    pub fn add_roi(&mut self, seed: Seed, params: GrowthParams) -> Result<RoiId, RunError> {
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let id = RoiId(self.next_roi);
        let (_, volume, device) = self.roi_parts();
        let roi = match SessionRoi::new(id, volume, device, seed, params) {
            Ok(r) => r,
            Err(e) => {
                self.release_unused_roi_values();
                return Err(e);
            }
        };
        self.next_roi += 1;
        self.rois.push(roi);
        self.versions.roi.consumed = Some(self.versions.resample.version);
        self.built(&["roi"]);
        Ok(id)
    }

    fn roi_index(&self, id: RoiId) -> Result<usize, RunError> {
        self.rois
            .iter()
            .position(|r| r.id == id)
            .ok_or_else(|| RunError::Other(format!("{}: no ROI map {}", self.context, id.0)))
    }

    /// Grows ROI map `id` by up to `n` steps (the stepwise expansion; fewer
    /// when it converges first).
    pub fn roi_step(&mut self, id: RoiId, n: usize) -> Result<GrowthReport, RunError> {
        let i = self.roi_index(id)?;
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let t = Instant::now();
        let (rois, volume, device) = self.roi_parts();
        let report = rois[i].step(volume, device, n)?;
        self.metrics
            .stage("roi")
            .record_run(t.elapsed(), report.visits);
        Ok(report)
    }

    /// Grows ROI map `id` to convergence (and to convergence again on every
    /// new volume).
    pub fn roi_run_to_end(&mut self, id: RoiId) -> Result<GrowthReport, RunError> {
        let i = self.roi_index(id)?;
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let t = Instant::now();
        let (rois, volume, device) = self.roi_parts();
        let report = rois[i].run_to_end(volume, device)?;
        self.metrics
            .stage("roi")
            .record_run(t.elapsed(), report.visits);
        Ok(report)
    }

    /// Removes ROI map `id` (freeing its GPU buffers, and the volume's
    /// upload with the last GPU map); false when there was none.
    pub fn remove_roi(&mut self, id: RoiId) -> bool {
        let Some(i) = self.rois.iter().position(|r| r.id == id) else {
            return false;
        };
        let mut roi = self.rois.remove(i);
        roi.release(self.gpu.as_deref());
        self.release_unused_roi_values();
        true
    }

    /// The ROI maps, in the order they were added.
    pub fn rois(&self) -> Vec<RoiInfo> {
        self.rois.iter().map(SessionRoi::info).collect()
    }

    /// ROI map `id` as it stands (a voxel box of the current volume's grid).
    pub fn roi_map(&self, id: RoiId) -> Option<&OpacityMap> {
        self.rois.iter().find(|r| r.id == id).map(|r| r.map())
    }

    /// What the model reports about its own work (iterations, points bound
    /// outside its proxy, …); empty without a model.
    pub fn model_notes(&mut self) -> Result<ModelNotes, RunError> {
        match self.model.as_mut() {
            Some(m) => Ok(m.model.notes().map_err(ModelCall::Notes.failed())?),
            None => Ok(ModelNotes::new()),
        }
    }

    /// The run report so far — the figures `metrics.json` holds: per-stage
    /// runs, skips, wall time and voxels, the model's notes, the backend
    /// and why, dims and memory. `total_wall_ms` is the time since the
    /// session opened.
    pub fn metrics(&mut self) -> Result<RunMetrics, RunError> {
        let notes = self.model_notes()?;
        let mut m = self.metrics.clone();
        if let Some(a) = &mut self.actuation {
            m.actuation = Some(a.report()?);
        }
        if self.model.is_some() {
            let stage = m.stage("model");
            for (name, value) in notes {
                stage.notes.insert(name, value.into());
            }
        }
        m.total_wall_ms = self.opened.elapsed().as_secs_f64() * 1e3;
        Ok(m)
    }

    /// The plugins on this session's search path — what `voxflex plugins`
    /// lists.
    pub fn plugins(&self) -> PluginListing {
        plugin_loader::list(&plugin_loader::search_path(&self.plugin_dirs))
    }

    /// The worker threads plugins are told they have.
    pub fn threads(&self) -> usize {
        if self.threads > 0 {
            self.threads
        } else {
            rayon::current_num_threads()
        }
    }

    /// Times `calls` converged model steps, each with a dirty-region query,
    /// through the plugin boundary — all a frame in which nothing moved
    /// costs (what `voxflex bench` reports). `None` without a model.
    pub fn time_idle_frames(&mut self, calls: u64) -> Option<Duration> {
        let m = self.model.as_mut()?;
        let t = Instant::now();
        for i in 0..calls {
            let _ = m.model.step(FrameInfo {
                frame: m.frame + i,
                frames: u64::MAX,
                dt_s: 0.0,
            });
            let _ = m.model.dirty_region();
        }
        Some(t.elapsed())
    }

    /// Bytes of the resampler's scratch beyond its input and output.
    pub fn resample_scratch_bytes(&self) -> usize {
        self.resample
            .as_ref()
            .map_or(0, |r| r.resampler.scratch_bytes())
    }

    /// The pieces a scene run's output stage writes from: the current
    /// volume, the metrics, the GPU, the renderer and the region to
    /// re-render.
    pub(crate) fn output_parts(&mut self) -> Result<OutputParts<'_>, RunError> {
        self.ensure_volume()?;
        let (volume, lent) = match &self.resampled {
            Some((_, v)) => (v, None),
            None => (
                self.source.as_ref(),
                Some(SharedVolume::new(self.source.clone())),
            ),
        };
        Ok(OutputParts {
            volume,
            lent,
            metrics: &mut self.metrics,
            gpu: self.gpu.as_ref(),
            renderer: self.renderer.as_mut().map(|r| &mut r.stage),
            render_dirty: &mut self.render_dirty,
            versions: &mut self.versions,
        })
    }
}

/// See [`Session::output_parts`].
pub(crate) struct OutputParts<'a> {
    pub(crate) volume: &'a Volume,
    /// `volume` to lend the renderer when it is the (unchanging) source.
    pub(crate) lent: Option<SharedVolume>,
    pub(crate) metrics: &'a mut RunMetrics,
    pub(crate) gpu: Option<&'a Arc<dyn GpuService>>,
    pub(crate) renderer: Option<&'a mut RenderStage>,
    pub(crate) render_dirty: &'a mut DirtyRegion,
    pub(crate) versions: &'a mut Versions,
}

impl Drop for Session {
    fn drop(&mut self) {
        // The model goes first: its own GPU buffers live in the context.
        self.model = None;
        self.release_gpu();
    }
}

/// A stage that did work.
fn ran(stage: &'static str, why: String, wall: Duration, voxels: u64) -> StageOutcome {
    StageOutcome {
        stage,
        ran: true,
        why,
        wall,
        voxels,
    }
}

/// A stage skipped because its input did not move.
fn skipped(stage: &'static str, why: String) -> StageOutcome {
    StageOutcome {
        stage,
        ran: false,
        why,
        wall: Duration::ZERO,
        voxels: 0,
    }
}

fn no_model() -> RunError {
    RunError::Other("the session has no model; swap_model first".into())
}

fn roi_err(e: impl std::fmt::Display) -> RunError {
    RunError::Other(format!("ROI map: {e}"))
}

#[cfg(test)]
mod tests;

/// What [`Session::move_to`] builds: the model's and the renderer's plugin
/// and parameters (TOML), where the session has them.
struct StageSpecs {
    model: Option<(LoadedPlugin, String)>,
    renderer: Option<(LoadedPlugin, String)>,
}
