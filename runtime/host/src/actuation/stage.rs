//! The actuation stage: before every model step it chooses each
//! actuator's effort `λ` — given by its script, driven to a scripted
//! measure, or by the inverse solve towards the effectors' targets — and
//! hands the forces `Σ λ_a J_aᵀ + loads` to the deformation model as point
//! loads; after the step it reads the points back and linearises the
//! actuators again at their new positions (one linearisation per frame).
//!
//! Every actuator and effector point is bound to the model once, as one
//! point set, so one compliance solve per actuator observes every
//! effector and every actuator's measure at once.

mod inverse_step;

use inverse_step::InverseStep;

use super::anderson::Anderson;
use super::geometry::RestGeometry;
use super::report::{ActuationReport, ActuatorSeries, EffectorSeries};
use super::secant::Secant;
use super::settings::ActuationSettings;
use rayon::prelude::*;
use std::ops::Range;
use voxflex_core::actuator::{
    ActuatorCommand, ActuatorGeometry, ActuatorLinearisation, ActuatorModel,
};
use voxflex_core::deformation::{
    BindingId, DeformationModel, DisplacementTarget, FrameInfo, RestPoints,
};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::keyframes::Keyframes;

/// One actuator of the stage.
pub(crate) struct Actuator {
    /// Name in metrics and messages.
    pub(crate) name: String,
    /// Its plugin's name.
    pub(crate) plugin: String,
    pub(crate) model: Box<dyn ActuatorModel>,
    /// Its points in the stage's point set.
    range: Range<usize>,
    /// The effort now.
    effort: f64,
    /// Linearised at the points' current positions.
    lin: ActuatorLinearisation,
    command: ActuatorCommand,
}

/// An actuator the stage is built with: its plugin instance (created, not
/// yet initialised), rest geometry and gravity.
pub(crate) struct NewActuator {
    /// Name in metrics and messages.
    pub(crate) name: String,
    /// Its plugin's name.
    pub(crate) plugin: String,
    pub(crate) model: Box<dyn ActuatorModel>,
    pub(crate) geometry: RestGeometry,
    /// m/s², world axes.
    pub(crate) gravity: DVec3,
}

/// One effector of the stage.
pub(crate) struct Effector {
    pub(crate) name: String,
    /// Its point's index in the stage's point set.
    index: usize,
    targets: [Keyframes; 3],
}

/// The stage: actuators, effectors, their points bound on the model.
pub(crate) struct ActuationStage {
    actuators: Vec<Actuator>,
    effectors: Vec<Effector>,
    /// Every actuator's points, then every effector's, at rest (mm).
    rest: Vec<DVec3>,
    /// The same points now (mm).
    positions: Vec<DVec3>,
    binding: Option<BindingId>,
    report: ActuationReport,
    /// The inverse solve's trust region: per actuator, the largest
    /// effort change of one frame (`∞` until a step disappoints).
    trust: Vec<f64>,
    /// The last inverse step, to judge it by what the model did.
    last: Option<InverseStep>,
    /// The learned correction of the effectors' response.
    secant: Secant,
    /// Per actuator, the largest effort change an inverse step has made
    /// (the scale of its trust region's floor).
    largest_step: Vec<f64>,
    /// The forces applied in the last step (µN per point).
    applied: Vec<DVec3>,
    /// The last responses solved (`K⁻¹ J_aᵀ` per actuator, mm per unit
    /// effort at every stage point) and the inverse steps since.
    responses: Option<(Vec<Vec<DVec3>>, u32)>,
    /// The last inverse step got less than a quarter of the improvement
    /// it predicted: the next one solves its responses afresh.
    disappointed: bool,
    /// The settling warning was given.
    warned_unsettled: bool,
    /// How each frame settles (`[actuation]`).
    settle: ActuationSettings,
}

/// Past iterates the settling mixes ([`Anderson`]).
const ANDERSON_DEPTH: usize = 4;

