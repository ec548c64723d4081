//! The mass-spring model on a tetrahedral proxy's edges.
//!
//! **Springs.** One spring per edge, with Van Gelder's stiffness (1998,
//! "Approximate simulation of elastic membranes by triangulated spring
//! meshes", extended to tetrahedra): `k = E Σ V_t / L²` over the
//! tetrahedra `t` sharing the edge, `L` its rest length — a published rule
//! from the material and the mesh, not a fit to any reference. Springs
//! carry no shear or volume term: the model has no Poisson effect and its
//! bending stiffness depends on the mesh, which is the error the
//! mass-spring-vs-FEM comparison reports. (Sharing each tetrahedron's
//! uniaxial strain energy over its six edges instead, `E V / (6 L²)`,
//! measured 4–8× too soft in bending on the cantilever.)
//!
//! **Volume springs** (`volume_stiffness = κ`, default 0: off): per
//! tetrahedron the energy `½ k_v min(V − V₀, 0)²` with `k_v = κ E / V₀`
//! (`V` its signed volume, `V₀` at rest, `E` its material's Young's
//! modulus), so the force on corner `c` is `−k_v (V − V₀) ∂V/∂x_c` while
//! the tetrahedron is smaller than at rest — inverted ones included — and
//! nothing otherwise. Springs alone cannot untangle a mesh: a tetrahedron
//! turned inside out has the same edge lengths as at rest, so it is an
//! equilibrium of the springs (a released 100 mm grab left 24 tetrahedra
//! inverted for good); the volume term pushes it back through. It acts in
//! compression only because `∂V/∂x` is a face-area vector: in tension it
//! grows with the square of the stretch, so a strongly stretched
//! tetrahedron (next to a large grab) would stiffen far beyond the
//! explicit step computed at rest, while a compressed one stays within it.
//! `κ = 1` gives the volume term a bulk stiffness `E` (a linear solid of
//! Poisson ratio 1/3 has bulk modulus `E`); `κ = 0`, the default, turns it
//! off. *Why off by default:* the term also stiffens every compressed
//! tetrahedron in ordinary deformation, so it changes the model (the
//! cantilever's tip error against FEM went from +1.4 % to +10.2 % at r = 2,
//! and its implicit run to rest from 11 ms to 4.6 s), and the scalar pass
//! costs about 10× the explicit sub-step (2.4–2.9 ms against 0.25–0.29 ms
//! on the 104,528-spring bench). Inverted tetrahedra are always counted and
//! warned about (`inverted_tetrahedra`), and the warning names this key.
//!
//! **Damping.** Along each spring, `c = damping_ratio · 2 √(k m̄)` on the
//! relative velocity of its ends (`m̄` the ends' reduced mass), plus mass
//! damping `α` on every node.
//!
//! **Integration.**
//! - `integrator = "explicit"`: symplectic Euler,
//!   `v += h M⁻¹ f(x, v)`, `x += h v`, with `h` the frame's time step split
//!   into as many sub-steps as the stability limit needs: `h ≤ 0.9 · 2 / ω`,
//!   with `ω² ≤ max_i 2 Σ_j k_ij / m_i` (Gershgorin on `M⁻¹ K`). More than
//!   `max_substeps` sub-steps is refused with a message saying what to do.
//! - `integrator = "implicit"` (the default): one linearised
//!   backward-Euler step per frame, `(M + h D + h² K) v⁺ = M v + h f(x, v)`,
//!   `K` the springs' tangent stiffness, solved by block-Jacobi PCG. Its
//!   step does not shrink with the stiffest material, and on the `grab`
//!   front (docs/BENCHMARKS.md) it comes to rest with the explicit
//!   integrator's error in about half the time.

use crate::gpu::GpuSprings;
use crate::kernel::{Fixup, NodeRows, SpringKernel, Substep};
use rayon::prelude::*;
use serde::Deserialize;
use std::collections::HashMap;
use std::sync::Arc;
use voxflex_core::error::ModelError;
use voxflex_core::glam::{DMat3, DVec3};
use voxflex_core::gpu::GpuService;
use voxflex_core::tet_mesh::TetMesh;
use voxflex_mesh::mesh_model::pcg::{self, CgSettings};
use voxflex_mesh::mesh_model::pcg_gpu::GpuPcg;
use voxflex_mesh::mesh_model::{
    BlockMatrix, Boundary, ElasticMaterial, MeshSolver, NodeState, SolveReport, lumped_masses,
};

