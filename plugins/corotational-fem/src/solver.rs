//! The corotational solves (Müller & Gross 2004): per element, the rotation
//! `R` of its deformation gradient; the stiffness warped to `R K Rᵀ`; the
//! elastic force `f_int = K_rot u − f0`, linear in `u` for fixed rotations.
//!
//! - **Quasi-static** (`solver = "static"`): the equilibrium
//!   `f_int(u) = f_ext` by Newton iterations with the warped stiffness
//!   `K_rot` as tangent and a backtracking line search on the force
//!   residual, load-stepped when a whole frame's step does not converge;
//!   converged when the force residual is below `static_tolerance` of the
//!   force scale, and an error (not a wrong answer) when it cannot be.
//! - **Implicit backward Euler** (`solver = "dynamic"`), one linearisation
//!   per step of `h` seconds with lumped masses `M` and Rayleigh damping
//!   `D = α M + β K_rot`:
//!   `(M + h D + h² K_rot) v⁺ = M v + h (f_ext − f_int(u))`, `u⁺ = u + h v⁺`.
//!
//! Both assemble the warped stiffness into a [`BlockMatrix`] and solve with
//! PCG (incomplete Cholesky for the static solves, block Jacobi for the
//! implicit steps and on the GPU, by default), warm-started from the last
//! answer; a linear solve that stops above `cg_tolerance` warns and is
//! counted in the model's notes.

use crate::element::Element;
use rayon::prelude::*;
use serde::Deserialize;
use std::sync::Arc;
use voxflex_core::deformation::ModelNotes;
use voxflex_core::error::ModelError;
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::gpu::GpuService;
use voxflex_core::mesh_model::pcg::{self, CgOutcome, CgSettings, Preconditioner};
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

/// The PCG's preconditioner (`preconditioner = "…"`).
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum PreconditionerKind {
    /// Incomplete Cholesky for the static solver (bending-dominated, where
    /// block Jacobi needs about twice the iterations), block Jacobi for the
    /// implicit steps (mass-dominated, where it converges in tens and
    /// costs no factorisation) and on the GPU.
    #[default]
    Auto,
    /// IC(0) on the block pattern (CPU only).
    IncompleteCholesky,
    /// Each node's 3 × 3 diagonal block inverted (CPU and GPU).
    BlockJacobi,
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
    /// PCG iteration cap per solve; `None` (the default) derives it from
    /// the problem size ([`pcg::size_cap`]).
    #[serde(default)]
    pub cg_max_iterations: Option<u32>,
    /// The PCG's preconditioner (default `"auto"`).
    #[serde(default)]
    pub preconditioner: PreconditionerKind,
    /// Newton iterations per load step of the static solve (default 25).
    #[serde(default = "default_static_iterations")]
    pub static_iterations: u32,
    /// The static solve has converged when the force residual
    /// `|f_ext − f_int(u)|` on the free nodes is at most this fraction of
    /// the force scale (the largest of `|f_ext|` there, `|f_int(u)|` over
    /// all nodes, reactions included, and the residual the load step
    /// started from) (default 1e-6).
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
    25
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
            cg_max_iterations: None,
            preconditioner: PreconditionerKind::default(),
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
        CgSettings::checked(self.cg_tolerance, self.cg_max_iterations.unwrap_or(1))
            .map_err(|m| ModelError(format!("corotational-fem params: {m}")))?;
        if self.static_iterations == 0 || self.substeps == 0 {
            return fail("static_iterations and substeps must be ≥ 1".into());
        }
        if !(self.static_tolerance > 0.0 && self.static_tolerance < 1.0) {
            return fail(format!(
                "static_tolerance {} must lie in (0, 1) (a relative force residual)",
                self.static_tolerance
            ));
        }
        let valid = |d: f64| d.is_finite() && d >= 0.0;
        if !valid(self.mass_damping) || !valid(self.stiffness_damping) {
            return fail("mass_damping and stiffness_damping must be finite and ≥ 0".into());
        }
        Ok(())
    }

    /// The preconditioner the CPU PCG uses for this solver.
    fn cpu_preconditioner(&self) -> Preconditioner {
        match (self.preconditioner, self.solver) {
            (PreconditionerKind::BlockJacobi, _)
            | (PreconditionerKind::Auto, SolverKind::Dynamic) => Preconditioner::BlockJacobi,
            _ => Preconditioner::IncompleteCholesky,
        }
    }
}

