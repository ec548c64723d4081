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
//! With `element = "p2"` both run on the corners and the mid-edge nodes
//! ([`crate::edge_nodes`]) with quadratic elements ([`crate::quadratic`]),
//! the rotation taken per Gauss point; the code below is the same.
//!
//! Both assemble the warped stiffness into a [`BlockMatrix`] and solve with
//! PCG (for the static solves AMG on P2 or from [`AMG_AUTO_NODES`] free
//! nodes, else incomplete Cholesky; block Jacobi for the implicit steps
//! and on the GPU, by default), warm-started from the last
//! answer; a linear solve that stops above `cg_tolerance` warns and is
//! counted in the model's notes.

mod elements;
mod newton;
mod recycle;

pub use newton::SMALLEST_LOAD_STEP;

use crate::edge_nodes::EdgeNodes;
use crate::element::Element;
use elements::Elements;
use serde::Deserialize;
use std::sync::Arc;
use voxflex_core::deformation::ModelNotes;
use voxflex_core::error::ModelError;
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::gpu::GpuService;
use voxflex_core::tet_mesh::TetMesh;
use voxflex_mesh::mesh_model::amg::Amg;
use voxflex_mesh::mesh_model::ichol::IncompleteCholesky;
use voxflex_mesh::mesh_model::pcg::{self, CgOutcome, CgSettings, Preconditioner};
use voxflex_mesh::mesh_model::pcg_gpu::GpuPcg;
use voxflex_mesh::mesh_model::{
    BlockMatrix, Boundary, EdgeLayer, ElasticMaterial, MeshSolver, NodeState, ProxySpec,
    SolveReport, lumped_masses,
};

/// Which solve runs each frame.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, schemars::JsonSchema, serde::Serialize,
)]
#[serde(rename_all = "lowercase")]
pub enum SolverKind {
    /// Equilibrium under the current loads and constraints.
    Static,
    /// Implicit backward-Euler time stepping.
    #[default]
    Dynamic,
}

/// The finite element (`element = "…"`; deserialised by hand for its
/// message, described to the schema by the derive).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, schemars::JsonSchema, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ElementKind {
    /// 4-node linear tetrahedra on the proxy's nodes (`"p1"`), one
    /// rotation per element.
    #[default]
    P1,
    /// 10-node quadratic tetrahedra (`"p2"`): the proxy's nodes plus one
    /// per edge ([`crate::edge_nodes`]), a rotation per Gauss point
    /// ([`crate::quadratic`]). Far less stiff in bending than P1 on the
    /// same proxy.
    P2,
}

impl<'de> Deserialize<'de> for ElementKind {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        match s.as_str() {
            "p1" => Ok(Self::P1),
            "p2" => Ok(Self::P2),
            _ => Err(serde::de::Error::custom(format!(
                "element = \"{s}\" is not an element; use \"p1\" (linear tetrahedra) or \"p2\" \
                 (10-node quadratic tetrahedra)"
            ))),
        }
    }
}

/// The PCG's preconditioner (`preconditioner = "…"`).
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, schemars::JsonSchema, serde::Serialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum PreconditionerKind {
    /// For the static solver (bending-dominated) AMG from
    /// [`AMG_AUTO_NODES`] ([`AMG_AUTO_NODES_P2`] with P2) free nodes, else incomplete Cholesky
    /// (block Jacobi needs about twice its iterations); block Jacobi for
    /// the implicit steps (mass-dominated, where it converges in tens and
    /// costs no setup) and on the GPU.
    #[default]
    Auto,
    /// IC(0) on the block pattern (CPU only).
    IncompleteCholesky,
    /// Each node's 3 × 3 diagonal block inverted (CPU and GPU).
    BlockJacobi,
    /// Smoothed-aggregation algebraic multigrid, one V-cycle
    /// ([`voxflex_mesh::mesh_model::amg`]; CPU only): iterations nearly
    /// flat as the mesh is refined.
    Amg,
}