/// The time integrator.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, schemars::JsonSchema, serde::Serialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    /// Symplectic Euler with a stable sub-step.
    Explicit,
    /// One linearised backward-Euler step per frame (the default: on the
    /// `grab` front it reaches the explicit integrator's error at rest in
    /// about half the time, and stiff materials such as bone do not shrink
    /// its step).
    #[default]
    Implicit,
}

/// The solver's keys of `[model.params.mass-spring]`.
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SpringParams {
    /// `"implicit"` (default) or `"explicit"`.
    #[serde(default)]
    pub integrator: Integrator,
    /// Spring damping as a fraction of critical (default 0.1).
    #[serde(default = "default_damping_ratio")]
    #[schemars(range(min = 0))]
    pub damping_ratio: f64,
    /// Mass damping α, 1/s (default 1).
    #[serde(default = "default_mass_damping")]
    #[schemars(extend("unit" = "1/s"), range(min = 0))]
    pub mass_damping: f64,
    /// Most explicit sub-steps per frame before the step is refused
    /// (default 10,000).
    #[serde(default = "default_max_substeps")]
    #[schemars(range(min = 1))]
    pub max_substeps: u32,
    /// PCG relative residual of the implicit step (default 1e-6).
    #[serde(default = "pcg::default_tolerance")]
    pub cg_tolerance: f64,
    /// PCG iteration cap of the implicit step (default 200).
    #[serde(default = "pcg::default_max_iterations")]
    pub cg_max_iterations: u32,
    /// Volume springs' stiffness `κ` as a multiple of each tetrahedron's
    /// Young's modulus (dimensionless, ≥ 0; default 0: off):
    /// see the module.
    #[serde(default = "default_volume_stiffness")]
    #[schemars(range(min = 0))]
    pub volume_stiffness: f64,
}

fn default_damping_ratio() -> f64 {
    0.1
}
fn default_mass_damping() -> f64 {
    1.0
}
fn default_max_substeps() -> u32 {
    10_000
}
fn default_volume_stiffness() -> f64 {
    0.0
}

impl Default for SpringParams {
    fn default() -> Self {
        Self {
            integrator: Integrator::default(),
            damping_ratio: default_damping_ratio(),
            mass_damping: default_mass_damping(),
            max_substeps: default_max_substeps(),
            cg_tolerance: pcg::default_tolerance(),
            cg_max_iterations: pcg::default_max_iterations(),
            volume_stiffness: default_volume_stiffness(),
        }
    }
}

impl SpringParams {
    fn validate(&self) -> Result<(), ModelError> {
        let fail = |m: String| Err(ModelError(format!("mass-spring params: {m}")));
        let valid = |d: f64| d.is_finite() && d >= 0.0;
        if !valid(self.damping_ratio) || !valid(self.mass_damping) {
            return fail("damping_ratio and mass_damping must be finite and ≥ 0".into());
        }
        if self.max_substeps == 0 {
            return fail("max_substeps must be ≥ 1".into());
        }
        if !valid(self.volume_stiffness) {
            return fail(format!(
                "volume_stiffness {} must be finite and ≥ 0 (a multiple of Young's modulus; \
                 0 turns the volume springs off)",
                self.volume_stiffness
            ));
        }
        CgSettings::checked(self.cg_tolerance, self.cg_max_iterations)
            .map_err(|m| ModelError(format!("mass-spring params: {m}")))?;
        Ok(())
    }
}

/// The springs, structure of arrays.
#[derive(Clone, Debug, Default)]
pub struct Springs {
    /// End nodes.
    pub ends: Vec<[u32; 2]>,
    /// Rest length, mm.
    pub rest: Vec<f64>,
    /// Stiffness, µN/mm.
    pub k: Vec<f64>,
    /// Damping coefficient, µN·s/mm.
    pub c: Vec<f64>,
}

/// The volume springs, one per tetrahedron (see the module).
#[derive(Clone, Debug, Default)]
pub struct VolumeSprings {
    /// Corners, the proxy's tetrahedron order.
    pub corners: Vec<[u32; 4]>,
    /// `k_v = κ E / V₀`, µN/mm⁵.
    pub k: Vec<f64>,
}

