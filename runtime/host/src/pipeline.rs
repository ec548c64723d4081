//! The scene pipeline:
//!
//! ```text
//! source → model (+ interactions) → map onto the sampling mesh → resample → output
//! ```
//!
//! [`run_scene`] is a loop over a [`Session`] (the stages, their versions
//! and their metrics live there): each stage's output carries a version
//! number; a stage runs only when an input version changed, and only over
//! the dirty region; a converged model produces no new version, so nothing
//! downstream runs. Stages the scene does not ask for are never built,
//! plugins it does not name are never loaded, and the GPU is never
//! initialised for a CPU scene.
//!
//! Across runs, a stamp file in the output directory fingerprints what the
//! outputs depend on (the scene text, the bytes of the source and its
//! detached data file, of the plugin libraries and of voxflex itself) and
//! records the size of every file written ([`crate::fingerprint`]): a
//! second run of an unchanged scene whose outputs are all still there
//! re-runs no stage and writes nothing, `metrics.json` included (unless
//! `force`). Runs into one directory take turns under an advisory lock
//! ([`crate::out_dir`]).

use crate::backend::BackendError;
use crate::fingerprint::{Inputs, Stamp};
use crate::metrics::{PluginReport, RunMetrics};
use crate::plugin_loader::PluginError;
use crate::scene::{Scene, SceneError, SliceName};
use crate::session::{Interaction, ScenePlugins, Session};
use crate::visualise;
use std::path::{Path, PathBuf};
use std::time::Instant;
use voxflex_core::deformation::DirtyRegion;
use voxflex_core::error::{GpuError, IoError, ModelError};
use voxflex_core::render::RenderVolume;
use voxflex_core::volume::Volume;
use voxflex_io::png::{SliceAxis, Window, write_slice_png};
use voxflex_io::{ReadOptions, read_volume_with, write_atomically, write_volume};
use voxflex_phantom::{VolumeSource, parse_source, phantom};
use voxflex_resample::ResampleError;

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
    /// A session's call into its deformation model failed; `call` says
    /// which (see [`RunError::model_call`]). The message is the model's
    /// own, as [`RunError::Model`] gives it (a scene's `validate` and `run`
    /// give the same words).
    #[error("{error}")]
    ModelCall {
        /// The call that failed.
        call: crate::session::ModelCall,
        /// The model's error.
        error: ModelError,
    },
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
                    oblique: v.oblique,
                },
                v.non_finite,
                background,
            )?)
        }
    }
}

/// Runs a scene to completion and writes its outputs and `metrics.json`:
/// a loop over a [`Session`] that hands it the scene's interactions at
/// their frames, steps it, and writes the outputs (slices, NIfTI, ROI maps,
/// renders) when the volume changed at the frames `[output]` asks for.
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
    let plugins = ScenePlugins::load(scene)?;

    let fingerprint = fingerprint(scene, &plugins.files(), &out_dir);
    let current = Stamp::read(&out_dir)
        .ok_or_else(|| "no stamp of a completed run".to_string())
        .and_then(|s| s.check(&out_dir, &fingerprint));
    match current {
        Ok(()) if !opts.force => {
            // Nothing runs and nothing is written: metrics.json stays the
            // report of the run that made the outputs.
            let mut metrics = RunMetrics {
                scene: scene.settings.name.clone(),
                voxflex_version: env!("CARGO_PKG_VERSION").into(),
                frames: scene.settings.frames,
                plugin: plugins.model.as_ref().map(|p| PluginReport {
                    name: p.name.clone(),
                    version: p.version.clone(),
                    path: p.path.display().to_string(),
                }),
                up_to_date: true,
                backend: "none".into(),
                backend_reason: "outputs up to date".into(),
                ..Default::default()
            };
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

    let mut session = Session::open_loaded(scene, &plugins)?;
    let frames = scene.settings.frames;
    let mut outputs: Vec<String> = vec![];
    for frame in 0..frames {
        for i in scene.interactions.iter().filter(|i| i.frame == frame) {
            session.interact(&Interaction::Toml(i.toml.clone()))?;
        }
        session.step()?;
        // Stage: output (every changed frame on request, else after the last).
        let last = frame + 1 == frames;
        if out_cfg.every_frame || last {
            let suffix = if out_cfg.every_frame && !last {
                format!("_f{frame:04}")
            } else {
                String::new()
            };
            let written = output_stage(scene, &mut session, &out_cfg, &out_dir, &suffix, last)?;
            outputs.extend(written);
        }
        if let Some(p) = opts.progress.as_mut() {
            p(frame + 1, frames);
        }
    }

    // What the model reports about its own work (iterations, points bound
    // outside its proxy, ...) lands under the model stage's notes.
    let mut metrics = session.metrics()?;
    drop(session);
    metrics.outputs = outputs;
    metrics.warnings = warnings.finish();
    metrics.total_wall_ms = started.elapsed().as_secs_f64() * 1e3;
    write_text(&out_dir.join(METRICS_FILE), &metrics.to_json())?;
    let mut written = metrics.outputs.clone();
    written.push(METRICS_FILE.into());
    let stamp = Stamp::record(fingerprint, &out_dir, &written);
    write_text(&out_dir.join(STAMP_FILE), &stamp.to_json())?;
    Ok(metrics)
}

/// The output stage of one frame: when the volume changed since the last
/// output, writes the slices and NIfTI, then grows the scene's ROI maps and
/// renders, on what was just written; returns the files written.
fn output_stage(
    scene: &Scene,
    session: &mut Session,
    out_cfg: &crate::scene::OutputSettings,
    out_dir: &Path,
    suffix: &str,
    last: bool,
) -> Result<Vec<String>, RunError> {
    let mut parts = session.output_parts()?;
    let input = parts.versions.resample.version;
    if !parts.versions.output.is_due(input) {
        parts.metrics.stage("output").skipped += 1;
        return Ok(vec![]);
    }
    let t = Instant::now();
    let volume = parts.volume;
    let mut written = write_outputs(volume, out_cfg, out_dir, suffix, last)?;
    // Stages: roi and render, on what was just written.
    let maps = if scene.rois.is_empty() {
        vec![]
    } else {
        let (maps, stats) = visualise::grow_rois(scene, volume, parts.gpu, parts.metrics)?;
        if let (Some(stage), Some(settings)) = (
            parts.renderer.as_deref_mut(),
            visualise::gaussian_tf_settings(scene, &stats),
        ) {
            stage.configure(&settings)?;
        }
        if last {
            written.extend(visualise::write_maps(scene, &volume.grid, &maps, out_dir)?);
        }
        maps
    };
    if let (Some(stage), Some(settings)) = (parts.renderer, &scene.render) {
        let mut settings = settings.clone();
        if !suffix.is_empty() {
            settings.file = settings.file.replace(".png", &format!("{suffix}.png"));
        }
        let files = stage.render(
            &settings,
            match &parts.lent {
                Some(source) => RenderVolume::Shared(source),
                None => RenderVolume::Cpu(volume.view()),
            },
            *parts.render_dirty,
            &maps,
            out_dir,
            parts.metrics,
        )?;
        written.extend(files);
        *parts.render_dirty = DirtyRegion::None;
    }
    parts.versions.output.ran_on(input);
    parts
        .metrics
        .stage("output")
        .record_run(t.elapsed(), volume.grid.len() as u64);
    Ok(written)
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
