//! The corotational solves (Müller & Gross 2004): per element, the rotation
//! `R` of its deformation gradient; the stiffness warped to `R K Rᵀ`; the
//! elastic force `f_int = K_rot u − f0`, linear in `u` for fixed rotations.
//!
//! - **Quasi-static** (`solver = "static"`): the equilibrium
//!   `K_rot u = f_ext + f0`, re-linearised about the new rotations up to
//!   `static_iterations` times per frame (until the largest change is below
//!   `static_tolerance` mm).
//! - **Implicit backward Euler** (`solver = "dynamic"`), one linearisation
//!   per step of `h` seconds with lumped masses `M` and Rayleigh damping
//!   `D = α M + β K_rot`:
//!   `(M + h D + h² K_rot) v⁺ = M v + h (f_ext − f_int(u))`, `u⁺ = u + h v⁺`.
//!
//! Both assemble the warped stiffness into a [`BlockMatrix`] and solve with
//! block-Jacobi PCG, warm-started from the last answer.

use crate::element::Element;
use rayon::prelude::*;
use serde::Deserialize;
use std::sync::Arc;
use voxflex_core::error::ModelError;
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::gpu::GpuService;
use voxflex_core::mesh_model::pcg::{self, CgOutcome, CgSettings};
use voxflex_core::mesh_model::pcg_gpu::GpuPcg;
use voxflex_core::mesh_model::{
    BlockMatrix, Boundary, ElasticMaterial, MeshSolver, NodeState, SolveReport, lumped_masses,
};
use voxflex_core::tet_mesh::TetMesh;

/// Which solve runs each frame.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SolverKind {
    /// Equilibrium under the current loads and constraints.
    Static,
    /// Implicit backward-Euler time stepping.
    #[default]
    Dynamic,
}

/// The solver's keys of `[model.params.corotational-fem]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FemParams {
    /// `"dynamic"` (default) or `"static"`.
    #[serde(default)]
    pub solver: SolverKind,
    /// PCG stops at this relative residual (default 1e-6).
    #[serde(default = "pcg::default_tolerance")]
    pub cg_tolerance: f64,
    /// PCG iteration cap per solve (default 200).
    #[serde(default = "pcg::default_max_iterations")]
    pub cg_max_iterations: u32,
    /// Re-linearisations per frame of the static solve (default 8).
    #[serde(default = "default_static_iterations")]
    pub static_iterations: u32,
    /// The static solve stops re-linearising when no node moves more than
    /// this, mm (default 1e-6).
    #[serde(default = "default_static_tolerance")]
    pub static_tolerance: f64,
    /// Implicit steps per frame (default 1).
    #[serde(default = "one")]
    pub substeps: u32,
    /// Rayleigh mass damping α, 1/s (default 1).
    #[serde(default = "default_mass_damping")]
    pub mass_damping: f64,
    /// Rayleigh stiffness damping β, s (default 0.01).
    #[serde(default = "default_stiffness_damping")]
    pub stiffness_damping: f64,
}

fn default_static_iterations() -> u32 {
    8
}
fn default_static_tolerance() -> f64 {
    1e-6
}
fn one() -> u32 {
    1
}
fn default_mass_damping() -> f64 {
    1.0
}
fn default_stiffness_damping() -> f64 {
    0.01
}

impl Default for FemParams {
    fn default() -> Self {
        Self {
            solver: SolverKind::default(),
            cg_tolerance: pcg::default_tolerance(),
            cg_max_iterations: pcg::default_max_iterations(),
            static_iterations: default_static_iterations(),
            static_tolerance: default_static_tolerance(),
            substeps: one(),
            mass_damping: default_mass_damping(),
            stiffness_damping: default_stiffness_damping(),
        }
    }
}

impl FemParams {
    fn validate(&self) -> Result<(), ModelError> {
        let fail = |m: String| Err(ModelError(format!("corotational-fem params: {m}")));
        CgSettings::checked(self.cg_tolerance, self.cg_max_iterations)
            .map_err(|m| ModelError(format!("corotational-fem params: {m}")))?;
        if self.static_iterations == 0 || self.substeps == 0 {
            return fail("static_iterations and substeps must be ≥ 1".into());
        }
        if self.static_tolerance.is_nan() || self.static_tolerance <= 0.0 {
            return fail(format!(
                "static_tolerance {} must be > 0 (mm)",
                self.static_tolerance
            ));
        }
        let valid = |d: f64| d.is_finite() && d >= 0.0;
        if !valid(self.mass_damping) || !valid(self.stiffness_damping) {
            return fail("mass_damping and stiffness_damping must be finite and ≥ 0".into());
        }
        Ok(())
    }
}