/// The mass-spring solver.
pub struct MassSpring {
    params: SpringParams,
    rest: Vec<DVec3>,
    masses: Vec<f64>,
    springs: Springs,
    /// The volume springs (empty when `volume_stiffness` is 0).
    volumes: VolumeSprings,
    /// Largest stable explicit step, s.
    stable_dt: f64,
    /// Per tetrahedron: its six edges' springs and its share of each
    /// stiffness (implicit assembly).
    tet_edges: Vec<[(u32, f64); 6]>,
    matrix: Option<BlockMatrix>,
    /// The force kernel and its f32 node state.
    kernel: SpringKernel,
    /// The explicit integrator's WGSL twin, on the GPU backend.
    gpu: Option<GpuSprings>,
    /// The implicit integrator's PCG on the GPU backend.
    gpu_pcg: Option<GpuPcg>,
}

/// `∂V/∂x_c` (mm²) of the signed volume of the tetrahedron with corners
/// `x` (mm), for its four corners.
pub fn volume_gradient(x: [DVec3; 4]) -> [DVec3; 4] {
    let [d1, d2, d3] = [1, 2, 3].map(|c| x[c] - x[0]);
    let g = [d2.cross(d3), d3.cross(d1), d1.cross(d2)].map(|v| v / 6.0);
    [-(g[0] + g[1] + g[2]), g[0], g[1], g[2]]
}

/// The corner pairs of a tetrahedron's six edges.
const EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

impl MassSpring {
    /// The springs.
    pub fn springs(&self) -> &Springs {
        &self.springs
    }

    /// The volume springs.
    pub fn volume_springs(&self) -> &VolumeSprings {
        &self.volumes
    }

    /// Largest stable explicit time step, s.
    pub fn stable_dt(&self) -> f64 {
        self.stable_dt
    }

    /// Total force per node (springs, mass damping, external; µN) at
    /// the kernel's current state, into `out`.
    fn node_forces(&mut self, bc: &Boundary, out: &mut [DVec3]) {
        self.kernel.spring_pass();
        let (kernel, alpha, masses) = (&self.kernel, self.params.mass_damping, &self.masses);
        out.par_iter_mut()
            .enumerate()
            .with_min_len(2048)
            .for_each(|(n, o)| {
                let [fx, fy, fz] = kernel.node_force(n);
                let [vx, vy, vz] = kernel.node(n).1;
                let v = DVec3::new(vx as f64, vy as f64, vz as f64);
                *o = DVec3::new(fx as f64, fy as f64, fz as f64) + bc.force[n]
                    - alpha * masses[n] * v;
            });
    }

    fn step_explicit(
        &mut self,
        dt: f64,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        let needed = (dt / self.stable_dt).ceil().max(1.0);
        if needed > self.params.max_substeps as f64 {
            return Err(ModelError(format!(
                "mass-spring: the frame time step {dt} s needs {needed} explicit sub-steps of at \
                 most {:.3e} s (the stiffest spring's limit), above max_substeps = {}; raise \
                 max_substeps, lower the scene's dt_s, soften the stiffest material, or use \
                 integrator = \"implicit\"",
                self.stable_dt, self.params.max_substeps
            )));
        }
        let substeps = needed as u32;
        let h = dt / substeps as f64;
        if let Some(gpu) = &self.gpu {
            gpu.frame(
                substeps,
                h,
                self.params.mass_damping,
                &self.masses,
                bc,
                state,
            )?;
            bc.impose(&mut state.u);
            return Ok(SolveReport {
                substeps,
                ..SolveReport::default()
            });
        }
        let free: Vec<bool> = bc.constrained().iter().map(|c| !c).collect();
        let fixed: Vec<usize> = (0..free.len()).filter(|&n| bc.fixed[n]).collect();
        let start_u = state.u.clone();
        self.kernel.load(&state.u, &state.v);
        let ext: Vec<[f32; 4]> = bc
            .force
            .iter()
            .map(|f| [f.x as f32, f.y as f32, f.z as f32, 0.0])
            .collect();
        let inv_mass: Vec<f32> = self.masses.iter().map(|&m| (1.0 / m) as f32).collect();
        let step = Substep {
            h: h as f32,
            ext: &ext,
            inv_mass: &inv_mass,
            free: &free,
            alpha: self.params.mass_damping as f32,
            hanging: &bc.hanging,
        };
        // Imposed nodes: fixed ones stay (the integrator leaves them), driven
        // ones move linearly to their targets over the frame, hanging ones
        // follow their masters.
        for &n in &fixed {
            self.kernel.set_node(n, [0.0; 3], [0.0; 3]);
        }
        let drive = |s: u32, rows: &mut NodeRows| {
            let frac = s as f64 / substeps as f64;
            for &(n, target) in &bc.driven {
                let n = n as usize;
                let u = start_u[n].lerp(target, frac);
                let now = DVec3::from_array(rows.node(n).0.map(f64::from));
                rows.set_node(
                    n,
                    u.as_vec3().to_array(),
                    ((u - now) / h).as_vec3().to_array(),
                );
            }
            rows.tie(&bc.hanging);
        };
        let fixup: Option<Fixup> =
            (!bc.driven.is_empty() || !bc.hanging.is_empty()).then_some(&drive);
        self.kernel.substeps(substeps, &step, fixup);
        self.kernel.store(&mut state.u, &mut state.v);
        bc.impose(&mut state.u);
        Ok(SolveReport {
            substeps,
            ..SolveReport::default()
        })
    }

