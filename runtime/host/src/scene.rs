//! Scene files: what to load, which model deforms it, on which backend, for
//! how many frames, and what to write.
//!
//! Every table rejects unknown keys with `file:line:column`, the key, and the
//! closest valid key. Plugin parameters (`[model.params]`) and interactions
//! (`[[interaction]]`) are passed through as TOML text: the plugin validates
//! them itself and names its own keys; [`crate::preflight`] has the plugin
//! check both without running (what `voxflex validate` does).
//!
//! ```toml
//! [scene]
//! name = "demo"
//! backend = "auto"          # "cpu" | "gpu" | "auto"
//! frames = 12
//!
//! [volume]
//! source = "phantom:head"   # or a .nii/.nii.gz/.mhd/.nrrd path (relative to this file)
//! dims = [128, 128, 128]    # phantoms only
//!
//! [model]
//! plugin = "affine"
//! [model.params]
//! field = "twist"
//! angle_deg = 40
//!
//! [resample]
//! interpolation = "trilinear"   # or "tetrahedral"
//! max_output_factor = 8         # largest output, × the source's voxels
//!
//! [output]
//! dir = "out/demo"
//! slices = ["axial", "coronal", "sagittal"]
//! window = { level = 40, width = 400 }
//! nifti = "deformed.nii.gz"
//! ```

use crate::actuation::{ActuationSettings, ActuatorSettings, EffectorSettings};
use crate::backend::BackendChoice;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use voxflex_core::non_finite::NonFinitePolicy;
use voxflex_core::oblique::ObliquePlacement;
use voxflex_resample::{Interpolation, ResampleParams};

/// Largest scene file read (1 MiB): scene files are a few kilobytes.
pub const MAX_SCENE_BYTES: u64 = 1 << 20;
/// Largest `[render] turntable` (and `voxflex render --turntable`), frames.
pub const MAX_TURNTABLE_FRAMES: u32 = 3600;
/// Largest `[render] width` / `height` (and `voxflex render --size`), pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// A scene file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Read {
        /// Scene file.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// Syntax error, unknown key, wrong type or invalid value.
    #[error("{location}: {message}")]
    Invalid {
        /// `file:line:column` (or just the file).
        location: String,
        /// What is wrong and what to do.
        message: String,
    },
}

/// `[scene]`: run-wide settings.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SceneSettings {
    /// Name used in reports.
    #[serde(default = "default_name")]
    pub name: String,
    /// Where algorithms run.
    #[serde(default)]
    pub backend: BackendChoice,
    /// Frames to simulate (≥ 1).
    #[serde(default = "default_frames")]
    pub frames: u64,
    /// Simulated seconds per frame (> 0).
    #[serde(default = "default_dt")]
    pub dt_s: f64,
    /// Worker threads; 0 = one per core.
    #[serde(default)]
    pub threads: usize,
    /// Directories searched first for plugins (relative to the scene file).
    #[serde(default)]
    pub plugin_dirs: Vec<PathBuf>,
}

fn default_name() -> String {
    "scene".into()
}
fn default_frames() -> u64 {
    1
}
fn default_dt() -> f64 {
    1.0 / 30.0
}

impl Default for SceneSettings {
    fn default() -> Self {
        Self {
            name: default_name(),
            backend: BackendChoice::default(),
            frames: default_frames(),
            dt_s: default_dt(),
            threads: 0,
            plugin_dirs: vec![],
        }
    }
}

/// `[volume]`: the source volume.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct VolumeSettings {
    /// `phantom:<name>` or a file path (relative to the scene file).
    pub source: String,
    /// Phantom resolution in voxels (x, y, z); phantoms only.
    #[serde(default)]
    pub dims: Option<[usize; 3]>,
    /// Refuse volumes with more voxels than this.
    #[serde(default = "default_max_voxels")]
    pub max_voxels: usize,
    /// NaN and ±∞ voxels of a file: `"replace"` (default; warn with the
    /// counts, NaN → background, ±∞ → the finite range's ends) or
    /// `"refuse"`. See [`voxflex_core::non_finite`].
    #[serde(default)]
    pub non_finite: NonFinitePolicy,
    /// A file whose header is oblique (voxel axes rotated against the
    /// world axes by other than multiples of 90°): `"closest-axes"`
    /// (default; voxels kept, placed along the closest axes with a
    /// warning), `"linear"` or `"nearest"` (resampled where the header puts
    /// it). See [`voxflex_core::oblique`].
    #[serde(default)]
    pub oblique: ObliquePlacement,
}

fn default_max_voxels() -> usize {
    1 << 30
}

/// `[model]`: the deformation plugin and its parameters.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ModelSettings {
    /// Plugin name (`affine`, `chainmail`, …).
    pub plugin: String,
    /// The plugin's own table, passed to it as TOML text (or, per plugin,
    /// `[model.params.<plugin>]`; see [`Scene::model_params_toml`]).
    #[serde(default)]
    pub params: toml::Table,
}

/// `[[interaction]]`: a scripted interaction applied at the start of `frame`.
#[derive(Clone, Debug, PartialEq)]
pub struct Interaction {
    /// Frame (from 0) at which the model receives it.
    pub frame: u64,
    /// The rest of the table, as the model receives it (TOML text).
    pub toml: String,
    /// Its position among the file's `[[interaction]]` tables, from 0 (for
    /// messages: see [`locate_in_array`]).
    pub index: usize,
}

/// `[resample]`: the resampling stage.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ResampleSettings {
    /// Value of output voxels outside the deformed volume (default: the
    /// source volume's minimum).
    #[serde(default)]
    pub background: Option<f32>,
    /// Pass 2's interpolant: `"trilinear"` (default) samples the source
    /// trilinearly at each output voxel's rest position; `"tetrahedral"`
    /// interpolates the owner tetrahedron's vertex values (the paper's).
    #[serde(default)]
    pub interpolation: Option<Interpolation>,
    /// Largest output grid, as a multiple of the source's voxel count
    /// (finite, ≥ 1; default 8): guards against displacements in the wrong
    /// units; raise it for large legitimate deformations.
    #[serde(default)]
    pub max_output_factor: Option<f64>,
}

