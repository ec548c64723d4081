//! [`Session::roi_auto_lambda`]: an ROI map's λ chosen by the plateau rule
//! of `voxflex_opacity::auto_lambda` (the scene's `lambda = "auto"`) on
//! the session's current volume — what the viewer's *auto λ* box drives.

use super::{RoiId, Session, roi_err};
use crate::pipeline::RunError;
use std::time::Instant;
use voxflex_opacity::auto_lambda::{Trial, auto_map};
use voxflex_opacity::{GrowthParams, GrowthReport, ScanInput};

/// What [`Session::roi_auto_lambda`] chose and tried.
#[derive(Clone, Debug, PartialEq)]
pub struct AutoLambdaReport {
    /// The λ chosen, now the map's λ.
    pub lambda: f32,
    /// Every candidate λ tried, in increasing order (the last may have
    /// jumped: see `voxflex_opacity::auto_lambda`).
    pub trials: Vec<Trial>,
    /// The map's making at the chosen λ: written from the scan, converged,
    /// no growth step (`visits`: the scan's relaxations up to that λ).
    pub report: GrowthReport,
}

impl Session {
    /// Chooses ROI map `id`'s λ by the plateau rule (the scene's
    /// `lambda = "auto"`: sizes of its region at λ = 1 … 32, √2
    /// apart, on the current volume with its o_min, o_max and σ floor),
    /// makes it the map's λ and writes the converged map at it from the
    /// same scan, with no growth (`voxflex_opacity::auto_lambda::auto_map`;
    /// on every new volume the map is written again from a scan at the
    /// same λ: the rule is not re-run when the volume changes; call this
    /// again for that). Runs on the CPU whatever the session's backend.
    /// Errors when there is no map `id`, leaving the maps as they were.
    pub fn roi_auto_lambda(&mut self, id: RoiId) -> Result<AutoLambdaReport, RunError> {
        let i = self.roi_index(id)?;
        self.ensure_volume()?;
        self.ensure_roi_values()?;
        let t = Instant::now();
        let (rois, volume, device) = self.roi_parts();
        let (seed, params) = (rois[i].seed, rois[i].params);
        // The scan reads the volume with the map's bounds applied, as the
        // map's growth does, on the CPU whatever the backend.
        let input = ScanInput {
            volume: volume.view(),
            values: volume.view(),
            limits: rois[i].limits,
            seed,
        };
        let auto = auto_map(input, params).map_err(roi_err)?;
        let roi = &mut rois[i];
        roi.params = GrowthParams {
            lambda: auto.search.lambda,
            ..params
        };
        roi.lambda_auto = true;
        roi.to_end = true;
        let report = roi.settle(auto.grown, device);
        self.metrics
            .stage("roi")
            .record_run(t.elapsed(), report.visits);
        Ok(AutoLambdaReport {
            lambda: auto.search.lambda,
            trials: auto.search.trials,
            report,
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::session::{RoiId, Seed};
    use voxflex_core::glam::DVec3;
    use voxflex_opacity::auto_lambda::{CANDIDATES, map_at};
    use voxflex_opacity::{
        GrowthLimits, GrowthParams, LambdaChoice, RoiRequest, ScanInput, grow_roi,
    };

    #[test]
    fn auto_lambda_writes_the_map_the_scene_rule_writes_and_a_given_lambda_ends_it() {
        let (mut s, id) = crate::session::tests::head_session_with_brain_roi();
        let seed = Seed::World(DVec3::new(40.0, 0.0, 15.0));
        let params = GrowthParams::default();
        let auto = s.roi_auto_lambda(id).unwrap();
        assert!(CANDIDATES.contains(&auto.lambda), "{auto:?}");
        assert!(auto.report.converged && auto.trials.len() > 1, "{auto:?}");
        let info = &s.rois()[0];
        assert!(info.lambda_auto && info.converged, "{info:?}");
        assert_eq!(info.params.lambda, auto.lambda);
        // The scene's `lambda = "auto"` on the same volume and seed: the
        // same λ and the same map, voxel for voxel.
        let scene = grow_roi(
            s.volume().unwrap().view(),
            &RoiRequest {
                seed,
                params,
                lambda: LambdaChoice::Auto,
                limits: GrowthLimits::default(),
                steps: None,
            },
            None,
        )
        .unwrap();
        assert_eq!(scene.lambda, auto.lambda);
        assert_eq!(s.roi_map(id).unwrap(), &scene.grown.map);
        // Written from the scan, not grown.
        assert_eq!((auto.report.steps, s.rois()[0].steps), (0, 0));
        // Made again (new bounds; a new volume takes the same path) it is
        // written again from a scan at the same λ, the rule not re-run.
        let limits = GrowthLimits {
            intensity: None,
            max_distance_mm: Some(20.0),
        };
        let again = s.set_roi_limits(id, limits).unwrap();
        assert!(again.converged && again.steps == 0, "{again:?}");
        let info = &s.rois()[0];
        assert!(info.lambda_auto && info.params.lambda == auto.lambda);
        let volume = s.volume().unwrap().clone();
        let input = ScanInput {
            volume: volume.view(),
            values: volume.view(),
            limits,
            seed,
        };
        let bounded = map_at(input, params, auto.lambda).unwrap();
        assert_eq!(s.roi_map(id).unwrap(), &bounded.map);
        assert_ne!(bounded.map, scene.grown.map);
        s.set_roi_limits(id, GrowthLimits::default()).unwrap();
        assert_eq!(s.roi_map(id).unwrap(), &scene.grown.map);
        // A λ given again makes it a fixed-λ map, grown.
        s.set_roi_params(
            id,
            GrowthParams {
                lambda: 8.0,
                ..params
            },
        )
        .unwrap();
        assert!(!s.rois()[0].lambda_auto && s.rois()[0].steps > 0);
        let e = s.roi_auto_lambda(RoiId(99)).unwrap_err().to_string();
        assert!(e.contains("no ROI map 99"), "{e}");
    }
}
