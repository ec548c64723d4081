//! The inverse step of the actuation stage: one frame's responses (a
//! compliance solve per actuator), the QP over the efforts not given, the
//! secant-corrected effector rows, and the trust region that judges each
//! step by what the model did.

use super::{ActuationStage, Actuator, clamp, failed, target};
use crate::actuation::inverse::{InverseProblem, MeasureRow};
use voxflex_core::actuator::ActuatorCommand;
use voxflex_core::deformation::{BindingId, DeformationModel, FrameInfo};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;

/// Effort changes below this fraction of the efforts' scale are the QP's
/// rounding, not a step.
const QP_NOISE: f64 = 1e-9;

/// The trust region never shrinks below this fraction of the largest
/// step an actuator has taken: a run of disappointing frames (a moving
/// target, a body still settling) must not freeze the efforts for good.
const TRUST_FLOOR: f64 = 0.02;

/// What the last frame's inverse step expected (see
/// [`ActuationStage::judge_last_step`]).
pub(super) struct InverseStep {
    /// Effector offset norm before the step, and as the linearisation
    /// predicted after it (mm).
    before: f64,
    predicted: f64,
    /// The targets it aimed at (mm).
    targets: Vec<DVec3>,
    /// `(actuator, effort change)` of the unknowns.
    delta: Vec<(usize, f64)>,
}

impl ActuationStage {
    /// Each actuator's response (mm at every stage point per unit
    /// effort): `K⁻¹ J_aᵀ`, and for loads that grow with the measure (a
    /// hydraulic cavity) the unified constraint `K⁻¹ (J_aᵀ + J_wᵀ J_a K⁻¹ J_aᵀ)`.
    fn responses(
        &mut self,
        model: &mut dyn DeformationModel,
        binding: BindingId,
    ) -> Result<Vec<Vec<DVec3>>, ModelError> {
        let n = self.rest.len();
        let mut out = Vec::with_capacity(self.actuators.len());
        for a in &self.actuators {
            let solve = |model: &mut dyn DeformationModel, v: &[DVec3]| {
                let mut f = vec![DVec3::ZERO; n];
                f[a.range.clone()].copy_from_slice(v);
                let mut u = vec![DVec3::ZERO; n];
                model
                    .compliance(binding, &f, &mut u)
                    .map_err(|e| failed(&format!("compliance of [[actuator]] {}", a.name), e))?;
                Ok::<_, ModelError>(u)
            };
            let mut u = solve(model, &a.lin.directions)?;
            self.report.compliance_solves += 1;
            if !a.lin.load_growth.is_empty() {
                let s = measure_response(a, &u);
                let ug = solve(model, &a.lin.load_growth)?;
                self.report.compliance_solves += 1;
                for (ui, gi) in u.iter_mut().zip(&ug) {
                    *ui += s * *gi;
                }
            }
            out.push(u);
        }
        Ok(out)
    }

    /// The responses this inverse step uses: solved afresh on the first
    /// step, every `response_refresh_frames` steps and, when frames
    /// settle, after a disappointing step; else the last ones (the secant
    /// correction keeps learning what they miss).
    fn current_responses(
        &mut self,
        model: &mut dyn DeformationModel,
        binding: BindingId,
    ) -> Result<Vec<Vec<DVec3>>, ModelError> {
        let every = self.settle.response_refresh_frames;
        // A settled frame judges the responses by what the model did; a
        // lagged one (settle_iterations = 0) mostly measures its own lag.
        let misled = self.disappointed && self.settle.settle_iterations > 0;
        let (r, age) = match self.responses.take() {
            Some((r, age)) if age + 1 < every && !misled => {
                self.report.responses_reused += 1;
                (r, age + 1)
            }
            _ => (self.responses(model, binding)?, 0),
        };
        // Kept only when a later step may use it (never at the default
        // every = 1: no copy of the responses on that path).
        if age + 1 < every {
            self.responses = Some((r.clone(), age));
        }
        Ok(r)
    }

