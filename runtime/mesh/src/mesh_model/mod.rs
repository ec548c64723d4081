//! What every mesh-based deformation model shares, so that a plugin such as
//! `mass-spring` or `corotational-fem` is only its solver.
//!
//! [`MeshModel<S>`] is the whole [`crate::deformation::DeformationModel`]:
//! it builds the tetrahedral proxy from the scene (a uniform or octree
//! proxy of the volume, or a mesh file; [`params`]), gives each tetrahedron
//! its material, binds rest points barycentrically, turns the scene's
//! interactions into boundary conditions ([`boundary`]: fixed nodes, grabs
//! along paths, loads ramped in, gravity), calls the solver once per frame,
//! maps, and exports the deformed proxy as `.vtu`. A solver implements
//! [`MeshSolver`]: one step from the boundary conditions.
//!
//! Frames: node indices are the proxy's; positions and displacements in
//! world millimetres; forces in µN (mm-g-s units; stresses in Pa).

pub mod amg;
pub mod block_matrix;
pub mod boundary;
#[cfg(any(test, feature = "test-support"))]
pub mod cantilever;
pub mod carve;
pub mod cut;
pub mod edge_layer;
pub mod elastica;
pub mod ichol;
pub mod inversion;
pub mod material;
mod model;
pub mod params;
#[cfg(any(test, feature = "test-support"))]
pub mod parity;
pub mod pcg;
pub mod pcg_gpu;
pub mod pieces;
#[cfg(any(test, feature = "test-support"))]
pub mod small_features;

pub use block_matrix::BlockMatrix;
pub use boundary::Boundary;
pub use edge_layer::EdgeLayer;
pub use material::{ElasticMaterial, lumped_masses};
pub use model::MeshModel;
pub use params::{MaterialSpec, MeshModelParams, ProxySpec};
pub use pcg::{CgOutcome, CgSettings};

use crate::deformation::ModelNotes;
#[cfg(any(test, feature = "test-support"))]
use crate::error::GpuError;
use crate::error::ModelError;
use crate::gpu::GpuService;
#[cfg(any(test, feature = "test-support"))]
use crate::gpu::{BufferId, GpuServiceExt};
use crate::tet_mesh::TetMesh;
use glam::DVec3;
use std::sync::Arc;

/// The nodes' state: displacement (mm) and velocity (mm/s) per node.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodeState {
    /// Displacement from the rest position, mm.
    pub u: Vec<DVec3>,
    /// Velocity, mm/s (dynamic solvers).
    pub v: Vec<DVec3>,
}

impl NodeState {
    /// At rest: every node at zero displacement and velocity.
    pub fn at_rest(nodes: usize) -> Self {
        Self {
            u: vec![DVec3::ZERO; nodes],
            v: vec![DVec3::ZERO; nodes],
        }
    }
}

#[cfg(any(test, feature = "test-support"))]
/// The largest displacement of `a` and the largest difference between
/// `a` and `b` (mm): how parity and accuracy tests compare two fields.
pub fn largest_and_difference(a: &[DVec3], b: &[DVec3]) -> (f64, f64) {
    let largest = a.iter().map(|u| u.length()).fold(0.0, f64::max);
    let worst = a
        .iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f64::max);
    (largest, worst)
}

#[cfg(any(test, feature = "test-support"))]
/// The largest difference between the device arrays `bufs` (x, y, z; f32)
/// and `want` (mm): how GPU parity tests compare a map into device buffers.
pub fn device_difference(
    gpu: &dyn GpuService,
    bufs: [BufferId; 3],
    want: [&[f32]; 3],
) -> Result<f32, GpuError> {
    let mut worst = 0f32;
    for (buf, want) in bufs.into_iter().zip(want) {
        let mut got = vec![0f32; want.len()];
        gpu.download(buf, &mut got)?;
        worst = got
            .iter()
            .zip(want)
            .map(|(g, w)| (g - w).abs())
            .fold(worst, f32::max);
    }
    Ok(worst)
}

/// What a solver's step did, for metrics and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SolveReport {
    /// Explicit sub-steps taken (1 for implicit and static solves).
    pub substeps: u32,
    /// Linear-solver iterations, summed over the step.
    pub iterations: u32,
    /// Relative residual of the last linear solve (0 for explicit steps).
    pub residual: f64,
    /// The largest relative residual of the step's linear solves.
    pub worst_residual: f64,
    /// Linear solves of the step that stopped above their tolerance.
    pub unconverged: u32,
}

