//! [`GrowRunner`]: "seed a growth with these parameters and run it" on
//! either backend, so the automatic λ search ([`super::auto_lambda`]) and
//! [`super::roi`] are written once for the CPU and the GPU.

use super::bounds::VoxelBounds;
use super::cpu::CpuGrowth;
use super::extinction::Extinction;
use super::gpu::{GpuGrowth, GpuOpacityVolume};
use super::params::GrowthParams;
use super::report::GrowthReport;
use super::seed::{Seed, SeedStats};
use super::state::Growth;
use super::{OpacityError, OpacityMap};
use crate::volume::VolumeView;
use voxflex_core::gpu::GpuService;

/// One growth: converged, or stopped by its steps cap.
#[derive(Clone, Debug)]
pub struct Grown {
    /// The map as it stands.
    pub map: OpacityMap,
    /// Every step run.
    pub report: GrowthReport,
    /// The seed's statistics.
    pub stats: SeedStats,
    /// The update constants used.
    pub ext: Extinction,
}

/// Voxels of `map` at opacity ≥ 0.5 (fixed point ≥ 32768); voxels outside
/// the map's box hold `outside` (`o_min`).
pub fn voxels_above_half(map: &OpacityMap) -> usize {
    map.values.iter().filter(|&&q| q >= 32768).count()
}

/// Grows maps from one seed on one backend.
pub trait GrowRunner {
    /// Seeds a growth with `params` and runs it to convergence, or for at
    /// most `steps` steps.
    fn grow(&mut self, params: GrowthParams, steps: Option<usize>) -> Result<Grown, OpacityError> {
        self.grow_within(params, steps, None)
    }

    /// [`GrowRunner::grow`] with a working box that covers `room` (voxel
    /// indices) from the start ([`CpuGrowth::with_room`]); the map is the
    /// same.
    fn grow_within(
        &mut self,
        params: GrowthParams,
        steps: Option<usize>,
        room: Option<VoxelBounds>,
    ) -> Result<Grown, OpacityError>;
}

/// The CPU backend: statistics from `volume`, values read from `values`
/// (the same volume, or its bounded copy from
/// [`super::GrowthLimits::apply`]).
pub struct CpuRunner<'a> {
    /// The unbounded volume (seed statistics).
    pub volume: VolumeView<'a>,
    /// The values the growth reads.
    pub values: VolumeView<'a>,
    /// The seed.
    pub seed: Seed,
}

impl GrowRunner for CpuRunner<'_> {
    fn grow_within(
        &mut self,
        params: GrowthParams,
        steps: Option<usize>,
        room: Option<VoxelBounds>,
    ) -> Result<Grown, OpacityError> {
        // Each step is four short parallel loops: on a worker they split
        // with no hand-over (a growth of 50 steps on a small volume spent
        // most of its time in hand-overs).
        voxflex_core::on_worker::on_worker(|| {
            let mut g = CpuGrowth::with_room(self.volume, &self.seed, params, room)?;
            let report = g.step(self.values, steps.unwrap_or(usize::MAX))?;
            Ok(Grown {
                map: g.map(),
                report,
                stats: *g.stats(),
                ext: *g.extinction(),
            })
        })
    }
}

/// The GPU backend: statistics from `volume` (CPU copy), values read from
/// `values` (the upload of the same volume or of its bounded copy).
pub struct GpuRunner<'a> {
    /// The device.
    pub gpu: &'a dyn GpuService,
    /// The uploaded values the growth reads.
    pub values: &'a GpuOpacityVolume,
    /// The unbounded volume (seed statistics).
    pub volume: VolumeView<'a>,
    /// The seed.
    pub seed: Seed,
}

impl GrowRunner for GpuRunner<'_> {
    fn grow_within(
        &mut self,
        params: GrowthParams,
        steps: Option<usize>,
        room: Option<VoxelBounds>,
    ) -> Result<Grown, OpacityError> {
        let (gpu, values) = (self.gpu, self.values);
        let mut g = GpuGrowth::with_room(gpu, values, self.volume, &self.seed, params, room)?;
        let out = g
            .step(gpu, values, steps.unwrap_or(usize::MAX))
            .and_then(|report| Ok((report, g.map(gpu)?)));
        let (stats, ext) = (*g.stats(), *g.extinction());
        g.release(gpu);
        let (report, map) = out?;
        Ok(Grown {
            map,
            report,
            stats,
            ext,
        })
    }
}
