//! Which ROI maps [`Session::render`] shows: a front end hides a map from
//! the 3D image without removing it ([`Session::set_roi_shown`]); a hidden
//! map still grows and follows the volume.

use super::{RoiId, Session};
use crate::pipeline::RunError;

impl Session {
    /// Shows (`true`, the default for a new map) or hides ROI map `id` in
    /// [`Session::render`]'s images. Errors when there is no map `id`.
    pub fn set_roi_shown(&mut self, id: RoiId, shown: bool) -> Result<(), RunError> {
        let i = self.roi_index(id)?;
        self.rois[i].shown = shown;
        Ok(())
    }

    /// True when ROI map `id` exists and [`Session::render`] shows it.
    pub fn roi_shown(&self, id: RoiId) -> bool {
        self.rois.iter().any(|r| r.id == id && r.shown)
    }
}