impl ResampleSettings {
    /// `base` with the keys this table sets.
    pub fn apply(&self, base: ResampleParams) -> ResampleParams {
        ResampleParams {
            background: self.background.unwrap_or(base.background),
            interpolation: self.interpolation.unwrap_or(base.interpolation),
            max_output_factor: self.max_output_factor.unwrap_or(base.max_output_factor),
            ..base
        }
    }
}

/// Slice orientation names for `[output] slices`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SliceName {
    /// Normal z.
    Axial,
    /// Normal y.
    Coronal,
    /// Normal x.
    Sagittal,
}

/// Window/level for PNG slices, in data units (e.g. HU).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WindowSettings {
    /// Centre of the window.
    pub level: f32,
    /// Width of the window (> 0).
    pub width: f32,
}

/// `[output]`: what to write.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OutputSettings {
    /// Output directory (relative to the working directory).
    #[serde(default = "default_out")]
    pub dir: PathBuf,
    /// Mid-slice PNGs to write.
    #[serde(default = "default_slices")]
    pub slices: Vec<SliceName>,
    /// Window/level of the PNGs (default: the data range).
    #[serde(default)]
    pub window: Option<WindowSettings>,
    /// File name of the deformed volume (`.nii` or `.nii.gz`); none = not written.
    #[serde(default)]
    pub nifti: Option<String>,
    /// Write slices after every frame that changed, not only the last.
    #[serde(default)]
    pub every_frame: bool,
}

fn default_out() -> PathBuf {
    PathBuf::from("out")
}
fn default_slices() -> Vec<SliceName> {
    vec![SliceName::Axial, SliceName::Coronal, SliceName::Sagittal]
}

impl Default for OutputSettings {
    fn default() -> Self {
        Self {
            dir: default_out(),
            slices: default_slices(),
            window: None,
            nifti: None,
            every_frame: false,
        }
    }
}

/// Projection names for `[render.camera] projection`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub enum ProjectionName {
    /// Parallel rays.
    #[default]
    Orthographic,
    /// Rays through the eye.
    Perspective,
}

/// `[render.camera]`: an orbit camera around the volume centre.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraSettings {
    /// Degrees about world +z; 0 looks along +y (anterior view).
    #[serde(default)]
    pub azimuth_deg: f64,
    /// Degrees above the x–y plane.
    #[serde(default)]
    pub elevation_deg: f64,
    /// Eye–centre distance, mm (default: twice the volume's diagonal).
    #[serde(default)]
    pub distance_mm: Option<f64>,
    /// Ray geometry.
    #[serde(default)]
    pub projection: ProjectionName,
    /// Perspective vertical field of view, degrees.
    #[serde(default = "default_fov")]
    pub fov_deg: f64,
    /// Orthographic image height, mm (default: the volume's diagonal).
    #[serde(default)]
    pub height_mm: Option<f64>,
    /// Point looked at and orbited, world mm (default: the centre of the
    /// rendered volume's grid).
    #[serde(default)]
    pub target_mm: Option<[f64; 3]>,
}

fn default_fov() -> f64 {
    30.0
}

impl Default for CameraSettings {
    fn default() -> Self {
        Self {
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            distance_mm: None,
            projection: ProjectionName::Orthographic,
            fov_deg: default_fov(),
            height_mm: None,
            target_mm: None,
        }
    }
}

/// `[render]`: direct volume rendering of the (deformed) volume.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// Renderer plugin (default `raycast`).
    #[serde(default = "default_renderer")]
    pub plugin: String,
    /// Image width, pixels.
    #[serde(default = "default_image_size")]
    pub width: u32,
    /// Image height, pixels.
    #[serde(default = "default_image_size")]
    pub height: u32,
    /// The camera.
    #[serde(default)]
    pub camera: CameraSettings,
    /// Frames of a turntable around the volume (0 = one image).
    #[serde(default)]
    pub turntable: u32,
    /// Image file name in the output directory (`render.png`; a turntable
    /// writes `render_000.png`, …).
    #[serde(default = "default_render_file")]
    pub file: String,
    /// The renderer's own table (transfer function, shading, clipping…).
    #[serde(default)]
    pub params: toml::Table,
}

fn default_renderer() -> String {
    "raycast".into()
}
fn default_image_size() -> u32 {
    512
}
fn default_render_file() -> String {
    "render.png".into()
}

/// A slice click seed for `[[roi]] seed_slice`.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SliceSeed {
    /// Slice orientation.
    pub axis: SliceName,
    /// Slice index (voxels along the slice normal).
    pub index: usize,
    /// `[column, row]` in the slice PNG, pixels from the top-left.
    pub pixel: [usize; 2],
}

/// `[[roi]]`: a spatial opacity map grown from a seed.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RoiSettings {
    /// Name used for the written map (`roi_<name>.nii.gz`).
    #[serde(default)]
    pub name: Option<String>,
    /// Seed as a world point, mm.
    #[serde(default)]
    pub seed: Option<[f64; 3]>,
    /// Seed as a slice click.
    #[serde(default)]
    pub seed_slice: Option<SliceSeed>,
    /// Extinction scale λ: `"auto"` (the default: the plateau rule,
    /// `voxflex_opacity::auto_lambda`) or a number (the paper's is
    /// 30, which leaks on contrast CT — see docs/GUIDE.md "On contrast CT").
    #[serde(default = "default_lambda")]
    pub lambda: LambdaSetting,
    /// Intensity window `[lo, hi]` (volume units, HU for CT): voxels outside
    /// never rise above `o_min`.
    #[serde(default)]
    pub intensity: Option<[f32; 2]>,
    /// Largest Euclidean distance (world mm) from the seed voxel's centre a
    /// raised voxel may have.
    #[serde(default)]
    pub max_distance_mm: Option<f64>,
    /// Opacity outside the region (default 0.03).
    #[serde(default = "default_o_min")]
    pub o_min: f32,
    /// Opacity of the seed (default 1).
    #[serde(default = "default_o_max")]
    pub o_max: f32,
    /// Half-width (voxels) of the cube around the seed whose mean and σ
    /// set the extinction: 1 is the paper's 1-ring, the default 2
    /// (`voxflex_opacity::GrowthParams::seed_radius` says why), at most 8.
    /// Signed so that a negative value is refused by the scene check with
    /// the key's name, like every other bad value.
    #[serde(default = "default_seed_radius")]
    pub seed_radius: i64,
    /// Neighbours that pass opacity on: 6 (faces only, the default) or 26
    /// (the paper's; `voxflex_opacity::GrowthParams::connectivity` says why).
    #[serde(default = "default_connectivity")]
    pub connectivity: i64,
    /// Growth steps; absent = run to convergence.
    #[serde(default)]
    pub steps: Option<usize>,
    /// Also write the map as NIfTI (u16 fixed point, 65535 = 1).
    #[serde(default)]
    pub write: bool,
    /// Weight the renderer's transfer function by the paper's automatic
    /// Gaussian around this seed's mean and σ (`t(x)·(a + b·g(x))`, a = 0.01,
    /// b = 0.99). At most one `[[roi]]` may set it.
    #[serde(default)]
    pub gaussian_tf: bool,
}