/// The corotational FEM solver.
pub struct CorotationalFem {
    params: FemParams,
    elements: Vec<Element>,
    masses: Vec<f64>,
    matrix: BlockMatrix,
    /// Scratch: 16 warped blocks per element.
    blocks: Vec<DMat3>,
    /// Scratch: 4 force offsets per element, and summed per node.
    corner_f0: Vec<DVec3>,
    f0: Vec<DVec3>,
    /// The PCG's WGSL twin, on the GPU backend.
    gpu: Option<GpuPcg>,
}

impl CorotationalFem {
    /// Rotations from `u`, the warped stiffness assembled with `diagonal`
    /// on the diagonal blocks and scaled by `k_scale`, and `f0` per node.
    fn linearise(&mut self, u: &[DVec3], k_scale: f64, diagonal: Option<&[f64]>) {
        let elements = &self.elements;
        self.blocks
            .par_chunks_mut(16)
            .zip(self.corner_f0.par_chunks_mut(4))
            .zip(elements.par_iter())
            .with_min_len(256)
            .for_each(|((k, f0), e)| {
                let ue = e.nodes.map(|n| u[n as usize]);
                e.corotate(e.rotation(ue), k, f0);
                if k_scale != 1.0 {
                    for b in k.iter_mut() {
                        *b *= k_scale;
                    }
                }
            });
        self.matrix.assemble(&self.blocks, diagonal);
        self.matrix.sum_corners(&self.corner_f0, &mut self.f0);
    }

    /// Solves the assembled system on the GPU when there is one, else with
    /// the rayon PCG.
    fn solve(
        &self,
        bc: &Boundary,
        free: &[bool],
        rhs: &[DVec3],
        x: &mut [DVec3],
    ) -> Result<CgOutcome, ModelError> {
        match &self.gpu {
            Some(g) => g
                .solve(&self.matrix, free, &bc.hanging, rhs, x, self.settings())
                .map_err(|e| ModelError(format!("corotational-fem (GPU): {e}"))),
            None => Ok(pcg::solve(&self.matrix, bc, free, rhs, x, self.settings())),
        }
    }

    fn settings(&self) -> CgSettings {
        CgSettings {
            tolerance: self.params.cg_tolerance,
            max_iterations: self.params.cg_max_iterations,
        }
    }

    /// The elastic force on every node at displacements `u` (µN), each
    /// element rotated by its own `R(u)`: `Σ R K (Rᵀ x − X)`.
    pub fn elastic_forces(&self, u: &[DVec3]) -> Vec<DVec3> {
        let mut f = vec![DVec3::ZERO; u.len()];
        for e in &self.elements {
            let fe = e.elastic_force(e.nodes.map(|n| u[n as usize]));
            for (a, &n) in e.nodes.iter().enumerate() {
                f[n as usize] += fe[a];
            }
        }
        f
    }

    fn step_static(
        &mut self,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        let free: Vec<bool> = bc.constrained().iter().map(|c| !c).collect();
        let mut report = SolveReport {
            substeps: 1,
            ..SolveReport::default()
        };
        bc.impose(&mut state.u);
        for _ in 0..self.params.static_iterations {
            self.linearise(&state.u, 1.0, None);
            let rhs: Vec<DVec3> = bc
                .force
                .iter()
                .zip(&self.f0)
                .map(|(f, g)| *f + *g)
                .collect();
            let before = state.u.clone();
            let out = self.solve(bc, &free, &rhs, &mut state.u)?;
            report.iterations += out.iterations;
            report.residual = out.residual;
            let change = state
                .u
                .iter()
                .zip(&before)
                .map(|(a, b)| (*a - *b).abs().max_element())
                .fold(0.0, f64::max);
            if change <= self.params.static_tolerance {
                break;
            }
        }
        state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
        Ok(report)
    }

