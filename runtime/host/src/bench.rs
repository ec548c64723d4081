//! `voxflex bench`: figures anyone can reproduce, measured through the real
//! path — the `affine` plugin loaded from its shared library, the resampler
//! of voxflex-core, the backend chosen like a scene's.
//!
//! Reports, for an N³ head phantom (default 256³):
//! - full-volume twist: map (plugin) and resample wall time;
//! - the same with the deformation confined to 5% of the volume (a ball
//!   whose bounding box, the dirty region, holds 5% of the voxels):
//!   dirty-region resample time and its speed-up over the full one;
//! - resampling memory beyond the input and output volumes, bytes/voxel;
//! - plugin-boundary overhead per frame (the C-ABI calls, timed with a no-op
//!   step) as a fraction of the frame.
//!
//! `--accuracy` reports instead, per interpolation mode, resampling time and
//! error against an f64 reference under affine, twist and bend (see
//! [`accuracy`]). `--fronts` runs every model's run-time/error front and
//! writes tables and plots (see [`fronts`]).
//!
//! `--stress` runs instead the numerical stress suite of every deformation
//! model on randomized scenes (see [`stress`]).

mod accuracy;
mod fronts;
pub mod stress;

use crate::backend::{self, BackendChoice};
use crate::plugin_loader;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_core::deformation::{
    DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo, RestPoints,
};
use voxflex_core::volume::Volume;
use voxflex_phantom::phantom;
use voxflex_resample::gpu::GpuSource;
use voxflex_resample::{DisplacementsRef, Interpolation, ResampleParams, Resampler};

/// Arguments of `voxflex bench`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// Phantom edge length, voxels (the volume is N³).
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Backend: cpu, gpu or auto.
    #[arg(long, default_value = "cpu")]
    pub backend: BackendChoice,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Fraction of the volume the local deformation is confined to (its
    /// ball's bounding box, the dirty region).
    #[arg(long, default_value_t = 0.05)]
    pub local_fraction: f64,
    /// Extra plugin directories searched first.
    #[arg(long = "plugin-dir")]
    pub plugin_dirs: Vec<PathBuf>,
    /// Also write the figures as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Resampler interpolation (tetrahedral | trilinear; default: the
    /// resampler's default, trilinear).
    #[arg(long)]
    pub interpolation: Option<Interpolation>,
    /// Measure both interpolation modes instead: resample time and error
    /// (HU) against an f64 reference under affine, twist and bend.
    #[arg(long, conflicts_with = "fronts")]
    pub accuracy: bool,
    /// Measure the run-time/error front of every model instead (FEM
    /// cantilever and elastica, the same grab across models, resampling,
    /// ROI maps) and write `<front>.csv`, `<front>.svg` and `front.md`
    /// into `--out`.
    #[arg(long)]
    pub fronts: bool,
    /// With `--fronts`: tiny sizes (seconds; what the tests run).
    #[arg(long, requires = "fronts")]
    pub quick: bool,
    /// With `--fronts`: only these fronts (fem_cantilever, fem_elastica,
    /// grab, resample, roi; repeatable).
    #[arg(long, requires = "fronts")]
    pub only: Vec<String>,
    /// With `--fronts`: the output directory.
    #[arg(long, default_value = "docs/fronts")]
    pub out: PathBuf,
    /// Run the numerical stress suite instead: randomized scenes for every
    /// deformation model (see `bench::stress`).
    #[arg(long, conflicts_with_all = ["fronts", "accuracy"])]
    pub stress: bool,
    /// Stress: scenes per model.
    #[arg(long, default_value_t = 250)]
    pub stress_scenes: u64,
    /// Stress: frames per scene.
    #[arg(long, default_value_t = 13)]
    pub stress_frames: u64,
    /// Stress: only these models (repeatable; default: all four).
    #[arg(long)]
    pub stress_model: Vec<String>,
    /// Stress: the RNG seed that draws the scenes.
    #[arg(long, default_value_t = 13)]
    pub seed: u64,
}

/// Running the benchmark failed.
#[derive(Debug, thiserror::Error)]
#[error("bench: {0}")]
pub struct BenchError(String);

