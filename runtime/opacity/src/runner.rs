//! [`GrowRunner`]: "seed a growth with these parameters and run it" on
//! either backend, so the automatic λ search ([`super::auto_lambda`]) and
//! [`super::roi`] are written once for the CPU and the GPU.

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

/// Steps between two checks of the region's size when a run may be cut
/// short ([`GrowRunner::grow`]'s `abort_above`).
pub const CHECK_EVERY: usize = 16;

/// One finished (or cut short) growth.
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
    /// True when the run was stopped because more than `abort_above` voxels
    /// reached opacity ≥ 0.5 (the growth is monotone, so the converged map
    /// would have at least as many).
    pub aborted: bool,
}

/// Voxels of `map` at opacity ≥ 0.5 (fixed point ≥ 32768); voxels outside
/// the map's box hold `outside` (`o_min`).
pub fn voxels_above_half(map: &OpacityMap) -> usize {
    map.values.iter().filter(|&&q| q >= 32768).count()
}

/// Grows maps from one seed on one backend.
pub trait GrowRunner {
    /// Seeds a growth with `params` and runs it to convergence, or for at
    /// most `steps` steps; with `abort_above = Some(n)` it stops as soon as
    /// more than `n` voxels hold opacity ≥ 0.5 (checked every
    /// [`CHECK_EVERY`] steps and at the end).
    fn grow(
        &mut self,
        params: GrowthParams,
        steps: Option<usize>,
        abort_above: Option<usize>,
    ) -> Result<Grown, OpacityError>;
}

/// Runs `step(n)` in chunks of [`CHECK_EVERY`] with the abort check, which
/// asks `above_half` for the voxels at opacity ≥ 0.5 (the map is built
/// once, at the end).
fn drive(
    steps: Option<usize>,
    abort_above: Option<usize>,
    mut step: impl FnMut(usize) -> Result<GrowthReport, OpacityError>,
    mut map: impl FnMut() -> Result<OpacityMap, OpacityError>,
    mut above_half: impl FnMut() -> Result<usize, OpacityError>,
) -> Result<(GrowthReport, OpacityMap, bool), OpacityError> {
    let mut total = GrowthReport::default();
    let mut left = steps.unwrap_or(usize::MAX);
    let chunk = if abort_above.is_some() {
        CHECK_EVERY
    } else {
        usize::MAX
    };
    loop {
        let r = step(chunk.min(left))?;
        total.merge(&r);
        left = left.saturating_sub(r.steps as usize);
        let done = r.converged || left == 0;
        if let Some(n) = abort_above
            && !done
        {
            if above_half()? > n {
                return Ok((total, map()?, true));
            }
            continue;
        }
        if done {
            let m = map()?;
            let aborted = abort_above.is_some_and(|n| voxels_above_half(&m) > n);
            return Ok((total, m, aborted));
        }
    }
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
    fn grow(
        &mut self,
        params: GrowthParams,
        steps: Option<usize>,
        abort_above: Option<usize>,
    ) -> Result<Grown, OpacityError> {
        // Each step is four short parallel loops: on a worker they split
        // with no hand-over (a growth of 50 steps on a small volume spent
        // most of its time in hand-overs).
        voxflex_core::on_worker::on_worker(|| {
            let mut g = CpuGrowth::new(self.volume, &self.seed, params)?;
            let values = self.values;
            let cell = std::cell::RefCell::new(&mut g);
            let (report, map, aborted) = drive(
                steps,
                abort_above,
                |n| cell.borrow_mut().step(values, n),
                || Ok(cell.borrow().map()),
                || Ok(cell.borrow().voxels_above_half()),
            )?;
            Ok(Grown {
                map,
                report,
                stats: *g.stats(),
                ext: *g.extinction(),
                aborted,
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
    fn grow(
        &mut self,
        params: GrowthParams,
        steps: Option<usize>,
        abort_above: Option<usize>,
    ) -> Result<Grown, OpacityError> {
        let (gpu, values) = (self.gpu, self.values);
        let g = GpuGrowth::new(gpu, values, self.volume, &self.seed, params)?;
        let cell = std::cell::RefCell::new(g);
        let out = drive(
            steps,
            abort_above,
            |n| cell.borrow_mut().step(gpu, values, n),
            || cell.borrow().map(gpu),
            || Ok(voxels_above_half(&cell.borrow().map(gpu)?)),
        );
        let g = cell.into_inner();
        let (stats, ext) = (*g.stats(), *g.extinction());
        g.release(gpu);
        let (report, map, aborted) = out?;
        Ok(Grown {
            map,
            report,
            stats,
            ext,
            aborted,
        })
    }
}