    fn step_dynamic(
        &mut self,
        dt: f64,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        let free: Vec<bool> = bc.constrained().iter().map(|c| !c).collect();
        let h = dt / self.params.substeps as f64;
        let (alpha, beta) = (self.params.mass_damping, self.params.stiffness_damping);
        let mut report = SolveReport::default();
        for s in 1..=self.params.substeps {
            // A = (1 + hα) M + (hβ + h²) K_rot.
            let diagonal: Vec<f64> = self.masses.iter().map(|m| (1.0 + h * alpha) * m).collect();
            self.linearise(&state.u, h * beta + h * h, Some(&diagonal));
            // f_int(u) = K_rot u − f0, with K_rot = A's stiffness part / (hβ + h²).
            let k_u = {
                let mut ku = vec![DVec3::ZERO; state.u.len()];
                self.matrix.mul(&state.u, &mut ku);
                let scale = 1.0 / (h * beta + h * h);
                ku.iter_mut()
                    .zip(&state.u)
                    .zip(&diagonal)
                    .for_each(|((k, u), d)| *k = (*k - *d * *u) * scale);
                ku
            };
            let rhs: Vec<DVec3> = (0..state.u.len())
                .map(|n| self.masses[n] * state.v[n] + h * (bc.force[n] - (k_u[n] - self.f0[n])))
                .collect();
            // Imposed velocities: fixed nodes stop, driven ones reach their
            // target (spread over the frame's sub-steps), hanging ones
            // follow their masters.
            let mut v = state.v.clone();
            for (n, f) in bc.fixed.iter().enumerate() {
                if *f {
                    v[n] = DVec3::ZERO;
                }
            }
            let remaining = (self.params.substeps - s + 1) as f64;
            for &(n, target) in &bc.driven {
                v[n as usize] = (target - state.u[n as usize]) / (h * remaining);
            }
            let out = self.solve(bc, &free, &rhs, &mut v)?;
            report.iterations += out.iterations;
            report.residual = out.residual;
            for (u, vn) in state.u.iter_mut().zip(&v) {
                *u += h * *vn;
            }
            state.v = v;
            report.substeps += 1;
        }
        bc.impose(&mut state.u);
        Ok(report)
    }
}

impl MeshSolver for CorotationalFem {
    const NAME: &'static str = "corotational-fem";
    const DESCRIPTION: &'static str =
        "corotational linear FEM on a tetrahedral proxy (static or implicit backward Euler, PCG)";
    type Params = FemParams;

    const GPU: bool = true;

    fn use_gpu(&mut self, gpu: Arc<dyn GpuService>) -> Result<(), ModelError> {
        self.gpu = Some(
            GpuPcg::new(gpu, &self.matrix)
                .map_err(|e| ModelError(format!("corotational-fem (GPU): {e}")))?,
        );
        Ok(())
    }

    fn new(
        mesh: &TetMesh,
        materials: &[ElasticMaterial],
        params: FemParams,
    ) -> Result<Self, ModelError> {
        params.validate()?;
        let elements: Vec<Element> = (0..mesh.tets.len())
            .map(|t| Element::new(mesh, t, &materials[mesh.labels[t] as usize]))
            .collect();
        let n = mesh.nodes.len();
        Ok(Self {
            matrix: BlockMatrix::on_mesh(mesh),
            masses: lumped_masses(mesh, materials),
            blocks: vec![DMat3::ZERO; 16 * elements.len()],
            corner_f0: vec![DVec3::ZERO; 4 * elements.len()],
            f0: vec![DVec3::ZERO; n],
            gpu: None,
            elements,
            params,
        })
    }

    fn step(
        &mut self,
        dt_s: f64,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        match self.params.solver {
            SolverKind::Static => self.step_static(bc, state),
            SolverKind::Dynamic => {
                if !(dt_s > 0.0 && dt_s.is_finite()) {
                    return Err(ModelError(format!(
                        "corotational-fem: the dynamic solver needs a positive frame time step \
                         (got {dt_s} s); set the scene's time step or use solver = \"static\""
                    )));
                }
                self.step_dynamic(dt_s, bc, state)
            }
        }
    }
}