/// The solver's keys of `[model.params.corotational-fem]`.
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FemParams {
    /// `"p1"` (default) or `"p2"`; without a `proxy` key P2 runs on cells
    /// twice P1's default ([`MeshSolver::default_proxy`]).
    #[serde(default)]
    pub element: ElementKind,
    /// `"dynamic"` (default) or `"static"`.
    #[serde(default)]
    pub solver: SolverKind,
    /// PCG stops at this relative residual (default 1e-6).
    #[serde(default = "pcg::default_tolerance")]
    #[schemars(range(min = 0, max = 1))]
    pub cg_tolerance: f64,
    /// The compliance solves (`K⁻¹ b` for an actuator's forces, which only
    /// predict the inverse step's response; the step itself is solved to
    /// `cg_tolerance` and `static_tolerance`) stop at this relative PCG
    /// residual (default 1e-4).
    #[serde(default = "default_compliance_cg_tolerance")]
    #[schemars(range(min = 0, max = 1))]
    pub compliance_cg_tolerance: f64,
    /// PCG iteration cap per solve; `None` (the default) derives it from
    /// the problem size ([`pcg::size_cap`]).
    #[serde(default)]
    #[schemars(range(min = 1))]
    pub cg_max_iterations: Option<u32>,
    /// The PCG's preconditioner (default `"auto"`).
    #[serde(default)]
    pub preconditioner: PreconditionerKind,
    /// Newton iterations per load step of the static solve (default 25).
    #[serde(default = "default_static_iterations")]
    #[schemars(range(min = 1))]
    pub static_iterations: u32,
    /// The static solve has converged when the force residual
    /// `|f_ext − f_int(u)|` on the free nodes is at most this fraction of
    /// the force scale (the largest of `|f_ext|` there, `|f_int(u)|` over
    /// all nodes, reactions included, the residual the load step started
    /// from, and the mean force scale of the load steps converged before)
    /// (default 1e-6).
    #[serde(default = "default_static_tolerance")]
    #[schemars(range(min = 0, max = 1))]
    pub static_tolerance: f64,
    /// The interactive static solve (default false): each frame runs at
    /// most `static_iterations` Newton iterations on the whole frame's
    /// load (no load stepping) and keeps the iterate where they stop, so
    /// the body lags its equilibrium and catches up over the next frames —
    /// SOFA's one-solve-per-step loop with `static_iterations = 1`. Frames
    /// that end above `static_tolerance` are counted (`lagged_frames`) and
    /// the first one is warned about; `newton_force_residual` is the last
    /// frame's. Needs `solver = "static"`.
    #[serde(default)]
    pub static_lag: bool,
    /// Implicit steps per frame (default 1).
    #[serde(default = "one")]
    #[schemars(range(min = 1))]
    pub substeps: u32,
    /// Rayleigh mass damping α, 1/s (default 1).
    #[serde(default = "default_mass_damping")]
    #[schemars(extend("unit" = "1/s"), range(min = 0))]
    pub mass_damping: f64,
    /// Rayleigh stiffness damping β, s (default 0.01).
    #[serde(default = "default_stiffness_damping")]
    #[schemars(extend("unit" = "s"), range(min = 0))]
    pub stiffness_damping: f64,
}

