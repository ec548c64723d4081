//! # voxflex-cavity — a pneumatic or hydraulic cavity actuator
//!
//! A fluid-filled cavity in a soft body, after SoftRobots'
//! SurfacePressureConstraint and Rodríguez, Coevoet and Duriez,
//! "Real-time simulation of hydraulic components for interactive control
//! of soft robots" (ICRA 2017).
//!
//! The cavity is the closed triangle surface of its fluid (normals out),
//! whose vertices the host binds to the deformation model. Its **measure**
//! is the enclosed volume's growth from rest, `m = V(x) − V₀` (mm³); a
//! pressure `λ` (Pa = µN/mm²) pushes vertex `i` with `λ ∂V/∂xᵢ`, where
//! `∂V/∂xᵢ = Σ_t S_t n_t / 3` over the triangles around it (area × unit
//! normal / 3, mm²) — the paper's `J_aᵀ λ` ([`model`]).
//!
//! `fluid = "air"` (pneumatic) neglects the fluid's weight. `fluid =
//! "water"` (hydraulic, incompressible, ρ = 1000 kg/m³ unless
//! `density_kg_m3` says otherwise) also weighs the fluid every frame on
//! the paper's grid of vertical columns (`voxflex-fluid`): the loads
//! `w_i ĝ` (µN) on the floor's vertices, and how they grow per mm³ pumped
//! in, `w_i ĝ / v` — the paper's `J_w`, which the host folds into the
//! unified hydraulic constraint ([`fluid_load`]).
//!
//! The script ([`params`]) gives the pressure (`pressure_pa`: the effort),
//! the volume (`volume_mm3`: the measure, the pressure found to reach it)
//! or neither (the inverse solve chooses the pressure within
//! `[0, max_pressure_pa]` and the volume within `volume_growth_mm3`).
//!
//! Units: positions mm, volumes mm³, pressures Pa (µN/mm²), forces µN,
//! density kg/m³, gravity m/s² (the scene's, world axes).
//!
//! Backend: the weighing runs where the scene computes — rayon on the CPU,
//! or the WGSL kernels of `voxflex_fluid::gpu` on the host's device when
//! the scene's backend resolves to `gpu` (the host then offers the plugin
//! its GPU service). Both give the same weights within f32 rounding (the
//! parity tests hold them to 1e-5 of the largest vertex weight); the
//! metrics note `weighed_on_gpu` says which ran.
//!
//! Scene usage:
//!
//! ```toml
//! [[actuator]]
//! plugin = "cavity"
//! # … the host's keys: which surface, bound to which model …
//! [actuator.params]
//! fluid = "water"                        # "air" (default) or "water"
//! density_kg_m3 = 1000                   # water only (default 1000)
//! columns_per_side = 200                 # water only: the weighing grid (default 200)
//! leverage_alpha = 0.25                  # water only: parallel leveraging α (default 0.25)
//! pressure_pa = [[0, 0], [100, 30000]]   # [[frame, Pa]] — or volume_mm3 = [[frame, mm³]]
//! max_pressure_pa = 50000                # effort bounds [0, max] (default unbounded)
//! volume_growth_mm3 = [-500, 5000]       # measure bounds (default unbounded)
//! ```

#![warn(missing_docs)]

pub mod fluid_load;
pub mod model;
pub mod params;

pub use model::Cavity;
pub use params::{CavityParams, Fluid};

use voxflex_abi::ffi::{CAPABILITY_CPU, CAPABILITY_GPU};
use voxflex_abi::{ActuatorPlugin, HostContext};
use voxflex_core::error::ModelError;

/// The parameter schema the host reads (`voxflex plugins --params
/// cavity`), derived from the type `create` parses.
impl voxflex_abi::DeclaresParams for Cavity {
    fn params_schema() -> Result<String, String> {
        voxflex_abi::params_schema::json(&schemars::schema_for!(CavityParams))
    }
}

impl ActuatorPlugin for Cavity {
    const NAME: &'static str = "cavity";
    const DESCRIPTION: &'static str = "pneumatic or hydraulic cavity: volume growth, pressure \
         Jacobian and the fluid's weight (SoftRobots' SurfacePressureConstraint, ICRA 2017)";
    const CAPABILITIES: u32 = CAPABILITY_CPU | CAPABILITY_GPU;

    /// Parses and validates the parameter table: every error that does
    /// not need the surface is given here, so `voxflex validate` reports it.
    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError> {
        let params = CavityParams::from_toml(params_toml)?;
        let gpu = host.gpu();
        tracing::debug!(?params, on_gpu = gpu.is_some(), "cavity plugin created");
        Ok(Self::on(params, gpu))
    }
}

voxflex_abi::export_actuator_plugin!(Cavity);

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_abi::DeclaresParams;

    #[test]
    fn the_schema_declares_every_key_with_its_unit() {
        let schema = Cavity::params_schema().unwrap();
        for key in [
            "fluid",
            "density_kg_m3",
            "columns_per_side",
            "leverage_alpha",
            "pressure_pa",
            "volume_mm3",
            "max_pressure_pa",
            "volume_growth_mm3",
            "\"unit\":\"Pa\"",
            "\"water\"",
        ] {
            assert!(schema.contains(key), "{key} missing from {schema}");
        }
    }
}
