//! # voxflex-corotational-fem — corotational linear FEM on a tetrahedral proxy
//!
//! Linear tetrahedra with the corotational formulation of Müller & Gross
//! (2004): each element's rotation `R` is taken from its deformation
//! gradient (`F = U Σ Vᵀ` with the sign fix of Irving et al. 2004, so
//! inverted elements recover), the stiffness is warped to `R K Rᵀ`, and a
//! frame is either a quasi-static equilibrium or implicit backward-Euler
//! steps, both solved by block-Jacobi preconditioned conjugate gradients
//! on an assembled block-sparse matrix, warm-started.
//!
//! `element = "p2"` runs 10-node quadratic tetrahedra instead
//! ([`quadratic`]: a rotation per Gauss point, so the force stays an
//! energy's gradient) on the proxy's corners plus one node per edge, which
//! the solver owns ([`edge_nodes`]: boundary conditions, loads and masses
//! moved onto them; the model's map adds their quadratic part). [`front`]
//! measures P1 against P2 on issue 12's slender cantilever.
//!
//! Everything but the solver — the proxy, materials, boundary conditions,
//! interactions, binding and map — is [`voxflex_mesh::mesh_model`]'s.
//!
//! Scene usage:
//!
//! ```toml
//! [model]
//! plugin = "corotational-fem"
//! [model.params.corotational-fem]
//! proxy = { kind = "uniform", step = 3 }   # the P1 default; or { kind = "octree", max_cell = 8 }, { kind = "file", path = "m.msh" }
//! materials = [
//!   { name = "soft tissue", range = [-50, 300], youngs_modulus = 3000, poisson_ratio = 0.45 },
//!   { name = "bone", range = [300, 4000], youngs_modulus = 1e7, poisson_ratio = 0.3, density = 1900 },
//! ]
//! solver = "dynamic"       # or "static"
//! element = "p1"           # or "p2" (10-node quadratic tetrahedra; without a `proxy` key on cells of 8)
//! cg_tolerance = 1e-6
//! ```

#![warn(missing_docs)]

#[cfg(test)]
mod actuation_tests;
#[cfg(test)]
mod amg_tests;
#[cfg(test)]
mod convergence_tests;
pub mod edge_nodes;
pub mod element;
#[cfg(test)]
mod element_checks;
pub mod front;
#[cfg(test)]
mod gpu_tests;
#[cfg(test)]
mod p2_tests;
pub mod polar;
pub mod quadratic;
pub mod solver;
#[cfg(test)]
mod tests;

pub use solver::{
    AMG_AUTO_NODES, AMG_AUTO_NODES_P2, AmgStats, CorotationalFem, ElementKind, FemParams,
    PreconditionerKind, SolverKind, StaticStats,
};

voxflex_abi::export_deformation_plugin!(voxflex_mesh::mesh_model::MeshModel<CorotationalFem>);
