//! # voxflex-template — the plugin a new deformation model starts from
//!
//! A real, minimal deformation plugin: a smooth radial bulge inside a ball,
//! ramped in over a few frames, with a rayon CPU path and a WGSL GPU path
//! that agree to rounding. Copy it with
//!
//! ```sh
//! scripts/new-plugin.sh my-model     # → plugins/my-model, shaders/my-model
//! ```
//!
//! which renames the crate, the library and the plugin and adds the crate
//! to the workspace; then change what the `STEP` comments point at
//! (docs/PLUGINS.md walks through them):
//!
//! 1. `Cargo.toml` — the crate name (`voxflex-<name>`) decides the library
//!    file, `libvoxflex_<name>.so`, that the host looks for.
//! 2. [`params`] — the `[model.params]` keys, parsed and validated.
//! 3. [`field`] — what moves where: one displacement function (CPU).
//! 4. [`model`] — the [`DeformationModel`](voxflex_core::deformation::DeformationModel)
//!    impl: init, bind, interact, step, dirty region, map (rayon and GPU).
//! 5. `shaders/template/bulge.wgsl` — the WGSL twin of step 3.
//! 6. Below — the parameter schema the host reads (derived from step 2).
//! 7. Below — the name, description and capabilities the host lists
//!    (`voxflex plugins`), `create`, and the one export line.
//! 8. `tests/tests/template_plugin.rs` — load the built `.so` through the
//!    runtime, run a scene, and hold the GPU path to the CPU path.
//!
//! Scene usage:
//!
//! ```toml
//! [model]
//! plugin = "template"
//! [model.params]
//! radius_mm = 30       # ball around `centre` (default: the volume centre)
//! amplitude_mm = 10    # negative: a dent
//! ramp_frames = 5
//! ```

#![warn(missing_docs)]

pub mod field;
pub mod model;
pub mod params;

pub use model::TemplateField;
pub use params::TemplateParams;

use voxflex_abi::ffi::{CAPABILITY_CPU, CAPABILITY_GPU};
use voxflex_abi::{DeformationPlugin, HostContext};
use voxflex_core::error::ModelError;

// STEP 6: the parameter schema the host reads (`voxflex plugins --params
// template`, `voxflex validate`, the viewer's form): derived from the very
// type `create` parses, so it cannot drift. Units and ranges are the
// `#[schemars(...)]` attributes on its fields (step 2).
impl voxflex_abi::DeclaresParams for TemplateField {
    fn params_schema() -> Result<String, String> {
        voxflex_abi::params_schema::json(&schemars::schema_for!(TemplateParams))
    }
}

// STEP 7: how the host sees the plugin. `NAME` is what a scene writes in
// `plugin = "…"` and must match the library file (`libvoxflex_<NAME with
// - as _>.so`); `CAPABILITIES` says which backends `map` supports (drop
// `CAPABILITY_GPU` for a CPU-only model: the host then refuses
// `backend = "gpu"` and runs it on the CPU under "auto").
impl DeformationPlugin for TemplateField {
    const NAME: &'static str = "template";
    const DESCRIPTION: &'static str =
        "radial bulge in a ball: the plugin template (copy with scripts/new-plugin.sh)";
    const CAPABILITIES: u32 = CAPABILITY_CPU | CAPABILITY_GPU;

    /// Parses and validates the parameter table: every error that does
    /// not need the volume is given here, so `voxflex validate` reports it.
    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError> {
        let params = TemplateParams::from_toml(params_toml)?;
        tracing::debug!(?params, "template plugin created");
        Ok(Self::new(params, host.gpu()))
    }
}

// The one line that makes this crate a plugin: it exports
// `voxflex_plugin_v1` with the ABI version and layout hash the host checks.
voxflex_abi::export_deformation_plugin!(TemplateField);

#[cfg(test)]
mod shader_tests;
