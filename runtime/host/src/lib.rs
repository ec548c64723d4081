//! # voxflex-runtime — the host
//!
//! Plugin discovery and checked loading ([`plugin_loader`]), scene files
//! ([`scene`]), the interactive pipeline object ([`session`]), backend selection ([`backend`]) and the wgpu GPU context
//! ([`gpu_context`], the only place voxflex links wgpu), the scene pipeline
//! with versioned, dirty-region stages ([`pipeline`]), the checks of
//! `voxflex validate` ([`preflight`]), run reports ([`metrics`]), the
//! up-to-date check ([`fingerprint`]), the output directory's path rules
//! and lock ([`out_dir`]) and the `voxflex bench` measurements
//! ([`mod@bench`]).

#![warn(missing_docs)]

pub mod actuation;
pub mod backend;
pub mod bench;
pub mod fingerprint;
pub mod gpu_context;
pub mod metrics;
pub mod out_dir;
pub mod param_schema;
pub mod pipeline;
pub mod plugin_loader;
pub mod preflight;
pub mod scene;
pub mod session;
pub mod visualise;
pub mod warnings;
