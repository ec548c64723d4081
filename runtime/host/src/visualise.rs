//! The visual stages of a scene, after resampling: spatial opacity maps
//! (`[[roi]]`) and direct volume rendering (`[render]`). Both are built only
//! when the scene asks for them; the renderer plugin is never loaded
//! otherwise.

use crate::metrics::RunMetrics;
use crate::pipeline::RunError;
use crate::plugin_loader::LoadedPlugin;
use crate::scene::{LambdaSetting, ProjectionName, RenderSettings, RoiSettings, Scene, SliceName};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;
use voxflex_abi::host_side::HostServices;
use voxflex_abi::renderer::RendererProxy;
use voxflex_core::camera::{Camera, Projection};
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::grid::Grid;
use voxflex_core::render::{ImageTarget, RenderStats, RenderVolume, Renderer};
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_io::png::SliceAxis;
use voxflex_io::{write_atomically, write_volume};
use voxflex_opacity::{
    GpuOpacityVolume, GrowthLimits, GrowthParams, LambdaChoice, OpacityMap, RoiOutcome, RoiRequest,
    Seed, SeedStats, grow_roi,
};

/// The seed of a `[[roi]]` table.
pub fn roi_seed(roi: &RoiSettings) -> Seed {
    match (roi.seed, roi.seed_slice) {
        (Some(p), _) => Seed::World(DVec3::from_array(p)),
        (None, Some(s)) => Seed::Slice {
            axis: match s.axis {
                SliceName::Axial => SliceAxis::Axial,
                SliceName::Coronal => SliceAxis::Coronal,
                SliceName::Sagittal => SliceAxis::Sagittal,
            },
            index: s.index,
            pixel: s.pixel,
        },
        // Refused by scene validation.
        (None, None) => Seed::Voxel([0, 0, 0]),
    }
}

/// The core request of a `[[roi]]` table.
pub fn roi_request(roi: &RoiSettings) -> RoiRequest {
    RoiRequest {
        seed: roi_seed(roi),
        params: GrowthParams {
            o_min: roi.o_min,
            o_max: roi.o_max,
            // Checked to lie in 1 ..= MAX_SEED_RADIUS when the scene loaded;
            // anything else is refused again by the growth's own check.
            seed_radius: u32::try_from(roi.seed_radius).unwrap_or(0),
            connectivity: u32::try_from(roi.connectivity).unwrap_or(0),
            ..GrowthParams::default()
        },
        lambda: match roi.lambda {
            LambdaSetting::Value(l) => LambdaChoice::Fixed(l),
            // Anything but "auto" is refused when the scene loads.
            LambdaSetting::Word(_) => LambdaChoice::Auto,
        },
        limits: GrowthLimits {
            intensity: roi.intensity,
            max_distance_mm: roi.max_distance_mm,
        },
        steps: roi.steps,
    }
}

/// The `metrics.json` notes of one map: λ used (and the automatic search's
/// trials), what stopped it, its size and any warnings.
pub fn roi_notes(out: &RoiOutcome) -> serde_json::Value {
    let mut m = serde_json::Map::new();
    m.insert("lambda".into(), (out.lambda as f64).into());
    if let Some(a) = &out.auto {
        let trials: Vec<serde_json::Value> = a
            .trials
            .iter()
            .map(|t| {
                serde_json::json!({
                    "lambda": t.lambda, "voxels": t.voxels, "visits": t.visits, "aborted": t.aborted
                })
            })
            .collect();
        m.insert("lambda_auto_trials".into(), trials.into());
    }
    m.insert("stopped_by".into(), out.stop().into());
    let made = if out.from_scan() {
        "lambda scan"
    } else {
        "growth"
    };
    m.insert("made_by".into(), made.into());
    m.insert("steps".into(), out.grown.report.steps.into());
    m.insert("converged".into(), out.grown.report.converged.into());
    m.insert("voxels_above_half".into(), out.voxels.into());
    m.insert("seed_mean".into(), (out.grown.stats.mean as f64).into());
    m.insert("seed_sigma".into(), (out.grown.stats.sigma as f64).into());
    m.insert("warnings".into(), out.warnings().into());
    m.into()
}

