//! Editing a session's ROI maps after they are seeded: new growth
//! constants ([`Session::set_roi_params`]) and a map written to a volume
//! file ([`Session::write_roi_map`]) — what the viewer's ROI panel drives.

use super::{RoiId, Session, roi_err};
use crate::pipeline::RunError;
use std::path::Path;
use voxflex_core::opacity_map::from_fixed;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_opacity::{GrowthLimits, GrowthParams, GrowthReport};

impl Session {
    /// Gives ROI map `id` new growth constants and grows it again from its
    /// seed on the current volume as far as before (the same number of
    /// steps, or to convergence if it was run to the end). Its λ is then
    /// the one given (no longer automatic). Errors, leaving
    /// the map as it was, when `params` is invalid (the message names the
    /// value) or there is no map `id`.
    pub fn set_roi_params(
        &mut self,
        id: RoiId,
        params: GrowthParams,
    ) -> Result<GrowthReport, RunError> {
        params.validate().map_err(roi_err)?;
        let i = self.roi_index(id)?;
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let (rois, volume, device) = self.roi_parts();
        let old = rois[i].params;
        let old_auto = rois[i].lambda_auto;
        rois[i].params = params;
        rois[i].lambda_auto = false;
        let report = rois[i].regrow(volume, device);
        if report.is_err() {
            rois[i].params = old;
            rois[i].lambda_auto = old_auto;
        }
        report
    }

    /// Gives ROI map `id` growth bounds — an intensity window (value
    /// units, inclusive) and a largest distance from the seed voxel's
    /// centre (world mm), the scene's `intensity` and `max_distance_mm`
    /// (`voxflex_opacity::GrowthLimits`: opacity never enters a voxel
    /// outside them) — and grows it again from its seed as far as before;
    /// `GrowthLimits::default()` bounds nothing. Errors, leaving the map as
    /// it was, when a bound is invalid or the seed's value lies outside
    /// the window (the message names the key or the value).
    pub fn set_roi_limits(
        &mut self,
        id: RoiId,
        limits: GrowthLimits,
    ) -> Result<GrowthReport, RunError> {
        limits.validate().map_err(roi_err)?;
        let i = self.roi_index(id)?;
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let (rois, volume, device) = self.roi_parts();
        let old = rois[i].limits;
        rois[i].limits = limits;
        let report = rois[i].regrow(volume, device);
        if report.is_err() {
            rois[i].limits = old;
            rois[i].regrow(volume, device)?;
        }
        report
    }

    /// Writes ROI map `id` as a volume file on the current volume's grid
    /// (world mm): one f32 opacity in [0, 1] per voxel, `outside` where
    /// the map never grew. The format follows the extension (`.nii`,
    /// `.nii.gz`). Errors when there is no map `id` or the file cannot be
    /// written (the message names the path).
    pub fn write_roi_map(&mut self, id: RoiId, path: &Path) -> Result<(), RunError> {
        self.ensure_volume()?;
        let grid = self.volume_ref().grid;
        let map = self
            .roi_map(id)
            .ok_or_else(|| RunError::Other(format!("{}: no ROI map {}", self.context, id.0)))?;
        let values: Vec<f32> = map.dense(grid.dims).into_iter().map(from_fixed).collect();
        let volume = Volume::new(grid, VoxelData::F32(values))
            .map_err(|e| RunError::Other(format!("{}: ROI map {}: {e}", self.context, id.0)))?;
        voxflex_io::write_volume(path, volume.view())?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::session::Seed;
    use voxflex_core::glam::DVec3;
    use voxflex_opacity::{GrowthLimits, GrowthParams, LambdaChoice, RoiRequest, grow_roi};

    #[test]
    fn bounds_hold_a_map_in_and_are_the_scene_paths_bounds() {
        let (mut s, id) = crate::session::tests::head_session_with_brain_roi();
        let seed = Seed::World(DVec3::new(40.0, 0.0, 15.0));
        let params = GrowthParams::default();
        s.roi_run_to_end(id).unwrap();
        let free = s.rois()[0].voxels_above_half;
        let limits = GrowthLimits {
            intensity: None,
            max_distance_mm: Some(12.0),
        };
        s.set_roi_limits(id, limits).unwrap();
        let info = s.rois()[0].clone();
        assert_eq!(info.limits, limits);
        assert!(
            info.converged && info.voxels_above_half < free / 4,
            "{info:?} vs {free}"
        );
        // The scene's `max_distance_mm` on the same volume and seed: the
        // same map, voxel for voxel.
        let scene = grow_roi(
            s.volume().unwrap().view(),
            &RoiRequest {
                seed,
                params,
                lambda: LambdaChoice::Fixed(params.lambda),
                limits,
                steps: None,
            },
            None,
        )
        .unwrap();
        assert_eq!(s.roi_map(id).unwrap(), &scene.grown.map);
        // A window the seed (brain, 30 HU) lies outside: refused, the map
        // keeps its bounds.
        let bad = GrowthLimits {
            intensity: Some([500.0, 2000.0]),
            max_distance_mm: None,
        };
        let e = s.set_roi_limits(id, bad).unwrap_err().to_string();
        assert!(e.contains("500"), "{e}");
        assert_eq!(s.rois()[0].limits, limits);
        assert_eq!(s.rois()[0].voxels_above_half, info.voxels_above_half);
    }
}
