//! # voxflex-cable — a cable actuator
//!
//! A cable threaded through a soft body and pulled through a fixed point,
//! after SoftRobots' CableConstraint (Coevoet et al.; used beside the
//! cavities of Rodríguez, Coevoet and Duriez, "Real-time simulation of
//! hydraulic components for interactive control of soft robots", ICRA
//! 2017).
//!
//! The cable runs from the fixed **pull point** `q` (`pull_point_mm`,
//! e.g. the finger's base; the body does not move it) through its points
//! on the body `p₀ … p_{n−1}`, in order, which the host binds to the
//! deformation model. Its length is `L = |p₀ − q| + Σ |p_{i+1} − pᵢ|`, its
//! **measure** the shortening from rest `m = L₀ − L` (mm), and a tension
//! `λ` (µN) pulls point `i` with `λ ∂m/∂xᵢ = −λ ∂L/∂pᵢ`: each segment
//! pulls its two ends towards each other along unit vectors ([`length`]).
//! On a straight cable every point but the last is pulled equally both
//! ways, and the last is pulled back along the cable. A zero-length
//! segment (two points at one place) pulls nothing rather than giving NaN.
//!
//! The script ([`params`]) gives the tension (`tension_uN`: the effort),
//! the shortening (`shortening_mm`: the measure, the tension found to
//! reach it) or neither (the inverse solve chooses the tension within
//! `[0, max_tension_uN]` — a cable only pulls — and the shortening up to
//! `max_shortening_mm`). The cable carries no loads.
//!
//! Units: positions and lengths mm, tensions and forces µN.
//!
//! Backend: the length and its gradient are a few operations per point, on
//! the CPU; the plugin declares [`CAPABILITY_CPU`].
//!
//! Scene usage:
//!
//! ```toml
//! [[actuator]]
//! plugin = "cable"
//! # … the host's keys: which points, bound to which model …
//! [actuator.params]
//! pull_point_mm = [0, 0, -5]             # required: fixed in space, world mm
//! tension_uN = [[0, 0], [100, 3e5]]      # [[frame, µN]] — or shortening_mm = [[frame, mm]]
//! max_tension_uN = 5e5                   # effort bounds [0, max] (default unbounded)
//! max_shortening_mm = 15                 # measure bounds [−∞, max] (default unbounded)
//! ```

#![warn(missing_docs)]

pub mod length;
pub mod model;
pub mod params;

pub use model::Cable;
pub use params::CableParams;

use voxflex_abi::ffi::CAPABILITY_CPU;
use voxflex_abi::{ActuatorPlugin, HostContext};
use voxflex_core::error::ModelError;

/// The parameter schema the host reads (`voxflex plugins --params
/// cable`), derived from the type `create` parses.
impl voxflex_abi::DeclaresParams for Cable {
    fn params_schema() -> Result<String, String> {
        voxflex_abi::params_schema::json(&schemars::schema_for!(CableParams))
    }
}

impl ActuatorPlugin for Cable {
    const NAME: &'static str = "cable";
    const DESCRIPTION: &'static str = "cable pulled through a fixed point: shortening and its gradient (SoftRobots' CableConstraint)";
    const CAPABILITIES: u32 = CAPABILITY_CPU;

    /// Parses and validates the parameter table: every error that does
    /// not need the points is given here, so `voxflex validate` reports it.
    fn create(params_toml: &str, _host: HostContext) -> Result<Self, ModelError> {
        let params = CableParams::from_toml(params_toml)?;
        tracing::debug!(?params, "cable plugin created");
        Ok(Self::new(params))
    }
}

voxflex_abi::export_actuator_plugin!(Cable);

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_abi::DeclaresParams;

    #[test]
    fn the_schema_declares_every_key_with_its_unit() {
        let schema = Cable::params_schema().unwrap();
        for key in [
            "pull_point_mm",
            "tension_uN",
            "shortening_mm",
            "max_tension_uN",
            "max_shortening_mm",
            "\"unit\":\"µN\"",
        ] {
            assert!(schema.contains(key), "{key} missing from {schema}");
        }
        assert!(
            !schema.contains("tension_un"),
            "the Rust field name leaked: {schema}"
        );
    }
}
