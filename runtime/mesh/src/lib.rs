//! # voxflex-mesh
//!
//! The mesh-model framework: tetrahedral proxies generated from a volume
//! ([`proxy`]), barycentric binding of rest points to a proxy
//! ([`barycentric`]), closed surfaces of label regions
//! ([`label_surface`], an actuator's cavity), and [`mesh_model::MeshModel<S>`], the whole
//! deformation model around a [`mesh_model::MeshSolver`] (boundary
//! conditions, PCG/AMG/incomplete-Cholesky solvers, cuts, carving, mesh
//! files) — with its plugin implementation, so a plugin crate that
//! implements `MeshSolver` exports `MeshModel<S>` with
//! `voxflex_abi::export_deformation_plugin!`.
//!
//! Its own crate, above voxflex-abi, because only the mesh-based plugins
//! (mass-spring, corotational FEM) and the host use it: the ABI depends on
//! voxflex-core alone, and ChainMail, affine and the renderer do not
//! recompile when a solver changes.
//!
//! Cargo feature `test-support` (off in release builds): the cantilever
//! and small-feature fixtures, the CPU/GPU parity checks of the binding,
//! and the field comparisons the plugins' parity tests share.

#![warn(missing_docs)]

pub mod barycentric;
pub mod label_surface;
pub mod mesh_model;
mod plugin;
pub mod proxy;

// The voxflex-core modules this crate builds on, imported at the root so
// `crate::grid`, `crate::tet_mesh`, ... read as they did when the
// framework was a module of voxflex-core.
use voxflex_core::{cut_polygon, deformation, error, gpu, grid, interaction, tet_mesh, volume};
