//! The ROI maps a session holds: spatial opacity maps grown stepwise from
//! a seed over the session's current volume (voxflex_opacity), shown
//! by [`super::Session::render`]. They grow on the session's backend: on
//! the CPU ([`CpuGrowth`]) or on its GPU ([`GpuGrowth`], over one upload of
//! the current volume shared by every map), bit for bit the same maps.
//! A map whose λ is automatic is not grown but written from the path-cost
//! scan at its λ, on the CPU whatever the backend (what the scene's
//! `lambda = "auto"` makes, voxel for voxel).

use voxflex_core::gpu::GpuService;
use voxflex_core::volume::Volume;
use voxflex_core::volume::VolumeView;
use voxflex_opacity::auto_lambda::map_at;
use voxflex_opacity::runner::Grown;
use voxflex_opacity::{
    CpuGrowth, GpuGrowth, GpuOpacityVolume, Growth, GrowthLimits, GrowthParams, GrowthReport,
    OpacityMap, ScanInput, Seed, VoxelBounds,
};

use super::roi_err;
use crate::pipeline::RunError;

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
    /// True when `params.lambda` was chosen by the plateau rule
    /// ([`super::Session::roi_auto_lambda`]) rather than given.
    pub lambda_auto: bool,
    /// Its growth bounds (intensity window, distance from the seed;
    /// [`super::Session::set_roi_limits`]).
    pub limits: GrowthLimits,
}

/// Where a session's ROI maps grow: on the CPU, or on the session's GPU
/// with the current volume uploaded there (one copy for every map).
#[derive(Clone, Copy)]
pub(crate) enum RoiDevice<'a> {
    /// rayon on the CPU.
    Cpu,
    /// The session's GPU and its upload of the current volume.
    Gpu {
        /// The session's GPU context.
        gpu: &'a dyn GpuService,
        /// The current volume's values in that context.
        values: &'a GpuOpacityVolume,
    },
}

impl<'a> RoiDevice<'a> {
    /// The GPU context, if any.
    pub(crate) fn gpu(&self) -> Option<&'a dyn GpuService> {
        match self {
            RoiDevice::Cpu => None,
            RoiDevice::Gpu { gpu, .. } => Some(*gpu),
        }
    }

    fn name(&self) -> &'static str {
        match self {
            RoiDevice::Cpu => "CPU",
            RoiDevice::Gpu { .. } => "GPU",
        }
    }
}

/// One map's growth in progress, on the device it was seeded on — or an
/// automatic-λ map written from its path-cost scan, converged, with
/// nothing left to grow.
#[derive(Debug)]
enum RoiGrowth {
    Cpu(CpuGrowth),
    Gpu(GpuGrowth),
    /// Written by `voxflex_opacity::auto_lambda::map_at` / `auto_map` (on
    /// the CPU, whatever the backend; the box of its voxels above `o_min`,
    /// voxel indices). Holds no buffers; the map is [`SessionRoi::map`].
    Scanned(VoxelBounds),
}

impl RoiGrowth {
    /// Seeds a growth on `volume` on `device`, its working box covering
    /// `room` (voxel indices) from the start (only the work depends on it).
    fn seed(
        volume: &Volume,
        device: RoiDevice<'_>,
        seed: &Seed,
        params: GrowthParams,
        room: Option<VoxelBounds>,
    ) -> Result<Self, voxflex_opacity::OpacityError> {
        let view = volume.view();
        Ok(match device {
            RoiDevice::Cpu => RoiGrowth::Cpu(CpuGrowth::with_room(view, seed, params, room)?),
            RoiDevice::Gpu { gpu, values } => {
                RoiGrowth::Gpu(GpuGrowth::with_room(gpu, values, view, seed, params, room)?)
            }
        })
    }

    /// The box of the voxels it raised (voxel indices of its volume).
    fn region(&self) -> VoxelBounds {
        match self {
            RoiGrowth::Cpu(g) => g.region(),
            RoiGrowth::Gpu(g) => g.region(),
            RoiGrowth::Scanned(b) => *b,
        }
    }

    fn runs_on(&self, device: RoiDevice<'_>) -> bool {
        matches!(
            (self, device),
            (RoiGrowth::Cpu(_), RoiDevice::Cpu)
                | (RoiGrowth::Gpu(_), RoiDevice::Gpu { .. })
                | (RoiGrowth::Scanned(_), _)
        )
    }

    fn is_converged(&self) -> bool {
        match self {
            RoiGrowth::Cpu(g) => g.is_converged(),
            RoiGrowth::Gpu(g) => g.is_converged(),
            RoiGrowth::Scanned(_) => true,
        }
    }

