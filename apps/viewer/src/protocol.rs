//! What the UI thread and the worker thread say to each other: commands
//! to the [`voxflex_runtime::session::Session`] the worker owns, and the
//! images and reports it sends back.

use crate::backend_panel::BackendStatus;
use crate::gpu_image::GpuFrame;
use crate::open::OpenRequest;
use std::path::PathBuf;
use std::time::Duration;
use voxflex_core::camera::Camera;
use voxflex_core::grid::Grid;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::param_schema::ParamSchema;
use voxflex_runtime::session::{
    GrowthLimits, GrowthParams, GrowthReport, RoiId, RoiInfo, SliceAxis, SliceImage, StepReport,
    Window,
};
use voxflex_runtime::visualise::RgbaImage;

/// The three slice views, in display order.
pub const AXES: [SliceAxis; 3] = [SliceAxis::Axial, SliceAxis::Coronal, SliceAxis::Sagittal];

/// What the views show: the worker slices and renders for the latest one.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewRequest {
    /// The cursor, voxel index (i, j, k) of the current volume: the slices
    /// shown pass through it.
    pub cursor: [usize; 3],
    /// The slices' window (volume value units).
    pub window: Window,
    /// The 3D view's camera at full quality.
    pub camera: Camera,
    /// True while the user drags (the 3D view renders at lower resolution).
    pub interacting: bool,
    /// ROI maps drawn over the slices, with their RGB colour.
    pub overlays: Vec<(RoiId, [u8; 3])>,
    /// ROI maps hidden (not handed to the renderer; not drawn on the
    /// slices either).
    pub hidden: Vec<RoiId>,
}

/// A command to the worker.
#[derive(Clone, Debug)]
pub enum Command {
    /// Show this view (coalesced: only the latest counts).
    View(ViewRequest),
    /// Seed an ROI map at a world point (mm).
    AddRoi {
        /// Seed, world mm.
        seed: [f64; 3],
        /// Growth constants.
        params: GrowthParams,
        /// Grow it to convergence at once.
        run_to_end: bool,
    },
    /// Grow a map `n` steps.
    RoiStep(RoiId, usize),
    /// Grow a map to convergence.
    RoiRunToEnd(RoiId),
    /// New growth constants for a map (re-grown as far as before).
    RoiParams(RoiId, GrowthParams),
    /// Remove a map.
    RemoveRoi(RoiId),
    /// Write a map as NIfTI.
    SaveRoi(RoiId, PathBuf),
    /// Use another deformation plugin with its parameters (TOML).
    SwapModel {
        /// Plugin name.
        plugin: String,
        /// Its parameters as TOML text.
        params: String,
    },
    /// Grab the tissue at `point` and move it to `to` (mm), then step.
    Drag {
        /// Grabbed point, world mm.
        point: [f64; 3],
        /// Target, world mm.
        to: [f64; 3],
    },
    /// Cut along a planar polygon (world mm), then step.
    Cut {
        /// Corners, world mm.
        polygon: Vec<[f64; 3]>,
    },
    /// Remove the tissue inside a ball, then step.
    Carve {
        /// Centre, world mm.
        centre: [f64; 3],
        /// Radius, mm.
        radius: f64,
    },
    /// Let go of everything grabbed, then step.
    Release,
    /// Put the model back at rest (same plugin and parameters) and step.
    Reset,
    /// Run one more step (a model still settling).
    Step,
    /// Write the session's state as a scene `voxflex run` replays (File →
    /// Save scene).
    SaveScene(PathBuf),
    /// Write the current (deformed) volume as NIfTI (`.nii`, `.nii.gz`).
    SaveVolume(PathBuf),
    /// Move the session to another backend (the *Backend* combo box).
    SetBackend(BackendChoice),
    /// Reconfigure the renderer with these `[render.params]` (TOML); the
    /// worker answers [`Reply::RenderApplied`] with `seq`, applied or not.
    RenderParams {
        /// Sequence number, echoed back.
        seq: u64,
        /// The renderer's parameters as TOML text.
        params_toml: String,
    },
    /// Render the 3D view at full quality and write it as PNG (File → Save
    /// view as PNG).
    SaveViewPng(PathBuf),
    /// Open a volume or scene, replacing the session (the old one is kept
    /// when this fails; the error names the file and the reason).
    Open(OpenRequest),
    /// Choose a map's λ by the plateau rule and grow it to the end at it.
    RoiAutoLambda(RoiId),
    /// New growth bounds for a map (re-grown as far as before within them).
    RoiLimits(RoiId, GrowthLimits),
    /// Find the world point under pixel `pixel` of `camera`'s image: the
    /// first sample along its ray at or above `min_value` (answered by
    /// [`Reply::Picked`]).
    Pick {
        /// The 3D view's camera (its image size gives the pixel units).
        camera: Camera,
        /// Pixel (x, y), top-left origin.
        pixel: [f64; 2],
        /// Value a sample must reach, volume units.
        min_value: f32,
    },
    /// Stop the worker.
    Quit,
}