/// The actuator forces may change by this fraction of their size over
/// the last frame before the run warns that the body has not settled.
pub const SETTLED_FORCE_CHANGE: f64 = 1e-2;

/// An error of the stage, naming what failed.
fn failed(what: &str, e: impl std::fmt::Display) -> ModelError {
    ModelError(format!("actuation: {what}: {e}"))
}

impl ActuationStage {
    /// The stage over `actuators` (initialised here) and effectors
    /// (`(name, rest point mm, targets)`).
    pub(crate) fn new(
        actuators: Vec<NewActuator>,
        effectors: Vec<(String, DVec3, [Keyframes; 3])>,
        settle: ActuationSettings,
    ) -> Result<Self, ModelError> {
        let mut rest = Vec::new();
        let mut stage_actuators = Vec::new();
        for NewActuator {
            name,
            plugin,
            mut model,
            geometry,
            gravity,
        } in actuators
        {
            model
                .init(ActuatorGeometry {
                    points: &geometry.points,
                    triangles: &geometry.triangles,
                    gravity_m_s2: gravity,
                })
                .map_err(|e| failed(&format!("[[actuator]] {name}"), e))?;
            let range = rest.len()..rest.len() + geometry.points.len();
            rest.extend(&geometry.points);
            stage_actuators.push(Actuator {
                name,
                plugin,
                model,
                range,
                effort: 0.0,
                lin: ActuatorLinearisation::default(),
                command: ActuatorCommand::Free,
            });
        }
        let effectors: Vec<Effector> = effectors
            .into_iter()
            .map(|(name, point, targets)| {
                rest.push(point);
                Effector {
                    name,
                    index: rest.len() - 1,
                    targets,
                }
            })
            .collect();
        let report = ActuationReport::new(&stage_actuators, &effectors_names(&effectors));
        let n_actuators = stage_actuators.len();
        Ok(Self {
            positions: rest.clone(),
            actuators: stage_actuators,
            effectors,
            rest,
            binding: None,
            report,
            trust: vec![f64::INFINITY; n_actuators],
            last: None,
            secant: Secant::default(),
            largest_step: vec![0.0; n_actuators],
            applied: Vec::new(),
            responses: None,
            disappointed: false,
            warned_unsettled: false,
            settle,
        })
    }

    /// Binds the points on `model` (again after a model swap) and
    /// linearises the actuators there. A model without the actuation
    /// capability is refused here, by name.
    pub(crate) fn bind(&mut self, model: &mut dyn DeformationModel) -> Result<(), ModelError> {
        let points: Vec<[f32; 3]> = self.rest.iter().map(|p| p.as_vec3().to_array()).collect();
        let binding = model
            .bind(RestPoints::Points(&points))
            .map_err(|e| failed("binding the actuator and effector points", e))?;
        let zero = vec![DVec3::ZERO; points.len()];
        model
            .set_point_loads(binding, &zero)
            .map_err(|e| failed("the scene's [model]", e))?;
        if !self.effectors.is_empty() {
            // Inverse control needs the compliance every frame: refuse a
            // model without it now, not at the first frame.
            model
                .compliance(binding, &zero, &mut zero.clone())
                .map_err(|e| failed("the scene's [model]", e))?;
        }
        self.secant = Secant::new(3 * self.effectors.len(), self.actuators.len());
        self.responses = None;
        self.binding = Some(binding);
        self.refresh(model)
    }