/// `"auto"`: on the labelled abdomen the paper's λ = 30 is off the
/// run-time/error front for every seed, the plateau rule just behind it
/// (docs/BENCHMARKS.md, "ROI maps").
fn default_lambda() -> LambdaSetting {
    LambdaSetting::Word("auto".into())
}

/// `[[roi]] lambda`: a number or a word (only `"auto"` is valid; checked
/// when the scene is loaded).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum LambdaSetting {
    /// A fixed λ.
    Value(f32),
    /// `"auto"`.
    Word(String),
}
fn default_o_min() -> f32 {
    0.03
}
fn default_o_max() -> f32 {
    1.0
}
fn default_connectivity() -> i64 {
    voxflex_opacity::GrowthParams::default().connectivity.into()
}
fn default_seed_radius() -> i64 {
    voxflex_opacity::GrowthParams::default().seed_radius.into()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    #[serde(default)]
    scene: SceneSettings,
    volume: VolumeSettings,
    #[serde(default)]
    model: Option<ModelSettings>,
    #[serde(default)]
    interaction: Vec<toml::Table>,
    #[serde(default)]
    resample: Option<ResampleSettings>,
    #[serde(default)]
    output: Option<OutputSettings>,
    #[serde(default)]
    render: Option<RenderSettings>,
    #[serde(default)]
    roi: Vec<RoiSettings>,
    #[serde(default)]
    actuator: Vec<ActuatorSettings>,
    #[serde(default)]
    effector: Vec<EffectorSettings>,
    #[serde(default)]
    actuation: Option<ActuationSettings>,
}

/// The `[[actuator]]` and `[[effector]]` tables' own checks, errors
/// pointing into the offending table.
fn check_actuation(file: &SceneFile, text: &str, path: &Path) -> Result<(), SceneError> {
    let at = |array: &str, n: usize, (key, message): (String, String)| SceneError::Invalid {
        location: locate_in_array(text, path, array, n, &key),
        message: format!("`{key}`: {message}"),
    };
    if !file.actuator.is_empty() && file.model.is_none() {
        return Err(at(
            "actuator",
            0,
            (
                "plugin".into(),
                "actuators act on a deformation model: add a [model] (corotational-fem)".into(),
            ),
        ));
    }
    if !file.effector.is_empty() && file.actuator.is_empty() {
        return Err(at(
            "effector",
            0,
            (
                "point".into(),
                "an effector is driven by actuators: add an [[actuator]]".into(),
            ),
        ));
    }
    if let Some(settle) = &file.actuation {
        if file.actuator.is_empty() {
            return Err(SceneError::Invalid {
                location: locate_key(text, path, "[actuation]"),
                message: "`[actuation]` settles actuator forces, and the scene has no \
                          [[actuator]]: add one or remove the table"
                    .into(),
            });
        }
        settle
            .check()
            .map_err(|(key, message)| SceneError::Invalid {
                location: locate_key(text, path, &key),
                message: format!("`[actuation] {key}` = {message}"),
            })?;
    }
    for (n, a) in file.actuator.iter().enumerate() {
        a.check().map_err(|e| at("actuator", n, e))?;
    }
    for (n, e) in file.effector.iter().enumerate() {
        e.targets().map_err(|e| at("effector", n, e))?;
    }
    Ok(())
}

/// A parsed, validated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// Scene file (for messages and relative paths).
    pub path: PathBuf,
    /// The file's text (fingerprinted to skip up-to-date runs).
    pub text: String,
    /// `[scene]`.
    pub settings: SceneSettings,
    /// `[volume]`.
    pub volume: VolumeSettings,
    /// `[model]`; none = the identity (no deformation stage).
    pub model: Option<ModelSettings>,
    /// `[[interaction]]`, sorted by frame.
    pub interactions: Vec<Interaction>,
    /// `[resample]`; present whenever there is a model.
    pub resample: Option<ResampleSettings>,
    /// `[output]`; none = write only metrics.
    pub output: Option<OutputSettings>,
    /// `[render]`; none = the renderer plugin is never loaded.
    pub render: Option<RenderSettings>,
    /// `[[roi]]` opacity maps.
    pub rois: Vec<RoiSettings>,
    /// `[[actuator]]` soft-robot actuators (need a `[model]`).
    pub actuators: Vec<ActuatorSettings>,
    /// `[[effector]]` inverse-control targets (need an actuator).
    pub effectors: Vec<EffectorSettings>,
    /// `[actuation]`: how each frame settles the actuator forces
    /// (defaults when the table is absent).
    pub actuation: ActuationSettings,
}