/// Grows every `[[roi]]` map over `volume`, on the GPU when one is given.
pub fn grow_rois(
    scene: &Scene,
    volume: &Volume,
    gpu: Option<&Arc<dyn GpuService>>,
    metrics: &mut RunMetrics,
) -> Result<(Vec<OpacityMap>, Vec<SeedStats>), RunError> {
    let t = Instant::now();
    let (mut maps, mut stats) = (vec![], vec![]);
    let (mut visits, mut useful) = (0u64, 0u64);
    let uploaded = match gpu {
        Some(g) if !scene.rois.is_empty() => {
            Some(GpuOpacityVolume::upload(g.as_ref(), volume.view()).map_err(roi_err)?)
        }
        _ => None,
    };
    let mut notes = serde_json::Map::new();
    for (n, roi) in scene.rois.iter().enumerate() {
        let name = roi.name.clone().unwrap_or_else(|| n.to_string());
        let req = roi_request(roi);
        let shared = match (gpu, &uploaded) {
            (Some(g), Some(values)) => Some((g.as_ref(), values)),
            _ => None,
        };
        let out = grow_roi(volume.view(), &req, shared).map_err(roi_err)?;
        for w in out.warnings() {
            tracing::warn!("[[roi]] {name}: {w}");
        }
        notes.insert(name, roi_notes(&out));
        let report = out.grown.report;
        stats.push(out.grown.stats);
        visits += report.visits;
        useful += report.useful;
        maps.push(out.grown.map);
    }
    if let (Some(g), Some(values)) = (gpu, uploaded) {
        values.release(g.as_ref());
    }
    let stage = metrics.stage("roi");
    stage.record_run(t.elapsed(), visits);
    stage.notes.insert("useful_visits".into(), useful.into());
    stage.notes.insert(
        "useful_fraction".into(),
        (useful as f64 / visits.max(1) as f64).into(),
    );
    stage.notes.insert("maps".into(), notes.into());
    stage.notes.insert(
        "map_bytes".into(),
        maps.iter().map(OpacityMap::bytes).sum::<usize>().into(),
    );
    Ok((maps, stats))
}

/// The `transfer_function` settings of `[render.params]` with the automatic
/// Gaussian of the `[[roi]]` marked `gaussian_tf` (mean and σ of its seed's
/// neighbourhood), as TOML for `Renderer::configure`; `None` when no ROI asks.
pub fn gaussian_tf_settings(scene: &Scene, stats: &[SeedStats]) -> Option<String> {
    let (_, s) = scene.rois.iter().zip(stats).find(|(r, _)| r.gaussian_tf)?;
    let mut tf = match scene.render.as_ref()?.params.get("transfer_function") {
        Some(toml::Value::Table(t)) => t.clone(),
        _ => toml::Table::from_iter([("preset".to_owned(), toml::Value::from("ct-bone"))]),
    };
    let mut g = toml::Table::new();
    g.insert("mean".into(), toml::Value::Float(s.mean as f64));
    g.insert("sigma".into(), toml::Value::Float(s.sigma as f64));
    tf.insert("gaussian".into(), toml::Value::Table(g));
    let mut root = toml::Table::new();
    root.insert("transfer_function".into(), toml::Value::Table(tf));
    toml::to_string(&root).ok()
}

fn roi_err(e: impl std::fmt::Display) -> RunError {
    RunError::Other(format!("[[roi]]: {e}"))
}

/// An opacity map as a u16 volume (65535 = opacity 1) on its voxel box of
/// `grid` (same spacing; origin at the box's first voxel, mm).
pub fn map_volume(grid: &Grid, map: &OpacityMap) -> Volume {
    let o = map.origin;
    let sub = Grid::new(
        map.dims,
        grid.spacing,
        grid.index_to_world(DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64)),
    );
    Volume {
        grid: sub,
        data: VoxelData::U16(map.values.clone()),
    }
}

/// Writes opacity maps as NIfTI (u16 fixed point on the map's voxel box).
pub fn write_maps(
    scene: &Scene,
    grid: &Grid,
    maps: &[OpacityMap],
    dir: &Path,
) -> Result<Vec<String>, RunError> {
    let mut written = vec![];
    for (n, (roi, map)) in scene.rois.iter().zip(maps).enumerate() {
        if !roi.write {
            continue;
        }
        let name = roi.name.clone().unwrap_or_else(|| n.to_string());
        let file = format!("roi_{name}.nii.gz");
        write_volume(&dir.join(&file), map_volume(grid, map).view())?;
        written.push(file);
    }
    Ok(written)
}

/// The camera of `[render]` for a volume on `grid`, turned `extra_azimuth` degrees.
pub fn camera_for(settings: &RenderSettings, grid: &Grid, extra_azimuth: f64) -> Camera {
    let (lo, hi) = grid.world_bounds();
    let diagonal = (hi - lo).length().max(1.0);
    let c = settings.camera;
    Camera {
        target: c.target_mm.map_or(grid.centre(), DVec3::from_array),
        azimuth_deg: c.azimuth_deg + extra_azimuth,
        elevation_deg: c.elevation_deg,
        distance_mm: c.distance_mm.unwrap_or(2.0 * diagonal),
        projection: match c.projection {
            ProjectionName::Orthographic => Projection::Orthographic {
                height_mm: c.height_mm.unwrap_or(diagonal),
            },
            ProjectionName::Perspective => Projection::Perspective {
                fov_y_deg: c.fov_deg,
            },
        },
        width: settings.width,
        height: settings.height,
    }
}

/// The renderer stage: the loaded plugin instance.
pub struct RenderStage {
    renderer: RendererProxy,
}

impl RenderStage {
    /// Creates and initialises a renderer plugin with the TOML text of its
    /// parameters; `context` (e.g. the scene file) prefixes errors.
    pub fn new(
        context: &str,
        plugin: &LoadedPlugin,
        params_toml: &str,
        services: Arc<HostServices>,
        backend: ExecutionBackend,
    ) -> Result<Self, RunError> {
        let vtable = plugin.renderer.ok_or_else(|| {
            RunError::Other(format!(
                "{context}: [render] plugin `{}` is a {} plugin, not a renderer",
                plugin.name,
                plugin.kind_name()
            ))
        })?;
        plugin.check_params(params_toml)?;
        // SAFETY: checked, never-unloaded library.
        let mut renderer =
            unsafe { RendererProxy::create(&plugin.name, vtable, params_toml, services) }?;
        renderer.init(backend)?;
        Ok(Self { renderer })
    }

