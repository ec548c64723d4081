//! # voxflex-abi
//!
//! The checked C ABI between the voxflex host and its plugins.
//!
//! Rust has no stable ABI, so only `#[repr(C)]` data ([`ffi`]) and
//! `extern "C"` functions cross the boundary. Each plugin library exports
//! one symbol, `voxflex_plugin_v1`, returning a [`ffi::PluginHeader`] whose
//! frozen layout carries [`ABI_VERSION`] and [`LAYOUT_HASH`]; the host
//! refuses a plugin whose version or hash differs from its own.
//!
//! - Plugin authors: implement [`plugin::DeformationPlugin`] and write
//!   `voxflex_abi::export_deformation_plugin!(MyModel);`.
//! - The host: [`host_side::HostServices`] builds the [`ffi::HostApi`]
//!   table (logging, threads, GPU service) and
//!   [`host_side::DeformationProxy`] turns a plugin back into a
//!   `voxflex_core::deformation::DeformationModel`.

#![warn(missing_docs)]

pub mod actuator;
pub mod convert;
pub mod ffi;
pub mod guard;
pub mod host_side;
pub mod layout;
pub mod log_bridge;
pub mod notes_text;
pub mod params_schema;
pub mod plugin;
pub mod renderer;

/// Version of the boundary. Bump on any change to a function signature or
/// to the meaning of a field; the layout hash catches layout changes.
pub const ABI_VERSION: u32 = 4;

/// Fingerprint of every `#[repr(C)]` boundary type (see [`layout`]).
pub const LAYOUT_HASH: u64 = layout::compute();

/// Name of the symbol every plugin library exports.
pub const ENTRY_SYMBOL: &str = "voxflex_plugin_v1";

pub use actuator::ActuatorPlugin;
pub use params_schema::DeclaresParams;
pub use plugin::{DeformationPlugin, HostContext};
pub use renderer::RendererPlugin;