impl Scene {
    /// Reads and validates a scene file.
    /// A path that is not a regular file (`/dev/zero`, a FIFO) or a file
    /// over [`MAX_SCENE_BYTES`] is refused before it is read.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let read_err = |source| SceneError::Read {
            path: path.to_path_buf(),
            source,
        };
        let meta = std::fs::metadata(path).map_err(read_err)?;
        if !meta.is_file() || meta.len() > MAX_SCENE_BYTES {
            return Err(SceneError::Invalid {
                location: path.display().to_string(),
                message: if meta.is_file() {
                    format!(
                        "{} bytes is not a scene file: scenes are at most {MAX_SCENE_BYTES} bytes",
                        meta.len()
                    )
                } else {
                    format!(
                        "is {}, not a scene file; give the path of a .toml file",
                        voxflex_io::file_kind(&meta)
                    )
                },
            });
        }
        let text = std::fs::read_to_string(path).map_err(read_err)?;
        Self::parse(&text, path)
    }

    /// Parses and validates scene text; `path` is used in messages and to
    /// resolve relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Scene, SceneError> {
        let file: SceneFile =
            toml::from_str(text).map_err(|e| describe_toml_error(&e, text, path))?;
        let invalid = |key: &str, message: String| SceneError::Invalid {
            location: locate_key(text, path, key),
            message: format!("`{key}`: {message}"),
        };
        let s = &file.scene;
        if s.frames == 0 || s.frames > 10_000_000 {
            return Err(invalid(
                "frames",
                format!("{} is out of range; use 1 to 10000000", s.frames),
            ));
        }
        if !(s.dt_s.is_finite() && s.dt_s > 0.0) {
            return Err(invalid(
                "dt_s",
                format!("{} must be a positive number of seconds", s.dt_s),
            ));
        }
        if s.threads > 4096 {
            return Err(invalid(
                "threads",
                format!("{} threads is absurd; use 0 for one per core", s.threads),
            ));
        }
        if let Some(d) = file.volume.dims {
            let total = d.iter().try_fold(1usize, |a, &b| a.checked_mul(b));
            if d.contains(&0) || total.is_none_or(|t| t > file.volume.max_voxels) {
                return Err(invalid(
                    "dims",
                    format!(
                        "{d:?} must be positive and hold at most max_voxels = {} voxels",
                        file.volume.max_voxels
                    ),
                ));
            }
        }
        if let Some(b) = file.resample.as_ref().and_then(|r| r.background)
            && !b.is_finite()
        {
            return Err(invalid("background", "must be a finite number".into()));
        }
        if let Some(f) = file.resample.as_ref().and_then(|r| r.max_output_factor)
            && !(f.is_finite() && f >= 1.0)
        {
            return Err(SceneError::Invalid {
                location: locate_key(text, path, "max_output_factor"),
                message: format!(
                    "`[resample] max_output_factor` = {f}: must be a finite number ≥ 1 (the largest \
                     output grid as a multiple of the source's voxel count; default {})",
                    ResampleParams::default().max_output_factor
                ),
            });
        }
        if let Some(o) = &file.output {
            if let Some(w) = o.window
                && !(w.width.is_finite() && w.width > 0.0 && w.level.is_finite())
            {
                return Err(invalid(
                    "window",
                    "needs a finite `level` and a `width` > 0".into(),
                ));
            }
            if let Some(n) = &o.nifti
                && !(n.ends_with(".nii") || n.ends_with(".nii.gz"))
            {
                return Err(invalid(
                    "nifti",
                    format!("`{n}` must end in .nii or .nii.gz"),
                ));
            }
            if let Some(n) = &o.nifti {
                crate::out_dir::check_file_name(n).map_err(|m| invalid("nifti", m))?;
            }
            crate::out_dir::check_dir(&o.dir).map_err(|m| invalid("dir", m))?;
        }
        if let Some(r) = &file.render {
            if r.width == 0
                || r.height == 0
                || r.width > MAX_IMAGE_SIDE
                || r.height > MAX_IMAGE_SIDE
            {
                return Err(invalid(
                    "width",
                    format!(
                        "{}×{} pixels is out of range; use 1 to {MAX_IMAGE_SIDE}",
                        r.width, r.height
                    ),
                ));
            }
            let c = r.camera;
            let finite = [c.azimuth_deg, c.elevation_deg, c.fov_deg]
                .iter()
                .all(|v| v.is_finite())
                && c.distance_mm.is_none_or(|d| d.is_finite() && d > 0.0)
                && c.height_mm.is_none_or(|h| h.is_finite() && h > 0.0)
                && c.target_mm.is_none_or(|t| t.iter().all(|v| v.is_finite()));
            if !finite || c.elevation_deg.abs() >= 90.0 || !(c.fov_deg > 0.0 && c.fov_deg < 180.0) {
                return Err(invalid(
                    "camera",
                    "needs finite angles, |elevation_deg| < 90, 0 < fov_deg < 180, positive distance_mm / height_mm and a finite target_mm".into(),
                ));
            }
            if r.turntable > MAX_TURNTABLE_FRAMES {
                return Err(invalid(
                    "turntable",
                    format!(
                        "{} frames is absurd; use 0 to {MAX_TURNTABLE_FRAMES}",
                        r.turntable
                    ),
                ));
            }
            if !r.file.ends_with(".png") {
                return Err(invalid("file", format!("`{}` must end in .png", r.file)));
            }
            crate::out_dir::check_file_name(&r.file).map_err(|m| invalid("file", m))?;
        }
        for (n, roi) in file.roi.iter().enumerate() {
            // Errors point into this [[roi]] table, not the first one.
            let invalid = |key: &str, message: String| SceneError::Invalid {
                location: locate_in_array(text, path, "roi", n, key),
                message: format!("`{key}`: {message}"),
            };
            if let Some(name) = &roi.name {
                crate::out_dir::check_file_name(name).map_err(|m| invalid("name", m))?;
            }
            if roi.seed.is_some() == roi.seed_slice.is_some() {
                return Err(SceneError::Invalid {
                    location: locate_in_array(text, path, "roi", n, ""),
                    message: "every [[roi]] needs exactly one of `seed = [x, y, z]` (mm) or `seed_slice = { axis, index, pixel }`".into(),
                });
            }
            if roi.seed.is_some_and(|s| s.iter().any(|v| !v.is_finite())) {
                return Err(invalid(
                    "seed",
                    "must be three finite millimetre coordinates".into(),
                ));
            }
            match &roi.lambda {
                LambdaSetting::Value(l) if !(l.is_finite() && *l > 0.0) => {
                    return Err(invalid(
                        "lambda",
                        format!(
                            "{l} must be a positive number or \"auto\" (the default; the paper's is 30)"
                        ),
                    ));
                }
                LambdaSetting::Word(w) if w != "auto" => {
                    return Err(invalid(
                        "lambda",
                        format!("\"{w}\" is not a λ; use a positive number or \"auto\""),
                    ));
                }
                _ => {}
            }
            if let Some([lo, hi]) = roi.intensity
                && !(lo.is_finite() && hi.is_finite() && lo <= hi)
            {
                return Err(invalid(
                    "intensity",
                    format!("[{lo}, {hi}] must be two finite values with lo ≤ hi (volume units)"),
                ));
            }
            if let Some(d) = roi.max_distance_mm
                && !(d.is_finite() && d > 0.0)
            {
                return Err(invalid(
                    "max_distance_mm",
                    format!("{d} must be a positive finite distance in mm"),
                ));
            }
            if !matches!(roi.connectivity, 6 | 26) {
                return Err(invalid(
                    "connectivity",
                    format!(
                        "{} must be 6 (face neighbours) or 26 (faces, edges and corners; the paper's)",
                        roi.connectivity
                    ),
                ));
            }
            if !(1..=voxflex_opacity::MAX_SEED_RADIUS.into()).contains(&roi.seed_radius) {
                return Err(invalid(
                    "seed_radius",
                    format!(
                        "{} must be 1 (the paper's 1-ring) to {} voxels (default 2)",
                        roi.seed_radius,
                        voxflex_opacity::MAX_SEED_RADIUS
                    ),
                ));
            }
        }
        if file.roi.iter().filter(|r| r.gaussian_tf).count() > 1 {
            return Err(invalid(
                "gaussian_tf",
                "at most one [[roi]] may set it".into(),
            ));
        }
        check_actuation(&file, text, path)?;
        let mut interactions = vec![];
        for (n, mut table) in file.interaction.into_iter().enumerate() {
            // Errors point into this [[interaction]] table, not the first.
            let here = |key: &str, message: String| SceneError::Invalid {
                location: locate_in_array(text, path, "interaction", n, key),
                message,
            };
            let frame = match table.remove("frame") {
                Some(toml::Value::Integer(f)) if f >= 0 => f as u64,
                Some(v) => {
                    return Err(here(
                        "frame",
                        format!("`frame`: {v} must be a frame number ≥ 0"),
                    ));
                }
                None => {
                    return Err(here(
                        "",
                        "every [[interaction]] needs `frame = <number>`".into(),
                    ));
                }
            };
            if frame >= s.frames {
                return Err(here(
                    "frame",
                    format!(
                        "`frame`: interaction at frame {frame} never happens: the scene has {} frames",
                        s.frames
                    ),
                ));
            }
            let toml = toml::to_string(&table).map_err(|e| here("", e.to_string()))?;
            interactions.push(Interaction {
                frame,
                toml,
                index: n,
            });
        }
        interactions.sort_by_key(|i| i.frame);
        let resample = match (&file.model, file.resample) {
            (Some(_), None) => Some(ResampleSettings::default()),
            (_, r) => r,
        };
        Ok(Scene {
            path: path.to_path_buf(),
            text: text.to_owned(),
            settings: file.scene,
            volume: file.volume,
            model: file.model,
            interactions,
            resample,
            output: file.output,
            render: file.render,
            rois: file.roi,
            actuators: file.actuator,
            effectors: file.effector,
            actuation: file.actuation.unwrap_or_default(),
        })
    }

    /// Directory of the scene file (base of relative paths).
    pub fn base_dir(&self) -> PathBuf {
        self.path
            .parent()
            .map(Path::to_path_buf)
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or_else(|| PathBuf::from("."))
    }

    /// `plugin_dirs` resolved against the scene file's directory.
    pub fn plugin_dirs(&self) -> Vec<PathBuf> {
        let base = self.base_dir();
        self.settings
            .plugin_dirs
            .iter()
            .map(|d| {
                if d.is_absolute() {
                    d.clone()
                } else {
                    base.join(d)
                }
            })
            .collect()
    }

    /// The renderer's parameters as TOML text.
    pub fn render_params_toml(&self) -> String {
        self.render
            .as_ref()
            .map(|r| toml::to_string(&r.params).unwrap_or_default())
            .unwrap_or_default()
    }

    /// The parameters this scene gives plugin `plugin` as TOML text: its
    /// `[model.params.<plugin>]` sub-table, or, for the scene's own model
    /// plugin, [`Self::model_params_toml`]; `None` when the scene has none
    /// for it (a front end swapping models asks this for each plugin).
    pub fn model_params_toml_for(&self, plugin: &str) -> Option<String> {
        let m = self.model.as_ref()?;
        match m.params.get(plugin) {
            Some(toml::Value::Table(t)) => toml::to_string(t).ok(),
            _ if m.plugin == plugin => Some(self.model_params_toml()),
            _ => None,
        }
    }

    /// The model's parameters as TOML text: the sub-table named after the
    /// plugin when `[model.params]` has one (`[model.params.chainmail]`,
    /// `[model.params.affine]`, …, so swapping models is a one-line edit of
    /// `plugin =`), else the whole table.
    pub fn model_params_toml(&self) -> String {
        self.model
            .as_ref()
            .map(|m| {
                let own = match m.params.get(&m.plugin) {
                    Some(toml::Value::Table(t)) => t,
                    _ => &m.params,
                };
                toml::to_string(own).unwrap_or_default()
            })
            .unwrap_or_default()
    }
}