fn err(e: impl std::fmt::Display) -> BenchError {
    BenchError(e.to_string())
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

struct Case {
    model: DeformationProxy,
    binding: voxflex_core::deformation::BindingId,
}

fn make_case(
    params: &str,
    plugin: &plugin_loader::LoadedPlugin,
    services: &Arc<HostServices>,
    volume: &Volume,
    backend: ExecutionBackend,
) -> Result<Case, BenchError> {
    let vtable = plugin
        .deformation
        .ok_or_else(|| err("affine is not a deformation plugin"))?;
    // SAFETY: checked, never-unloaded library.
    let mut model =
        unsafe { DeformationProxy::create(&plugin.name, vtable, params, services.clone()) }
            .map_err(err)?;
    model.init(volume.view(), backend).map_err(err)?;
    let binding = model.bind(RestPoints::Lattice(volume.grid)).map_err(err)?;
    Ok(Case { model, binding })
}

enum Disp {
    Cpu([Vec<f32>; 3]),
    Gpu([voxflex_core::gpu::BufferId; 3], GpuSource),
}

/// Runs the benchmark and returns a human-readable report.
pub fn run(args: &BenchArgs) -> Result<String, BenchError> {
    if args.size < 4 || args.size > 1024 {
        return Err(err(format!(
            "--size {} is out of range; use 4 to 1024",
            args.size
        )));
    }
    if !(args.local_fraction > 0.0 && args.local_fraction < 1.0) {
        return Err(err("--local-fraction must be in (0, 1)"));
    }
    if args.accuracy {
        return accuracy::run(args);
    }
    if args.fronts {
        return fronts::run(args);
    }
    if args.stress {
        return stress::run(args);
    }
    let repeat = args.repeat.max(1);
    let resolved = backend::resolve(args.backend).map_err(err)?;
    let gpu = resolved.gpu_service();
    let dirs = plugin_loader::search_path(&args.plugin_dirs);
    let plugin = plugin_loader::load_by_name("affine", &dirs).map_err(err)?;
    let n = args.size;
    let volume = phantom("head", [n, n, n]).map_err(err)?;
    let voxels = volume.grid.len();
    let services = HostServices::new(gpu.clone(), rayon::current_num_threads());
    let extent = volume.grid.world_bounds().1 - volume.grid.world_bounds().0;
    let centre = volume.grid.centre();
    // The deformation is confined to a ball whose bounding box — the dirty
    // region the model reports — holds `local_fraction` of the volume:
    // (2r)³ = f · box volume.
    let radius = 0.5 * (args.local_fraction * extent.x * extent.y * extent.z).cbrt();
    let full_params = format!(
        "field = \"twist\"\naxis = \"z\"\nangle_deg = 40\nramp_frames = {}",
        repeat + 1
    );
    let local_params = format!(
        "{full_params}\nregion = {{ centre = [{}, {}, {}], radius = {radius} }}",
        centre.x, centre.y, centre.z
    );

    let mut disp = match &gpu {
        Some(g) => {
            let b = |l| g.create_buffer(voxels as u64 * 4, l).map_err(err);
            Disp::Gpu(
                [b("dx")?, b("dy")?, b("dz")?],
                GpuSource::upload(g.as_ref(), volume.view()).map_err(err)?,
            )
        }
        None => Disp::Cpu([vec![0.0; voxels], vec![0.0; voxels], vec![0.0; voxels]]),
    };
    let background = volume.value_range().0;
    let mut out = String::new();
    let mut json = serde_json::Map::new();
    let _ = writeln!(
        out,
        "voxflex bench: {n}³ head phantom ({voxels} voxels), {}",
        resolved.reason
    );
    let _ = writeln!(out, "threads: {}", rayon::current_num_threads());
    let interpolation = args
        .interpolation
        .unwrap_or(ResampleParams::default().interpolation);
    let _ = writeln!(out, "interpolation: {interpolation}");

    let mut results = vec![];
    for (label, params) in [("full", &full_params), ("local", &local_params)] {
        let mut case = make_case(params, &plugin, &services, &volume, resolved.backend)?;
        let defaults = ResampleParams::default();
        let mut resampler = Resampler::new(ResampleParams {
            background,
            interpolation: args.interpolation.unwrap_or(defaults.interpolation),
            ..defaults
        });
        let (mut map_t, mut res_t, mut touched) = (vec![], vec![], 0u64);
        // Frame 0 brings the field in and resamples in full; frames 1..=repeat
        // each change it again (the ramp) and are timed.
        for frame in 0..=repeat as u64 {
            let step = case
                .model
                .step(FrameInfo {
                    frame,
                    frames: repeat as u64 + 1,
                    dt_s: 0.0,
                })
                .map_err(err)?;
            if !step.changed {
                return Err(err("the benchmark field did not change"));
            }
            let dirty = case.model.dirty_region();
            let t = Instant::now();
            let target = match &mut disp {
                Disp::Cpu([x, y, z]) => DisplacementTarget::Cpu { x, y, z },
                Disp::Gpu([x, y, z], _) => DisplacementTarget::Gpu {
                    x: *x,
                    y: *y,
                    z: *z,
                },
            };
            case.model.map(case.binding, target).map_err(err)?;
            let mapped = t.elapsed();
            let t = Instant::now();
            let dirty = if frame == 0 { DirtyRegion::All } else { dirty };
            let report = match (&disp, &gpu) {
                (Disp::Cpu([x, y, z]), _) => {
                    resampler.resample_cpu(volume.view(), DisplacementsRef { x, y, z }, None, dirty)
                }
                (Disp::Gpu(ids, src), Some(g)) => {
                    let r = resampler.resample_gpu(g.as_ref(), src, *ids, None, dirty);
                    // Wait for the GPU so the time is real.
                    let mut probe = [0f32; 1];
                    if let Some(b) = resampler.gpu_output_buffer() {
                        g.read_buffer(b, 0, bytemuck::cast_slice_mut(&mut probe))
                            .map_err(err)?;
                    }
                    r
                }
                _ => return Err(err("GPU displacements without a GPU")),
            }
            .map_err(err)?;
            if frame > 0 {
                map_t.push(mapped);
                res_t.push(t.elapsed());
                touched = report.voxels_touched;
            }
        }
        if let (Some(g), Disp::Gpu(..)) = (&gpu, &disp) {
            resampler.release_gpu(g.as_ref());
        }
        let (m, r) = (median(map_t), median(res_t));
        let _ = writeln!(
            out,
            "{label:>5} twist: map {:8.1} ms   resample {:8.1} ms   ({touched} output voxels re-filled)",
            ms(m),
            ms(r)
        );
        json.insert(format!("{label}_map_ms"), ms(m).into());
        json.insert(format!("{label}_resample_ms"), ms(r).into());
        json.insert(format!("{label}_voxels_touched"), touched.into());
        results.push((m, r, case, resampler.scratch_bytes()));
    }
    let speedup = ms(results[0].1) / ms(results[1].1).max(1e-9);
    let _ = writeln!(out, "local vs full resample: {speedup:.1}× faster");
    json.insert("local_speedup".into(), speedup.into());

    let extra = 12.0 + results[0].3 as f64 / voxels as f64;
    let _ = writeln!(
        out,
        "resample memory beyond input and output: {extra:.2} bytes/voxel (12 of them the displacement field)"
    );
    json.insert("extra_bytes_per_voxel".into(), extra.into());

    // Boundary overhead: a converged step + dirty_region through the C ABI,
    // which is all the boundary adds to a frame.
    let case = &mut results[0].2;
    let calls = 10_000u64;
    let t = Instant::now();
    for i in 0..calls {
        let _ = case.model.step(FrameInfo {
            frame: repeat as u64 + 1 + i,
            frames: u64::MAX,
            dt_s: 0.0,
        });
        let _ = case.model.dirty_region();
    }
    let per_frame = t.elapsed() / calls as u32;
    let frame = results[0].0 + results[0].1;
    let overhead = per_frame.as_secs_f64() / frame.as_secs_f64() * 100.0;
    let _ = writeln!(
        out,
        "plugin boundary: {:.2} µs per frame ({overhead:.1e} % of a {:.1} ms full frame)",
        per_frame.as_secs_f64() * 1e6,
        ms(frame)
    );
    json.insert(
        "boundary_us_per_frame".into(),
        (per_frame.as_secs_f64() * 1e6).into(),
    );
    json.insert("boundary_percent".into(), overhead.into());
    if let (Some(g), Disp::Gpu(ids, src)) = (&gpu, &disp) {
        ids.iter().for_each(|&b| g.destroy_buffer(b));
        src.release(g.as_ref());
    }
    if let Some(p) = &args.json {
        let text = serde_json::to_string_pretty(&json).map_err(err)?;
        voxflex_io::write_atomically(p, |w| w.write_all(text.as_bytes())).map_err(err)?;
    }
    Ok(out)
}