    /// Chooses the efforts of frame `frame` and applies their forces.
    pub(crate) fn before_step(
        &mut self,
        model: &mut dyn DeformationModel,
        frame: FrameInfo,
    ) -> Result<(), ModelError> {
        let binding = self.binding.ok_or_else(|| failed("step", "not bound"))?;
        for a in &mut self.actuators {
            a.command = a
                .model
                .command(frame)
                .map_err(|e| failed(&format!("[[actuator]] {}", a.name), e))?;
        }
        let known: Vec<Option<f64>> = self
            .actuators
            .iter()
            .map(|a| match a.command {
                ActuatorCommand::Effort(v) => Some(clamp(v, a.lin.effort_bounds)),
                _ => None,
            })
            .collect();
        let inverse = known.iter().any(Option::is_none);
        if inverse || !self.effectors.is_empty() {
            self.solve_inverse(model, binding, &known, frame)?;
        } else {
            for (a, k) in self.actuators.iter_mut().zip(&known) {
                a.effort = k.unwrap_or(a.effort);
            }
        }
        let mut forces = vec![DVec3::ZERO; self.rest.len()];
        for a in &self.actuators {
            let slot = &mut forces[a.range.clone()];
            for (i, f) in slot.iter_mut().enumerate() {
                *f += a.effort * a.lin.directions[i];
                if let Some(l) = a.lin.loads.get(i) {
                    *f += *l;
                }
            }
        }
        model
            .set_point_loads(binding, &forces)
            .map_err(|e| failed("applying the actuator forces", e))?;
        self.applied = forces;
        Ok(())
    }

    /// The forces the actuators would apply at the points' current
    /// positions with the current efforts (µN per point).
    fn forces_now(&self) -> Vec<DVec3> {
        let mut forces = vec![DVec3::ZERO; self.rest.len()];
        for a in &self.actuators {
            for (i, f) in forces[a.range.clone()].iter_mut().enumerate() {
                *f += a.effort * a.lin.directions[i]
                    + a.lin.loads.get(i).copied().unwrap_or_default();
            }
        }
        forces
    }

    /// How much the actuator forces changed over the last frame, relative
    /// to their size: they follow the walls they push, and a frame applies
    /// them as they were at its start, so a body that is still moving
    /// under its actuators has not reached the equilibrium of its efforts.
    fn force_change(&self) -> f64 {
        let now = self.forces_now();
        let size: f64 = self
            .applied
            .iter()
            .map(|f| f.length_squared())
            .sum::<f64>()
            .sqrt();
        let change: f64 = now
            .iter()
            .zip(&self.applied)
            .map(|(a, b)| (*a - *b).length_squared())
            .sum::<f64>()
            .sqrt();
        if size > 0.0 { change / size } else { 0.0 }
    }

    /// Reads the points back after the step and settles the follower
    /// forces: while the forces at the new shape differ from those applied
    /// by more than `[actuation] settle_tolerance`, they are applied again
    /// and the model repeats the frame's step (`resolve`), up to
    /// `settle_iterations` times. Then linearises at the settled shape
    /// and records the frame. Returns whether a repeated step moved the
    /// field.
    pub(crate) fn after_step(
        &mut self,
        model: &mut dyn DeformationModel,
        frame: FrameInfo,
    ) -> Result<bool, ModelError> {
        self.refresh(model)?;
        let binding = self.binding.ok_or_else(|| failed("settle", "not bound"))?;
        let mut moved = false;
        let mut iterations = 0;
        let mut mixing = Anderson::new(ANDERSON_DEPTH);
        while iterations < self.settle.settle_iterations
            && self.force_change() > self.settle.settle_tolerance
        {
            let forces = mixing.next(&self.applied, &self.forces_now());
            model
                .set_point_loads(binding, &forces)
                .map_err(|e| failed("applying the actuator forces", e))?;
            match model.resolve() {
                Ok(o) => moved |= o.changed,
                Err(e) => {
                    // The model keeps its last converged state: the frame
                    // ends unsettled, and says so.
                    self.report.settle_failures += 1;
                    tracing::warn!(
                        "actuation, frame {}: a repeated step to settle the actuator forces \
                         failed ({e}); the frame ends unsettled — ramp the efforts more slowly",
                        frame.frame
                    );
                    moved = true;
                    self.refresh(model)?;
                    break;
                }
            }
            self.applied = forces;
            self.refresh(model)?;
            iterations += 1;
        }
        self.report.settle_iterations.push(iterations);
        let coords = self.effector_coordinates();
        self.secant.observe(&coords);
        let offsets: Vec<(DVec3, DVec3)> = self
            .effectors
            .iter()
            .map(|e| (self.positions[e.index], target(e, frame.frame as f64)))
            .collect();
        let change = self.force_change();
        self.report.record(&self.actuators, &offsets, change);
        if frame.frame + 1 == frame.frames
            && change > SETTLED_FORCE_CHANGE
            && !self.warned_unsettled
        {
            self.warned_unsettled = true;
            tracing::warn!(
                "actuation: the actuator forces still changed by {:.1} % over the last frame \
                 (above {:.0} %): the body has not settled at its efforts (a pressure or a \
                 cable follows what it pushes, one frame behind); run more frames or ramp the \
                 efforts more slowly",
                100.0 * change,
                100.0 * SETTLED_FORCE_CHANGE
            );
        }
        Ok(moved)
    }