impl SolveReport {
    /// Counts one linear solve: its iterations, residual, and whether it
    /// converged (`converged`, see [`pcg::warn_unconverged`]).
    pub fn add_solve(&mut self, out: CgOutcome, converged: bool) {
        self.iterations += out.iterations;
        self.residual = out.residual;
        self.worst_residual = self.worst_residual.max(out.residual);
        self.unconverged += u32::from(!converged);
    }
}

/// A deformation solver on a tetrahedral proxy: the only part a mesh-based
/// plugin writes.
pub trait MeshSolver: Send + Sized + 'static {
    /// The plugin's name (`plugin = "…"`, `[model.params.<name>]`).
    const NAME: &'static str;
    /// One line for `voxflex plugins`.
    const DESCRIPTION: &'static str;
    /// The solver's own keys of the plugin's table (everything but
    /// [`MeshModelParams`]'s), refusing unknown keys.
    type Params: serde::de::DeserializeOwned + schemars::JsonSchema + Clone + Send;

    /// Builds the solver for `mesh` (rest configuration, world mm), whose
    /// tetrahedron `t` has material `materials[mesh.labels[t]]`.
    fn new(
        mesh: &TetMesh,
        materials: &[ElasticMaterial],
        params: Self::Params,
    ) -> Result<Self, ModelError>;

    /// The default spacing between the solver's nodes, voxels: each
    /// solver's own, at the knee of its combined run-time/error front
    /// (`voxflex bench --fronts`, docs/BENCHMARKS.md).
    const DEFAULT_NODE_SPACING: usize;

    /// The proxy of a scene that names none (no `proxy` key), given the
    /// solver's keys; by default uniform cells of
    /// [`MeshSolver::DEFAULT_NODE_SPACING`] voxels. A solver whose
    /// elements add nodes inside a cell (quadratic elements) returns
    /// larger cells with the same node spacing.
    fn default_proxy(params: &Self::Params) -> ProxySpec {
        let _ = params;
        ProxySpec::Uniform {
            step: Self::DEFAULT_NODE_SPACING,
        }
    }

    /// True when [`MeshSolver::use_gpu`] can move the solver onto a GPU.
    const GPU: bool = false;

    /// Appended to the warning about tetrahedra that stay inverted
    /// ([`inversion::InversionWatch`]): what in this solver's keys to
    /// change (empty by default).
    const INVERSION_HINT: &'static str = "";

    /// Moves the solver's steps onto `gpu` (its WGSL twins); the default
    /// refuses. Called again after a cut rebuilds the solver.
    fn use_gpu(&mut self, gpu: Arc<dyn GpuService>) -> Result<(), ModelError> {
        let _ = gpu;
        Err(ModelError(format!(
            "{}: no GPU path; use backend = \"cpu\" (or \"auto\")",
            Self::NAME
        )))
    }

    /// The mid-edge layer of a solver with quadratic elements, which `map`
    /// adds to the corners' linear interpolation ([`EdgeLayer`]); `None`
    /// (the default) for linear elements.
    fn edge_layer(&self) -> Option<EdgeLayer<'_>> {
        None
    }

    /// Adds the solver's own figures to the model's notes (→
    /// `metrics.json`); the default adds none.
    fn notes(&self, notes: &mut ModelNotes) {
        let _ = notes;
    }

    /// The compliance `K⁻¹ f` at `state` with the tangent stiffness `K`
    /// and `bc`'s constraints (imposed and hanging nodes do not move):
    /// node displacements (mm) under node forces `forces` (µN, one per
    /// model node), and the linear solve's report. The actuators' inverse
    /// solve asks for it; the state does not change. The default refuses.
    fn compliance(
        &mut self,
        bc: &Boundary,
        state: &NodeState,
        forces: &[DVec3],
    ) -> Result<(Vec<DVec3>, SolveReport), ModelError> {
        let _ = (bc, state, forces);
        Err(ModelError(format!(
            "{}: no compliance solve, so it cannot drive an actuator to an effector target \
             (inverse control) or to a scripted measure (volume, shortening); script the \
             effort (pressure, tension) or use corotational-fem",
            Self::NAME
        )))
    }

    /// True when a step finds an equilibrium that does not depend on the
    /// state it starts from (a static solve of an elastic body), so a
    /// repeated step ([`MeshModel::resolve`]) may start warm from the last
    /// answer instead of the frame's start. False (the default) for time
    /// stepping, whose step depends on where it starts.
    fn is_static(&self) -> bool {
        false
    }

    /// Advances `state` by `dt_s` seconds under `bc` (a static solver finds
    /// the equilibrium instead). On return the imposed displacements of
    /// `bc` hold exactly and every value is finite.
    fn step(
        &mut self,
        dt_s: f64,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError>;
}
