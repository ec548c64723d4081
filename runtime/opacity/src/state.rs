//! [`GrowthState`]: what a region growth keeps whatever its backend —
//! parameters, the seed's statistics, the update constants, the raised
//! region and working box (voxel indices) and the step counts — with the
//! seeding both backends share, and [`Growth`], the read-only view of it
//! that [`crate::CpuGrowth`] and [`crate::GpuGrowth`] offer.

use super::OpacityError;
use super::bounds::{VoxelBounds, initial_working_box};
use super::extinction::Extinction;
use super::params::GrowthParams;
use super::report::GrowthReport;
use super::seed::{Seed, SeedStats, seed_stats};
use crate::volume::VolumeView;

/// The backend-independent state of one growth.
#[derive(Clone, Debug)]
pub struct GrowthState {
    pub(crate) dims: [usize; 3],
    pub(crate) params: GrowthParams,
    pub(crate) stats: SeedStats,
    pub(crate) ext: Extinction,
    pub(crate) work: VoxelBounds,
    pub(crate) region: VoxelBounds,
    pub(crate) total: GrowthReport,
}

impl GrowthState {
    /// Seeds a growth on `volume` (already validated with `params`): the
    /// seed's neighbourhood statistics, the update constants and the initial boxes.
    /// Returns the state and the seed's index in the working box.
    ///
    /// With `room` (voxel indices, clipped to the volume), the working box
    /// covers it, plus the two voxels a step reads beyond the region, from
    /// the start: a growth whose region stays inside `room` never moves its
    /// field. Only the work depends on it, never the map.
    pub(crate) fn seed(
        volume: VolumeView<'_>,
        seed: &Seed,
        params: GrowthParams,
        room: Option<VoxelBounds>,
    ) -> Result<(Self, usize), OpacityError> {
        let voxel = seed.resolve(&volume.grid)?;
        let stats = seed_stats(volume, voxel, &params)?;
        let ext = Extinction::new(&stats, &params)?;
        let dims = volume.grid.dims;
        let region = VoxelBounds::point(voxel);
        let mut work = initial_working_box(&region, dims);
        if let Some(room) = room {
            let hi = [0, 1, 2].map(|a| room.hi[a].min(dims[a] - 1));
            let lo = [0, 1, 2].map(|a| room.lo[a].min(hi[a]));
            work = work.union(&VoxelBounds { lo, hi }.dilate([2; 3], dims));
        }
        let seed_local = work.local_linear(voxel);
        let state = Self {
            dims,
            params,
            stats,
            ext,
            work,
            region,
            total: GrowthReport::default(),
        };
        Ok((state, seed_local))
    }
}

/// What every growth reports, whatever its backend.
pub trait Growth {
    /// The backend-independent state.
    fn state(&self) -> &GrowthState;

    /// Counts of every step run so far.
    fn report(&self) -> GrowthReport {
        self.state().total
    }

    /// The seed's statistics (`d_s`, σ_s).
    fn stats(&self) -> &SeedStats {
        &self.state().stats
    }

    /// The constants of the update rule.
    fn extinction(&self) -> &Extinction {
        &self.state().ext
    }

    /// The parameters the growth was seeded with.
    fn params(&self) -> &GrowthParams {
        &self.state().params
    }

    /// Box (voxel indices) of the voxels raised so far, seed included.
    fn region(&self) -> VoxelBounds {
        self.state().region
    }

    /// Box (voxel indices) the working field covers.
    fn working_box(&self) -> VoxelBounds {
        self.state().work
    }
}
