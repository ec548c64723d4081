//! The scene pipeline:
//!
//! ```text
//! source → model (+ interactions) → map onto the sampling mesh → resample → output
//! ```
//!
//! Each stage's output carries a version number. A stage runs only when an
//! input version changed, and only over the dirty region; a converged model
//! produces no new version, so nothing downstream runs. Stages the scene
//! does not ask for are never built, plugins it does not name are never
//! loaded, and the GPU is never initialised for a CPU scene.
//!
//! Across runs, a stamp file in the output directory fingerprints what the
//! outputs depend on (the scene text, the bytes of the source and its
//! detached data file, of the plugin libraries and of voxflex itself) and
//! records the size of every file written ([`crate::fingerprint`]): a
//! second run of an unchanged scene whose outputs are all still there
//! re-runs no stage and writes nothing, `metrics.json` included (unless
//! `force`). Runs into one directory take turns under an advisory lock
//! ([`crate::out_dir`]).

use crate::backend::{self, BackendChoice, BackendError, ResolvedBackend};
use crate::fingerprint::{Inputs, Stamp};
use crate::metrics::{PluginReport, RunMetrics};
use crate::plugin_loader::{self, PluginError};
use crate::scene::{Scene, SceneError, SliceName};
use crate::visualise::{self, RenderStage};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_core::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo,
    RestPoints,
};
use voxflex_core::error::{GpuError, IoError, ModelError};
use voxflex_core::glam::DVec3;
use voxflex_core::gpu::GpuService;
use voxflex_core::grid::Grid;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_io::png::{SliceAxis, Window, write_slice_png};
use voxflex_io::{ReadOptions, read_volume_with, write_atomically, write_volume};
use voxflex_phantom::{VolumeSource, parse_source, phantom};
use voxflex_resample::gpu::GpuSource;
use voxflex_resample::{
    DisplacementsRef, ResampleError, ResampleOutput, ResampleParams, ResampleReport, Resampler,
    TetMask,
};

pub use crate::fingerprint::STAMP_FILE;
/// Name of the run report in the output directory.
pub const METRICS_FILE: &str = "metrics.json";

