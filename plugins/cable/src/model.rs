//! The cable as an [`ActuatorModel`]: its measure is the shortening from
//! rest, `m = L₀ − L(x)`, and a tension `λ` (µN) pulls point `i` with
//! `λ ∂m/∂xᵢ = −λ ∂L/∂pᵢ` ([`crate::length`]) — SoftRobots'
//! CableConstraint.

use crate::length::{cable_length, shortening_gradient};
use crate::params::CableParams;
use voxflex_core::actuator::{
    ActuatorCommand, ActuatorGeometry, ActuatorLinearisation, ActuatorModel,
};
use voxflex_core::deformation::{FrameInfo, ModelNotes};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;

/// Closest the first point may be to the pull point at rest, mm (1 nm):
/// closer, the first segment has no direction to pull along.
pub const MIN_FIRST_SEGMENT_MM: f64 = 1e-6;

/// What `init` learnt about the cable at rest.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Rest {
    /// Points on the body.
    points: usize,
    /// `L₀`, mm.
    length_mm: f64,
}

/// A cable pulled through a fixed point: the model of the `cable` plugin.
#[derive(Debug)]
pub struct Cable {
    params: CableParams,
    rest: Option<Rest>,
    /// `linearise` calls so far.
    linearisations: u64,
    /// The length at the last `linearise`, mm.
    last_length_mm: Option<f64>,
}

impl Cable {
    /// A cable with parsed parameters; [`ActuatorModel::init`] gives it
    /// its points.
    pub fn new(params: CableParams) -> Self {
        Self {
            params,
            rest: None,
            linearisations: 0,
            last_length_mm: None,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &CableParams {
        &self.params
    }

    /// `L₀`, mm (`None` before `init`).
    pub fn rest_length_mm(&self) -> Option<f64> {
        self.rest.map(|r| r.length_mm)
    }
}

/// Refuses points the cable cannot run through: none, a non-finite one, a
/// first point on the pull point, or a surface (a cable is a polyline).
fn check_geometry(geometry: &ActuatorGeometry<'_>, pull: DVec3) -> Result<(), ModelError> {
    let points = geometry.points;
    if points.is_empty() {
        return Err(ModelError::new(
            "cable: no points: give the cable's points on the body, in order from the pull \
             point",
        ));
    }
    if !geometry.triangles.is_empty() {
        return Err(ModelError(format!(
            "cable: got {} triangles, but a cable is a polyline of points; give no surface",
            geometry.triangles.len()
        )));
    }
    check_finite(points)?;
    let gap = points[0].distance(pull);
    if gap < MIN_FIRST_SEGMENT_MM {
        return Err(ModelError(format!(
            "cable: point 0 {:?} lies on the pull point {:?} ({gap} mm apart): the first \
             segment has no direction to pull along; move pull_point_mm or the first point",
            points[0].to_array(),
            pull.to_array()
        )));
    }
    Ok(())
}

/// Refuses a non-finite point, naming it.
fn check_finite(points: &[DVec3]) -> Result<(), ModelError> {
    match points.iter().position(|p| !p.is_finite()) {
        Some(i) => Err(ModelError(format!(
            "cable: point {i} is at {:?}, not a finite position (mm)",
            points[i].to_array()
        ))),
        None => Ok(()),
    }
}

impl ActuatorModel for Cable {
    fn init(&mut self, geometry: ActuatorGeometry<'_>) -> Result<(), ModelError> {
        let pull = self.params.pull_point();
        check_geometry(&geometry, pull)?;
        let rest = Rest {
            points: geometry.points.len(),
            length_mm: cable_length(pull, geometry.points),
        };
        tracing::debug!(
            points = rest.points,
            length_mm = rest.length_mm,
            "cable initialised"
        );
        self.rest = Some(rest);
        self.linearisations = 0;
        self.last_length_mm = None;
        Ok(())
    }

    fn command(&mut self, frame: FrameInfo) -> Result<ActuatorCommand, ModelError> {
        Ok(self.params.command(frame))
    }

    fn linearise(&mut self, positions: &[DVec3]) -> Result<ActuatorLinearisation, ModelError> {
        let rest = self
            .rest
            .ok_or_else(|| ModelError::new("cable: linearise before init"))?;
        if positions.len() != rest.points {
            return Err(ModelError(format!(
                "cable: linearise got {} positions for {} points",
                positions.len(),
                rest.points
            )));
        }
        check_finite(positions)?;
        let pull = self.params.pull_point();
        let length = cable_length(pull, positions);
        self.linearisations += 1;
        self.last_length_mm = Some(length);
        Ok(ActuatorLinearisation {
            directions: shortening_gradient(pull, positions),
            measure: rest.length_mm - length,
            loads: Vec::new(),
            load_growth: Vec::new(),
            effort_bounds: self.params.effort_bounds(),
            measure_bounds: self.params.measure_bounds(),
        })
    }

    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        let mut notes = ModelNotes::new();
        notes.insert("linearisations".into(), self.linearisations as f64);
        let Some(rest) = self.rest else {
            return Ok(notes);
        };
        notes.insert("points".into(), rest.points as f64);
        notes.insert("rest_length_mm".into(), rest.length_mm);
        if let Some(l) = self.last_length_mm {
            notes.insert("length_mm".into(), l);
            notes.insert("shortening_mm".into(), rest.length_mm - l);
        }
        Ok(notes)
    }
}

#[cfg(test)]
#[path = "model_tests.rs"]
mod tests;
