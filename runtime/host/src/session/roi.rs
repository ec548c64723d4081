//! The ROI maps a session holds: spatial opacity maps grown stepwise from
//! a seed over the session's current volume (voxflex_opacity), shown
//! by [`super::Session::render`].

use voxflex_core::volume::Volume;
use voxflex_opacity::{CpuGrowth, GrowthParams, GrowthReport, OpacityMap, Seed};

/// A session's handle to one of its ROI maps.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RoiId(pub u64);

/// What a front end sees of one ROI map.
#[derive(Clone, Debug, PartialEq)]
pub struct RoiInfo {
    /// Its handle.
    pub id: RoiId,
    /// Where it started (voxel index, world mm or slice click).
    pub seed: Seed,
    /// Its growth constants.
    pub params: GrowthParams,
    /// Steps grown so far on the current volume.
    pub steps: u64,
    /// True when no voxel can change any more.
    pub converged: bool,
    /// Voxels at opacity ≥ 0.5.
    pub voxels_above_half: usize,
}

/// One ROI map: its request, its growth on the current volume and the map
/// as it stands.
#[derive(Debug)]
pub(crate) struct SessionRoi {
    pub(crate) id: RoiId,
    pub(crate) seed: Seed,
    pub(crate) params: GrowthParams,
    growth: CpuGrowth,
    /// Steps grown on the current volume.
    steps: u64,
    /// Run to convergence (re-grown to convergence on a new volume).
    to_end: bool,
    map: OpacityMap,
}

impl SessionRoi {
    /// Seeds a map on `volume` (no step run).
    pub(crate) fn new(
        id: RoiId,
        volume: &Volume,
        seed: Seed,
        params: GrowthParams,
    ) -> Result<Self, voxflex_opacity::OpacityError> {
        let growth = CpuGrowth::new(volume.view(), &seed, params)?;
        let map = growth.map();
        Ok(Self {
            id,
            seed,
            params,
            growth,
            steps: 0,
            to_end: false,
            map,
        })
    }

    /// Grows up to `n` more steps on `volume` (the one it was seeded on).
    pub(crate) fn step(
        &mut self,
        volume: &Volume,
        n: usize,
    ) -> Result<GrowthReport, voxflex_opacity::OpacityError> {
        let report = self.growth.step(volume.view(), n)?;
        self.steps += report.steps;
        self.map = self.growth.map();
        Ok(report)
    }

    /// Grows to convergence, and again to convergence after every new volume.
    pub(crate) fn run_to_end(
        &mut self,
        volume: &Volume,
    ) -> Result<GrowthReport, voxflex_opacity::OpacityError> {
        self.to_end = true;
        self.step(volume, usize::MAX)
    }

    /// Seeds again on a new `volume` and grows as far as before: the same
    /// number of steps, or to convergence if it was run to the end.
    pub(crate) fn regrow(
        &mut self,
        volume: &Volume,
    ) -> Result<GrowthReport, voxflex_opacity::OpacityError> {
        let steps = if self.to_end {
            usize::MAX
        } else {
            self.steps as usize
        };
        self.growth = CpuGrowth::new(volume.view(), &self.seed, self.params)?;
        self.steps = 0;
        self.step(volume, steps)
    }

    /// The map as it stands (voxel box of the current volume).
    pub(crate) fn map(&self) -> &OpacityMap {
        &self.map
    }

    /// What a front end sees of it.
    pub(crate) fn info(&self) -> RoiInfo {
        RoiInfo {
            id: self.id,
            seed: self.seed,
            params: self.params,
            steps: self.steps,
            converged: self.growth.is_converged(),
            voxels_above_half: voxflex_opacity::runner::voxels_above_half(&self.map),
        }
    }
}