/// `file:line:column` of the first line that assigns `key` (or holds it).
fn locate_key(text: &str, path: &Path, key: &str) -> String {
    let needle = key.trim_start_matches('[').trim_end_matches(']');
    for (n, line) in text.lines().enumerate() {
        let t = line.trim_start();
        let hit = t.starts_with(needle)
            && t[needle.len()..].trim_start().starts_with(['=', ']', '.'])
            || (key.starts_with('[') && t.starts_with(key));
        if hit {
            return format!("{}:{}:{}", path.display(), n + 1, line.len() - t.len() + 1);
        }
    }
    path.display().to_string()
}

/// `file:line:column` of `key` inside the `n`-th (from 0) `[[array]]`
/// table, else of that table's header (else the file). An empty `key`
/// gives the header.
pub fn locate_in_array(text: &str, path: &Path, array: &str, n: usize, key: &str) -> String {
    let header = format!("[[{array}]]");
    let lines: Vec<&str> = text.lines().collect();
    let is_header = |l: &str| {
        let t = l.trim_start();
        t.starts_with(&header) && t[header.len()..].trim_start().is_empty_or_comment()
    };
    let Some(start) = (0..lines.len()).filter(|&i| is_header(lines[i])).nth(n) else {
        return path.display().to_string();
    };
    let at = |i: usize| {
        let t = lines[i].trim_start();
        format!(
            "{}:{}:{}",
            path.display(),
            i + 1,
            lines[i].len() - t.len() + 1
        )
    };
    if !key.is_empty() {
        for (i, line) in lines.iter().enumerate().skip(start + 1) {
            let t = line.trim_start();
            if t.starts_with('[') {
                break;
            }
            if t.starts_with(key) && t[key.len()..].trim_start().starts_with('=') {
                return at(i);
            }
        }
    }
    at(start)
}

