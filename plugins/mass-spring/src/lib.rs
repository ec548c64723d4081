//! # voxflex-mass-spring — a mass-spring model on a tetrahedral proxy
//!
//! Springs on the proxy's edges with stiffness from Young's modulus and the
//! tetrahedra's volumes, lumped masses, spring and mass damping; a
//! linearised backward-Euler step solved by PCG (the default), or explicit
//! symplectic Euler sub-stepped below the stability limit (see [`solver`]).
//!
//! Everything but the solver — the proxy, materials, boundary conditions,
//! interactions, binding and map — is [`voxflex_mesh::mesh_model`]'s, so a
//! scene swaps between this plugin and `corotational-fem` with one line.
//!
//! Scene usage:
//!
//! ```toml
//! [model]
//! plugin = "mass-spring"
//! [model.params.mass-spring]
//! proxy = { kind = "uniform", step = 3 }   # the default
//! materials = [{ name = "soft tissue", range = [-50, 300], youngs_modulus = 3000 }]
//! integrator = "implicit"   # the default; or "explicit"
//! damping_ratio = 0.1
//! ```

#![warn(missing_docs)]

mod gpu;
#[cfg(test)]
mod gpu_tests;
mod kernel;
pub mod solver;
#[cfg(test)]
mod tests;

pub use solver::{Integrator, MassSpring, SpringParams};

voxflex_abi::export_deformation_plugin!(voxflex_mesh::mesh_model::MeshModel<MassSpring>);
