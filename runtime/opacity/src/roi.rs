//! [`grow_roi`]: one region-of-interest map end to end — bounds applied,
//! λ fixed or chosen automatically, the growth run on the CPU or the GPU,
//! and what stopped it ([`RoiOutcome::stop`], [`RoiOutcome::warnings`]).

use super::auto_lambda::{AutoSearch, auto_lambda};
use super::gpu::GpuOpacityVolume;
use super::limits::{GrowthLimits, LimitHits};
use super::params::GrowthParams;
use super::path_cost::ScanInput;
use super::runner::{CpuRunner, GpuRunner, GrowRunner, Grown, voxels_above_half};
use super::seed::Seed;
use super::{OpacityError, check_volume};
use crate::volume::VolumeView;
use voxflex_core::gpu::GpuService;

/// How λ is set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LambdaChoice {
    /// This λ (> 0).
    Fixed(f32),
    /// The plateau rule of [`super::auto_lambda`].
    Auto,
}

impl std::fmt::Display for LambdaChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LambdaChoice::Fixed(l) => write!(f, "{l}"),
            LambdaChoice::Auto => f.write_str("auto"),
        }
    }
}

/// One map to grow.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoiRequest {
    /// Where it starts.
    pub seed: Seed,
    /// Opacity range and σ floor (`lambda` is replaced by the choice).
    pub params: GrowthParams,
    /// λ, fixed or automatic.
    pub lambda: LambdaChoice,
    /// Intensity window and distance bound.
    pub limits: GrowthLimits,
    /// Step cap (`None`: run to convergence).
    pub steps: Option<usize>,
}

/// Fraction of the volume above which a map is reported as a leak.
pub const LEAK_FRACTION: f64 = 0.5;

/// A grown map and how it ended.
#[derive(Clone, Debug)]
pub struct RoiOutcome {
    /// The growth at the λ used.
    pub grown: Grown,
    /// The λ used.
    pub lambda: f32,
    /// The automatic search, when λ was `auto`.
    pub auto: Option<AutoSearch>,
    /// Where the bounds stopped the growth.
    pub hits: LimitHits,
    /// Voxels at opacity ≥ 0.5.
    pub voxels: usize,
    /// Voxels of the volume.
    pub volume_voxels: usize,
}

impl RoiOutcome {
    /// What stopped the growth: `"converged"` or `"steps cap"`, followed by
    /// `"; bound: intensity (N voxels)"` / `"max_distance_mm (N voxels)"`
    /// when a bound held opacity back somewhere.
    pub fn stop(&self) -> String {
        let mut s = if self.grown.report.converged {
            "converged".to_string()
        } else {
            "steps cap".to_string()
        };
        let mut b = vec![];
        if self.hits.intensity > 0 {
            b.push(format!("intensity ({} voxels)", self.hits.intensity));
        }
        if self.hits.distance > 0 {
            b.push(format!("max_distance_mm ({} voxels)", self.hits.distance));
        }
        if !b.is_empty() {
            s += &format!("; bound: {}", b.join(", "));
        }
        s
    }

    /// True when the map was written from the automatic λ's path-cost scan
    /// rather than grown (`lambda` auto, run to convergence).
    pub fn from_scan(&self) -> bool {
        self.auto.as_ref().is_some_and(|a| a.from_scan)
    }

    /// True when the map covers more than [`LEAK_FRACTION`] of the volume.
    pub fn leaked(&self) -> bool {
        self.voxels as f64 > LEAK_FRACTION * self.volume_voxels as f64
    }

    /// Warnings for the log and the notes (empty when all is well).
    pub fn warnings(&self) -> Vec<String> {
        let mut w = vec![];
        if self.leaked() {
            w.push(format!(
                "leaked into {} voxels ({:.0} % of the volume) at lambda = {}; set lambda lower \
                 (or \"auto\"), intensity = [lo, hi] or max_distance_mm",
                self.voxels,
                100.0 * self.voxels as f64 / self.volume_voxels.max(1) as f64,
                self.lambda
            ));
        }
        if !self.grown.report.converged {
            w.push(format!(
                "stopped by the steps cap after {} steps before converging; raise or remove steps",
                self.grown.report.steps
            ));
        }
        w
    }
}

/// Grows one map on the CPU, or on `gpu` with `uploaded` holding the
/// (unbounded) `volume`'s values. A bounded request uploads its own copy
/// of the bounded values for the duration of the call.
pub fn grow_roi(
    volume: VolumeView<'_>,
    req: &RoiRequest,
    gpu: Option<(&dyn GpuService, &GpuOpacityVolume)>,
) -> Result<RoiOutcome, OpacityError> {
    check_volume(&volume)?;
    req.params.validate()?;
    if let LambdaChoice::Fixed(l) = req.lambda {
        GrowthParams {
            lambda: l,
            ..req.params
        }
        .validate()?;
    }
    let seed_voxel = req.seed.resolve(&volume.grid)?;
    let bounded = req.limits.apply(volume, seed_voxel)?;
    let values = bounded.as_ref().map_or(volume, |b| b.view());
    let run =
        |runner: &mut dyn GrowRunner| -> Result<(Grown, f32, Option<AutoSearch>), OpacityError> {
            match req.lambda {
                LambdaChoice::Fixed(lambda) => {
                    let p = GrowthParams {
                        lambda,
                        ..req.params
                    };
                    Ok((runner.grow(p, req.steps)?, lambda, None))
                }
                LambdaChoice::Auto => {
                    let input = ScanInput {
                        volume,
                        values,
                        limits: GrowthLimits::default(),
                        seed: req.seed,
                    };
                    let a = auto_lambda(input, runner, req.params, req.steps)?;
                    Ok((a.grown, a.search.lambda, Some(a.search)))
                }
            }
        };
    // An automatic λ run to convergence writes its map from the scan, on
    // the CPU: no growth, so nothing to upload.
    let gpu = gpu.filter(|_| !(req.lambda == LambdaChoice::Auto && req.steps.is_none()));
    let (grown, lambda, auto) = match gpu {
        None => run(&mut CpuRunner {
            volume,
            values,
            seed: req.seed,
        })?,
        Some((g, shared)) => {
            let own = match &bounded {
                Some(b) => Some(GpuOpacityVolume::upload(g, b.view())?),
                None => None,
            };
            let out = run(&mut GpuRunner {
                gpu: g,
                values: own.as_ref().unwrap_or(shared),
                volume,
                seed: req.seed,
            });
            if let Some(o) = own {
                o.release(g);
            }
            out?
        }
    };
    let hits = req.limits.hits(volume, &grown.map, seed_voxel, &grown.ext);
    Ok(RoiOutcome {
        voxels: voxels_above_half(&grown.map),
        volume_voxels: volume.grid.len(),
        grown,
        lambda,
        auto,
        hits,
    })
}