/// Figures of the static solves since the solver was built (→ notes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StaticStats {
    /// Newton iterations (linear solves) summed over the run.
    pub newton_iterations: u64,
    /// Load steps summed over the run (one per frame when no step had to
    /// be cut back).
    pub load_steps: u64,
    /// The relative force residual at the end of the last static frame.
    pub force_residual: f64,
}

/// Load steps are halved down to this fraction of a frame's load change
/// before the static solve gives up.
pub const SMALLEST_LOAD_STEP: f64 = 1.0 / 1024.0;

/// Backtracking halves the Newton step down to this fraction before the
/// load step is declared failed.
const SMALLEST_LINE_STEP: f64 = 1.0 / 64.0;

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
    /// The static solves' figures.
    stats: StaticStats,
}

/// Which part of the rotations' own stiffness the tangent carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Twist {
    /// None: `R K Rᵀ` (the implicit steps).
    None,
    /// The exact Hessian (indefinite where elements are compressed).
    Full,
    /// Its positive part only (positive definite).
    Clamped,
}

/// A Newton iterate's figures: relative force residual, residual force
/// per node (µN), total potential and the largest potential met (µN·mm),
/// and the force-scale floor of its load step (µN).
struct Point {
    residual: f64,
    g: Vec<DVec3>,
    potential: f64,
    scale: f64,
    floor: f64,
}

/// One Newton solve's end: converged or not, with its relative force
/// residual.
struct NewtonEnd {
    converged: bool,
    residual: f64,
}

/// Euclidean norm over the free nodes.
fn free_norm(v: &[DVec3], free: &[bool]) -> f64 {
    v.iter()
        .zip(free)
        .filter(|(_, f)| **f)
        .map(|(x, _)| x.length_squared())
        .sum::<f64>()
        .sqrt()
}

fn norm(v: &[DVec3]) -> f64 {
    v.iter().map(|x| x.length_squared()).sum::<f64>().sqrt()
}