/// What the worker opened.
#[derive(Clone, Debug)]
pub struct Opened {
    /// What was opened (file name or the built-in phantom).
    pub title: String,
    /// The volume's grid (world mm).
    pub grid: Grid,
    /// The volume's value range (min, max).
    pub value_range: (f32, f32),
    /// The 3D view's first camera: the scene's `[render]` camera, or the
    /// whole volume seen from the front.
    pub camera: Camera,
    /// Deformation plugins on the search path, with the parameters the
    /// scene gives each (empty when none).
    pub models: Vec<(String, String)>,
    /// Each deformation plugin's parameter schema.
    pub schemas: Vec<(String, ParamSchema)>,
    /// The model in use, if any.
    pub model: Option<String>,
    /// The adapter computing (`cpu` or a GPU's name).
    pub adapter: String,
    /// The file opened (`None`: the built-in phantom).
    pub path: Option<PathBuf>,
}

/// One slice as shown: gray pixels with ROI overlays as RGBA, and where its
/// pixels lie.
#[derive(Clone, Debug)]
pub struct SliceFrame {
    /// The slice (gray pixels and the pixel ↔ world mapping).
    pub slice: SliceImage,
    /// `width × height × 4` RGBA bytes, the overlays blended in.
    pub rgba: Vec<u8>,
}

/// One ROI map in the list, with its last growth.
#[derive(Clone, Debug)]
pub struct RoiRow {
    /// What the session reports of it.
    pub info: RoiInfo,
    /// The last growth run on it and its wall time.
    pub last: Option<(GrowthReport, Duration)>,
}

/// Time of one pipeline stage so far.
#[derive(Clone, Debug, PartialEq)]
pub struct StageTime {
    /// Stage name (`model`, `map`, `resample`, `roi`, `render`, …).
    pub stage: String,
    /// Runs so far.
    pub runs: u64,
    /// Total wall time, ms.
    pub wall_ms: f64,
}

/// A message from the worker.
#[derive(Clone, Debug)]
pub enum Reply {
    /// The session is open.
    Opened(Box<Opened>),
    /// The three slices, in [`AXES`] order, and the current volume's
    /// value at the cursor voxel.
    Slices(Box<[SliceFrame; 3]>, f32),
    /// The 3D view, with the scale it was rendered at (1 = full).
    Render {
        /// The image.
        image: RgbaImage,
        /// Resolution scale (1 = full; lower while interacting, see
        /// [`crate::adaptive`]).
        scale: f32,
        /// Wall time of the render.
        wall: Duration,
    },
    /// The 3D view rendered into the session's buffer on the device the
    /// UI shares (the GPU path: no read-back).
    GpuRender {
        /// The image on the GPU.
        frame: GpuFrame,
        /// Resolution scale (1 = full; lower while interacting, see
        /// [`crate::adaptive`]).
        scale: f32,
        /// Wall time of the render.
        wall: Duration,
    },
    /// Where the session computes (after opening and after a switch).
    Backend(BackendStatus),
    /// A backend switch failed; the session stays where it was.
    BackendError(String),
    /// The ROI maps.
    Rois(Vec<RoiRow>),
    /// The model now in use.
    Model(String),
    /// The session refused a model's parameters (the message names the key).
    ModelError(String),
    /// What the last step did.
    Step(StepReport),
    /// Per-stage times from the session's metrics.
    Stages(Vec<StageTime>),
    /// A command failed.
    Error(String),
    /// A one-line status (e.g. a file written).
    Status(String),
    /// What the *Rendering* panel starts from (after [`Reply::Opened`]).
    RenderInfo(Box<crate::render_info::RenderInfo>),
    /// Reconfigure `seq` was applied (or refused, with a [`Reply::Error`]).
    RenderApplied(u64),
    /// The answer to [`Command::Pick`]: the world point (mm), or `None`
    /// when the ray hit nothing.
    Picked(Option<[f64; 3]>),
}