    fn step_implicit(
        &mut self,
        dt: f64,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        // Linearised backward Euler for the velocity change Δv:
        // (M + h C + h² K) Δv = h (f(x, v) − h K v), with K = −∂f/∂x (the
        // springs' tangent stiffness) and C = −∂f/∂v (spring damping along
        // the springs, and α M).
        let h = dt;
        let x: Vec<DVec3> = self
            .rest
            .iter()
            .zip(&state.u)
            .map(|(r, u)| *r + *u)
            .collect();
        let mut f = vec![DVec3::ZERO; x.len()];
        self.kernel.load(&state.u, &state.v);
        self.node_forces(bc, &mut f);
        let s = &self.springs;
        // Per spring: the tangent stiffness (the transverse term clamped at
        // zero for compressed springs, so the system stays positive
        // definite) and the damping direction `d dᵀ`.
        let tangents: Vec<(DMat3, DMat3)> = (0..s.ends.len())
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let [a, b] = s.ends[i].map(|n| n as usize);
                let d = x[b] - x[a];
                let len = d.length().max(f64::MIN_POSITIVE);
                let dir = d / len;
                let ddt = DMat3::from_cols(dir * dir.x, dir * dir.y, dir * dir.z);
                let transverse = (1.0 - s.rest[i] / len).max(0.0);
                (
                    (ddt + (DMat3::IDENTITY - ddt) * transverse) * s.k[i],
                    ddt * s.c[i],
                )
            })
            .collect();
        // Volume springs in compression: `k_v g gᵀ` (the Gauss–Newton
        // part; the curvature term `k_v (V − V₀) ∂²V` is left out so the
        // system stays positive definite), g = ∂V/∂x now.
        let volumes = &self.volumes;
        let vol_grad = |t: usize| -> Option<(f64, [DVec3; 4])> {
            let c = volumes.corners.get(t)?;
            let rest = c.map(|i| self.rest[i as usize]);
            let now = c.map(|i| x[i as usize]);
            let v0 = (rest[1] - rest[0]).dot((rest[2] - rest[0]).cross(rest[3] - rest[0]));
            let v = (now[1] - now[0]).dot((now[2] - now[0]).cross(now[3] - now[0]));
            (v < v0).then(|| (volumes.k[t], volume_gradient(now)))
        };
        let blocks: Vec<DMat3> = self
            .tet_edges
            .par_iter()
            .enumerate()
            .flat_map_iter(|(t, edges)| {
                let mut k = [DMat3::ZERO; 16];
                if let Some((kv, g)) = vol_grad(t) {
                    for a in 0..4 {
                        for b in 0..4 {
                            let outer =
                                DMat3::from_cols(g[a] * g[b].x, g[a] * g[b].y, g[a] * g[b].z);
                            k[4 * a + b] += outer * (kv * h * h);
                        }
                    }
                }
                for (e, &(spring, share)) in edges.iter().enumerate() {
                    let (kk, cc) = tangents[spring as usize];
                    let block = (kk * (h * h) + cc * h) * share;
                    let (ca, cb) = EDGES[e];
                    k[4 * ca + ca] += block;
                    k[4 * cb + cb] += block;
                    k[4 * ca + cb] -= block;
                    k[4 * cb + ca] -= block;
                }
                k.into_iter()
            })
            .collect();
        let alpha = self.params.mass_damping;
        let diagonal: Vec<f64> = self.masses.iter().map(|m| (1.0 + h * alpha) * m).collect();
        let matrix = self.matrix.as_mut().expect("implicit matrix");
        matrix.assemble(&blocks, Some(&diagonal));
        let mut kv = vec![DVec3::ZERO; x.len()];
        for (i, &[a, b]) in s.ends.iter().enumerate() {
            let t = tangents[i].0 * (state.v[a as usize] - state.v[b as usize]);
            kv[a as usize] += t;
            kv[b as usize] -= t;
        }
        for t in 0..volumes.corners.len() {
            if let Some((k, g)) = vol_grad(t) {
                let c = volumes.corners[t].map(|i| i as usize);
                let rate: f64 = (0..4).map(|j| g[j].dot(state.v[c[j]])).sum();
                for j in 0..4 {
                    kv[c[j]] += k * rate * g[j];
                }
            }
        }
        let rhs: Vec<DVec3> = f
            .iter()
            .zip(&kv)
            .map(|(fi, k)| h * (*fi - h * *k))
            .collect();
        // Imposed velocity changes: fixed nodes stop, driven ones reach
        // their targets this step, hanging ones follow their masters.
        let mut dv = vec![DVec3::ZERO; x.len()];
        for (n, fixed) in bc.fixed.iter().enumerate() {
            if *fixed {
                dv[n] = -state.v[n];
            }
        }
        for &(n, target) in &bc.driven {
            let n = n as usize;
            dv[n] = (target - state.u[n]) / h - state.v[n];
        }
        let free: Vec<bool> = bc.constrained().iter().map(|c| !c).collect();
        let settings = CgSettings {
            tolerance: self.params.cg_tolerance,
            max_iterations: self.params.cg_max_iterations,
        };
        let out = match &self.gpu_pcg {
            Some(g) => g
                .solve(matrix, &free, &bc.hanging, &rhs, &mut dv, settings)
                .map_err(|e| ModelError(format!("mass-spring (GPU): {e}")))?,
            None => pcg::solve(matrix, bc, &free, &rhs, &mut dv, settings),
        };
        for ((u, v), d) in state.u.iter_mut().zip(state.v.iter_mut()).zip(&dv) {
            *v += *d;
            *u += h * *v;
        }
        bc.impose(&mut state.u);
        let converged = pcg::warn_unconverged(
            Self::NAME,
            "implicit step's",
            out,
            settings,
            "raise cg_max_iterations, lower the time step or raise damping",
        );
        let mut report = SolveReport {
            substeps: 1,
            ..SolveReport::default()
        };
        report.add_solve(out, converged);
        Ok(report)
    }
}

