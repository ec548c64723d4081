//! Soft-robot actuation (issue 16): `[[actuator]]` plugins (pneumatic and
//! hydraulic cavities, cables) acting on the scene's deformation model,
//! driven directly by their scripts or by inverse control towards
//! `[[effector]]` targets (Rodríguez, Coevoet, Duriez, ICRA 2017; Coevoet
//! et al.'s SoftRobots inverse framework).
//!
//! - [`settings`]: the scene tables.
//! - [`geometry`]: what each actuator acts on, at rest.
//! - [`inverse`]: one frame's inverse QP (clarabel).
//! - `stage`: the per-frame stage the session runs around the model step.
//! - [`report`]: what goes into `metrics.json`.
//!
//! **Where the inverse QP lives, and why (docs/DESIGN.md, "Actuators"):**
//! in the host. It couples every actuator and effector of a scene, and
//! the actuators are separate plugins (a finger may have a cavity and a
//! cable); the host is the one place that sees them all and the model.

mod anderson;
pub mod geometry;
pub mod inverse;
pub mod report;
mod secant;
pub mod settings;
pub(crate) mod stage;

pub use report::ActuationReport;
pub use settings::{ActuationSettings, ActuatorSettings, CavitySource, EffectorSettings};