/// `str::is_empty`, or a TOML comment.
trait EmptyOrComment {
    fn is_empty_or_comment(&self) -> bool;
}

impl EmptyOrComment for str {
    fn is_empty_or_comment(&self) -> bool {
        self.is_empty() || self.starts_with('#')
    }
}

fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// The `[table]` header governing byte `offset`.
fn enclosing_table(text: &str, offset: usize) -> String {
    text[..offset.min(text.len())]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('['))
        .map(|l| l.split('#').next().unwrap_or(l).trim().to_owned())
        .unwrap_or_else(|| "the top level".into())
}

fn describe_toml_error(e: &toml::de::Error, text: &str, path: &Path) -> SceneError {
    let (offset, location) = match e.span() {
        Some(span) => {
            let (l, c) = line_col(text, span.start);
            (span.start, format!("{}:{l}:{c}", path.display()))
        }
        None => (0, path.display().to_string()),
    };
    let raw = e.message().trim().to_owned();
    let message = match parse_unknown_field(&raw) {
        Some((unknown, expected)) => {
            let table = enclosing_table(text, offset);
            let best = expected
                .iter()
                .map(|k| (strsim::jaro_winkler(&unknown, k), k))
                .filter(|(score, _)| *score > 0.7)
                .max_by(|a, b| a.0.total_cmp(&b.0));
            let hint = match best {
                Some((_, k)) => format!("; did you mean `{k}`?"),
                None => String::new(),
            };
            format!(
                "unknown key `{unknown}` in {table}{hint} (valid keys: {})",
                expected.join(", ")
            )
        }
        None => raw,
    };
    SceneError::Invalid { location, message }
}

