//! What the actuation stage reports in `metrics.json` (`"actuation"`):
//! per actuator its effort and measure after every frame, per effector
//! its distance to the target, and the solves it took.

use super::stage::Actuator;
use serde::Serialize;
use voxflex_core::deformation::ModelNotes;
use voxflex_core::glam::DVec3;

/// The actuation part of `metrics.json`.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ActuationReport {
    /// One per `[[actuator]]`, in scene order.
    pub actuators: Vec<ActuatorSeries>,
    /// One per `[[effector]]`, in scene order.
    pub effectors: Vec<EffectorSeries>,
    /// Per frame, how much the actuator forces changed over it relative to
    /// their size: a pressure or cable follows what it pushes and a frame
    /// applies it as it was at the frame's start, so this is how far the
    /// body still was from the equilibrium of its efforts. Above 1 % at
    /// the last frame the run warns.
    pub force_change: Vec<f64>,
    /// Per frame, the repeated steps (`resolve`) its follower forces took
    /// to settle.
    pub settle_iterations: Vec<u32>,
    /// Repeated steps that failed (the model kept its last converged
    /// state; each also a warning).
    pub settle_failures: u64,
    /// Compliance solves the inverse problems and measure scripts took.
    pub compliance_solves: u64,
    /// Inverse steps that reused the last frames' responses instead of
    /// solving again (`[actuation] response_refresh_frames` above 1).
    pub responses_reused: u64,
    /// Interior-point iterations of the inverse QPs, summed.
    pub qp_iterations: u64,
    /// Frames whose inverse QP failed (infeasible scripts): the efforts
    /// stayed, and a warning said why.
    pub qp_failures: u64,
    /// Inverse steps the model's answer disappointed (less than a quarter
    /// of the predicted improvement), each shrinking the trust region.
    pub trust_shrinks: u64,
    /// Frames whose observed effector motion corrected the compliance's
    /// predicted response (the secant update).
    pub secant_updates: u64,
}

/// One actuator over the run.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ActuatorSeries {
    /// `name` (or `plugin#index`).
    pub name: String,
    /// The plugin.
    pub plugin: String,
    /// Effort λ applied in each frame (Pa for a cavity, µN for a cable).
    pub effort: Vec<f64>,
    /// Measure after each frame, relative to rest (mm³ of volume growth
    /// for a cavity, mm of shortening for a cable).
    pub measure: Vec<f64>,
    /// The plugin's own notes at the end of the run.
    pub notes: ModelNotes,
}

/// One effector over the run.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct EffectorSeries {
    /// `name` (or `effector#index`).
    pub name: String,
    /// Distance to the target after each frame, mm.
    pub distance_mm: Vec<f64>,
    /// Position after the last frame, world mm.
    pub position_mm: [f64; 3],
    /// Target of the last frame, world mm.
    pub target_mm: [f64; 3],
}

impl ActuationReport {
    /// Empty series for these actuators and effector names.
    pub(crate) fn new(actuators: &[Actuator], effectors: &[String]) -> Self {
        Self {
            actuators: actuators.iter().map(ActuatorSeries::of).collect(),
            effectors: effectors.iter().map(|n| EffectorSeries::named(n)).collect(),
            ..Self::default()
        }
    }

    /// Records a frame: each actuator's effort and measure, each
    /// effector's `(position, target)`.
    pub(crate) fn record(
        &mut self,
        actuators: &[Actuator],
        effectors: &[(DVec3, DVec3)],
        force_change: f64,
    ) {
        self.force_change.push(force_change);
        for (s, a) in self.actuators.iter_mut().zip(actuators) {
            s.effort.push(a.effort());
            s.measure.push(a.measure());
        }
        for (s, (p, t)) in self.effectors.iter_mut().zip(effectors) {
            s.distance_mm.push(p.distance(*t));
            s.position_mm = p.to_array();
            s.target_mm = t.to_array();
        }
    }
}