fn default_compliance_cg_tolerance() -> f64 {
    1e-4
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
            element: ElementKind::default(),
            solver: SolverKind::default(),
            cg_tolerance: pcg::default_tolerance(),
            compliance_cg_tolerance: default_compliance_cg_tolerance(),
            cg_max_iterations: None,
            preconditioner: PreconditionerKind::default(),
            static_iterations: default_static_iterations(),
            static_tolerance: default_static_tolerance(),
            static_lag: false,
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
        if self.static_lag && self.solver != SolverKind::Static {
            return fail(
                "static_lag = true needs solver = \"static\" (the dynamic solver already takes one implicit step a frame)"
                    .into(),
            );
        }
        if !(self.static_tolerance > 0.0 && self.static_tolerance < 1.0) {
            return fail(format!(
                "static_tolerance {} must lie in (0, 1) (a relative force residual)",
                self.static_tolerance
            ));
        }
        if !(self.compliance_cg_tolerance > 0.0 && self.compliance_cg_tolerance < 1.0) {
            return fail(format!(
                "compliance_cg_tolerance {} must lie in (0, 1) (a relative PCG residual)",
                self.compliance_cg_tolerance
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
    /// Frames of the interactive static solve (`static_lag`) that ended
    /// above `static_tolerance`.
    pub lagged_frames: u64,
}

/// The corotational FEM solver.
pub struct CorotationalFem {
    params: FemParams,
    elements: Elements,
    /// The mid-edge nodes (`element = "p2"`); the solves run on the
    /// corners and these.
    edge_nodes: Option<EdgeNodes>,
    masses: Vec<f64>,
    matrix: BlockMatrix,
    /// Scratch: 16 (P1) or 100 (P2) warped blocks per element.
    blocks: Vec<DMat3>,
    /// Scratch: 4 (10) force offsets per element, and summed per node.
    corner_f0: Vec<DVec3>,
    f0: Vec<DVec3>,
    /// The PCG's WGSL twin, on the GPU backend.
    gpu: Option<GpuPcg>,
    /// The static solves' figures.
    stats: StaticStats,
    /// The mean force scale of the converged static load steps (µN).
    force_scale: newton::ForceScale,
    /// The quadratic constant the last full Newton step showed (relative
    /// residual after ÷ before²; 0 before any, or after a step that
    /// backtracked): how loose its next linear solve may be
    /// ([`Self::newton_settings`]).
    newton_quadratic: f64,
    /// Rest positions of the solver's nodes (corners, then edge nodes for
    /// P2), mm.
    positions: Vec<DVec3>,
    /// Their positions at the last linearisation, mm: the rigid-body modes
    /// of `preconditioner = "amg"` are taken there, because the corotated
    /// tangent's near-null space is the rigid motions of the deformed body
    /// (modes of the rest body precondition a beam bent by 90° poorly).
    deformed: Vec<DVec3>,
    /// The displacements (mm) the matrix was last linearised at for a
    /// compliance solve (clamped twist, unscaled); `None` once any other
    /// linearisation replaced it. The actuators' compliance solves of one
    /// frame share it instead of linearising once each.
    compliance_tangent: Option<Vec<DVec3>>,
    /// The incomplete Cholesky factor of that tangent on these free nodes,
    /// shared by the frame's compliance solves (CPU, IC(0) only).
    compliance_ic: Option<(Vec<bool>, IncompleteCholesky)>,
    /// The last compliance answers, the warm start of the next
    /// ([`recycle`]).
    compliance_starts: recycle::Recycler,
    /// The AMG hierarchy (`preconditioner = "amg"`), kept between solves
    /// while the pattern and the free nodes stay, and its setup figures.
    amg: std::sync::Mutex<AmgState>,
}

/// The kept AMG hierarchy, its figures, and the CG iterations of the solve
/// right after its last setup or refresh (`baseline`) and of the last
/// solve: a hierarchy is reused unrefreshed (its V-cycle stays SPD; only
/// its quality drifts as the corotational values change) while the last
/// solve took at most [`AMG_STALE`] times the baseline's iterations.
#[derive(Default)]
struct AmgState {
    hierarchy: Option<Amg>,
    stats: AmgStats,
    baseline: Option<u32>,
    last: u32,
}

/// From this many free nodes `preconditioner = "auto"` uses AMG for the
/// static solver on P1 elements (measured: slower than block Jacobi and
/// IC(0) at 2,925 nodes, faster at 19,737).
pub const AMG_AUTO_NODES: usize = 10_000;

/// The same for P2 elements, whose nodes couple more (measured on the
/// `fem_cantilever` and `fem_elastica` fronts: AMG slower than IC(0) up to
/// 400 P2 tetrahedra, ~800 nodes — 86 against 65 ms, 264–393 against
/// 130–185 ms —, faster from 1,280–1,350, ~2,300 nodes).
pub const AMG_AUTO_NODES_P2: usize = 2_000;

/// A kept hierarchy is refreshed when the last solve needed more than this
/// many times the iterations of the solve right after its setup (plus 2).
const AMG_STALE: f64 = 1.5;

/// Compliance answers kept to warm-start the next ([`recycle`]): one
/// frame's worth for four hydraulic cavities (two solves each).
const COMPLIANCE_KEPT: usize = 8;

/// Setup figures of `preconditioner = "amg"` (→ notes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AmgStats {
    /// Full setups (aggregation, prolongators, Galerkin products).
    pub setups: u64,
    /// Solves that reused the kept hierarchy as it was.
    pub reuses: u64,
    /// Seconds spent in both, summed.
    pub setup_s: f64,
    /// Seconds spent in full setups alone, summed.
    pub full_setup_s: f64,
    /// Levels of the last hierarchy.
    pub levels: usize,
}

/// Which part of the rotations' own stiffness the tangent carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Twist {
    /// None: `R K Rᵀ` (the implicit steps).
    None,
    /// The exact Hessian (indefinite where elements are compressed).
    Full,
    /// Its positive part only (positive definite).
    Clamped,
}

impl CorotationalFem {
    /// Rotations from `u`, the warped stiffness assembled with `diagonal`
    /// on the diagonal blocks and scaled by `k_scale`, and `f0` per node;
    /// with `twist`, each element's rotation stiffness too
    /// ([`crate::element::add_twist`]; the static Newton tangent).
    fn linearise(&mut self, u: &[DVec3], k_scale: f64, diagonal: Option<&[f64]>, twist: Twist) {
        self.compliance_tangent = None;
        self.compliance_ic = None;
        self.elements
            .linearise(u, k_scale, twist, &mut self.blocks, &mut self.corner_f0);
        self.deformed.clear();
        self.deformed
            .extend(self.positions.iter().zip(u).map(|(p, u)| *p + *u));
        self.matrix.assemble(&self.blocks, diagonal);
        self.matrix.sum_corners(&self.corner_f0, &mut self.f0);
    }

    /// Solves the assembled system on the GPU when there is one, else with
    /// the rayon PCG, to `settings` ([`CorotationalFem::settings`], or
    /// looser for a Newton direction near convergence); warns when the
    /// solve stops above its tolerance and counts it in `report`.
    fn solve(
        &self,
        bc: &Boundary,
        free: &[bool],
        rhs: &[DVec3],
        x: &mut [DVec3],
        settings: CgSettings,
        report: &mut SolveReport,
    ) -> Result<CgOutcome, ModelError> {
        let out = self.solve_quietly(bc, free, rhs, x, settings)?;
        self.report_solve(out, settings, report);
        Ok(out)
    }

    /// Warns when `out` stopped above its tolerance (naming the keys that
    /// help) and counts it in `report`.
    fn report_solve(&self, out: CgOutcome, settings: CgSettings, report: &mut SolveReport) {
        let what = match self.params.solver {
            SolverKind::Static => "static (Newton)",
            SolverKind::Dynamic => "implicit step's",
        };
        let keys = if self.gpu.is_some() {
            "raise cg_max_iterations (or run the static solver on the CPU backend, \
             whose default preconditioner is incomplete Cholesky)"
        } else if self.params.preconditioner == PreconditionerKind::Amg {
            "raise cg_max_iterations or loosen cg_tolerance (or try preconditioner = \
             \"incomplete-cholesky\")"
        } else if self.params.cpu_preconditioner() == Preconditioner::BlockJacobi {
            "raise cg_max_iterations or set preconditioner = \"incomplete-cholesky\""
        } else {
            "raise cg_max_iterations or loosen cg_tolerance"
        };
        let converged = pcg::warn_unconverged(Self::NAME, what, out, settings, keys);
        report.add_solve(out, converged);
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
        settings: CgSettings,
    ) -> Result<CgOutcome, ModelError> {
        Ok(match &self.gpu {
            Some(g) => g
                .solve(&self.matrix, free, &bc.hanging, rhs, x, settings)
                .map_err(|e| ModelError(format!("corotational-fem (GPU): {e}")))?,
            None if self.uses_amg(free) => {
                let mut guard = self.amg.lock().unwrap_or_else(|e| e.into_inner());
                let AmgState {
                    hierarchy,
                    stats,
                    baseline,
                    last,
                } = &mut *guard;
                let (mut ready, mut fresh) = (false, false);
                let out = pcg::solve_preconditioned(
                    &self.matrix,
                    bc,
                    free,
                    rhs,
                    x,
                    settings,
                    &mut |r, z| {
                        if !ready {
                            let fits = hierarchy
                                .as_ref()
                                .is_some_and(|h| h.fits(&self.matrix, free));
                            let stale =
                                baseline.is_none_or(|b| *last as f64 > AMG_STALE * b as f64 + 2.0);
                            if fits && !stale {
                                stats.reuses += 1;
                            } else {
                                // A stale hierarchy is rebuilt, not only
                                // refreshed: its rigid-body modes must follow
                                // the body's rotation (measured on the
                                // elastica front: refreshing alone left P2
                                // large-deflection solves 2–4× slower than
                                // incomplete Cholesky).
                                let t = std::time::Instant::now();
                                *hierarchy = None;
                                let h = Amg::prepare(hierarchy, &self.matrix, free, &self.deformed);
                                stats.levels = h.level_sizes().len();
                                stats.setups += 1;
                                stats.full_setup_s += t.elapsed().as_secs_f64();
                                stats.setup_s += t.elapsed().as_secs_f64();
                                fresh = true;
                            }
                            ready = true;
                        }
                        hierarchy.as_ref().expect("prepared").apply(r, z)
                    },
                );
                if ready {
                    if fresh {
                        *baseline = Some(out.iterations);
                    }
                    *last = out.iterations;
                }
                out
            }
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

    /// True when the CPU PCG preconditions with AMG: `preconditioner =
    /// "amg"`, or `"auto"` for the static solver on at least
    /// [`AMG_AUTO_NODES`] ([`AMG_AUTO_NODES_P2`] with P2) free nodes (where it was measured faster
    /// than IC(0) and block Jacobi; docs/BENCHMARKS.md, "Corotational FEM").
    fn uses_amg(&self, free: &[bool]) -> bool {
        match (self.params.preconditioner, self.params.solver) {
            (PreconditionerKind::Amg, _) => true,
            (PreconditionerKind::Auto, SolverKind::Static) => {
                let nodes = match self.params.element {
                    ElementKind::P1 => AMG_AUTO_NODES,
                    ElementKind::P2 => AMG_AUTO_NODES_P2,
                };
                free.iter().filter(|f| **f).count() >= nodes
            }
            _ => false,
        }
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

    /// The mid-edge node layer (`element = "p2"`), with the full state.
    pub fn edge_nodes(&self) -> Option<&EdgeNodes> {
        self.edge_nodes.as_ref()
    }

    /// The element kind the solver runs.
    pub fn element(&self) -> ElementKind {
        self.params.element
    }

    /// Tetrahedra (elements).
    pub fn elements(&self) -> usize {
        self.elements.len()
    }

    /// One step on the solver's own nodes (corners, then edge nodes for
    /// P2).
    pub(crate) fn step_nodes(
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

    /// The figures of the static solves so far.
    pub fn static_stats(&self) -> StaticStats {
        self.stats
    }

    /// The AMG setup figures (`preconditioner = "amg"`).
    pub fn amg_stats(&self) -> AmgStats {
        self.amg.lock().unwrap_or_else(|e| e.into_inner()).stats
    }

    /// The elastic force on every node at displacements `u` (µN), each
    /// element rotated by its own `R(u)`: `Σ R K (Rᵀ x − X)` (per Gauss
    /// point for P2). With `element = "p2"` the nodes are the corners then
    /// the edge nodes ([`CorotationalFem::edge_nodes`]).
    pub fn elastic_forces(&self, u: &[DVec3]) -> Vec<DVec3> {
        let per_corner = self.elements.forces(u);
        let mut f = vec![DVec3::ZERO; u.len()];
        self.matrix.sum_corners(&per_corner, &mut f);
        f
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
            self.solve(bc, &free, &rhs, &mut v, self.settings(&free), &mut report)?;
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

    /// 3 voxels: the combined front over the cantilever, elastica, grab,
    /// two-material and cut fronts has no knee (it is straight in log–log),
    /// so the default is the most accurate spacing that keeps the
    /// interactive reference scene within 30 frames/s on 2 cores
    /// (docs/BENCHMARKS.md, "Combined fronts").
    const DEFAULT_NODE_SPACING: usize = 3;

    /// Uniform cells of [`MeshSolver::DEFAULT_NODE_SPACING`] voxels with
    /// P1; twice that with P2, whose mid-edge nodes keep the nodes as far
    /// apart.
    fn default_proxy(params: &FemParams) -> ProxySpec {
        let cells_per_spacing = match params.element {
            ElementKind::P1 => 1,
            ElementKind::P2 => 2,
        };
        ProxySpec::Uniform {
            step: cells_per_spacing * Self::DEFAULT_NODE_SPACING,
        }
    }

    const GPU: bool = true;

    fn use_gpu(&mut self, gpu: Arc<dyn GpuService>) -> Result<(), ModelError> {
        if self.params.preconditioner == PreconditionerKind::Amg {
            return Err(ModelError(
                "corotational-fem: preconditioner = \"amg\" (algebraic multigrid) has no GPU \
                 path; use preconditioner = \"block-jacobi\" or \"auto\" with backend = \"gpu\", \
                 or backend = \"cpu\""
                    .into(),
            ));
        }
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
        let (elements, edge_nodes, matrix, masses, positions) =
            match params.element {
                ElementKind::P1 => {
                    let elements: Vec<Element> = (0..mesh.tets.len())
                        .map(|t| Element::new(mesh, t, &materials[mesh.labels[t] as usize]))
                        .collect();
                    (
                        Elements::Linear(elements),
                        None,
                        BlockMatrix::on_mesh(mesh),
                        lumped_masses(mesh, materials),
                        mesh.nodes.clone(),
                    )
                }
                ElementKind::P2 => {
                    let layer = EdgeNodes::new(mesh, materials);
                    let elements = layer.elements(mesh, materials);
                    let nodes: Vec<[u32; 10]> = elements.iter().map(|e| e.nodes).collect();
                    let matrix = BlockMatrix::on_elements(layer.len(), &nodes);
                    let masses = layer.masses.clone();
                    let positions =
                        mesh.nodes
                            .iter()
                            .copied()
                            .chain(layer.edges.iter().map(|&[a, b]| {
                                0.5 * (mesh.nodes[a as usize] + mesh.nodes[b as usize])
                            }))
                            .collect();
                    (
                        Elements::Quadratic(elements),
                        Some(layer),
                        matrix,
                        masses,
                        positions,
                    )
                }
            };
        let n = masses.len();
        let per = elements.nodes_per_element();
        Ok(Self {
            matrix,
            masses,
            blocks: vec![DMat3::ZERO; per * per * elements.len()],
            corner_f0: vec![DVec3::ZERO; per * elements.len()],
            f0: vec![DVec3::ZERO; n],
            edge_nodes,
            gpu: None,
            stats: StaticStats::default(),
            force_scale: newton::ForceScale::default(),
            newton_quadratic: 0.0,
            deformed: positions.clone(),
            positions,
            compliance_tangent: None,
            compliance_ic: None,
            compliance_starts: recycle::Recycler::new(COMPLIANCE_KEPT),
            amg: Default::default(),
            elements,
            params,
        })
    }

    /// `newton_iterations` and `load_steps` summed over the run, and
    /// `newton_force_residual` (relative, at the end of the last static
    /// frame), for the static solver; `lagged_frames` with `static_lag`.
    fn notes(&self, notes: &mut ModelNotes) {
        if self.params.solver == SolverKind::Static {
            notes.insert(
                "newton_iterations".into(),
                self.stats.newton_iterations as f64,
            );
            notes.insert("load_steps".into(), self.stats.load_steps as f64);
            notes.insert("newton_force_residual".into(), self.stats.force_residual);
            if self.params.static_lag {
                notes.insert("lagged_frames".into(), self.stats.lagged_frames as f64);
            }
        }
        let a = self.amg_stats();
        if self.params.preconditioner == PreconditionerKind::Amg || a.setups > 0 {
            notes.insert("amg_setups".into(), a.setups as f64);
            notes.insert("amg_reuses".into(), a.reuses as f64);
            notes.insert("amg_setup_s".into(), a.setup_s);
            notes.insert("amg_full_setup_s".into(), a.full_setup_s);
            notes.insert("amg_levels".into(), a.levels as f64);
        }
    }

    fn step(
        &mut self,
        dt_s: f64,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        let Some(mut layer) = self.edge_nodes.take() else {
            return self.step_nodes(dt_s, bc, state);
        };
        // P2: the step runs on corners and edge nodes; the corners go back
        // to the model even when the step fails (a static solve keeps its
        // last converged state).
        layer.sync(state);
        let full_bc = layer.boundary(bc);
        let mut full = std::mem::take(&mut layer.state);
        let out = self.step_nodes(dt_s, &full_bc, &mut full);
        layer.state = full;
        layer.finish(state);
        self.edge_nodes = Some(layer);
        out
    }

    fn edge_layer(&self) -> Option<EdgeLayer<'_>> {
        self.edge_nodes.as_ref().map(EdgeNodes::layer)
    }

    fn is_static(&self) -> bool {
        self.params.solver == SolverKind::Static
    }

    /// `K⁻¹ f` with the static Newton solve's tangent at `state` (the
    /// warped stiffness plus the positive part of the rotations' own
    /// stiffness, [`Twist::Clamped`], so it is positive definite), by the
    /// same PCG as the steps. With P2 the forces act on the corners and the
    /// mid-edge nodes take none.
    fn compliance(
        &mut self,
        bc: &Boundary,
        state: &NodeState,
        forces: &[DVec3],
    ) -> Result<(Vec<DVec3>, SolveReport), ModelError> {
        let Some(mut layer) = self.edge_nodes.take() else {
            return self.compliance_nodes(bc, &state.u, forces);
        };
        layer.sync(state);
        let full_bc = layer.boundary(bc);
        let u = layer.state.u.clone();
        let mut full = forces.to_vec();
        full.resize(u.len(), DVec3::ZERO);
        let out = self.compliance_nodes(&full_bc, &u, &full);
        self.edge_nodes = Some(layer);
        let (mut x, report) = out?;
        x.truncate(forces.len());
        Ok((x, report))
    }
}

impl CorotationalFem {
    /// The start of a solve of the assembled matrix for `rhs` (µN per
    /// node): its Galerkin projection onto the last compliance answers
    /// ([`recycle`]; zero without any): an actuator's forces change a
    /// little a frame, so its next compliance solve starts close. (Newton
    /// directions started this way took as many iterations and a slower
    /// frame on the pendulum, so they start from zero.)
    fn recycled_start(&self, bc: &Boundary, free: &[bool], rhs: &[DVec3]) -> Vec<DVec3> {
        let b = pcg::reduced_rhs(bc, free, rhs);
        self.compliance_starts.start(&b, &mut |v, out| {
            pcg::apply_reduced(&self.matrix, bc, free, v, out)
        })
    }

    /// True when the compliance solves precondition with one IC(0) factor
    /// of the compliance tangent on `free`, factored here on first use:
    /// the frame's solves (one or two per actuator) then factor once
    /// instead of once each. False on the GPU, with AMG or block Jacobi,
    /// and where the factorisation breaks down (the solve then chooses).
    fn shares_compliance_ic(&mut self, free: &[bool]) -> bool {
        if self.gpu.is_some()
            || self.uses_amg(free)
            || self.params.cpu_preconditioner() != Preconditioner::IncompleteCholesky
        {
            return false;
        }
        if self.compliance_ic.as_ref().is_none_or(|(f, _)| f != free) {
            self.compliance_ic =
                IncompleteCholesky::new(&self.matrix, free).map(|ic| (free.to_vec(), ic));
        }
        self.compliance_ic.is_some()
    }

    /// [`MeshSolver::compliance`] on the solver's own nodes.
    fn compliance_nodes(
        &mut self,
        bc: &Boundary,
        u: &[DVec3],
        forces: &[DVec3],
    ) -> Result<(Vec<DVec3>, SolveReport), ModelError> {
        if self.compliance_tangent.as_deref() != Some(u) {
            self.linearise(u, 1.0, None, Twist::Clamped);
            self.compliance_tangent = Some(u.to_vec());
        }
        let free: Vec<bool> = bc.constrained().iter().map(|c| !c).collect();
        let mut x = self.recycled_start(bc, &free, forces);
        let mut report = SolveReport::default();
        let mut settings = self.settings(&free);
        settings.tolerance = self.params.compliance_cg_tolerance;
        if self.shares_compliance_ic(&free) {
            let (_, ic) = self.compliance_ic.as_ref().expect("shared");
            let out = pcg::solve_preconditioned(
                &self.matrix,
                bc,
                &free,
                forces,
                &mut x,
                settings,
                &mut |r, z| ic.apply(r, z),
            );
            self.report_solve(out, settings, &mut report);
        } else {
            self.solve(bc, &free, forces, &mut x, settings, &mut report)?;
        }
        self.compliance_starts.keep(&x);
        Ok((x, report))
    }
}