/// Splits serde's "unknown field `x`, expected one of `a`, `b`" (or
/// "expected `a`") into the key and the valid keys.
fn parse_unknown_field(msg: &str) -> Option<(String, Vec<String>)> {
    let rest = msg.strip_prefix("unknown field `")?;
    let (unknown, rest) = rest.split_once('`')?;
    let expected = rest
        .split('`')
        .enumerate()
        .filter(|(i, _)| i % 2 == 1)
        .map(|(_, s)| s.to_owned())
        .collect();
    Some((unknown.to_owned(), expected))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[scene]
name = "t"
backend = "cpu"
frames = 3

[volume]
source = "phantom:cube"
dims = [8, 8, 8]

[model]
plugin = "affine"
[model.params]
field = "twist"
angle_deg = 10

[[interaction]]
frame = 1
kind = "release"
"#;

    #[test]
    fn parses_a_good_scene() {
        let s = Scene::parse(GOOD, Path::new("t.toml")).unwrap();
        assert_eq!(s.settings.frames, 3);
        assert_eq!(s.model.as_ref().unwrap().plugin, "affine");
        assert!(s.model_params_toml().contains("angle_deg = 10"));
        assert_eq!(
            s.interactions,
            vec![Interaction {
                frame: 1,
                toml: "kind = \"release\"\n".into(),
                index: 0,
            }]
        );
        assert!(s.resample.is_some(), "a model implies the resample stage");
    }

    /// `[render.camera] target_mm` moves the orbit's centre; a non-finite
    /// one is refused naming `camera`.
    #[test]
    fn the_render_camera_takes_a_finite_target() {
        let table = "[render]\ncamera = { azimuth_deg = 30, target_mm = [1.5, -2, 3] }";
        let s = Scene::parse(&format!("{GOOD}\n{table}\n"), Path::new("t.toml")).unwrap();
        let r = s.render.as_ref().unwrap();
        assert_eq!(r.camera.target_mm, Some([1.5, -2.0, 3.0]));
        let grid = voxflex_core::grid::Grid::new([4, 4, 4], glam::DVec3::ONE, glam::DVec3::ZERO);
        let c = crate::visualise::camera_for(r, &grid, 0.0);
        assert_eq!(c.target, glam::DVec3::new(1.5, -2.0, 3.0));
        let bad = "[render]\ncamera = { target_mm = [0, nan, 0] }";
        let e = Scene::parse(&format!("{GOOD}\n{bad}\n"), Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("camera") && e.contains("target_mm"), "{e}");
    }

    #[test]
    fn outputs_stay_inside_the_output_directory() {
        let cases = [
            ("[output]\ndir = \"/\"", "`dir`"),
            ("[output]\ndir = \"\"", "`dir`"),
            ("[output]\nnifti = \"../up.nii.gz\"", "`nifti`"),
            ("[output]\nnifti = \"/tmp/abs.nii\"", "`nifti`"),
            ("[render]\nfile = \"../r.png\"", "`file`"),
            ("[render]\nfile = \"/r.png\"", "`file`"),
            (
                "[[roi]]\nname = \"../../x\"\nseed = [0.0, 0.0, 0.0]",
                "`name`",
            ),
            (
                "[[roi]]\nname = \"/etc/x\"\nseed = [0.0, 0.0, 0.0]",
                "`name`",
            ),
        ];
        for (table, key) in cases {
            let e = Scene::parse(&format!("{GOOD}\n{table}\n"), Path::new("t.toml"))
                .unwrap_err()
                .to_string();
            assert!(
                e.contains(key) && e.contains("output directory"),
                "{table}: {e}"
            );
        }
        let ok = "[output]\ndir = \"out/a\"\nnifti = \"d.nii.gz\"\n[render]\nfile = \"r.png\"";
        Scene::parse(&format!("{GOOD}\n{ok}\n"), Path::new("t.toml")).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn devices_fifos_and_huge_files_are_not_scenes() {
        let e = Scene::load(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(e.contains("/dev/zero") && e.contains("a device"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("s.toml");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.unwrap().success());
        // Before the check this read blocked until a writer appeared.
        let e = Scene::load(&fifo).unwrap_err().to_string();
        assert!(e.contains("a FIFO"), "{e}");
        let big = dir.path().join("big.toml");
        let mut text = GOOD.to_string();
        text.push_str(&"# padding\n".repeat((MAX_SCENE_BYTES as usize) / 10));
        std::fs::write(&big, &text).unwrap();
        let e = Scene::load(&big).unwrap_err().to_string();
        assert!(e.contains("at most 1048576 bytes"), "{e}");
        std::fs::write(&big, GOOD).unwrap();
        Scene::load(&big).unwrap();
    }

    #[test]
    fn per_plugin_params_tables_make_a_one_line_swap() {
        let text = GOOD.replace(
            "[model.params]\nfield = \"twist\"\nangle_deg = 10",
            "[model.params.affine]\nfield = \"twist\"\n[model.params.chainmail]\nmaterials = []",
        );
        let s = Scene::parse(&text, Path::new("t.toml")).unwrap();
        assert_eq!(s.model_params_toml().trim(), "field = \"twist\"");
        let s = Scene::parse(
            &text.replace("plugin = \"affine\"", "plugin = \"chainmail\""),
            Path::new("t.toml"),
        )
        .unwrap();
        assert_eq!(s.model_params_toml().trim(), "materials = []");
    }

    #[test]
    fn misspelt_key_names_line_column_and_suggestion() {
        let bad = GOOD.replace("backend = \"cpu\"", "backnd = \"cpu\"");
        let e = Scene::parse(&bad, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("t.toml:4:1: unknown key `backnd` in [scene]; did you mean `backend`?"),
            "{e}"
        );
    }

    #[test]
    fn unknown_table_is_rejected() {
        let bad = format!("{GOOD}\n[rendr]\nx = 1\n");
        let e = Scene::parse(&bad, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("unknown key `rendr`"), "{e}");
    }

    #[test]
    fn bad_values_are_named() {
        let e = Scene::parse(
            &GOOD.replace("frames = 3", "frames = 0"),
            Path::new("t.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("t.toml:5:1: `frames`"), "{e}");
        let e = Scene::parse(
            &GOOD.replace("backend = \"cpu\"", "backend = \"cuda\""),
            Path::new("t.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("t.toml:4:") && e.contains("cuda"), "{e}");
        let e = Scene::parse(
            &GOOD.replace("dims = [8, 8, 8]", "dims = [100000, 100000, 100000]"),
            Path::new("t.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`dims`") && e.contains("max_voxels"), "{e}");
        let e = Scene::parse(&GOOD.replace("frame = 1", "frame = 9"), Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("never happens"), "{e}");
    }

    /// An error in a later [[interaction]] points at that table's lines,
    /// not at the first table's `frame =`.
    #[test]
    fn interaction_errors_point_into_their_own_table() {
        let line_of =
            |t: &str, needle: &str| t.lines().position(|l| l.starts_with(needle)).unwrap() + 1;
        let text = format!("{GOOD}\n[[interaction]]\nframe = 7\nkind = \"release\"\n");
        let e = Scene::parse(&text, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        let frame7 = line_of(&text, "frame = 7");
        assert!(
            e.starts_with(&format!("t.toml:{frame7}:1: `frame`")) && e.contains("never happens"),
            "{e}"
        );
        let text = format!("{GOOD}\n[[interaction]]\nkind = \"release\"\n");
        let e = Scene::parse(&text, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        let second = text
            .lines()
            .enumerate()
            .filter(|(_, l)| *l == "[[interaction]]")
            .nth(1)
            .unwrap()
            .0
            + 1;
        assert!(
            e.starts_with(&format!("t.toml:{second}:1:")) && e.contains("needs `frame"),
            "{e}"
        );
        let s = Scene::parse(
            &format!("{GOOD}\n[[interaction]]\nframe = 0\nkind = \"release\"\n"),
            Path::new("t.toml"),
        )
        .unwrap();
        let order: Vec<(u64, usize)> = s.interactions.iter().map(|i| (i.frame, i.index)).collect();
        assert_eq!(
            order,
            vec![(0, 1), (1, 0)],
            "sorted by frame, each knows its table"
        );
        assert_eq!(
            locate_in_array(&text, Path::new("t.toml"), "interaction", 1, "kind"),
            format!("t.toml:{}:1", line_of(&text, "kind = \"release\"") + 3)
        );
    }

    #[test]
    fn non_finite_policy_defaults_to_replace_and_takes_refuse() {
        let s = Scene::parse(GOOD, Path::new("t.toml")).unwrap();
        assert_eq!(s.volume.non_finite, NonFinitePolicy::Replace);
        let text = GOOD.replace(
            "dims = [8, 8, 8]",
            "dims = [8, 8, 8]\nnon_finite = \"refuse\"",
        );
        let s = Scene::parse(&text, Path::new("t.toml")).unwrap();
        assert_eq!(s.volume.non_finite, NonFinitePolicy::Refuse);
        let text = GOOD.replace(
            "dims = [8, 8, 8]",
            "dims = [8, 8, 8]\nnon_finite = \"ignore\"",
        );
        let e = Scene::parse(&text, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("ignore") && e.contains("refuse"), "{e}");
    }

    #[test]
    fn oblique_placement_defaults_to_closest_axes_and_names_the_choices() {
        let s = Scene::parse(GOOD, Path::new("t.toml")).unwrap();
        assert_eq!(s.volume.oblique, ObliquePlacement::ClosestAxes);
        for (name, want) in [
            ("linear", ObliquePlacement::Linear),
            ("nearest", ObliquePlacement::Nearest),
            ("closest-axes", ObliquePlacement::ClosestAxes),
        ] {
            let text = GOOD.replace(
                "dims = [8, 8, 8]",
                &format!("dims = [8, 8, 8]\noblique = \"{name}\""),
            );
            let s = Scene::parse(&text, Path::new("t.toml")).unwrap();
            assert_eq!(s.volume.oblique, want);
        }
        let text = GOOD.replace("dims = [8, 8, 8]", "dims = [8, 8, 8]\noblique = \"cubic\"");
        let e = Scene::parse(&text, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("cubic") && e.contains("nearest"), "{e}");
    }

    #[test]
    fn roi_lambda_auto_and_bounds_parse_and_bad_values_name_the_key() {
        let roi = |extra: &str| format!("{GOOD}\n[[roi]]\nseed = [0.0, 0.0, 0.0]\n{extra}\n");
        let s = Scene::parse(
            &roi(
                "lambda = \"auto\"\nintensity = [60, 170.5]\nmax_distance_mm = 80\nseed_radius = 1\nconnectivity = 26",
            ),
            Path::new("t.toml"),
        )
        .unwrap();
        let r = &s.rois[0];
        assert_eq!(r.lambda, LambdaSetting::Word("auto".into()));
        assert_eq!(r.intensity, Some([60.0, 170.5]));
        assert_eq!(r.max_distance_mm, Some(80.0));
        assert_eq!(r.seed_radius, 1);
        assert_eq!(crate::visualise::roi_request(r).params.seed_radius, 1);
        assert_eq!(crate::visualise::roi_request(r).params.connectivity, 26);
        let s = Scene::parse(&roi("lambda = 12"), Path::new("t.toml")).unwrap();
        assert_eq!(s.rois[0].lambda, LambdaSetting::Value(12.0));
        assert_eq!(s.rois[0].intensity, None);
        assert_eq!(s.rois[0].seed_radius, 2);
        assert_eq!(s.rois[0].connectivity, 6);
        let s = Scene::parse(&roi(""), Path::new("t.toml")).unwrap();
        assert_eq!(s.rois[0].lambda, LambdaSetting::Word("auto".into()));
        // An error in the second [[roi]] points at its own line.
        let two = format!(
            "{}[[roi]]\nseed = [1.0, 0.0, 0.0]\nlambda = -3\n",
            roi("lambda = 4")
        );
        let e = Scene::parse(&two, Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        let line = two.lines().position(|l| l == "lambda = -3").unwrap() + 1;
        assert!(e.starts_with(&format!("t.toml:{line}:1: `lambda`")), "{e}");
        for (extra, key) in [
            ("lambda = \"automatic\"", "`lambda`"),
            ("lambda = -3", "`lambda`"),
            ("lambda = nan", "`lambda`"),
            ("intensity = [200, 100]", "`intensity`"),
            ("intensity = [nan, 100]", "`intensity`"),
            ("max_distance_mm = -1", "`max_distance_mm`"),
            ("max_distance_mm = 0", "`max_distance_mm`"),
            ("max_distance_mm = inf", "`max_distance_mm`"),
            ("seed_radius = 0", "`seed_radius`"),
            ("connectivity = 18", "`connectivity`"),
            ("connectivity = -6", "`connectivity`"),
            ("seed_radius = 9", "`seed_radius`"),
            ("seed_radius = -1", "`seed_radius`"),
        ] {
            let e = Scene::parse(&roi(extra), Path::new("t.toml"))
                .unwrap_err()
                .to_string();
            assert!(e.contains(key), "{extra}: {e}");
        }
    }

    #[test]
    fn resample_keys_are_read_and_validated() {
        let with = |table: &str| format!("{GOOD}\n[resample]\n{table}\n");
        let s = Scene::parse(
            &with("interpolation = \"tetrahedral\"\nmax_output_factor = 40"),
            Path::new("t.toml"),
        )
        .unwrap();
        let r = s.resample.unwrap();
        let p = r.apply(ResampleParams::default());
        assert_eq!(p.interpolation, Interpolation::Tetrahedral);
        assert_eq!(p.max_output_factor, 40.0);
        assert_eq!(
            p.background,
            ResampleParams::default().background,
            "unset keys keep the base"
        );
        let p = ResampleSettings::default().apply(ResampleParams::default());
        assert_eq!(p, ResampleParams::default());
        for bad in ["nan", "0", "-3", "0.5", "inf"] {
            let text = with(&format!("max_output_factor = {bad}"));
            let e = Scene::parse(&text, Path::new("t.toml"))
                .unwrap_err()
                .to_string();
            let line = text
                .lines()
                .position(|l| l.starts_with("max_output_factor"))
                .unwrap()
                + 1;
            assert!(
                e.starts_with(&format!("t.toml:{line}:1: `[resample] max_output_factor`"))
                    && e.contains("≥ 1"),
                "{bad}: {e}"
            );
        }
        let e = Scene::parse(&with("interpolation = \"cubic\""), Path::new("t.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("cubic") && e.contains("trilinear"), "{e}");
    }

    #[test]
    fn each_plugin_gets_its_own_params_table() {
        let text = "[scene]\nname = \"t\"\n[volume]\nsource = \"phantom:cube\"\ndims = [8, 8, 8]\n\
                    [model]\nplugin = \"affine\"\n[model.params.affine]\nangle_deg = 10\n\
                    [model.params.chainmail]\npropagation_iterations = 7\n";
        let s = Scene::parse(text, Path::new("t.toml")).unwrap();
        let own = s.model_params_toml_for("affine").unwrap();
        assert!(
            own.contains("angle_deg = 10") && !own.contains("propagation"),
            "{own}"
        );
        let other = s.model_params_toml_for("chainmail").unwrap();
        assert!(other.contains("propagation_iterations = 7"), "{other}");
        assert_eq!(s.model_params_toml_for("mass-spring"), None);
        // A flat table belongs to the scene's own plugin only.
        let flat = Scene::parse(GOOD, Path::new("t.toml")).unwrap();
        assert!(
            flat.model_params_toml_for("affine")
                .unwrap()
                .contains("angle_deg")
        );
        assert_eq!(flat.model_params_toml_for("chainmail"), None);
    }
}