    /// The map as it stands (a GPU growth reads it back from `device`);
    /// `None` for a scanned map, which the session already holds.
    fn map(&self, device: RoiDevice<'_>) -> Result<Option<OpacityMap>, RunError> {
        match (self, device.gpu()) {
            (RoiGrowth::Cpu(g), _) => Ok(Some(g.map())),
            (RoiGrowth::Gpu(g), Some(gpu)) => g.map(gpu).map(Some).map_err(roi_err),
            (RoiGrowth::Scanned(_), _) => Ok(None),
            (RoiGrowth::Gpu(_), None) => Err(roi_err(
                "a map grown on the GPU cannot be read without the GPU; remove it and add it again",
            )),
        }
    }

    /// Frees its GPU buffers (nothing for a CPU growth); `gpu` is the
    /// context it was seeded in.
    fn release(self, gpu: Option<&dyn GpuService>) {
        if let (RoiGrowth::Gpu(g), Some(gpu)) = (self, gpu) {
            g.release(gpu);
        }
    }
}

/// A bounded map's values — the current volume with its [`GrowthLimits`]
/// applied (blocked voxels raised so opacity never enters them) — on the
/// device it grows on.
#[derive(Debug)]
enum BoundedValues {
    Cpu(Volume),
    Gpu(GpuOpacityVolume),
}

/// The values a map's growth reads: the CPU view (`volume`'s, or its
/// bounded copy's) and `device` with its bounded upload in place of the
/// shared one.
fn reads<'a>(
    bounded: &'a Option<BoundedValues>,
    volume: &'a Volume,
    device: RoiDevice<'a>,
) -> (VolumeView<'a>, RoiDevice<'a>) {
    match (bounded, device) {
        (Some(BoundedValues::Cpu(b)), d) => (b.view(), d),
        (Some(BoundedValues::Gpu(values)), RoiDevice::Gpu { gpu, .. }) => {
            (volume.view(), RoiDevice::Gpu { gpu, values })
        }
        (_, d) => (volume.view(), d),
    }
}

/// One ROI map: its request, its growth on the current volume and the map
/// as it stands.
#[derive(Debug)]
pub(crate) struct SessionRoi {
    pub(crate) id: RoiId,
    pub(crate) seed: Seed,
    pub(crate) params: GrowthParams,
    /// `None` once released (a backend change): re-grown on next use.
    growth: Option<RoiGrowth>,
    /// Steps grown on the current volume.
    steps: u64,
    /// Run to convergence (re-grown to convergence on a new volume).
    pub(crate) to_end: bool,
    /// λ chosen by the plateau rule (see [`RoiInfo::lambda_auto`]).
    pub(crate) lambda_auto: bool,
    /// Its growth bounds.
    pub(crate) limits: GrowthLimits,
    /// The values its growth reads when bounded (made on each re-growth).
    bounded: Option<BoundedValues>,
    converged: bool,
    map: OpacityMap,
    /// Handed to the renderer ([`super::Session::set_roi_shown`]).
    pub(crate) shown: bool,
}

impl SessionRoi {
    /// Seeds a map on `volume` on `device` (no step run).
    pub(crate) fn new(
        id: RoiId,
        volume: &Volume,
        device: RoiDevice<'_>,
        seed: Seed,
        params: GrowthParams,
    ) -> Result<Self, RunError> {
        let growth = RoiGrowth::seed(volume, device, &seed, params, None).map_err(roi_err)?;
        let map = match growth.map(device) {
            Ok(Some(m)) => m,
            Ok(None) => unreachable!("a seeded growth is never a scanned map"),
            Err(e) => {
                growth.release(device.gpu());
                return Err(e);
            }
        };
        Ok(Self {
            id,
            seed,
            params,
            converged: growth.is_converged(),
            growth: Some(growth),
            steps: 0,
            to_end: false,
            lambda_auto: false,
            limits: GrowthLimits::default(),
            bounded: None,
            map,
            shown: true,
        })
    }

    /// Grows up to `n` more steps on `volume` (the current one) on
    /// `device` (re-grown there first as far as before when it grew
    /// elsewhere or was released).
    pub(crate) fn step(
        &mut self,
        volume: &Volume,
        device: RoiDevice<'_>,
        n: usize,
    ) -> Result<GrowthReport, RunError> {
        self.follow(volume, device)?;
        let (view, on) = reads(&self.bounded, volume, device);
        let report = match (&mut self.growth, on) {
            (Some(RoiGrowth::Cpu(g)), RoiDevice::Cpu) => g.step(view, n),
            (Some(RoiGrowth::Gpu(g)), RoiDevice::Gpu { gpu, values }) => g.step(gpu, values, n),
            (Some(RoiGrowth::Scanned(_)), _) => Ok(GrowthReport {
                converged: true,
                ..GrowthReport::default()
            }),
            _ => {
                return Err(roi_err(format!(
                    "map {} is not seeded on the session's {}; remove it and add it again",
                    self.id.0,
                    device.name()
                )));
            }
        }
        .map_err(roi_err)?;
        self.steps += report.steps;
        self.converged = report.converged;
        self.read_map(device)?;
        Ok(report)
    }

