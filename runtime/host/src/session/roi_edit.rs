//! Editing a session's ROI maps after they are seeded: new growth
//! constants ([`Session::set_roi_params`]) and a map written to a volume
//! file ([`Session::write_roi_map`]) — what the viewer's ROI panel drives.

use super::{RoiId, Session, roi_err};
use crate::pipeline::RunError;
use std::path::Path;
use voxflex_core::opacity_map::from_fixed;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_opacity::{GrowthParams, GrowthReport};

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