    /// What the stage did, for `metrics.json`.
    pub(crate) fn report(&mut self) -> Result<ActuationReport, ModelError> {
        let mut r = self.report.clone();
        r.secant_updates = self.secant.updates;
        for (a, series) in self.actuators.iter_mut().zip(&mut r.actuators) {
            series.notes = a
                .model
                .notes()
                .map_err(|e| failed(&format!("[[actuator]] {} notes", a.name), e))?;
        }
        Ok(r)
    }

    /// The points' positions from the model, and each actuator linearised
    /// there.
    fn refresh(&mut self, model: &mut dyn DeformationModel) -> Result<(), ModelError> {
        let binding = self.binding.ok_or_else(|| failed("refresh", "not bound"))?;
        let n = self.rest.len();
        let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
        model
            .map(
                binding,
                DisplacementTarget::Cpu {
                    x: &mut x,
                    y: &mut y,
                    z: &mut z,
                },
            )
            .map_err(|e| failed("reading the actuator points", e))?;
        for (i, p) in self.positions.iter_mut().enumerate() {
            *p = self.rest[i] + DVec3::new(x[i] as f64, y[i] as f64, z[i] as f64);
        }
        // The actuators are independent plugin instances: linearised side
        // by side, the pendulum's four cavities (each weighing a few short
        // parallel loops that leave the other core idle between them) take
        // this refresh from 8.8 to 7.9 ms.
        let positions = &self.positions;
        self.actuators.par_iter_mut().try_for_each(|a| {
            a.lin = a
                .model
                .linearise(&positions[a.range.clone()])
                .map_err(|e| failed(&format!("[[actuator]] {}", a.name), e))?;
            Ok(())
        })
    }
}

fn target(e: &Effector, frame: f64) -> DVec3 {
    DVec3::new(
        e.targets[0].at(frame),
        e.targets[1].at(frame),
        e.targets[2].at(frame),
    )
}

fn clamp(v: f64, bounds: [f64; 2]) -> f64 {
    v.max(bounds[0]).min(bounds[1])
}

fn effectors_names(e: &[Effector]) -> Vec<String> {
    e.iter().map(|e| e.name.clone()).collect()
}

impl Actuator {
    /// The effort now.
    pub(crate) fn effort(&self) -> f64 {
        self.effort
    }

    /// The measure at the points' current positions.
    pub(crate) fn measure(&self) -> f64 {
        self.lin.measure
    }
}

impl ActuatorSeries {
    /// An empty series for `a`.
    pub(crate) fn of(a: &Actuator) -> Self {
        Self {
            name: a.name.clone(),
            plugin: a.plugin.clone(),
            ..Self::default()
        }
    }
}

impl EffectorSeries {
    /// An empty series named `name`.
    pub(crate) fn named(name: &str) -> Self {
        Self {
            name: name.to_owned(),
            ..Self::default()
        }
    }
}
