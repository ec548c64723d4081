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
//!
//! `--actuators` reports instead the soft-robot figures: the pressurised
//! sphere against Lamé at two mesh levels and the four-cavity pendulum
//! under inverse control (frame time, settling, tracking).

mod accuracy;
mod actuators;
mod fronts;
pub mod lame;
pub mod stress;

use crate::backend::BackendChoice;
use crate::session::{Session, SessionDefaults, SessionSource};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Duration;
use voxflex_resample::{Interpolation, ResampleParams};

/// Options of `voxflex bench` (the CLI's `bench` arguments; the defaults
/// are the command's).
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Phantom edge length, voxels (the volume is N³).
    pub size: usize,
    /// Backend: cpu, gpu or auto.
    pub backend: BackendChoice,
    /// Timed repetitions (the median is reported).
    pub repeat: usize,
    /// Fraction of the volume the local deformation is confined to (its
    /// ball's bounding box, the dirty region).
    pub local_fraction: f64,
    /// Extra plugin directories searched first.
    pub plugin_dirs: Vec<PathBuf>,
    /// Also write the figures as JSON to this file.
    pub json: Option<PathBuf>,
    /// Resampler interpolation (default: the resampler's default).
    pub interpolation: Option<Interpolation>,
    /// Measure both interpolation modes instead (see [`accuracy`]).
    pub accuracy: bool,
    /// Measure the run-time/error front of every model instead and write
    /// `<front>.csv`, `<front>.svg` and `front.md` into `out` (see
    /// [`fronts`]).
    pub fronts: bool,
    /// With `fronts`: tiny sizes (seconds; what the tests run).
    pub quick: bool,
    /// With `fronts`: only these fronts (fem_cantilever, fem_elastica,
    /// grab, resample, roi).
    pub only: Vec<String>,
    /// With `fronts`: the output directory.
    pub out: PathBuf,
    /// Run the numerical stress suite instead (see [`stress`]).
    pub stress: bool,
    /// Run the soft-robot actuator figures instead (see `actuators`):
    /// Lamé's sphere, the four-cavity pendulum under inverse control.
    pub actuators: bool,
    /// Stress: scenes per model.
    pub stress_scenes: u64,
    /// Stress: frames per scene.
    pub stress_frames: u64,
    /// Stress: only these models (default: all four).
    pub stress_model: Vec<String>,
    /// Stress: the RNG seed that draws the scenes.
    pub seed: u64,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            size: 256,
            backend: BackendChoice::Cpu,
            repeat: 3,
            local_fraction: 0.05,
            plugin_dirs: vec![],
            json: None,
            interpolation: None,
            accuracy: false,
            fronts: false,
            quick: false,
            only: vec![],
            out: PathBuf::from("docs/fronts"),
            stress: false,
            actuators: false,
            stress_scenes: 250,
            stress_frames: 13,
            stress_model: vec![],
            seed: 13,
        }
    }
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

/// Runs the benchmark and returns a human-readable report.
pub fn run(args: &BenchOptions) -> Result<String, BenchError> {
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
    if args.actuators {
        return actuators::run(args);
    }
    let repeat = args.repeat.max(1);
    let n = args.size;
    let defaults = ResampleParams::default();
    // The session the scenes run: the affine plugin from its library, the
    // resampler, the backend chosen like a scene's; each resample waits for
    // the GPU so its time is the work's.
    let mut session = Session::from_volume(
        SessionSource::Phantom {
            name: "head".into(),
            dims: [n, n, n],
        },
        SessionDefaults {
            backend: args.backend,
            plugin_dirs: args.plugin_dirs.clone(),
            frames: repeat as u64 + 1,
            dt_s: 0.0,
            resample: ResampleParams {
                interpolation: args.interpolation.unwrap_or(defaults.interpolation),
                ..defaults
            },
            wait_for_gpu: true,
            ..SessionDefaults::default()
        },
    )
    .map_err(err)?;
    let volume = session.source();
    let voxels = volume.grid.len();
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

    let mut out = String::new();
    let mut json = serde_json::Map::new();
    let reason = session.metrics().map_err(err)?.backend_reason;
    let _ = writeln!(
        out,
        "voxflex bench: {n}³ head phantom ({voxels} voxels), {reason}"
    );
    let _ = writeln!(out, "threads: {}", rayon::current_num_threads());
    let interpolation = args
        .interpolation
        .unwrap_or(ResampleParams::default().interpolation);
    let _ = writeln!(out, "interpolation: {interpolation}");

    let mut results = vec![];
    let mut idle = Duration::ZERO;
    let calls = 10_000u64;
    for (label, params) in [("full", &full_params), ("local", &local_params)] {
        // A new model maps and resamples in full at its first frame.
        session.swap_model("affine", params).map_err(err)?;
        let (mut map_t, mut res_t, mut touched) = (vec![], vec![], 0u64);
        // Frame 0 brings the field in and resamples in full; frames 1..=repeat
        // each change it again (the ramp) and are timed.
        for frame in 0..=repeat {
            let step = session.step().map_err(err)?;
            let stage = |name: &str| step.stage(name).filter(|s| s.ran);
            let (Some(map), Some(resample)) = (stage("map"), stage("resample")) else {
                return Err(err("the benchmark field did not change"));
            };
            if frame > 0 {
                map_t.push(map.wall);
                res_t.push(resample.wall);
                touched = resample.voxels;
            }
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
        results.push((m, r, session.resample_scratch_bytes()));
        if label == "full" {
            // Boundary overhead: a converged step + dirty_region through the
            // C ABI, which is all the boundary adds to a frame.
            idle = session
                .time_idle_frames(calls)
                .ok_or_else(|| err("the session has no model"))?;
        }
    }
    let speedup = ms(results[0].1) / ms(results[1].1).max(1e-9);
    let _ = writeln!(out, "local vs full resample: {speedup:.1}× faster");
    json.insert("local_speedup".into(), speedup.into());

    let extra = 12.0 + results[0].2 as f64 / voxels as f64;
    let _ = writeln!(
        out,
        "resample memory beyond input and output: {extra:.2} bytes/voxel (12 of them the displacement field)"
    );
    json.insert("extra_bytes_per_voxel".into(), extra.into());

    let per_frame = idle / calls as u32;
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
    if let Some(p) = &args.json {
        let text = serde_json::to_string_pretty(&json).map_err(err)?;
        voxflex_io::write_atomically(p, |w| w.write_all(text.as_bytes())).map_err(err)?;
    }
    Ok(out)
}