impl MeshSolver for MassSpring {
    const NAME: &'static str = "mass-spring";
    const DESCRIPTION: &'static str = "mass-spring model on a tetrahedral proxy's edges (implicit backward Euler, or explicit with stable sub-steps)";
    type Params = SpringParams;
    /// 3 voxels: the combined front over the grab, two-material and cut
    /// fronts has no knee (it is straight in log–log), so the default is
    /// the most accurate spacing that keeps the interactive reference scene
    /// within 30 frames/s on 2 cores (docs/BENCHMARKS.md, "Combined
    /// fronts").
    const DEFAULT_NODE_SPACING: usize = 3;

    fn new(
        mesh: &TetMesh,
        materials: &[ElasticMaterial],
        params: SpringParams,
    ) -> Result<Self, ModelError> {
        params.validate()?;
        let masses = lumped_masses(mesh, materials);
        let mut index: HashMap<[u32; 2], u32> = HashMap::new();
        let mut springs = Springs::default();
        let mut tet_edges = Vec::with_capacity(mesh.tets.len());
        for (t, tet) in mesh.tets.iter().enumerate() {
            let e_mod = materials[mesh.labels[t] as usize].youngs_modulus;
            let v = mesh.volume(t);
            let mut edges = [(0u32, 0.0f64); 6];
            for (e, &(a, b)) in EDGES.iter().enumerate() {
                let key = [tet[a].min(tet[b]), tet[a].max(tet[b])];
                let len = (mesh.nodes[key[1] as usize] - mesh.nodes[key[0] as usize]).length();
                let k = e_mod * v / (len * len);
                let id = *index.entry(key).or_insert_with(|| {
                    springs.ends.push(key);
                    springs.rest.push(len);
                    springs.k.push(0.0);
                    springs.ends.len() as u32 - 1
                });
                springs.k[id as usize] += k;
                edges[e] = (id, k);
            }
            tet_edges.push(edges);
        }
        // Springs in order of their ends, so that the force kernel reads
        // nodes and each node gathers its springs from nearby memory.
        let mut order: Vec<u32> = (0..springs.ends.len() as u32).collect();
        order.sort_unstable_by_key(|&i| springs.ends[i as usize]);
        let mut new_id = vec![0u32; order.len()];
        for (new, &old) in order.iter().enumerate() {
            new_id[old as usize] = new as u32;
        }
        springs.ends = order.iter().map(|&i| springs.ends[i as usize]).collect();
        springs.rest = order.iter().map(|&i| springs.rest[i as usize]).collect();
        springs.k = order.iter().map(|&i| springs.k[i as usize]).collect();
        for edges in &mut tet_edges {
            for (id, _) in edges.iter_mut() {
                *id = new_id[*id as usize];
            }
        }
        // Each tetrahedron's share of its edges' stiffness, as a fraction.
        for edges in &mut tet_edges {
            for (id, k) in edges.iter_mut() {
                *k /= springs.k[*id as usize];
            }
        }
        springs.c = springs
            .ends
            .iter()
            .zip(&springs.k)
            .map(|(&[a, b], &k)| {
                let (ma, mb) = (masses[a as usize], masses[b as usize]);
                let reduced = ma * mb / (ma + mb);
                params.damping_ratio * 2.0 * (k * reduced).sqrt()
            })
            .collect();
        let n = mesh.nodes.len();
        let volumes = if params.volume_stiffness > 0.0 {
            VolumeSprings {
                corners: mesh.tets.clone(),
                k: (0..mesh.tets.len())
                    .map(|t| {
                        let e_mod = materials[mesh.labels[t] as usize].youngs_modulus;
                        params.volume_stiffness * e_mod / mesh.volume(t)
                    })
                    .collect(),
            }
        } else {
            VolumeSprings::default()
        };
        // Gershgorin: ω² ≤ max_i (row sum of |K| at node i) / m_i, with
        // 2 k per spring, and per volume spring (`K = k_v g gᵀ` at rest, g
        // = ∂V/∂x) `k_v |g_i|_∞ Σ_j |g_j|_1`.
        let mut ksum = vec![0.0; n];
        for ([a, b], k) in springs.ends.iter().zip(&springs.k) {
            ksum[*a as usize] += 2.0 * k;
            ksum[*b as usize] += 2.0 * k;
        }
        for (c, kv) in volumes.corners.iter().zip(&volumes.k) {
            let g = volume_gradient(c.map(|i| mesh.nodes[i as usize]));
            let total: f64 = g.iter().map(|v| v.abs().element_sum()).sum();
            for (i, gi) in c.iter().zip(g) {
                ksum[*i as usize] += kv * gi.abs().max_element() * total;
            }
        }
        let omega2 = ksum
            .iter()
            .zip(&masses)
            .map(|(k, m)| if *m > 0.0 { k / m } else { 0.0 })
            .fold(0.0, f64::max);
        let stable_dt = if omega2 > 0.0 {
            0.9 * 2.0 / omega2.sqrt()
        } else {
            f64::INFINITY
        };
        let matrix =
            (params.integrator == Integrator::Implicit).then(|| BlockMatrix::on_mesh(mesh));
        Ok(Self {
            kernel: SpringKernel::new(&springs, &volumes, &mesh.nodes),
            volumes,
            gpu: None,
            gpu_pcg: None,
            params,
            rest: mesh.nodes.clone(),
            masses,
            springs,
            stable_dt,
            tet_edges,
            matrix,
        })
    }

    const GPU: bool = true;

    const INVERSION_HINT: &'static str = "; raise `volume_stiffness` (its volume springs push \
        inverted tetrahedra back through; 0 turns them off)";

    fn use_gpu(&mut self, gpu: Arc<dyn GpuService>) -> Result<(), ModelError> {
        match (&self.params.integrator, &self.matrix) {
            (Integrator::Implicit, Some(matrix)) => {
                self.gpu_pcg = Some(
                    GpuPcg::new(gpu, matrix)
                        .map_err(|e| ModelError(format!("mass-spring (GPU): {e}")))?,
                );
            }
            _ => self.gpu = Some(GpuSprings::new(gpu, &self.kernel, self.rest.len())?),
        }
        Ok(())
    }

    fn step(
        &mut self,
        dt_s: f64,
        bc: &Boundary,
        state: &mut NodeState,
    ) -> Result<SolveReport, ModelError> {
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(ModelError(format!(
                "mass-spring: needs a positive frame time step (got {dt_s} s); set the scene's dt_s"
            )));
        }
        match self.params.integrator {
            Integrator::Explicit => self.step_explicit(dt_s, bc, state),
            Integrator::Implicit => self.step_implicit(dt_s, bc, state),
        }
    }
}