    /// Grows to convergence, and again to convergence after every new volume.
    pub(crate) fn run_to_end(
        &mut self,
        volume: &Volume,
        device: RoiDevice<'_>,
    ) -> Result<GrowthReport, RunError> {
        self.to_end = true;
        self.step(volume, device, usize::MAX)
    }

    /// Seeds again on a new `volume` on `device` and grows as far as
    /// before: the same number of steps, or to convergence if it was run to
    /// the end. The old growth is released (it lived in `device`'s context,
    /// or on the CPU). An automatic-λ map run to the end is written from a
    /// path-cost scan at its λ instead ([`SessionRoi::settle`]), on the
    /// CPU: the map the scene's `lambda = "auto"` makes at that λ.
    pub(crate) fn regrow(
        &mut self,
        volume: &Volume,
        device: RoiDevice<'_>,
    ) -> Result<GrowthReport, RunError> {
        if self.lambda_auto && self.to_end {
            let input = ScanInput {
                volume: volume.view(),
                values: volume.view(),
                limits: self.limits,
                seed: self.seed,
            };
            let grown = map_at(input, self.params, self.params.lambda).map_err(roi_err)?;
            return Ok(self.settle(grown, device));
        }
        let steps = if self.to_end {
            usize::MAX
        } else {
            self.steps as usize
        };
        // The new volume's region is most likely near the old one's: the new
        // growth's field starts there, instead of at the seed and copied
        // into larger boxes as it grows. Only the work depends on it (a
        // box past a smaller new grid is clipped to it), never the map.
        let room = self.growth.as_ref().map(RoiGrowth::region);
        self.release(device.gpu());
        self.bound(volume, device)?;
        let (_, on) = reads(&self.bounded, volume, device);
        let growth = RoiGrowth::seed(volume, on, &self.seed, self.params, room).map_err(roi_err)?;
        self.growth = Some(growth);
        self.steps = 0;
        self.step(volume, device, steps)
    }

    /// Makes `grown` — a converged map written from a path-cost scan on
    /// the current volume — the map, with nothing left to grow; its old
    /// growth is released from `device`. Returns its report.
    pub(crate) fn settle(&mut self, grown: Grown, device: RoiDevice<'_>) -> GrowthReport {
        self.release(device.gpu());
        self.bounded = None;
        let map = grown.map;
        let hi = [0, 1, 2].map(|a| map.origin[a] + map.dims[a] - 1);
        self.growth = Some(RoiGrowth::Scanned(VoxelBounds { lo: map.origin, hi }));
        self.map = map;
        self.steps = grown.report.steps;
        self.converged = grown.report.converged;
        grown.report
    }

    /// Applies its bounds to `volume` for a growth on `device` (nothing
    /// when unbounded; errors when the seed's value lies outside the
    /// intensity window).
    fn bound(&mut self, volume: &Volume, device: RoiDevice<'_>) -> Result<(), RunError> {
        let seed = self.seed.resolve(&volume.grid).map_err(roi_err)?;
        let Some(b) = self.limits.apply(volume.view(), seed).map_err(roi_err)? else {
            return Ok(());
        };
        self.bounded = Some(match device {
            RoiDevice::Cpu => BoundedValues::Cpu(b),
            RoiDevice::Gpu { gpu, .. } => {
                BoundedValues::Gpu(GpuOpacityVolume::upload(gpu, b.view()).map_err(roi_err)?)
            }
        });
        Ok(())
    }

    /// Re-grows on `device` as far as before when its growth is released
    /// or lives on another device (a CPU growth is dropped; a GPU one must
    /// have been released with its context before).
    pub(crate) fn follow(
        &mut self,
        volume: &Volume,
        device: RoiDevice<'_>,
    ) -> Result<Option<GrowthReport>, RunError> {
        match &self.growth {
            Some(g) if g.runs_on(device) => Ok(None),
            _ => self.regrow(volume, device).map(Some),
        }
    }

    /// Frees its growth's GPU buffers (`gpu`: the context it grew in); the
    /// map as it stands is kept, the growth is seeded again on next use.
    pub(crate) fn release(&mut self, gpu: Option<&dyn GpuService>) {
        if let Some(g) = self.growth.take() {
            g.release(gpu);
        }
        if let (Some(BoundedValues::Gpu(v)), Some(gpu)) = (self.bounded.take(), gpu) {
            v.release(gpu);
        }
    }

    /// True when its growth holds GPU buffers.
    pub(crate) fn on_gpu(&self) -> bool {
        matches!(self.growth, Some(RoiGrowth::Gpu(_)))
    }

    fn read_map(&mut self, device: RoiDevice<'_>) -> Result<(), RunError> {
        if let Some(map) = self
            .growth
            .as_ref()
            .map(|g| g.map(device))
            .transpose()?
            .flatten()
        {
            self.map = map;
        }
        Ok(())
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
            converged: self.converged,
            voxels_above_half: voxflex_opacity::runner::voxels_above_half(&self.map),
            lambda_auto: self.lambda_auto,
            limits: self.limits,
        }
    }
}
