//! Tracked points: landmarks or probes — fiducials shown in a viewer, an
//! actuator's sensors, the probe points of `voxflex bench --fronts` —
//! whose displacement a front end reads on demand.
//!
//! [`Session::track_points`] binds a set of rest points (world mm, the
//! source volume's frame) on the session's model and returns its
//! [`TrackId`]; the set is bound again on every new model
//! ([`Session::swap_model`], [`Session::set_backend`]), so a handle stays
//! valid across swaps. [`Session::tracked_displacements`] maps the set now:
//! one displacement per point, mm, world axes (a point's current position
//! is its rest position plus its displacement). Mapping tracked points
//! neither runs nor skips a pipeline stage: the map and resample stages
//! re-run as their [`super::Versions`] say. [`Session::untrack`] forgets a
//! set.
//!
//! Without a model there is nothing to bind to: `track_points` and
//! `tracked_displacements` return an error saying to `swap_model` first.

use super::Session;
use super::model_call::ModelCall;
use super::model_stage::ModelStage;
use crate::pipeline::RunError;
use voxflex_core::deformation::{BindingId, DisplacementTarget, RestPoints};
use voxflex_core::glam::DVec3;

/// A session's handle to one set of tracked points.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TrackId(pub u64);

/// One set of tracked points, as given.
pub(crate) struct TrackedSet {
    pub(crate) id: TrackId,
    /// Rest positions, world mm.
    pub(crate) points: Vec<[f32; 3]>,
}

/// Binds `set` on `stage`'s model and records the binding there.
pub(crate) fn bind(stage: &mut ModelStage, set: &TrackedSet) -> Result<(), RunError> {
    let binding = stage
        .model
        .bind(RestPoints::Points(&set.points))
        .map_err(ModelCall::Bind.failed())?;
    stage.tracked.push((set.id, binding));
    Ok(())
}

fn binding_of(stage: &ModelStage, id: TrackId) -> Option<BindingId> {
    stage
        .tracked
        .iter()
        .find(|(t, _)| *t == id)
        .map(|(_, b)| *b)
}

impl Session {
    /// Tracks `points` (rest positions, world mm, in the source volume's
    /// frame): binds them on the current model, and on every model after
    /// it. Errors without a model, for an empty set, or when the model
    /// refuses the points (a [`ModelCall::Bind`] error; nothing is tracked
    /// then).
    pub fn track_points(&mut self, points: &[[f32; 3]]) -> Result<TrackId, RunError> {
        if points.is_empty() {
            return Err(RunError::Other(format!(
                "{}: track_points: no points given; pass at least one world point (mm)",
                self.context
            )));
        }
        let context = self.context.clone();
        let m = self.model.as_mut().ok_or_else(|| no_model(&context))?;
        let set = TrackedSet {
            id: TrackId(self.next_track),
            points: points.to_vec(),
        };
        bind(m, &set)?;
        self.next_track += 1;
        let id = set.id;
        self.tracked.push(set);
        Ok(id)
    }

    /// The displacement of each point of set `id` now, in the order given:
    /// mm, world axes (the point is at rest position + displacement). Maps
    /// them through the model on each call (on the GPU the model reads its
    /// state back); the pipeline's stages and versions are untouched.
    /// Errors without a model, for an unknown `id`, or when the model's
    /// map fails (a [`ModelCall::Map`] error).
    pub fn tracked_displacements(&mut self, id: TrackId) -> Result<Vec<DVec3>, RunError> {
        let context = self.context.clone();
        let n = self
            .tracked
            .iter()
            .find(|s| s.id == id)
            .map(|s| s.points.len())
            .ok_or_else(|| {
                RunError::Other(format!(
                    "{context}: no tracked points {}; use the id track_points returned",
                    id.0
                ))
            })?;
        let m = self.model.as_mut().ok_or_else(|| no_model(&context))?;
        let binding = binding_of(m, id).ok_or_else(|| {
            RunError::Other(format!(
                "{context}: tracked points {} are not bound on the model",
                id.0
            ))
        })?;
        // A map resets the model's dirty region: keep it for the resample.
        self.dirty = self.dirty.union(m.model.dirty_region());
        let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
        m.model
            .map(
                binding,
                DisplacementTarget::Cpu {
                    x: &mut x,
                    y: &mut y,
                    z: &mut z,
                },
            )
            .map_err(ModelCall::Map.failed())?;
        finite(
            &context,
            id,
            (0..n)
                .map(|i| DVec3::new(x[i] as f64, y[i] as f64, z[i] as f64))
                .collect(),
        )
    }

    /// Stops tracking set `id` (its binding on the current model stays
    /// until the model is swapped); false when there was none.
    pub fn untrack(&mut self, id: TrackId) -> bool {
        let Some(i) = self.tracked.iter().position(|s| s.id == id) else {
            return false;
        };
        self.tracked.remove(i);
        if let Some(m) = self.model.as_mut() {
            m.tracked.retain(|(t, _)| *t != id);
        }
        true
    }

    /// The tracked sets, in the order they were added.
    pub fn tracked(&self) -> Vec<TrackId> {
        self.tracked.iter().map(|s| s.id).collect()
    }
}

/// `u` when every displacement is finite; otherwise an error naming the
/// set and the first point the model mapped to NaN or ∞ (a model that
/// diverged must not hand a front end a wrong position without a word).
fn finite(context: &str, id: TrackId, u: Vec<DVec3>) -> Result<Vec<DVec3>, RunError> {
    match u.iter().position(|d| !d.is_finite()) {
        None => Ok(u),
        Some(i) => Err(RunError::Other(format!(
            "{context}: tracked points {}: the model mapped point {i} to a non-finite \
             displacement {:?} (the model diverged: see its warnings and notes)",
            id.0, u[i]
        ))),
    }
}

fn no_model(context: &str) -> RunError {
    RunError::Other(format!(
        "{context}: tracked points need a model; call swap_model first"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_finite_tracked_displacement_is_an_error_naming_the_point() {
        let ok = vec![DVec3::new(1.0, -2.0, 0.5), DVec3::ZERO];
        assert_eq!(finite("s", TrackId(3), ok.clone()).unwrap(), ok);
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let u = vec![DVec3::ZERO, DVec3::new(0.0, bad, 0.0)];
            let e = finite("s", TrackId(3), u).unwrap_err().to_string();
            assert!(
                e.contains("tracked points 3") && e.contains("point 1") && e.contains("non-finite"),
                "{e}"
            );
        }
    }
}