    /// Changes renderer settings (TOML of its parameter keys).
    pub fn configure(&mut self, settings_toml: &str) -> Result<(), RunError> {
        Ok(self.renderer.configure(settings_toml)?)
    }

    /// Hands the renderer `volume` (with `dirty`, the world box in mm that
    /// changed since the last call) and the opacity `maps` (voxel boxes of
    /// `volume`'s grid).
    pub fn set_scene(
        &mut self,
        volume: &Volume,
        dirty: DirtyRegion,
        maps: &[OpacityMap],
    ) -> Result<(), RunError> {
        self.set_scene_on(RenderVolume::Cpu(volume.view()), dirty, maps)
    }

    /// [`Self::set_scene`] with the volume where it lives: in memory, or in
    /// a GPU buffer of the renderer's device (the resampler's output, bound
    /// as is by a GPU renderer).
    pub fn set_scene_on(
        &mut self,
        volume: RenderVolume<'_>,
        dirty: DirtyRegion,
        maps: &[OpacityMap],
    ) -> Result<(), RunError> {
        self.renderer.set_volume(volume, dirty)?;
        self.renderer.set_opacity_maps(maps)?;
        Ok(())
    }

    /// Renders what [`Self::set_scene`] handed over through `camera` into
    /// an RGBA8 image in memory (row-major, top row first).
    pub fn render_image(&mut self, camera: &Camera) -> Result<(RgbaImage, RenderStats), RunError> {
        let mut pixels = vec![0u8; camera.width as usize * camera.height as usize * 4];
        let stats = self.render_into(camera, ImageTarget::Cpu(&mut pixels))?;
        Ok((
            RgbaImage {
                width: camera.width,
                height: camera.height,
                pixels,
            },
            stats,
        ))
    }

    /// Renders what [`Self::set_scene`] handed over through `camera` into
    /// `target` (`camera.width × camera.height` RGBA8 pixels, sRGB,
    /// straight alpha, top row first).
    pub fn render_into(
        &mut self,
        camera: &Camera,
        target: ImageTarget<'_>,
    ) -> Result<RenderStats, RunError> {
        Ok(self.renderer.render(camera, target)?)
    }

    /// Renders `volume` (copied, or kept when shared) with `maps` and
    /// writes the image(s); returns the files.
    pub fn render(
        &mut self,
        settings: &RenderSettings,
        volume: RenderVolume<'_>,
        dirty: DirtyRegion,
        maps: &[OpacityMap],
        dir: &Path,
        metrics: &mut RunMetrics,
    ) -> Result<Vec<String>, RunError> {
        let t = Instant::now();
        self.set_scene_on(volume, dirty, maps)?;
        let frames = settings.turntable.max(1);
        let mut written = vec![];
        let (mut rays, mut samples) = (0u64, 0u64);
        for f in 0..frames {
            let camera = camera_for(settings, &volume.grid(), 360.0 * f as f64 / frames as f64);
            let (image, stats) = self.render_image(&camera)?;
            rays += stats.rays;
            samples += stats.samples;
            let file = if settings.turntable == 0 {
                settings.file.clone()
            } else {
                settings.file.replace(".png", &format!("_{f:03}.png"))
            };
            write_rgba_png(&dir.join(&file), &image)?;
            written.push(file);
        }
        let stage = metrics.stage("render");
        stage.record_run(t.elapsed(), rays);
        stage.notes.insert("samples".into(), samples.into());
        Ok(written)
    }
}

/// An RGBA8 image in memory.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RgbaImage {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width × height × 4` bytes (R, G, B, A), row-major, top row first.
    pub pixels: Vec<u8>,
}

impl RgbaImage {
    /// The (R, G, B, A) of pixel (`x`, `y`), from the top-left corner.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = (y as usize * self.width as usize + x as usize) * 4;
        [
            self.pixels[i],
            self.pixels[i + 1],
            self.pixels[i + 2],
            self.pixels[i + 3],
        ]
    }
}

/// Writes an RGBA8 image as a PNG, atomically: encoded straight from the
/// pixels into the temporary file (no copy of the image, no buffer of the
/// encoded file).
pub fn write_rgba_png(path: &Path, image: &RgbaImage) -> Result<(), RunError> {
    use image::ImageEncoder;
    if image.pixels.len() != image.width as usize * image.height as usize * 4 {
        return Err(RunError::Other(format!(
            "{}: image size mismatch",
            path.display()
        )));
    }
    write_atomically(path, |w| {
        image::codecs::png::PngEncoder::new(w)
            .write_image(
                &image.pixels,
                image.width,
                image.height,
                image::ExtendedColorType::Rgba8,
            )
            .map_err(std::io::Error::other)
    })?;
    Ok(())
}
