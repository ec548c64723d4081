//! The one trait every actuator model is seen through: something that
//! pushes on a set of bound points with one scalar effort `λ`.
//!
//! An actuator (a pneumatic or hydraulic cavity, a cable) is described by
//! a scalar **measure** `m(x)` of the points it acts on — a cavity's
//! volume growth, a cable's shortening — and pushes on those points along
//! the measure's gradient: the force on point `i` is `λ ∂m/∂xᵢ`, so `λ`
//! is work-conjugate to `m` (a pressure in Pa for a volume in mm³, a
//! tension in µN for a length in mm). These are the SoftRobots
//! constraints' `J_aᵀ λ` (Coevoet et al.; Rodríguez, Coevoet, Duriez,
//! ICRA 2017). The actuator may also carry loads that act whatever `λ`
//! is (the weight of the fluid in a cavity) and that grow with `m` (the
//! weight of the fluid pumped in: the paper's unified hydraulic
//! constraint).
//!
//! Life cycle, driven by the host's actuation stage (and, for plugins,
//! forwarded unchanged across the C ABI by `voxflex-abi`):
//!
//! 1. [`ActuatorModel::init`] once, with the points at rest.
//! 2. Every frame: [`ActuatorModel::command`] (what the actuator's script
//!    asks for this frame) and [`ActuatorModel::linearise`] at the points'
//!    current positions. The host then chooses `λ` (given, driven to a
//!    measure, or by the inverse solve), applies the forces through the
//!    deformation model's point loads, and steps the model.
//!
//! Frames and units: positions in world millimetres, forces in µN
//! (mm-g-s units, so a pressure is µN/mm² = Pa), gravity in m/s².

use crate::deformation::{FrameInfo, ModelNotes};
use crate::error::ModelError;
use glam::DVec3;

/// What an actuator acts on, at rest.
#[derive(Clone, Copy, Debug)]
pub struct ActuatorGeometry<'a> {
    /// The points it pushes on (a cavity's surface vertices, a cable's
    /// points from its fixed end), world mm at rest.
    pub points: &'a [DVec3],
    /// A cavity's triangles (indices into `points`, counter-clockwise seen
    /// from outside the cavity, so normals point out of the fluid); empty
    /// for an actuator that is not a surface.
    pub triangles: &'a [[u32; 3]],
    /// Gravity, m/s², world axes (the scene's).
    pub gravity_m_s2: DVec3,
}

/// What an actuator's script asks of it for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ActuatorCommand {
    /// Nothing: `λ` is the inverse solve's to choose (within the bounds).
    Free,
    /// `λ` given (Pa for a cavity, µN for a cable).
    Effort(f64),
    /// The measure driven to this value (mm³ of volume growth for a
    /// cavity, mm of shortening for a cable), `λ` found to reach it.
    Measure(f64),
}

/// An actuator linearised at the points' current positions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ActuatorLinearisation {
    /// `∂m/∂xᵢ` per point: the force (µN) on each point per unit `λ` —
    /// the row `J_aᵀ` of the paper.
    pub directions: Vec<DVec3>,
    /// The measure now, relative to rest (mm³ of volume growth, mm of
    /// shortening).
    pub measure: f64,
    /// Forces that act whatever `λ` is (the fluid's weight), µN per point;
    /// empty when there are none.
    pub loads: Vec<DVec3>,
    /// How `loads` grow per unit of measure (µN per mm³ for a hydraulic
    /// cavity: the weight of the fluid pumped in, `J_wᵀ`); empty when they
    /// do not.
    pub load_growth: Vec<DVec3>,
    /// The interval `λ` must stay in (a pressure or a tension only pushes
    /// or pulls: `[0, max]`).
    pub effort_bounds: [f64; 2],
    /// The interval the measure must stay in (volume growth limits, the
    /// cable's stroke), relative to rest.
    pub measure_bounds: [f64; 2],
}

impl ActuatorLinearisation {
    /// Checks the shapes and finiteness against `points` points, naming
    /// `who` (the actuator) in the error.
    pub fn check(&self, points: usize, who: &str) -> Result<(), ModelError> {
        let arrays = [
            ("directions", &self.directions, false),
            ("loads", &self.loads, true),
            ("load_growth", &self.load_growth, true),
        ];
        for (name, a, may_be_empty) in arrays {
            if a.len() != points && !(may_be_empty && a.is_empty()) {
                return Err(ModelError(format!(
                    "{who}: {name} holds {} values for {points} points",
                    a.len()
                )));
            }
            if a.iter().any(|v| !v.is_finite()) {
                return Err(ModelError(format!("{who}: {name} is not finite")));
            }
        }
        let scalars = [self.measure, self.effort_bounds[0], self.measure_bounds[0]];
        if scalars.iter().any(|v| v.is_nan())
            || self.effort_bounds[0] > self.effort_bounds[1]
            || self.measure_bounds[0] > self.measure_bounds[1]
        {
            return Err(ModelError(format!(
                "{who}: measure {} or bounds (effort {:?}, measure {:?}) are not valid",
                self.measure, self.effort_bounds, self.measure_bounds
            )));
        }
        Ok(())
    }
}

/// An actuator seen as a scalar measure of its points and the effort
/// conjugate to it.
pub trait ActuatorModel: Send {
    /// Once, before anything else: the points at rest. Refuses geometry
    /// the actuator cannot use (an open cavity surface, a one-point
    /// cable), naming what is wrong.
    fn init(&mut self, geometry: ActuatorGeometry<'_>) -> Result<(), ModelError>;

    /// What the actuator's script asks for at `frame`.
    fn command(&mut self, frame: FrameInfo) -> Result<ActuatorCommand, ModelError>;

    /// The actuator at the points' current positions (world mm, one per
    /// point of [`ActuatorGeometry::points`]).
    fn linearise(&mut self, positions: &[DVec3]) -> Result<ActuatorLinearisation, ModelError>;

    /// What the actuator reports about its work (see [`ModelNotes`]);
    /// asked once at the end of a run.
    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        Ok(ModelNotes::new())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_points() -> ActuatorLinearisation {
        ActuatorLinearisation {
            directions: vec![DVec3::X, -DVec3::X],
            measure: 0.0,
            loads: Vec::new(),
            load_growth: Vec::new(),
            effort_bounds: [0.0, f64::INFINITY],
            measure_bounds: [f64::NEG_INFINITY, f64::INFINITY],
        }
    }

    #[test]
    fn a_linearisation_of_the_right_shape_passes() {
        two_points().check(2, "cable").unwrap();
    }

    #[test]
    fn wrong_lengths_non_finite_values_and_crossed_bounds_are_named() {
        let e = two_points().check(3, "cable").unwrap_err();
        assert!(
            e.0.contains("directions holds 2 values for 3 points"),
            "{e}"
        );
        let mut l = two_points();
        l.loads = vec![DVec3::NAN; 2];
        let e = l.check(2, "cavity").unwrap_err();
        assert!(e.0.contains("loads is not finite"), "{e}");
        let mut l = two_points();
        l.effort_bounds = [1.0, 0.0];
        assert!(l.check(2, "cavity").unwrap_err().0.contains("bounds"));
    }
}