impl CorotationalFem {
    /// Rotations from `u`, the warped stiffness assembled with `diagonal`
    /// on the diagonal blocks and scaled by `k_scale`, and `f0` per node;
    /// with `twist`, each element's rotation stiffness too
    /// ([`Element::add_twist_stiffness`]; the static Newton tangent).
    fn linearise(&mut self, u: &[DVec3], k_scale: f64, diagonal: Option<&[f64]>, twist: Twist) {
        let elements = &self.elements;
        self.blocks
            .par_chunks_mut(16)
            .zip(self.corner_f0.par_chunks_mut(4))
            .zip(elements.par_iter())
            .with_min_len(256)
            .for_each(|((k, f0), e)| {
                let ue = e.nodes.map(|n| u[n as usize]);
                e.corotate(e.rotation(ue), k, f0);
                match twist {
                    Twist::None => {}
                    Twist::Full => e.add_twist_stiffness(ue, k, false),
                    Twist::Clamped => e.add_twist_stiffness(ue, k, true),
                }
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
    /// the rayon PCG; warns when the solve stops above its tolerance and
    /// counts it in `report`.
    fn solve(
        &self,
        bc: &Boundary,
        free: &[bool],
        rhs: &[DVec3],
        x: &mut [DVec3],
        report: &mut SolveReport,
    ) -> Result<CgOutcome, ModelError> {
        let out = self.solve_quietly(bc, free, rhs, x)?;
        let what = match self.params.solver {
            SolverKind::Static => "static (Newton)",
            SolverKind::Dynamic => "implicit step's",
        };
        let keys = if self.gpu.is_some() {
            "raise cg_max_iterations (or run the static solver on the CPU backend, \
             whose default preconditioner is incomplete Cholesky)"
        } else if self.params.cpu_preconditioner() == Preconditioner::BlockJacobi {
            "raise cg_max_iterations or set preconditioner = \"incomplete-cholesky\""
        } else {
            "raise cg_max_iterations or loosen cg_tolerance"
        };
        let converged = pcg::warn_unconverged(Self::NAME, what, out, self.settings(free), keys);
        report.add_solve(out, converged);
        Ok(out)
    }

    /// The solve of [`CorotationalFem::solve`], neither warning nor
    /// counted: for a Newton direction tried first with the exact,
    /// possibly indefinite, tangent.
    fn solve_quietly(
        &self,
        bc: &Boundary,
        free: &[bool],
        rhs: &[DVec3],
        x: &mut [DVec3],
    ) -> Result<CgOutcome, ModelError> {
        let settings = self.settings(free);
        Ok(match &self.gpu {
            Some(g) => g
                .solve(&self.matrix, free, &bc.hanging, rhs, x, settings)
                .map_err(|e| ModelError(format!("corotational-fem (GPU): {e}")))?,
            None => pcg::solve_with(
                &self.matrix,
                bc,
                free,
                rhs,
                x,
                settings,
                self.params.cpu_preconditioner(),
            ),
        })
    }

    /// The PCG settings: the scene's cap, or one derived from the number
    /// of free nodes.
    fn settings(&self, free: &[bool]) -> CgSettings {
        CgSettings {
            tolerance: self.params.cg_tolerance,
            max_iterations: self
                .params
                .cg_max_iterations
                .unwrap_or_else(|| pcg::size_cap(free.iter().filter(|f| **f).count())),
        }
    }

    /// The figures of the static solves so far.
    pub fn static_stats(&self) -> StaticStats {
        self.stats
    }

    /// The elastic force on every node at displacements `u` (µN), each
    /// element rotated by its own `R(u)`: `Σ R K (Rᵀ x − X)`.
    pub fn elastic_forces(&self, u: &[DVec3]) -> Vec<DVec3> {
        let per_corner: Vec<DVec3> = self
            .elements
            .par_iter()
            .with_min_len(256)
            .flat_map_iter(|e| e.elastic_force(e.nodes.map(|n| u[n as usize])))
            .collect();
        let mut f = vec![DVec3::ZERO; u.len()];
        self.matrix.sum_corners(&per_corner, &mut f);
        f
    }

    /// The total potential `Σ_e E_e(u) − f_ext · u` (µN·mm): the static
    /// solve's merit function, whose gradient is `f_int − f_ext`.
    fn potential(&self, u: &[DVec3], f_ext: &[DVec3]) -> f64 {
        let strain: f64 = self
            .elements
            .par_iter()
            .with_min_len(256)
            .map(|e| e.energy(e.nodes.map(|n| u[n as usize])))
            .sum();
        strain - f_ext.iter().zip(u).map(|(f, x)| f.dot(*x)).sum::<f64>()
    }

    /// The static equilibrium `f_int(u) = f_ext` on the free nodes, by
    /// Newton iterations with load stepping.
    ///
    /// From the state `u0` it is given, the solve follows the path
    /// `f_ext(λ) = λ f + (1 − λ) f_int(u0)` with the imposed displacements
    /// moving linearly from their values in `u0` to their targets, so that
    /// `u0` solves `λ = 0` exactly and `λ = 1` is the frame's problem. It
    /// first tries the whole step; a load step whose Newton iterations do
    /// not converge is halved (down to [`SMALLEST_LOAD_STEP`]), and a
    /// converged one doubles the next. Giving up is a [`ModelError`] that
    /// leaves the last converged state.
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
        let u0 = state.u.clone();
        let f_int0 = self.elastic_forces(&u0);
        let mut target = u0.clone();
        bc.impose(&mut target);
        let (mut done, mut step) = (0.0f64, 1.0f64);
        let mut newton = 0u64;
        let mut last = NewtonEnd {
            converged: false,
            residual: f64::NAN,
        };
        while done < 1.0 {
            let lambda = (done + step).min(1.0);
            let f_ext: Vec<DVec3> = bc
                .force
                .iter()
                .zip(&f_int0)
                .map(|(f, g)| lambda * *f + (1.0 - lambda) * *g)
                .collect();
            let mut trial = state.u.clone();
            for (n, c) in free.iter().enumerate() {
                if !c {
                    trial[n] = u0[n].lerp(target[n], lambda);
                }
            }
            bc.tie(&mut trial);
            let (end, iterations) = self.newton(bc, &free, &f_ext, &mut trial, &mut report)?;
            newton += u64::from(iterations);
            last = end;
            self.stats.load_steps += 1;
            if last.converged {
                state.u = trial;
                done = lambda;
                step = (2.0 * step).min(1.0);
            } else {
                step *= 0.5;
                if step < SMALLEST_LOAD_STEP {
                    break;
                }
            }
        }
        self.stats.newton_iterations += newton;
        self.stats.force_residual = last.residual;
        state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
        if done < 1.0 {
            return Err(ModelError(format!(
                "corotational-fem: the static solve did not converge: relative force residual \
                 {:.2e} above static_tolerance {:.1e} after {newton} Newton iterations, with \
                 this frame's loads and imposed displacements applied only to {:.4} (load steps \
                 down to 1/{}); the step is too large for a quasi-static solve from this state: \
                 ramp the load in over more frames (`frames` of the load or grab interaction), \
                 raise static_iterations ({}), or use solver = \"dynamic\" (a piece that \
                 nothing fixes or grabs has no static equilibrium at all)",
                last.residual,
                self.params.static_tolerance,
                done,
                (1.0 / SMALLEST_LOAD_STEP) as u32,
                self.params.static_iterations,
            )));
        }
        Ok(report)
    }

    /// The relative force residual `|f_ext − f_int(u)|` (free nodes, hanging
    /// nodes' forces moved onto their masters) over the force scale — the
    /// largest of `|f_ext|` there, `|f_int(u)|` over all nodes (reactions
    /// included) and `floor` (µN; the residual a load step starts from, so
    /// that a step whose answer is stress-free, such as a grabbed piece
    /// moving rigidly, still has a scale) — and the residual force per node.
    fn force_residual(
        &self,
        bc: &Boundary,
        free: &[bool],
        f_ext: &[DVec3],
        u: &[DVec3],
        floor: f64,
    ) -> (f64, Vec<DVec3>) {
        let f_int = self.elastic_forces(u);
        let mut g: Vec<DVec3> = f_ext.iter().zip(&f_int).map(|(a, b)| *a - *b).collect();
        let mut ext = f_ext.to_vec();
        bc.untie(&mut g);
        bc.untie(&mut ext);
        let scale = free_norm(&ext, free).max(norm(&f_int)).max(floor);
        let r = free_norm(&g, free);
        let relative = if scale > 0.0 { r / scale } else { r };
        (
            if relative.is_finite() {
                relative
            } else {
                f64::INFINITY
            },
            g,
        )
    }

    /// Newton iterations on `f_int(u) = f_ext` from `u` (imposed values in
    /// place). The tangent is the potential's exact Hessian (`R K Rᵀ` plus
    /// the rotations' own stiffness); where that solve fails (an
    /// indefinite Hessian: compressed elements, or far from equilibrium)
    /// or gives no descent, the iteration is redone with its positive part
    /// only. The step is backtracked until it lowers the total potential
    /// enough (Armijo; the force is the potential's gradient, and along a
    /// descent direction it must fall) — or, once the potential's change
    /// is below its rounding, the force residual. Returns how it ended and
    /// the iterations taken.
    fn newton(
        &mut self,
        bc: &Boundary,
        free: &[bool],
        f_ext: &[DVec3],
        u: &mut Vec<DVec3>,
        report: &mut SolveReport,
    ) -> Result<(NewtonEnd, u32), ModelError> {
        let tolerance = self.params.static_tolerance;
        let (_, g) = self.force_residual(bc, free, f_ext, u, 0.0);
        let floor = free_norm(&g, free);
        let (residual, g) = self.force_residual(bc, free, f_ext, u, floor);
        let potential = self.potential(u, f_ext);
        let mut at = Point {
            residual,
            g,
            potential,
            scale: potential.abs(),
            floor,
        };
        let mut iterations = 0;
        while at.residual > tolerance && iterations < self.params.static_iterations {
            iterations += 1;
            let mut moved = false;
            for twist in [Twist::Full, Twist::Clamped] {
                self.linearise(u, 1.0, None, twist);
                let mut du = vec![DVec3::ZERO; u.len()];
                if twist == Twist::Full {
                    let out = self.solve_quietly(bc, free, &at.g, &mut du)?;
                    if !out.converged(self.settings(free)) {
                        report.iterations += out.iterations;
                        continue;
                    }
                    report.add_solve(out, true);
                } else {
                    self.solve(bc, free, &at.g, &mut du, report)?;
                }
                if let Some(next) = self.line_search(bc, free, f_ext, u, &du, &at) {
                    at = next;
                    moved = true;
                    break;
                }
            }
            if !moved {
                break;
            }
        }
        Ok((
            NewtonEnd {
                converged: at.residual <= tolerance,
                residual: at.residual,
            },
            iterations,
        ))
    }

    /// Backtracks along `du` from `u` (halving down to
    /// [`SMALLEST_LINE_STEP`]); moves `u` and returns the new point, or
    /// `None` when `du` is no descent direction or no step is accepted.
    fn line_search(
        &self,
        bc: &Boundary,
        free: &[bool],
        f_ext: &[DVec3],
        u: &mut Vec<DVec3>,
        du: &[DVec3],
        at: &Point,
    ) -> Option<Point> {
        // The potential's slope along du is −g · du.
        let descent: f64 = at.g.iter().zip(du).map(|(a, b)| a.dot(*b)).sum();
        if descent.is_nan() || descent <= 0.0 {
            return None;
        }
        let mut s = 1.0;
        while s >= SMALLEST_LINE_STEP {
            let mut trial: Vec<DVec3> = u.iter().zip(du).map(|(a, d)| *a + s * *d).collect();
            bc.tie(&mut trial);
            let (r, g) = self.force_residual(bc, free, f_ext, &trial, at.floor);
            let p = self.potential(&trial, f_ext);
            let flat = (p - at.potential).abs() <= 1e-11 * at.scale;
            if p <= at.potential - 1e-4 * s * descent || flat && r < at.residual {
                *u = trial;
                return Some(Point {
                    residual: r,
                    g,
                    potential: p,
                    scale: at.scale.max(p.abs()),
                    floor: at.floor,
                });
            }
            s *= 0.5;
        }
        None
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
            self.linearise(&state.u, h * beta + h * h, Some(&diagonal), Twist::None);
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
            self.solve(bc, &free, &rhs, &mut v, &mut report)?;
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
        if self.params.preconditioner == PreconditionerKind::IncompleteCholesky {
            return Err(ModelError(
                "corotational-fem: preconditioner = \"incomplete-cholesky\" has no GPU path; \
                 use preconditioner = \"block-jacobi\" or \"auto\" with backend = \"gpu\", \
                 or backend = \"cpu\""
                    .into(),
            ));
        }
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
            stats: StaticStats::default(),
            elements,
            params,
        })
    }

    /// `newton_iterations` and `load_steps` summed over the run, and
    /// `newton_force_residual` (relative, at the end of the last static
    /// frame), for the static solver.
    fn notes(&self, notes: &mut ModelNotes) {
        if self.params.solver == SolverKind::Static {
            notes.insert(
                "newton_iterations".into(),
                self.stats.newton_iterations as f64,
            );
            notes.insert("load_steps".into(), self.stats.load_steps as f64);
            notes.insert("newton_force_residual".into(), self.stats.force_residual);
        }
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