/// Running a scene failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The scene file is invalid.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A plugin could not be loaded.
    #[error(transparent)]
    Plugin(#[from] PluginError),
    /// The backend could not be set up.
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// A volume file could not be read or written.
    #[error(transparent)]
    Io(#[from] IoError),
    /// The model failed.
    #[error("{0}")]
    Model(#[from] ModelError),
    /// The resampler failed.
    #[error("resample: {0}")]
    Resample(#[from] ResampleError),
    /// A GPU call failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// Anything else, already phrased for the user.
    #[error("{0}")]
    Other(String),
}

/// Options of one run beyond the scene file.
#[derive(Default)]
pub struct RunOptions {
    /// Replaces `[output] dir`.
    pub out_dir: Option<PathBuf>,
    /// Re-run even when the outputs are up to date.
    pub force: bool,
    /// Called after every frame with (frame done, frames).
    pub progress: Option<Box<dyn FnMut(u64, u64)>>,
}

/// Loads the scene's source volume (phantom or file).
pub fn load_source(scene: &Scene) -> Result<Volume, RunError> {
    let v = &scene.volume;
    match parse_source(&v.source) {
        VolumeSource::Phantom(name) => {
            let dims = v.dims.unwrap_or([128, 128, 128]);
            phantom(&name, dims).map_err(|e| {
                RunError::Other(format!("{}: [volume] source: {e}", scene.path.display()))
            })
        }
        VolumeSource::File(p) => {
            if v.dims.is_some() {
                return Err(RunError::Other(format!(
                    "{}: [volume] dims applies to phantoms only; remove it for file `{}`",
                    scene.path.display(),
                    p.display()
                )));
            }
            let path = if p.is_absolute() {
                p
            } else {
                scene.base_dir().join(p)
            };
            // NaN voxels become the background the resampler would use.
            let background = scene.resample.as_ref().and_then(|r| r.background);
            Ok(read_volume_with(
                &path,
                &ReadOptions {
                    max_voxels: v.max_voxels,
                },
                v.non_finite,
                background,
            )?)
        }
    }
}

fn configure_threads(threads: usize) {
    if threads > 0 {
        // Only the first call in a process takes effect; later scenes share it.
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global();
    }
}

/// Where the resampler reads displacements from.
enum Displacements {
    Cpu([Vec<f32>; 3]),
    Gpu {
        disp: [voxflex_core::gpu::BufferId; 3],
        source: GpuSource,
    },
}

/// The deformation stages, built only when the scene names a model.
struct DeformStages {
    model: Box<dyn DeformationModel>,
    binding: BindingId,
    displacements: Displacements,
    resampler: Resampler,
    /// Tetrahedra the model removed (cuts, carving); allocated when the
    /// model first reports one, with the cell bytes it writes into.
    mask: Option<(TetMask, Vec<u8>)>,
    source_grid: Grid,
}

impl DeformStages {
    /// Asks the model for removed tetrahedra (after a map); returns true
    /// when the mask changed. An empty array asks only whether there are
    /// any, so scenes without topology changes never allocate a mask.
    fn update_mask(&mut self) -> Result<bool, RunError> {
        if self.mask.is_none() {
            if !self.model.removed_tetrahedra(self.binding, &mut [])? {
                return Ok(false);
            }
            let mask = TetMask::new(&self.source_grid)?;
            let bytes = vec![0u8; mask.cell_count()];
            self.mask = Some((mask, bytes));
        }
        let (mask, bytes) = self.mask.as_mut().expect("allocated above");
        if !self.model.removed_tetrahedra(self.binding, bytes)? {
            return Ok(false);
        }
        Ok(mask.replace_bits(bytes)?)
    }
}

/// Runs a scene to completion and writes its outputs and `metrics.json`.
pub fn run_scene(scene: &Scene, mut opts: RunOptions) -> Result<RunMetrics, RunError> {
    let started = Instant::now();
    let out_cfg = scene.output.clone().unwrap_or_default();
    let out_dir = opts.out_dir.clone().unwrap_or_else(|| out_cfg.dir.clone());
    crate::out_dir::check_dir(&out_dir).map_err(|m| {
        RunError::Other(format!(
            "{}: output directory ([output] dir or --out) {m}",
            scene.path.display()
        ))
    })?;
    std::fs::create_dir_all(&out_dir).map_err(|source| IoError::Io {
        path: out_dir.clone(),
        source,
    })?;
    // Held until this function returns: a second run into the same
    // directory waits, then finds the outputs up to date.
    let _lock = crate::out_dir::lock(&out_dir).map_err(|source| IoError::Io {
        path: out_dir.join(crate::out_dir::LOCK_FILE),
        source,
    })?;
    crate::out_dir::remove_stale_temp_files(&out_dir);
    let plugin_dirs = plugin_loader::search_path(&scene.plugin_dirs());
    let plugin = match &scene.model {
        Some(m) => Some(plugin_loader::load_by_name(&m.plugin, &plugin_dirs)?),
        None => None,
    };
    // The renderer plugin is loaded only when the scene has a [render] table.
    let renderer_plugin = match &scene.render {
        Some(r) => Some(plugin_loader::load_by_name(&r.plugin, &plugin_dirs)?),
        None => None,
    };

    let mut metrics = RunMetrics {
        scene: scene.settings.name.clone(),
        voxflex_version: env!("CARGO_PKG_VERSION").into(),
        frames: scene.settings.frames,
        plugin: plugin.as_ref().map(|p| PluginReport {
            name: p.name.clone(),
            version: p.version.clone(),
            path: p.path.display().to_string(),
        }),
        ..Default::default()
    };

    let plugin_files: Vec<&Path> = plugin
        .iter()
        .chain(renderer_plugin.iter())
        .map(|p| p.path.as_path())
        .collect();
    let fingerprint = fingerprint(scene, &plugin_files, &out_dir);
    let current = Stamp::read(&out_dir)
        .ok_or_else(|| "no stamp of a completed run".to_string())
        .and_then(|s| s.check(&out_dir, &fingerprint));
    match current {
        Ok(()) if !opts.force => {
            // Nothing runs and nothing is written: metrics.json stays the
            // report of the run that made the outputs.
            metrics.up_to_date = true;
            metrics.backend = "none".into();
            metrics.backend_reason = "outputs up to date".into();
            for stage in [
                "source", "model", "map", "resample", "output", "roi", "render",
            ] {
                metrics.stage(stage).skipped = 1;
            }
            metrics.total_wall_ms = started.elapsed().as_secs_f64() * 1e3;
            return Ok(metrics);
        }
        Ok(()) => tracing::debug!("{}: outputs up to date; --force", out_dir.display()),
        Err(why) => tracing::debug!("{}: running: {why}", out_dir.display()),
    }
    // A partial run must never look up to date.
    let _ = std::fs::remove_file(out_dir.join(STAMP_FILE));
    // Every warning from here on also goes into metrics.json.
    let warnings = crate::warnings::capture();

    configure_threads(scene.settings.threads);
    // A deformation plugin without a GPU path runs the scene on the CPU
    // under `auto`, and refuses an explicit `gpu`.
    let cpu_only_model = plugin.as_ref().filter(|p| {
        p.deformation.is_some() && p.capabilities & voxflex_abi::ffi::CAPABILITY_GPU == 0
    });
    let choice = match (scene.settings.backend, cpu_only_model) {
        (BackendChoice::Gpu, Some(p)) => {
            return Err(RunError::Other(format!(
                "{}: backend = \"gpu\", but plugin `{}` has no GPU path; use backend = \"cpu\" or \"auto\"",
                scene.path.display(),
                p.name
            )));
        }
        (BackendChoice::Auto, Some(_)) => BackendChoice::Cpu,
        (c, _) => c,
    };
    let mut resolved: ResolvedBackend =
        if scene.model.is_some() || scene.render.is_some() || !scene.rois.is_empty() {
            backend::resolve(choice)?
        } else {
            // Nothing to compute: never initialise a GPU.
            backend::resolve(BackendChoice::Cpu)?
        };
    if let (BackendChoice::Auto, Some(p)) = (scene.settings.backend, cpu_only_model) {
        resolved.reason = format!(
            "backend = \"auto\": plugin `{}` computes on the CPU only, so rayon on the CPU",
            p.name
        );
    }
    metrics.backend = match resolved.backend {
        ExecutionBackend::Cpu => "cpu".into(),
        ExecutionBackend::Gpu => "gpu".into(),
    };
    metrics.backend_reason = resolved.reason.clone();
    let gpu = resolved.gpu_service();

    // Stage: source.
    let t = Instant::now();
    let source = load_source(scene)?;
    metrics
        .stage("source")
        .record_run(t.elapsed(), source.grid.len() as u64);
    metrics.source_dims = source.grid.dims;
    metrics.output_dims = source.grid.dims;

    // Stages: model → map → resample (only with a model).
    let mut deform = match (&scene.model, &plugin) {
        (Some(_), Some(p)) => {
            let vtable = p.deformation.ok_or_else(|| {
                RunError::Other(format!(
                    "{}: plugin `{}` is a {} plugin; [model] needs a deformation plugin",
                    scene.path.display(),
                    p.name,
                    p.kind_name()
                ))
            })?;
            let services = HostServices::new(gpu.clone(), rayon::current_num_threads());
            // SAFETY: the vtable comes from a checked, never-unloaded library.
            let mut model = unsafe {
                DeformationProxy::create(&p.name, vtable, &scene.model_params_toml(), services)
            }?;
            model.init(source.view(), resolved.backend)?;
            let binding = model.bind(RestPoints::Lattice(source.grid))?;
            let n = source.grid.len();
            let displacements = match (&resolved.backend, &gpu) {
                (ExecutionBackend::Gpu, Some(gpu)) => Displacements::Gpu {
                    disp: [
                        gpu.create_buffer(n as u64 * 4, "displacement x")?,
                        gpu.create_buffer(n as u64 * 4, "displacement y")?,
                        gpu.create_buffer(n as u64 * 4, "displacement z")?,
                    ],
                    source: GpuSource::upload(gpu.as_ref(), source.view())?,
                },
                _ => Displacements::Cpu([vec![0.0; n], vec![0.0; n], vec![0.0; n]]),
            };
            let background = scene
                .resample
                .as_ref()
                .and_then(|r| r.background)
                .unwrap_or_else(|| source.value_range().0);
            let params = ResampleParams {
                background,
                ..ResampleParams::default()
            };
            let params = match &scene.resample {
                Some(r) => r.apply(params),
                None => params,
            };
            let resampler = Resampler::new(params);
            Some(DeformStages {
                model: Box::new(model),
                binding,
                displacements,
                resampler,
                mask: None,
                source_grid: source.grid,
            })
        }
        _ => {
            metrics.stages_not_built = vec!["model".into(), "map".into(), "resample".into()];
            None
        }
    };

    let services = HostServices::new(gpu.clone(), rayon::current_num_threads());
    let mut render_stage = match (&scene.render, &renderer_plugin) {
        (Some(_), Some(p)) => Some(RenderStage::new(
            &scene.path.display().to_string(),
            p,
            &scene.render_params_toml(),
            services.clone(),
            resolved.backend,
        )?),
        _ => {
            metrics.stages_not_built.push("render".into());
            None
        }
    };
    if scene.rois.is_empty() {
        metrics.stages_not_built.push("roi".into());
    }
    let mut render_dirty = DirtyRegion::All;

    // Versions: a stage runs when its input version moved past what it consumed.
    let mut model_version = 0u64;
    let mut map_version = 0u64;
    // The first frame always maps and resamples: a model that does not
    // move still has an output (the volume as it is).
    let mut map_input = u64::MAX;
    let mut resample_version = 0u64;
    let mut resample_input = 0u64;
    let mut output_input = u64::MAX; // outputs not written yet
    let mut dirty = DirtyRegion::None;
    let mut resampled: Option<Volume> = None;
    let frames = scene.settings.frames;

    for frame in 0..frames {
        if let Some(d) = deform.as_mut() {
            // Stage: model.
            let t = Instant::now();
            for i in scene.interactions.iter().filter(|i| i.frame == frame) {
                d.model.interact(&i.toml)?;
            }
            let outcome = d.model.step(FrameInfo {
                frame,
                frames,
                dt_s: scene.settings.dt_s,
            })?;
            metrics.stage("model").record_run(t.elapsed(), 0);
            if outcome.changed {
                model_version += 1;
            }

            // Stage: map.
            if model_version != map_input {
                let t = Instant::now();
                dirty = dirty.union(d.model.dirty_region());
                let target = match &mut d.displacements {
                    Displacements::Cpu([x, y, z]) => DisplacementTarget::Cpu { x, y, z },
                    Displacements::Gpu {
                        disp: [x, y, z], ..
                    } => DisplacementTarget::Gpu {
                        x: *x,
                        y: *y,
                        z: *z,
                    },
                };
                d.model.map(d.binding, target)?;
                d.update_mask()?;
                map_input = model_version;
                map_version += 1;
                metrics
                    .stage("map")
                    .record_run(t.elapsed(), source.grid.len() as u64);
            } else {
                metrics.stage("map").skipped += 1;
            }

            // Stage: resample.
            if map_version != resample_input {
                let t = Instant::now();
                let report = resample_stage(d, &source, &gpu, dirty)?;
                dirty = DirtyRegion::None;
                resample_input = map_version;
                resample_version += 1;
                metrics
                    .stage("resample")
                    .record_run(t.elapsed(), report.voxels_touched);
                render_dirty =
                    render_dirty.union(refilled_region(&report, d.resampler.output_grid()));
                if let Some(g) = d.resampler.output_grid() {
                    metrics.output_dims = g.dims;
                }
                // Displacements (3 × f32) plus the resampler's own scratch.
                metrics.resample_extra_bytes_per_voxel =
                    12.0 + d.resampler.scratch_bytes() as f64 / source.grid.len().max(1) as f64;
            } else {
                metrics.stage("resample").skipped += 1;
            }
        }

        // Stage: output (every changed frame on request, else after the last).
        let last = frame + 1 == frames;
        if (out_cfg.every_frame || last) && resample_version != output_input {
            let t = Instant::now();
            let volume: &Volume = match &deform {
                Some(d) => {
                    let out = read_back(d, &gpu)?;
                    resampled.insert(
                        Volume::new(out.grid, VoxelData::F32(out.values))
                            .map_err(|e| RunError::Other(e.to_string()))?,
                    )
                }
                None => &source,
            };
            let suffix = if out_cfg.every_frame && !last {
                format!("_f{frame:04}")
            } else {
                String::new()
            };
            let mut written = write_outputs(volume, &out_cfg, &out_dir, &suffix, last)?;
            metrics.outputs.append(&mut written);
            // Stages: roi and render, on what was just written.
            let maps = if scene.rois.is_empty() {
                vec![]
            } else {
                let (maps, stats) =
                    visualise::grow_rois(scene, volume, gpu.as_ref(), &mut metrics)?;
                if let (Some(stage), Some(settings)) = (
                    render_stage.as_mut(),
                    visualise::gaussian_tf_settings(scene, &stats),
                ) {
                    stage.configure(&settings)?;
                }
                if last {
                    metrics.outputs.extend(visualise::write_maps(
                        scene,
                        &volume.grid,
                        &maps,
                        &out_dir,
                    )?);
                }
                maps
            };
            if let (Some(stage), Some(settings)) = (render_stage.as_mut(), &scene.render) {
                let mut settings = settings.clone();
                if !suffix.is_empty() {
                    settings.file = settings.file.replace(".png", &format!("{suffix}.png"));
                }
                let files = stage.render(
                    &settings,
                    volume,
                    render_dirty,
                    &maps,
                    &out_dir,
                    &mut metrics,
                )?;
                metrics.outputs.extend(files);
                render_dirty = DirtyRegion::None;
            }
            output_input = resample_version;
            metrics
                .stage("output")
                .record_run(t.elapsed(), volume.grid.len() as u64);
        } else if out_cfg.every_frame || last {
            metrics.stage("output").skipped += 1;
        }
        if let Some(p) = opts.progress.as_mut() {
            p(frame + 1, frames);
        }
    }

    // What the model reports about its own work (iterations, points bound
    // outside its proxy, ...), under the model stage's notes.
    if let Some(d) = deform.as_mut() {
        let notes = d.model.notes()?;
        let stage = metrics.stage("model");
        for (name, value) in notes {
            stage.notes.insert(name, value.into());
        }
    }
    if let Some(mut d) = deform
        && let (Displacements::Gpu { disp, source }, Some(gpu)) = (&d.displacements, &gpu)
    {
        disp.iter().for_each(|&id| gpu.destroy_buffer(id));
        source.release(gpu.as_ref());
        d.resampler.release_gpu(gpu.as_ref());
    }
    metrics.warnings = warnings.finish();
    metrics.total_wall_ms = started.elapsed().as_secs_f64() * 1e3;
    write_text(&out_dir.join(METRICS_FILE), &metrics.to_json())?;
    let mut written = metrics.outputs.clone();
    written.push(METRICS_FILE.into());
    let stamp = Stamp::record(fingerprint, &out_dir, &written);
    write_text(&out_dir.join(STAMP_FILE), &stamp.to_json())?;
    Ok(metrics)
}

/// Resamples over the dirty region; returns the voxels touched.
fn resample_stage(
    d: &mut DeformStages,
    source: &Volume,
    gpu: &Option<Arc<dyn GpuService>>,
    dirty: DirtyRegion,
) -> Result<ResampleReport, RunError> {
    let mask = d.mask.as_ref().map(|(m, _)| m);
    let report = match (&d.displacements, &gpu) {
        (Displacements::Cpu([x, y, z]), _) => {
            d.resampler
                .resample_cpu(source.view(), DisplacementsRef { x, y, z }, mask, dirty)?
        }
        (Displacements::Gpu { disp, source }, Some(gpu)) => {
            d.resampler
                .resample_gpu(gpu.as_ref(), source, *disp, mask, dirty)?
        }
        (Displacements::Gpu { .. }, None) => {
            return Err(RunError::Other("GPU displacements without a GPU".into()));
        }
    };
    Ok(report)
}

/// The world box (mm) of the output voxels a resample re-filled.
fn refilled_region(report: &ResampleReport, output: Option<Grid>) -> DirtyRegion {
    match (
        report.full || report.output_grid_changed,
        report.region,
        output,
    ) {
        (false, Some((lo, hi)), Some(g)) => {
            let f = |v: [usize; 3]| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64);
            DirtyRegion::Box {
                min: g.index_to_world(f(lo)),
                max: g.index_to_world(f(hi)),
            }
        }
        (false, None, Some(_)) => DirtyRegion::None,
        _ => DirtyRegion::All,
    }
}

/// The resampled values, read back from the GPU when they live there.
fn read_back(
    d: &DeformStages,
    gpu: &Option<Arc<dyn GpuService>>,
) -> Result<ResampleOutput, RunError> {
    match (&d.displacements, &gpu) {
        (Displacements::Gpu { .. }, Some(gpu)) => Ok(d.resampler.read_gpu_output(gpu.as_ref())?),
        _ => d
            .resampler
            .cpu_output()
            .ok_or_else(|| RunError::Other("no resampled output yet".into())),
    }
}

fn write_outputs(
    volume: &Volume,
    cfg: &crate::scene::OutputSettings,
    dir: &Path,
    suffix: &str,
    last: bool,
) -> Result<Vec<String>, RunError> {
    let mut written = vec![];
    let window = match cfg.window {
        Some(w) => Window {
            level: w.level,
            width: w.width,
        },
        None => {
            let (lo, hi) = volume.value_range();
            Window {
                level: 0.5 * (lo + hi),
                width: (hi - lo).max(f32::MIN_POSITIVE),
            }
        }
    };
    for s in &cfg.slices {
        let (axis, name, along) = match s {
            SliceName::Axial => (SliceAxis::Axial, "axial", 2),
            SliceName::Coronal => (SliceAxis::Coronal, "coronal", 1),
            SliceName::Sagittal => (SliceAxis::Sagittal, "sagittal", 0),
        };
        let file = format!("{name}{suffix}.png");
        write_slice_png(
            &dir.join(&file),
            volume.view(),
            axis,
            volume.grid.dims[along] / 2,
            window,
        )?;
        written.push(file);
    }
    if last && let Some(n) = &cfg.nifti {
        write_volume(&dir.join(n), volume.view())?;
        written.push(n.clone());
    }
    Ok(written)
}

fn write_text(path: &Path, text: &str) -> Result<(), RunError> {
    write_atomically(path, |w| w.write_all(text.as_bytes()))?;
    Ok(())
}

/// Fingerprint of everything a run's outputs depend on.
fn fingerprint(scene: &Scene, plugins: &[&Path], out_dir: &Path) -> String {
    let source = match parse_source(&scene.volume.source) {
        VolumeSource::File(p) if p.is_absolute() => Some(p),
        VolumeSource::File(p) => Some(scene.base_dir().join(p)),
        VolumeSource::Phantom(_) => None,
    };
    crate::fingerprint::fingerprint(&Inputs {
        scene_text: &scene.text,
        out_dir,
        plugins,
        source,
        host: crate::fingerprint::host_identity(),
    })
}