    /// Builds and solves the frame's inverse problem over the actuators
    /// whose effort is not given; `known` holds the given ones.
    pub(super) fn solve_inverse(
        &mut self,
        model: &mut dyn DeformationModel,
        binding: BindingId,
        known: &[Option<f64>],
        frame: FrameInfo,
    ) -> Result<(), ModelError> {
        self.judge_last_step();
        let responses = self.current_responses(model, binding)?;
        let unknown: Vec<usize> = (0..known.len()).filter(|&a| known[a].is_none()).collect();
        // What the given efforts' changes do, before the unknowns move.
        let mut shift = vec![DVec3::ZERO; self.rest.len()];
        for (a, k) in known.iter().enumerate() {
            if let Some(v) = k {
                let d = v - self.actuators[a].effort;
                for (s, r) in shift.iter_mut().zip(&responses[a]) {
                    *s += d * *r;
                }
            }
        }
        let mut p = InverseProblem::default();
        let when = frame.frame as f64;
        // Per effector coordinate, its response to every actuator: the
        // compliance's, corrected by what the last frames taught.
        let rows = self.effector_rows(&responses);
        let given: Vec<f64> = known
            .iter()
            .zip(&self.actuators)
            .map(|(k, a)| k.map_or(0.0, |v| v - a.effort))
            .collect();
        for (row, w) in rows.iter().enumerate() {
            let e = &self.effectors[row / 3];
            let k = row % 3;
            let offset = self.positions[e.index][k] + dot(w, &given) - target(e, when)[k];
            p.effector_response
                .push(unknown.iter().map(|&a| w[a]).collect());
            p.effector_offset.push(offset);
        }
        for &a in &unknown {
            p.efforts.push(self.actuators[a].effort);
            p.effort_bounds.push(self.actuators[a].lin.effort_bounds);
            p.step_limits.push(self.trust[a]);
        }
        for b in &self.actuators {
            let target = match b.command {
                ActuatorCommand::Measure(m) => Some(m),
                _ => None,
            };
            let bounded = b.lin.measure_bounds.iter().any(|v| v.is_finite());
            if target.is_none() && !bounded {
                continue;
            }
            p.measures.push(MeasureRow {
                response: unknown
                    .iter()
                    .map(|&a| measure_response(b, &responses[a]))
                    .collect(),
                now: b.lin.measure + measure_response(b, &shift),
                bounds: b.lin.measure_bounds,
                target,
            });
        }
        tracing::debug!(?p, "actuation: inverse problem of frame {}", frame.frame);
        let targets: Vec<DVec3> = self.effectors.iter().map(|e| target(e, when)).collect();
        let before = p.effector_offset.iter().map(|d| d * d).sum::<f64>().sqrt();
        let delta = match p.solve() {
            Ok(s) => {
                self.report.qp_iterations += u64::from(s.iterations);
                self.last = (!self.effectors.is_empty()).then(|| InverseStep {
                    before,
                    predicted: s.predicted_offset,
                    targets,
                    delta: unknown
                        .iter()
                        .copied()
                        .zip(s.delta.iter().copied())
                        .collect(),
                });
                s.delta
            }
            Err(why) => {
                self.report.qp_failures += 1;
                tracing::warn!(
                    "actuation, frame {}: {why}; the efforts stay as they were (a scripted \
                     measure outside the actuator's bounds, or conflicting scripts)",
                    frame.frame
                );
                vec![0.0; unknown.len()]
            }
        };
        let before_efforts: Vec<f64> = self.actuators.iter().map(|a| a.effort).collect();
        for (a, k) in known.iter().enumerate() {
            if let Some(v) = k {
                self.actuators[a].effort = *v;
            }
        }
        let largest = delta.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        for (&a, d) in unknown.iter().zip(delta) {
            let act = &mut self.actuators[a];
            // The interior-point answer carries its own rounding (1e-10 of
            // the problem's scale): a change that small is no change, and
            // an effort of 1e-10 Pa on a body at rest would hand the model
            // a load whose only scale is rounding noise.
            let noise = QP_NOISE * act.effort.abs().max(largest).max(1.0);
            if d.abs() > noise {
                act.effort = clamp(act.effort + d, act.lin.effort_bounds);
            }
        }
        let change: Vec<f64> = self
            .actuators
            .iter()
            .zip(&before_efforts)
            .map(|(a, b)| a.effort - b)
            .collect();
        let predicted = rows.iter().map(|w| dot(w, &change)).collect();
        let coords = self.effector_coordinates();
        self.secant
            .record(&before_efforts, change, coords, predicted);
        Ok(())
    }

    /// Per effector coordinate (x, y, z of each effector), its response to
    /// a unit effort of every actuator (mm): the compliance's plus the
    /// secant correction.
    fn effector_rows(&self, responses: &[Vec<DVec3>]) -> Vec<Vec<f64>> {
        let mut rows = Vec::with_capacity(3 * self.effectors.len());
        for e in &self.effectors {
            for k in 0..3 {
                let row = rows.len();
                rows.push(
                    responses
                        .iter()
                        .enumerate()
                        .map(|(a, r)| r[e.index][k] + self.secant.correction(row, a))
                        .collect(),
                );
            }
        }
        rows
    }

    /// The effectors' coordinates now (x, y, z of each), mm.
    pub(super) fn effector_coordinates(&self) -> Vec<f64> {
        self.effectors
            .iter()
            .flat_map(|e| self.positions[e.index].to_array())
            .collect()
    }
}

impl ActuationStage {
    /// Judges the last inverse step by the model's answer (a trust region,
    /// as in Levenberg–Marquardt): where the effectors got less than a
    /// quarter of the predicted improvement, the next steps of the
    /// actuators that moved are limited to a quarter of theirs; where they
    /// got most of it, the limit doubles. A soft body's response to its
    /// actuators changes fast under large strain (a bulging wall takes the
    /// volume a bend needed), and a full Gauss–Newton step then overshoots
    /// and oscillates.
    fn judge_last_step(&mut self) {
        let Some(last) = self.last.take() else {
            return;
        };
        let now: f64 = self
            .effectors
            .iter()
            .zip(&last.targets)
            .map(|(e, t)| (self.positions[e.index] - *t).length_squared())
            .sum::<f64>()
            .sqrt();
        let expected = last.before - last.predicted;
        // A step that promised nothing (at an optimum) cannot disappoint.
        let rho = if expected <= 1e-12 * last.before.max(1e-12) {
            1.0
        } else {
            (last.before - now) / expected
        };
        self.disappointed = rho < 0.25;
        for (a, d) in last.delta {
            self.largest_step[a] = self.largest_step[a].max(d.abs());
            if rho < 0.25 {
                let floor = TRUST_FLOOR * self.largest_step[a];
                self.trust[a] = (0.25 * d.abs().min(self.trust[a])).max(floor);
                self.report.trust_shrinks += 1;
            } else if rho > 0.75 && self.trust[a].is_finite() {
                self.trust[a] *= 2.0;
            }
        }
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `J_b · u` over actuator `b`'s points: the change of its measure under
/// the displacements `u` of every stage point.
fn measure_response(b: &Actuator, u: &[DVec3]) -> f64 {
    b.lin
        .directions
        .iter()
        .zip(&u[b.range.clone()])
        .map(|(d, v)| d.dot(*v))
        .sum()
}
