//! The command-line arguments of `voxflex bench`, turned into the host's
//! plain [`BenchOptions`].

use std::path::PathBuf;
use voxflex_resample::Interpolation;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::bench::BenchOptions;

/// Arguments of `voxflex bench`.
#[derive(Clone, Debug, clap::Args)]
pub struct BenchArgs {
    /// Phantom edge length, voxels (the volume is N³).
    #[arg(long, default_value_t = BenchOptions::default().size)]
    pub size: usize,
    /// Backend: cpu, gpu or auto.
    #[arg(long, default_value_t = BenchOptions::default().backend)]
    pub backend: BackendChoice,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = BenchOptions::default().repeat)]
    pub repeat: usize,
    /// Fraction of the volume the local deformation is confined to (its
    /// ball's bounding box, the dirty region).
    #[arg(long, default_value_t = BenchOptions::default().local_fraction)]
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
    /// cantilever and elastica, the same grab and the same cut across
    /// models, resampling, ROI maps) and write `<front>.csv`, `<front>.svg`
    /// and `front.md` into `--out`.
    #[arg(long)]
    pub fronts: bool,
    /// With `--fronts` or `--actuators`: tiny sizes (seconds; what the
    /// tests run).
    #[arg(long)]
    pub quick: bool,
    /// With `--fronts`: only these fronts (fem_cantilever, fem_elastica,
    /// grab, cut, resample, roi, render; repeatable).
    #[arg(long, requires = "fronts")]
    pub only: Vec<String>,
    /// With `--fronts`: the output directory.
    #[arg(long, default_value_os_t = BenchOptions::default().out)]
    pub out: PathBuf,
    /// Run the numerical stress suite instead: randomized scenes for every
    /// deformation model (see `bench::stress`).
    #[arg(long, conflicts_with_all = ["fronts", "accuracy"])]
    pub stress: bool,
    /// Report the soft-robot actuator figures instead: a pressurised
    /// thick-walled sphere against Lamé at two mesh levels, and the
    /// four-cavity hydraulic pendulum under inverse control (time per
    /// frame, settling, tracking error). `--quick` runs 5 frames.
    #[arg(long, conflicts_with_all = ["fronts", "accuracy", "stress"])]
    pub actuators: bool,
    /// Stress: scenes per model.
    #[arg(long, default_value_t = BenchOptions::default().stress_scenes)]
    pub stress_scenes: u64,
    /// Stress: frames per scene.
    #[arg(long, default_value_t = BenchOptions::default().stress_frames)]
    pub stress_frames: u64,
    /// Stress: only these models (repeatable; default: all four).
    #[arg(long)]
    pub stress_model: Vec<String>,
    /// Stress: the RNG seed that draws the scenes.
    #[arg(long, default_value_t = BenchOptions::default().seed)]
    pub seed: u64,
}

impl From<BenchArgs> for BenchOptions {
    fn from(a: BenchArgs) -> Self {
        BenchOptions {
            size: a.size,
            backend: a.backend,
            repeat: a.repeat,
            local_fraction: a.local_fraction,
            plugin_dirs: a.plugin_dirs,
            json: a.json,
            interpolation: a.interpolation,
            accuracy: a.accuracy,
            fronts: a.fronts,
            quick: a.quick,
            only: a.only,
            out: a.out,
            stress: a.stress,
            actuators: a.actuators,
            stress_scenes: a.stress_scenes,
            stress_frames: a.stress_frames,
            stress_model: a.stress_model,
            seed: a.seed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        bench: BenchArgs,
    }

    /// The command's defaults are the host's.
    #[test]
    fn defaults_are_the_hosts() {
        let a: BenchOptions = Cli::try_parse_from(["bench"]).unwrap().bench.into();
        let d = BenchOptions::default();
        assert_eq!(
            (a.size, a.backend, a.repeat, a.local_fraction, a.out.clone()),
            (d.size, d.backend, d.repeat, d.local_fraction, d.out.clone())
        );
        assert_eq!(
            (a.stress_scenes, a.stress_frames, a.seed),
            (d.stress_scenes, d.stress_frames, d.seed)
        );
        let a: BenchOptions = Cli::try_parse_from(["bench", "--size", "64", "--backend", "gpu"])
            .unwrap()
            .bench
            .into();
        assert_eq!((a.size, a.backend), (64, BackendChoice::Gpu));
    }
}
