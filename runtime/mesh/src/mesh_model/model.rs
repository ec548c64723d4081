//! [`MeshModel`]: a [`MeshSolver`] wrapped into a whole deformation model.

use super::boundary::{Boundary, reach_at, traction_faces};
use super::carve::{GONE, carve_mesh, keep_nodes};
use super::cut::cut_mesh;
use super::inversion::{InversionWatch, inverted_tetrahedra};
use super::material::{ElasticMaterial, lumped_masses};
use super::params::{MeshModelParams, ProxySpec, solver_params, split};
use super::pieces::unanchored_pieces;
use super::{MeshSolver, NodeState, SolveReport};
use crate::barycentric;
use crate::barycentric::{BarycentricBinding, GpuBinding};
use crate::cut_polygon::CutPolygon;
use crate::deformation::{
    BindingId, DeformationModel, DirtyRegion, DisplacementTarget, ExecutionBackend, FrameInfo,
    ModelNotes, RestPoints, StepOutcome,
};
use crate::error::ModelError;
use crate::gpu::{BufferId, GpuService};
use crate::grid::Grid;
use crate::interaction::{CarveRegion, FarGrabs, GrabMotion, InteractionSpec};
use crate::proxy::{HangingNode, octree_proxy, uniform_proxy_with_losses};
use crate::tet_mesh::TetMesh;
use crate::volume::VolumeView;
use glam::DVec3;
use std::sync::Arc;
use voxflex_io::{msh::read_msh, tetgen::read_tetgen, vtu::write_vtu_with};
use voxflex_resample::{tets_at_vertex, tets_cut_by};

/// A node moved by less than this (mm) in a step does not count as a
/// change (downstream stages skip a frame where nothing moved more).
const STILL_MM: f64 = 1e-6;

/// A load being ramped in.
struct Load {
    /// Full nodal forces, µN.
    forces: Vec<DVec3>,
    /// A traction's faces and their full forces ([`Boundary::faces`]).
    faces: Vec<([u32; 3], DVec3)>,
    frames: u64,
    done: u64,
}

/// A grabbed node and where it goes.
struct Grab {
    node: u32,
    motion: GrabMotion,
    /// Displacement it is held at, mm.
    held: DVec3,
}

/// A mesh-based deformation model: the proxy, its boundary conditions and
/// bindings, around solver `S`.
pub struct MeshModel<S: MeshSolver> {
    params: MeshModelParams,
    solver_params: Option<S::Params>,
    built: Option<Built<S>>,
    bindings: Vec<Bound>,
    grabs: Vec<Grab>,
    loads: Vec<Load>,
    /// The field changed since the last `map`.
    unmapped: bool,
    last: SolveReport,
    /// Steps, sub-steps and linear-solver iterations since `init`.
    totals: SolveTotals,
    /// The host's GPU service, if it offered one.
    gpu: Option<Arc<dyn GpuService>>,
    /// On the GPU backend: the node displacements as `[x, y, z, 0]` and
    /// each binding on the device (re-uploaded after a cut).
    device: Option<DeviceMap>,
    /// Labelled voxels no proxy cell of their material covers (proxies
    /// built from the volume; `proxy::unrepresented_voxels`).
    labelled_voxels_lost: usize,
    /// Bound points (voxel centres, tracked points) that the cuts so far
    /// left carried by a proxy tetrahedron on the other side of the cut.
    cut_voxels_across: usize,
    /// Bound points (voxel centres, tracked points) that cuts found across
    /// from their carrying tetrahedron and bound to one of their own side.
    cut_voxels_rebound: usize,
    /// Inverted tetrahedra after each frame.
    inversions: InversionWatch,
    /// Grabs whose point lay beyond one element from the proxy.
    far_grabs: FarGrabs,
}

/// Counts summed over a run's steps.
#[derive(Clone, Copy, Debug, Default)]
struct SolveTotals {
    steps: u64,
    substeps: u64,
    iterations: u64,
    /// Compliance solves asked for by actuators.
    compliance_solves: u64,
    /// Linear solves that stopped above their tolerance, and the largest
    /// relative residual of any solve.
    unconverged: u64,
    worst_residual: f64,
}

/// The device side of `map` on the GPU backend.
struct DeviceMap {
    nodes: BufferId,
    node_count: usize,
    /// The [`Built::version`] of the mesh the bindings were uploaded for.
    version: u64,
    bindings: Vec<Option<GpuBinding>>,
}

/// A binding, and for a lattice of voxel centres its grid and the
/// sampling-mesh tetrahedra the model's cuts removed.
struct Bound {
    binding: BarycentricBinding,
    lattice: Option<Grid>,
    /// The rest points (mm) of a binding that is not a lattice, to bind
    /// them again after a carve.
    points: Vec<DVec3>,
    /// `(cell, tetrahedron bits)` removed by cuts.
    removed: Vec<(usize, u8)>,
    /// Removed tetrahedra not yet reported to the host.
    unreported: bool,
    /// External forces on the points (µN; empty: none), set by
    /// `set_point_loads` and spread onto the nodes every step.
    loads: Vec<DVec3>,
}

/// What `init` builds.
struct Built<S: MeshSolver> {
    mesh: TetMesh,
    materials: Vec<ElasticMaterial>,
    solver: S,
    /// The solver's parameters, to rebuild it after a cut.
    solver_params: S::Params,
    state: NodeState,
    /// Fixed nodes and hanging ties (forces and drives are set per step).
    bc: Boundary,
    /// Gravity's nodal forces, µN.
    gravity: Vec<DVec3>,
    /// The displacements as f32 arrays, for `map`.
    u32: [Vec<f32>; 3],
    /// Bumped by every change of topology (cut, carve).
    version: u64,
    /// The last frame's nodal forces before the point loads (µN), and the
    /// state and time step it started from: what `resolve` repeats.
    frame_forces: Vec<DVec3>,
    step_start: Option<(NodeState, f64)>,
}

impl<S: MeshSolver> Built<S> {
    /// Current node positions, mm.
    fn positions(&self) -> Vec<DVec3> {
        self.mesh
            .nodes
            .iter()
            .zip(&self.state.u)
            .map(|(r, u)| *r + *u)
            .collect()
    }
}

impl<S: MeshSolver> MeshModel<S> {
    /// A model from the TOML text of its `[model.params.<plugin>]` table;
    /// the proxy is built in `init`.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let (params, rest) = split(S::NAME, text)?;
        let solver_params = solver_params::<S::Params>(S::NAME, rest)?;
        Ok(Self::new(params, solver_params))
    }

    /// A model from parsed parameters.
    /// A scene without a `proxy` key gets the solver's
    /// ([`MeshSolver::default_proxy`]).
    pub fn new(mut params: MeshModelParams, solver_params: S::Params) -> Self {
        if params.proxy.is_none() {
            params.proxy = Some(S::default_proxy(&solver_params));
        }
        Self {
            params,
            solver_params: Some(solver_params),
            built: None,
            bindings: Vec::new(),
            grabs: Vec::new(),
            loads: Vec::new(),
            unmapped: true,
            last: SolveReport::default(),
            totals: SolveTotals::default(),
            gpu: None,
            device: None,
            labelled_voxels_lost: 0,
            cut_voxels_across: 0,
            cut_voxels_rebound: 0,
            inversions: InversionWatch::default(),
            far_grabs: FarGrabs::default(),
        }
    }

    /// The host's GPU service, for `backend = "gpu"`.
    pub fn with_gpu(mut self, gpu: Option<Arc<dyn GpuService>>) -> Self {
        self.gpu = gpu;
        self
    }

    /// Builds the model on a given mesh (labels are material indices) with
    /// the given materials, bypassing the scene's proxy: for programs and
    /// tests that bring their own mesh.
    pub fn with_mesh(
        mesh: TetMesh,
        materials: Vec<ElasticMaterial>,
        gravity: DVec3,
        solver_params: S::Params,
    ) -> Result<Self, ModelError> {
        let mut m = Self::new(
            MeshModelParams {
                proxy: Some(S::default_proxy(&solver_params)),
                materials: Vec::new(),
                gravity: gravity.to_array(),
                vtu: None,
            },
            solver_params,
        );
        m.build(mesh, materials, Vec::new())?;
        Ok(m)
    }

    fn build(
        &mut self,
        mesh: TetMesh,
        materials: Vec<ElasticMaterial>,
        hanging: Vec<HangingNode>,
    ) -> Result<(), ModelError> {
        if let Some(&l) = mesh.labels.iter().find(|&&l| l as usize >= materials.len()) {
            return Err(ModelError(format!(
                "{}: a tetrahedron has material {l} but there are {} materials",
                S::NAME,
                materials.len()
            )));
        }
        let params = self
            .solver_params
            .take()
            .ok_or_else(|| ModelError(format!("{}: init called twice", S::NAME)))?;
        let solver = S::new(&mesh, &materials, params.clone())?;
        let n = mesh.nodes.len();
        let g = DVec3::from_array(self.params.gravity);
        let gravity = lumped_masses(&mesh, &materials)
            .into_iter()
            .map(|m| m * g)
            .collect();
        let mut bc = Boundary::new(n);
        bc.hanging = hanging;
        tracing::info!(
            nodes = n,
            tetrahedra = mesh.tets.len(),
            hanging = bc.hanging.len(),
            "{}: proxy built",
            S::NAME
        );
        self.built = Some(Built {
            mesh,
            materials,
            solver,
            solver_params: params,
            state: NodeState::at_rest(n),
            bc,
            gravity,
            u32: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            version: 0,
            frame_forces: Vec::new(),
            step_start: None,
        });
        Ok(())
    }

    fn built(&self) -> Result<&Built<S>, ModelError> {
        built_ref(&self.built)
    }

    /// The proxy (after `init`).
    pub fn mesh(&self) -> Option<&TetMesh> {
        self.built.as_ref().map(|b| &b.mesh)
    }

    /// The nodes' displacements (mm) and velocities (mm/s), after `init`.
    pub fn state(&self) -> Option<&NodeState> {
        self.built.as_ref().map(|b| &b.state)
    }

    /// Puts the nodes at displacements `u` (mm), at rest (zero velocity):
    /// for programs and tests that start from a deformed state.
    pub fn set_displacements(&mut self, u: &[DVec3]) -> Result<(), ModelError> {
        let b = built_mut(&mut self.built)?;
        if u.len() != b.state.u.len() || u.iter().any(|v| !v.is_finite()) {
            return Err(ModelError(format!(
                "{}: {} displacements given for {} nodes (all must be finite)",
                S::NAME,
                u.len(),
                b.state.u.len()
            )));
        }
        b.state.u.copy_from_slice(u);
        b.state.v.iter_mut().for_each(|v| *v = DVec3::ZERO);
        // `map` reads the f32 copy: keep it in step.
        for (n, u) in u.iter().enumerate() {
            for a in 0..3 {
                b.u32[a][n] = u[a] as f32;
            }
        }
        self.unmapped = true;
        Ok(())
    }

    /// The hanging-node ties of an octree proxy (after `init`).
    pub fn hanging(&self) -> &[HangingNode] {
        self.built.as_ref().map_or(&[], |b| &b.bc.hanging)
    }

    /// The solver (after `init`).
    pub fn solver(&self) -> Option<&S> {
        self.built.as_ref().map(|b| &b.solver)
    }

    /// What the last step's solve did.
    pub fn last_solve(&self) -> SolveReport {
        self.last
    }

    /// Builds the proxy and materials the scene asks for from `volume`.
    fn proxy(
        &self,
        volume: VolumeView<'_>,
    ) -> Result<(TetMesh, Vec<ElasticMaterial>, Vec<HangingNode>, usize), ModelError> {
        let name = S::NAME;
        let specs = &self.params.materials;
        let materials: Vec<ElasticMaterial> =
            specs.iter().map(ElasticMaterial::from_spec).collect();
        let mesh_error = |e: crate::error::MeshError| ModelError(format!("{name}: {e}"));
        let spec = self
            .params
            .proxy
            .clone()
            .or_else(|| self.solver_params.as_ref().map(S::default_proxy))
            .ok_or_else(|| ModelError(format!("{name}: no proxy and no solver keys")))?;
        match &spec {
            ProxySpec::File { path } => {
                let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
                let mut mesh = match ext {
                    "msh" => read_msh(path),
                    "node" => read_tetgen(path),
                    _ => {
                        return Err(ModelError(format!(
                            "{name} proxy: {} is neither a Gmsh `.msh` nor a TetGen `.node` file",
                            path.display()
                        )));
                    }
                }
                .map_err(|e| ModelError(format!("{name} proxy: {e}")))?;
                for l in mesh.labels.iter_mut() {
                    let m = specs
                        .iter()
                        .position(|s| s.label == Some(*l))
                        .ok_or_else(|| {
                            ModelError(format!(
                                "{name} proxy: {} has tetrahedra tagged {l} but no material has \
                             `label = {l}`; add one to `materials`",
                                path.display()
                            ))
                        })?;
                    *l = m as u16;
                }
                Ok((mesh, materials, Vec::new(), 0))
            }
            proxy => {
                let labels = voxel_materials(volume, specs);
                let g = volume.grid;
                let label = |v: [usize; 3]| {
                    let l = labels[g.linear(v[0], v[1], v[2])];
                    (l != u16::MAX).then_some(l)
                };
                let (mesh, hanging, lost) = match proxy {
                    ProxySpec::Uniform { step } => {
                        let (mesh, lost) =
                            uniform_proxy_with_losses(&g, *step, label).map_err(mesh_error)?;
                        (mesh, Vec::new(), lost)
                    }
                    ProxySpec::Octree { max_cell } => {
                        let p = octree_proxy(&g, *max_cell, label).map_err(mesh_error)?;
                        let lost = p.unrepresented_voxels(g.dims, &label);
                        (p.mesh, p.hanging, lost)
                    }
                    ProxySpec::File { .. } => unreachable!("handled above"),
                };
                if lost > 0 {
                    tracing::warn!(
                        labelled_voxels_lost = lost,
                        "{name}: {lost} labelled voxels lie in proxy cells of another material \
                         (features smaller than a cell) and move with that material; lower \
                         `proxy.step`, or use `proxy = {{ kind = \"octree\", max_cell = … }}`, \
                         whose leaves follow material boundaries"
                    );
                }
                Ok((mesh, materials, hanging, lost))
            }
        }
    }

    /// Moves the solver and `map` onto the host's GPU.
    pub fn use_gpu(&mut self) -> Result<(), ModelError> {
        let gpu = self.gpu.clone().ok_or_else(|| {
            ModelError(format!(
                "{}: backend is gpu but the host offered no GPU service",
                S::NAME
            ))
        })?;
        let b = built_mut(&mut self.built)?;
        b.solver.use_gpu(gpu)?;
        self.device = Some(DeviceMap {
            nodes: BufferId(u64::MAX),
            node_count: 0,
            version: 0,
            bindings: Vec::new(),
        });
        Ok(())
    }

    /// Maps a binding into device buffers: the node displacements go up
    /// (16 B per node) and the barycentric map runs on the device.
    fn map_on_device(&mut self, binding: usize, out: [BufferId; 3]) -> Result<(), ModelError> {
        let name = S::NAME;
        let gpu = self
            .gpu
            .clone()
            .ok_or_else(|| ModelError(format!("{name}: a GPU target needs the GPU backend")))?;
        let b = built_ref(&self.built)?;
        let device = self
            .device
            .as_mut()
            .ok_or_else(|| ModelError(format!("{name}: a GPU target needs backend = \"gpu\"")))?;
        let n = b.mesh.nodes.len();
        if device.node_count != n {
            if device.node_count != 0 {
                gpu.destroy_buffer(device.nodes);
            }
            device.nodes = gpu.create_buffer(16 * n as u64, "mesh model nodes")?;
            device.node_count = n;
        }
        if device.version != b.version {
            // The tetrahedra changed (a cut or carve): upload the bindings
            // again.
            for old in device.bindings.drain(..).flatten() {
                old.release(&*gpu);
            }
            device.version = b.version;
        }
        let nodes: Vec<[f32; 4]> = (0..n)
            .map(|i| [b.u32[0][i], b.u32[1][i], b.u32[2][i], 0.0])
            .collect();
        gpu.write_buffer(device.nodes, 0, bytemuck::cast_slice(&nodes))?;
        if device.bindings.len() <= binding {
            device.bindings.resize_with(binding + 1, || None);
        }
        if device.bindings[binding].is_none() {
            device.bindings[binding] = Some(self.bindings[binding].binding.upload(&b.mesh, &*gpu)?);
        }
        let bound = device.bindings[binding].as_ref().expect("uploaded above");
        bound.map(&*gpu, device.nodes, out)?;
        Ok(())
    }

    /// The nodes within `[lo, hi]` (rest positions, mm).
    fn nodes_in(mesh: &TetMesh, lo: DVec3, hi: DVec3) -> Vec<u32> {
        (0..mesh.nodes.len() as u32)
            .filter(|&n| {
                let p = mesh.nodes[n as usize];
                p.cmpge(lo).all() && p.cmple(hi).all()
            })
            .collect()
    }

    fn apply(&mut self, spec: &InteractionSpec) -> Result<(), ModelError> {
        let name = S::NAME;
        let b = built_mut(&mut self.built)?;
        match spec {
            InteractionSpec::Grab { point, .. } => {
                // The node whose *rest* position is nearest the point (the
                // rule of every model: a drag re-sends the same point with a
                // new target and keeps the same node however far it moved).
                // A cut's duplicates share a rest position: among them the
                // one already held (a drag goes on with it), then the one
                // nearest the point now.
                let p = DVec3::from_array(*point);
                let held: Vec<u32> = self.grabs.iter().map(|g| g.node).collect();
                let key = |n: usize| {
                    (
                        (b.mesh.nodes[n] - p).length_squared(),
                        !held.contains(&(n as u32)),
                        (b.mesh.nodes[n] + b.state.u[n] - p).length_squared(),
                    )
                };
                let node = (0..b.mesh.nodes.len())
                    .min_by(|&x, &y| {
                        let (kx, ky) = (key(x), key(y));
                        kx.0.total_cmp(&ky.0)
                            .then(kx.1.cmp(&ky.1))
                            .then(kx.2.total_cmp(&ky.2))
                    })
                    .ok_or_else(|| ModelError(format!("{name} grab: the proxy has no node")))?;
                let now = b.mesh.nodes[node] + b.state.u[node];
                self.far_grabs
                    .check(name, p, b.mesh.nodes[node], reach_at(&b.mesh, node as u32));
                let motion = GrabMotion::new(spec, now).expect("a grab has a motion");
                let held = b.state.u[node];
                self.grabs.retain(|g| g.node != node as u32);
                self.grabs.push(Grab {
                    node: node as u32,
                    motion,
                    held,
                });
            }
            InteractionSpec::Fix { min, max, material } => {
                let mat = match material {
                    Some(m) => Some(
                        b.materials
                            .iter()
                            .position(|x| x.name.as_deref() == Some(m.as_str()))
                            .ok_or_else(|| {
                                ModelError(format!("{name} fix: no material is named `{m}`"))
                            })? as u16,
                    ),
                    None => None,
                };
                let mut of_material = vec![mat.is_none(); b.mesh.nodes.len()];
                if let Some(m) = mat {
                    for (t, tet) in b.mesh.tets.iter().enumerate() {
                        if b.mesh.labels[t] == m {
                            for &n in tet {
                                of_material[n as usize] = true;
                            }
                        }
                    }
                }
                let inside = |p: DVec3| match (min, max) {
                    (Some(lo), Some(hi)) => {
                        p.cmpge(DVec3::from_array(*lo)).all()
                            && p.cmple(DVec3::from_array(*hi)).all()
                    }
                    _ => true,
                };
                let mut fixed = 0;
                for (n, &of) in of_material.iter().enumerate() {
                    if of && inside(b.mesh.nodes[n]) {
                        b.bc.fixed[n] = true;
                        b.state.u[n] = DVec3::ZERO;
                        b.state.v[n] = DVec3::ZERO;
                        fixed += 1;
                    }
                }
                if fixed == 0 {
                    tracing::warn!("{name} fix: no node lies in the region");
                }
            }
            InteractionSpec::Release => self.grabs.clear(),
            InteractionSpec::Load {
                min,
                max,
                traction,
                force,
                frames,
            } => {
                let (lo, hi) = (DVec3::from_array(*min), DVec3::from_array(*max));
                let mut forces = vec![DVec3::ZERO; b.mesh.nodes.len()];
                let mut loaded = Vec::new();
                match (traction, force) {
                    (Some(t), _) => {
                        loaded = traction_faces(&b.mesh, lo, hi, DVec3::from_array(*t));
                        for (f, force) in &loaded {
                            for &n in f {
                                forces[n as usize] += *force / 3.0;
                            }
                        }
                        if loaded.is_empty() {
                            return Err(ModelError(format!(
                                "{name} load: no boundary face of the proxy has its centre in \
                                 the box {min:?}..{max:?} (mm)"
                            )));
                        }
                    }
                    (None, Some(f)) => {
                        let nodes = Self::nodes_in(&b.mesh, lo, hi);
                        if nodes.is_empty() {
                            return Err(ModelError(format!(
                                "{name} load: no node of the proxy lies in the box \
                                 {min:?}..{max:?} (mm)"
                            )));
                        }
                        // N → µN, shared equally.
                        let each = DVec3::from_array(*f) * 1e6 / nodes.len() as f64;
                        for n in nodes {
                            forces[n as usize] = each;
                        }
                    }
                    (None, None) => unreachable!("validated by InteractionSpec::from_toml"),
                }
                self.loads.push(Load {
                    forces,
                    faces: loaded,
                    frames: *frames,
                    done: 0,
                });
            }
            InteractionSpec::Cut { polygon } => {
                let cut = CutPolygon::new(polygon);
                self.cut(&cut)?;
            }
            InteractionSpec::Carve { .. } => {
                let region = CarveRegion::of(spec).expect("a carve validated on parsing");
                self.carve(&region)?;
            }
        }
        Ok(())
    }

    /// Cuts the proxy along `cut` (current positions) by duplicating nodes,
    /// rebuilds the solver on the cut mesh, and marks the sampling-mesh
    /// tetrahedra of every lattice binding that the cut crosses.
    fn cut(&mut self, cut: &CutPolygon) -> Result<(), ModelError> {
        let name = S::NAME;
        let b = built_mut(&mut self.built)?;
        let x: Vec<DVec3> = b.positions();
        // The lattice bindings' removed tetrahedra, and the points the cut
        // leaves across from their carrying tetrahedron (bound anew on their
        // own side), from the positions before the cut (both sides still
        // coincide there). Tetrahedron indices survive `cut_mesh`.
        let (mut rebound, mut across) = (0, 0);
        // A point carried across lies in its tetrahedron, which the cut
        // crosses: within the largest tetrahedron's extent of the polygon.
        let reach = DVec3::splat(largest_extent(&b.mesh, &x));
        let mut star = None;
        for bound in &mut self.bindings {
            let near = points_near(bound, b, (cut.lo - reach, cut.hi + reach));
            let (r, left) = rebind_across(bound, &near, &b.mesh, &x, cut, &mut star);
            rebound += r;
            across += left;
            let Some(near) = lattice_near(bound, b, (cut.lo, cut.hi)) else {
                continue;
            };
            let removed = tets_cut_by(near.cells, (near.first, near.end), &near.positions, cut);
            bound.unreported |= !removed.is_empty();
            bound.removed.extend(removed);
        }
        let result = cut_mesh(&mut b.mesh, &x, cut);
        if result.faces == 0 {
            tracing::warn!("{name} cut: the polygon crosses no face of the proxy");
            return Ok(());
        }
        for &n in &result.origin {
            let n = n as usize;
            b.state.u.push(b.state.u[n]);
            b.state.v.push(b.state.v[n]);
            b.bc.fixed.push(b.bc.fixed[n]);
            for a in 0..3 {
                b.u32[a].push(b.u32[a][n]);
            }
        }
        // A load keeps acting on the nodes it was defined on; copies start
        // without it.
        let nodes = b.mesh.nodes.len();
        for load in &mut self.loads {
            load.forces.resize(nodes, DVec3::ZERO);
        }
        self.topology_changed("cut")?;
        self.cut_voxels_rebound += rebound;
        if rebound > 0 {
            tracing::info!(
                "{name} cut: {rebound} voxel centres across the cut from the proxy tetrahedron \
                 that carried them now follow a tetrahedron of their own side"
            );
        }
        if across > 0 {
            self.cut_voxels_across += across;
            tracing::warn!(
                "{name} cut: {across} voxel centres lie across the cut from the proxy \
                 tetrahedron that carries them, with no tetrahedron of their own side around \
                 it, and move with the other piece; a finer `proxy` or the chainmail plugin \
                 cuts voxel-sharp (note `cut_voxels_across`)"
            );
        }
        tracing::info!(
            faces = result.faces,
            new_nodes = result.origin.len(),
            "{name}: proxy cut"
        );
        Ok(())
    }

    /// After a `what` (cut or carve) changed the mesh: gravity's nodal
    /// forces, the solver (on the GPU if it was there), and the bindings on
    /// the device follow the new mesh; a warning names pieces it severed
    /// from every fixed or grabbed node.
    fn topology_changed(&mut self, what: &str) -> Result<(), ModelError> {
        let b = built_mut(&mut self.built)?;
        // A step from before the change cannot be repeated on the new mesh.
        b.step_start = None;
        let mut anchored = b.bc.fixed.clone();
        for g in &self.grabs {
            anchored[g.node as usize] = true;
        }
        if anchored.contains(&true) {
            let (pieces, nodes) = unanchored_pieces(&b.mesh, &b.bc.hanging, |n| anchored[n]);
            if pieces > 0 {
                tracing::warn!(
                    "{}: the {what} left {pieces} piece(s) ({nodes} nodes) attached to no \
                     fixed or grabbed node: they move freely (fall under gravity), and a \
                     static solve cannot place them; fix or grab them",
                    S::NAME
                );
            }
        }
        let nodes = b.mesh.nodes.len();
        b.bc.force.resize(nodes, DVec3::ZERO);
        let g = DVec3::from_array(self.params.gravity);
        b.gravity = lumped_masses(&b.mesh, &b.materials)
            .into_iter()
            .map(|m| m * g)
            .collect();
        b.solver = S::new(&b.mesh, &b.materials, b.solver_params.clone())?;
        if self.device.is_some()
            && let Some(gpu) = self.gpu.clone()
        {
            b.solver.use_gpu(gpu)?;
        }
        b.version += 1;
        self.unmapped = true;
        Ok(())
    }

    /// Removes the tetrahedra whose centroid (current positions) lies in
    /// `region`, and the nodes only they used; the points bound inside them
    /// follow the nearest remaining tetrahedron, and the sampling-mesh
    /// tetrahedra at every lattice point now in `region` are removed, so
    /// the hole shows in the resampled volume (the rule ChainMail's carve
    /// uses).
    fn carve(&mut self, region: &CarveRegion) -> Result<(), ModelError> {
        let name = S::NAME;
        let b = built_mut(&mut self.built)?;
        let x: Vec<DVec3> = b.positions();
        let carved = carve_mesh(&b.mesh, &x, region);
        if carved.removed == 0 {
            tracing::warn!(
                "{name} carve: no tetrahedron of the proxy has its centre in {region:?}"
            );
            return Ok(());
        }
        if carved.mesh.tets.is_empty() {
            return Err(ModelError(format!(
                "{name} carve: {region:?} (mm) holds the whole proxy; carve a smaller region"
            )));
        }
        // The sampling mesh first, from the positions before the carve.
        for bound in &mut self.bindings {
            let Some(near) = lattice_near(bound, b, region.bounds()) else {
                continue;
            };
            let mut removed = Vec::new();
            for (i, p) in near.positions.iter().enumerate() {
                if region.contains(*p) {
                    removed.extend(tets_at_vertex(near.cells, near.point(i)));
                }
            }
            bound.unreported |= !removed.is_empty();
            bound.removed.extend(removed);
        }
        let mut rebound = 0;
        for bound in &mut self.bindings {
            let (lattice, points) = (bound.lattice, &bound.points);
            rebound += bound
                .binding
                .after_removal(
                    &b.mesh,
                    &carved.mesh,
                    &carved.tet_index,
                    |i| match lattice {
                        Some(g) => {
                            let [x, y, z] = g.unlinear(i);
                            g.index_to_world(DVec3::new(x as f64, y as f64, z as f64))
                        }
                        None => points[i],
                    },
                );
        }
        let index = &carved.node_index;
        b.state.u = keep_nodes(&b.state.u, index);
        b.state.v = keep_nodes(&b.state.v, index);
        b.bc.fixed = keep_nodes(&b.bc.fixed, index);
        for a in 0..3 {
            b.u32[a] = keep_nodes(&b.u32[a], index);
        }
        // A hanging node keeps its tie while all of it remains.
        let ties = b.bc.hanging.len();
        b.bc.hanging = std::mem::take(&mut b.bc.hanging)
            .into_iter()
            .filter_map(|h| {
                let node = index[h.node as usize];
                let masters: Option<Vec<(u32, f32)>> = h
                    .masters
                    .iter()
                    .map(|&(m, w)| (index[m as usize] != GONE).then(|| (index[m as usize], w)))
                    .collect();
                Some(HangingNode {
                    node: (node != GONE).then_some(node)?,
                    masters: masters?,
                })
            })
            .collect();
        for load in &mut self.loads {
            load.forces = keep_nodes(&load.forces, index);
            load.faces.retain_mut(|(f, _)| {
                *f = f.map(|n| index[n as usize]);
                !f.contains(&GONE)
            });
        }
        let grabs = self.grabs.len();
        self.grabs.retain_mut(|g| {
            g.node = index[g.node as usize];
            g.node != GONE
        });
        tracing::info!(
            tetrahedra = carved.removed,
            nodes = index.iter().filter(|&&n| n == GONE).count(),
            rebound,
            hanging_ties_dropped = ties - b.bc.hanging.len(),
            grabs_dropped = grabs - self.grabs.len(),
            "{name}: proxy carved"
        );
        b.mesh = carved.mesh;
        self.topology_changed("carve")
    }

    /// One frame: grabs and loads advance, the solver steps.
    pub fn advance(&mut self, dt_s: f64) -> Result<bool, ModelError> {
        let b = self
            .built
            .as_mut()
            .ok_or_else(|| ModelError(format!("{}: step before init", S::NAME)))?;
        b.bc.driven.clear();
        for g in &mut self.grabs {
            if let Some(target) = g.motion.advance() {
                g.held = target - b.mesh.nodes[g.node as usize];
            }
            b.bc.driven.push((g.node, g.held));
        }
        b.bc.force.clone_from(&b.gravity);
        b.bc.gravity = DVec3::from_array(self.params.gravity);
        b.bc.faces.clear();
        for load in &mut self.loads {
            load.done = (load.done + 1).min(load.frames);
            let ramp = load.done as f64 / load.frames as f64;
            for (f, l) in b.bc.force.iter_mut().zip(&load.forces) {
                *f += ramp * *l;
            }
            b.bc.faces
                .extend(load.faces.iter().map(|&(f, force)| (f, ramp * force)));
        }
        b.frame_forces.clone_from(&b.bc.force);
        self.spread_point_loads();
        let b = built_mut(&mut self.built)?;
        b.step_start = Some((b.state.clone(), dt_s));
        self.solve_step(dt_s)
    }

    /// Adds every binding's point loads to the boundary's nodal forces.
    fn spread_point_loads(&mut self) {
        let Some(b) = self.built.as_mut() else {
            return;
        };
        for bound in self.bindings.iter().filter(|b| !b.loads.is_empty()) {
            bound.binding.spread(&b.mesh, &bound.loads, &mut b.bc.force);
        }
    }

    /// The frame's step again — from the state it started from, or for a
    /// static solver ([`MeshSolver::is_static`]) from the last answer —
    /// with the point loads as they are now set (the frame's grabs, ramped
    /// loads and gravity unchanged): how an actuator whose forces follow the
    /// body (a pressure on moving walls) reaches the equilibrium of its
    /// effort within one frame. Returns whether the field changed.
    pub fn resolve(&mut self) -> Result<bool, ModelError> {
        let b = built_mut(&mut self.built)?;
        let (start, dt_s) = b
            .step_start
            .clone()
            .ok_or_else(|| ModelError(format!("{}: resolve before a step", S::NAME)))?;
        b.bc.force.clone_from(&b.frame_forces);
        if !b.solver.is_static() {
            // A time step depends on where it starts: repeat it from there.
            // A static equilibrium does not, so it starts warm.
            b.state = start;
        }
        self.spread_point_loads();
        self.solve_step(dt_s)
    }

    /// The solver's step from the prepared boundary, then the checks, the
    /// counts and the f32 copy of the displacements.
    fn solve_step(&mut self, dt_s: f64) -> Result<bool, ModelError> {
        let b = built_mut(&mut self.built)?;
        let before = b.state.u.clone();
        self.last = b.solver.step(dt_s, &b.bc, &mut b.state)?;
        self.totals.steps += 1;
        self.totals.substeps += u64::from(self.last.substeps);
        self.totals.iterations += u64::from(self.last.iterations);
        self.totals.unconverged += u64::from(self.last.unconverged);
        self.totals.worst_residual = self.totals.worst_residual.max(self.last.worst_residual);
        if let Some(n) = b
            .state
            .u
            .iter()
            .chain(&b.state.v)
            .position(|v| !v.is_finite())
        {
            return Err(ModelError(format!(
                "{}: the solve diverged (node {} is no longer finite); lower the time step, \
                 raise the sub-steps or use the implicit solver",
                S::NAME,
                n % b.state.u.len()
            )));
        }
        let inverted = inverted_tetrahedra(&b.mesh, &b.state.u);
        let grabbed = !self.grabs.is_empty();
        self.inversions
            .record(inverted, grabbed, S::NAME, S::INVERSION_HINT);
        let moved = b
            .state
            .u
            .iter()
            .zip(&before)
            .any(|(a, p)| (*a - *p).abs().max_element() > STILL_MM);
        if moved {
            for (n, u) in b.state.u.iter().enumerate() {
                for a in 0..3 {
                    b.u32[a][n] = u[a] as f32;
                }
            }
            if let Some(path) = &self.params.vtu {
                let u = [&b.u32[0][..], &b.u32[1][..], &b.u32[2][..]];
                // Every external force (gravity, loads, actuators), and the
                // actuators' alone (pressure, fluid weight, cable): the
                // difference of the force with and without point loads.
                let actuator: Vec<DVec3> = if b.frame_forces.len() == b.bc.force.len() {
                    b.bc.force
                        .iter()
                        .zip(&b.frame_forces)
                        .map(|(f, g)| *f - *g)
                        .collect()
                } else {
                    vec![DVec3::ZERO; b.bc.force.len()]
                };
                let vectors = [
                    ("external_force_uN", &b.bc.force[..]),
                    ("actuator_force_uN", &actuator[..]),
                ];
                write_vtu_with(path, &b.mesh, Some(u), &vectors)
                    .map_err(|e| ModelError(format!("{} vtu: {e}", S::NAME)))?;
            }
        }
        self.unmapped |= moved;
        Ok(moved)
    }
}

impl<S: MeshSolver> Drop for MeshModel<S> {
    fn drop(&mut self) {
        if let (Some(device), Some(gpu)) = (self.device.take(), &self.gpu) {
            if device.node_count != 0 {
                gpu.destroy_buffer(device.nodes);
            }
            for b in device.bindings.into_iter().flatten() {
                b.release(&**gpu);
            }
        }
    }
}

/// What `init` built, or the error of a model used before it.
fn built_ref<S: MeshSolver>(built: &Option<Built<S>>) -> Result<&Built<S>, ModelError> {
    built
        .as_ref()
        .ok_or_else(|| ModelError(format!("{}: used before init", S::NAME)))
}

/// What `init` built, mutably, or the error of a model used before it.
fn built_mut<S: MeshSolver>(built: &mut Option<Built<S>>) -> Result<&mut Built<S>, ModelError> {
    built
        .as_mut()
        .ok_or_else(|| ModelError(format!("{}: used before init", S::NAME)))
}

/// Lattice points near a world box, at their current positions
/// ([`lattice_near`]).
struct LatticeBox {
    /// Cells of the lattice's sampling mesh per axis.
    cells: [usize; 3],
    /// First and last point index per axis (inclusive).
    first: [usize; 3],
    end: [usize; 3],
    /// Current position (mm) of every point in the box, x fastest.
    positions: Vec<DVec3>,
}

impl LatticeBox {
    /// Lattice index of the box's `i`-th point.
    fn point(&self, i: usize) -> [usize; 3] {
        let span = [0, 1, 2].map(|a| self.end[a] - self.first[a] + 1);
        [
            self.first[0] + i % span[0],
            self.first[1] + i / span[0] % span[1],
            self.first[2] + i / (span[0] * span[1]),
        ]
    }
}

/// A bound point: its index in the binding, its rest and its current
/// position (mm).
type NearPoint = (usize, DVec3, DVec3);

/// The points of `bound` whose current positions may lie in the world box
/// `(lo, hi)` (mm): a lattice's through [`lattice_near`], a point list's
/// (tracked points, usually few) by their positions.
fn points_near<S: MeshSolver>(
    bound: &Bound,
    b: &Built<S>,
    (lo, hi): (DVec3, DVec3),
) -> Vec<NearPoint> {
    if let Some(g) = bound.lattice {
        let Some(near) = lattice_near(bound, b, (lo, hi)) else {
            return Vec::new();
        };
        return near
            .positions
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                let [a, b, c] = near.point(i);
                let rest = g.index_to_world(DVec3::new(a as f64, b as f64, c as f64));
                (g.linear(a, b, c), rest, p)
            })
            .collect();
    }
    bound
        .points
        .iter()
        .enumerate()
        .filter_map(|(i, &rest)| {
            let p = rest + bound.binding.displacement_of(&b.mesh, i, &b.state.u);
            (p.cmpge(lo).all() && p.cmple(hi).all()).then_some((i, rest, p))
        })
        .collect()
}

/// Binds anew the points of `near` that a cut leaves across from the
/// tetrahedron carrying them (the segment from the point to the
/// tetrahedron's centroid, current positions, crosses `cut`), so the
/// embedding is cut voxel-sharp and not only along the proxy's faces: of
/// the tetrahedra sharing a node with the old one and whose centroid lies
/// on the point's side, the one whose smallest weight at the point's rest
/// position is largest (the one holding it best; the point may lie just
/// outside it and follows the point its clamped weights give). `star`
/// (node → tetrahedra) is built by the first point carried across. Returns
/// the points bound anew and those left across (no such tetrahedron).
fn rebind_across(
    bound: &mut Bound,
    near: &[NearPoint],
    mesh: &TetMesh,
    x: &[DVec3],
    cut: &CutPolygon,
    star: &mut Option<Vec<Vec<u32>>>,
) -> (usize, usize) {
    let centroid = |t: u32| {
        mesh.tets[t as usize]
            .iter()
            .map(|&n| x[n as usize])
            .sum::<DVec3>()
            / 4.0
    };
    let (mut rebound, mut left) = (0, 0);
    for &(at, rest, p) in near {
        let old = bound.binding.tet[at];
        if !cut.crosses(p, centroid(old)) {
            continue;
        }
        let star = star.get_or_insert_with(|| node_star(mesh));
        let smallest_weight = |t: u32| {
            barycentric::weights(mesh.corners(t as usize), rest)
                .into_iter()
                .fold(f64::INFINITY, f64::min)
        };
        let best = mesh.tets[old as usize]
            .iter()
            .flat_map(|&n| &star[n as usize])
            .copied()
            .filter(|&t| t != old && !cut.crosses(p, centroid(t)))
            .map(|t| (t, smallest_weight(t)))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match best {
            Some((t, _)) => {
                bound.binding.bind_to(mesh, at, t, rest);
                rebound += 1;
            }
            None => left += 1,
        }
    }
    (rebound, left)
}

/// The tetrahedra of each node of `mesh`, ascending.
fn node_star(mesh: &TetMesh) -> Vec<Vec<u32>> {
    let mut star = vec![Vec::new(); mesh.nodes.len()];
    for (t, tet) in mesh.tets.iter().enumerate() {
        for &n in tet {
            star[n as usize].push(t as u32);
        }
    }
    star
}

/// The largest extent along any axis of a tetrahedron of `mesh` at node
/// positions `x` (mm).
fn largest_extent(mesh: &TetMesh, x: &[DVec3]) -> f64 {
    mesh.tets
        .iter()
        .map(|t| {
            let p = t.map(|n| x[n as usize]);
            let lo = p.iter().fold(p[0], |a, b| a.min(*b));
            let hi = p.iter().fold(p[0], |a, b| a.max(*b));
            (hi - lo).max_element()
        })
        .fold(0.0, f64::max)
}

/// For a lattice binding, the lattice points whose current positions may
/// lie in the world box `(lo, hi)` (mm): the index box grown by the largest
/// node displacement and two spacings, with every point's current position.
/// `None` for other bindings, or when the box misses the lattice.
fn lattice_near<S: MeshSolver>(
    bound: &Bound,
    b: &Built<S>,
    (lo, hi): (DVec3, DVec3),
) -> Option<LatticeBox> {
    let g = bound.lattice?;
    let max_u = b
        .state
        .u
        .iter()
        .map(|u| u.abs().max_element())
        .fold(0.0, f64::max);
    let grow = DVec3::splat(max_u) + g.spacing.abs() * 2.0;
    let (a, c) = (g.world_to_index(lo - grow), g.world_to_index(hi + grow));
    let (lo, hi) = (a.min(c), a.max(c));
    let last = g.dims.map(|d| d as f64 - 1.0);
    if (0..3).any(|k| hi[k] < 0.0 || lo[k] > last[k]) {
        return None;
    }
    let first = [0, 1, 2].map(|k| lo[k].floor().max(0.0) as usize);
    let end = [0, 1, 2].map(|k| hi[k].ceil().min(last[k]) as usize);
    let mut positions = Vec::new();
    for k in first[2]..=end[2] {
        for j in first[1]..=end[1] {
            for i in first[0]..=end[0] {
                let p = g.linear(i, j, k);
                let u = bound.binding.displacement_of(&b.mesh, p, &b.state.u);
                let rest = g.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
                positions.push(rest + u);
            }
        }
    }
    Some(LatticeBox {
        cells: g.dims.map(|d| d.saturating_sub(1)),
        first,
        end,
        positions,
    })
}

/// Per voxel: the index of the first material whose range holds its value
/// (`u16::MAX` for none).
fn voxel_materials(volume: VolumeView<'_>, specs: &[super::MaterialSpec]) -> Vec<u16> {
    (0..volume.grid.len())
        .map(|l| {
            let v = volume.data.get_f32(l) as f64;
            specs
                .iter()
                .position(|s| s.range.is_some_and(|r| v >= r[0] && v < r[1]))
                .map_or(u16::MAX, |m| m as u16)
        })
        .collect()
}

impl<S: MeshSolver> DeformationModel for MeshModel<S> {
    fn init(
        &mut self,
        volume: VolumeView<'_>,
        backend: ExecutionBackend,
    ) -> Result<(), ModelError> {
        let (mesh, materials, hanging, lost) = self.proxy(volume)?;
        self.labelled_voxels_lost = lost;
        self.build(mesh, materials, hanging)?;
        if backend == ExecutionBackend::Gpu {
            self.use_gpu()?;
        }
        Ok(())
    }

    fn bind(&mut self, rest: RestPoints<'_>) -> Result<BindingId, ModelError> {
        rest.check_finite()?;
        let b = self.built()?;
        let binding = BarycentricBinding::bind(&b.mesh, rest.len(), |i| rest.point(i));
        if binding.outside > 0 {
            tracing::info!(
                outside = binding.outside,
                points = binding.len(),
                "{}: points outside the proxy follow its nearest surface",
                S::NAME
            );
        }
        let (lattice, points) = match rest {
            RestPoints::Lattice(g) => (Some(g), Vec::new()),
            RestPoints::Points(p) => (
                None,
                p.iter()
                    .map(|v| DVec3::from_array(v.map(f64::from)))
                    .collect(),
            ),
        };
        self.bindings.push(Bound {
            binding,
            lattice,
            points,
            removed: Vec::new(),
            unreported: false,
            loads: Vec::new(),
        });
        self.unmapped = true;
        Ok(BindingId(self.bindings.len() as u64 - 1))
    }

    fn interact(&mut self, interaction_toml: &str) -> Result<(), ModelError> {
        let spec = InteractionSpec::from_toml(interaction_toml)?;
        if self.built.is_none() {
            // Before init: a dry run (parsed and validated, nothing applied).
            return Ok(());
        }
        self.apply(&spec)
    }

    fn step(&mut self, frame: FrameInfo) -> Result<StepOutcome, ModelError> {
        let changed = self.advance(frame.dt_s)?;
        Ok(StepOutcome { changed })
    }

    fn dirty_region(&self) -> DirtyRegion {
        if self.unmapped {
            DirtyRegion::All
        } else {
            DirtyRegion::None
        }
    }

    /// `proxy_nodes`, `proxy_tetrahedra`, `bound_points`,
    /// `labelled_voxels_lost` (labelled voxels in proxy cells of another
    /// material), `inverted_tetrahedra` (after the last frame) and
    /// `inverted_tetrahedra_max` (over the run), `bound_points_outside_proxy` (bound to the nearest tetrahedron with
    /// clamped weights), `cut_voxels_rebound` (voxel centres the cuts found
    /// carried by a tetrahedron across the cut and bound to one of their own
    /// side), `cut_voxels_across` (those left across, with no tetrahedron of
    /// their side at hand: they move with the other piece), `steps`, `substeps` and `solver_iterations` summed
    /// over the run, and `last_residual` (relative, of the last linear
    /// solve; 0 for explicit steps), `worst_residual` (the largest relative
    /// residual of any linear solve of the run, each held to its own
    /// tolerance, which a solver may loosen: inexact Newton directions,
    /// compliance solves) and `unconverged_solves` (linear solves that
    /// stopped above their tolerance), then the solver's own notes.
    fn notes(&mut self) -> Result<ModelNotes, ModelError> {
        let mut notes = ModelNotes::new();
        if let Some(b) = &self.built {
            notes.insert("proxy_nodes".into(), b.mesh.nodes.len() as f64);
            notes.insert("proxy_tetrahedra".into(), b.mesh.tets.len() as f64);
        }
        let (points, outside) = self.bindings.iter().fold((0, 0), |(p, o), b| {
            (p + b.binding.len(), o + b.binding.outside)
        });
        notes.insert("bound_points".into(), points as f64);
        notes.insert(
            "labelled_voxels_lost".into(),
            self.labelled_voxels_lost as f64,
        );
        notes.insert("bound_points_outside_proxy".into(), outside as f64);
        notes.insert("cut_voxels_across".into(), self.cut_voxels_across as f64);
        notes.insert("cut_voxels_rebound".into(), self.cut_voxels_rebound as f64);
        notes.insert("steps".into(), self.totals.steps as f64);
        notes.insert("inverted_tetrahedra".into(), self.inversions.current as f64);
        notes.insert("inverted_tetrahedra_max".into(), self.inversions.max as f64);
        notes.insert("substeps".into(), self.totals.substeps as f64);
        notes.insert("solver_iterations".into(), self.totals.iterations as f64);
        notes.insert("last_residual".into(), self.last.residual);
        notes.insert("worst_residual".into(), self.totals.worst_residual);
        notes.insert("unconverged_solves".into(), self.totals.unconverged as f64);
        if self.totals.compliance_solves > 0 {
            notes.insert(
                "compliance_solves".into(),
                self.totals.compliance_solves as f64,
            );
        }
        self.far_grabs.add_notes(&mut notes);
        if let Some(b) = &self.built {
            b.solver.notes(&mut notes);
        }
        Ok(notes)
    }

    fn removed_tetrahedra(
        &mut self,
        binding: BindingId,
        cell_bits: &mut [u8],
    ) -> Result<bool, ModelError> {
        let bound = self
            .bindings
            .get_mut(binding.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", binding.0)))?;
        if cell_bits.is_empty() {
            return Ok(!bound.removed.is_empty());
        }
        if !bound.unreported {
            return Ok(false);
        }
        let mut changed = false;
        for &(cell, bits) in &bound.removed {
            if let Some(c) = cell_bits.get_mut(cell) {
                changed |= *c & bits != bits;
                *c |= bits;
            }
        }
        bound.unreported = false;
        Ok(changed)
    }

    /// Spread over the corners of each point's tetrahedron by its weights
    /// from the next step on (P2 too: the corners take a point's force by
    /// its linear weights, which keeps it work-consistent with
    /// [`DeformationModel::compliance`]'s observation).
    fn set_point_loads(&mut self, binding: BindingId, forces: &[DVec3]) -> Result<(), ModelError> {
        let bound = self
            .bindings
            .get_mut(binding.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", binding.0)))?;
        if forces.len() != bound.binding.len() {
            return Err(ModelError(format!(
                "{}: {} point loads for a binding of {} points",
                S::NAME,
                forces.len(),
                bound.binding.len()
            )));
        }
        if let Some(i) = forces.iter().position(|f| !f.is_finite()) {
            return Err(ModelError(format!(
                "{}: the load on bound point {i} is not finite",
                S::NAME
            )));
        }
        bound.loads = forces.to_vec();
        Ok(())
    }

    fn resolve(&mut self) -> Result<StepOutcome, ModelError> {
        let changed = MeshModel::resolve(self)?;
        Ok(StepOutcome { changed })
    }

    /// The solver's compliance on the proxy, spread and read at the points
    /// by their linear barycentric weights (for P2 the mid-edge nodes take
    /// no force and the corners' displacements are read).
    fn compliance(
        &mut self,
        binding: BindingId,
        forces: &[DVec3],
        out: &mut [DVec3],
    ) -> Result<(), ModelError> {
        let b = built_mut(&mut self.built)?;
        let bound = &self
            .bindings
            .get(binding.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", binding.0)))?
            .binding;
        if forces.len() != bound.len() || out.len() != bound.len() {
            return Err(ModelError(format!(
                "{}: compliance of {} forces into {} outputs for a binding of {} points",
                S::NAME,
                forces.len(),
                out.len(),
                bound.len()
            )));
        }
        let mut nodal = vec![DVec3::ZERO; b.mesh.nodes.len()];
        bound.spread(&b.mesh, forces, &mut nodal);
        let (u, report) = b.solver.compliance(&b.bc, &b.state, &nodal)?;
        bound.gather(&b.mesh, &u, out);
        self.totals.compliance_solves += 1;
        self.totals.iterations += u64::from(report.iterations);
        self.totals.unconverged += u64::from(report.unconverged);
        self.totals.worst_residual = self.totals.worst_residual.max(report.worst_residual);
        Ok(())
    }

    fn map(&mut self, binding: BindingId, out: DisplacementTarget<'_>) -> Result<(), ModelError> {
        let b = self.built()?;
        let bound = &self
            .bindings
            .get(binding.0 as usize)
            .ok_or_else(|| ModelError(format!("unknown binding id {}", binding.0)))?
            .binding;
        let (x, y, z) = match out {
            DisplacementTarget::Cpu { x, y, z } => (x, y, z),
            DisplacementTarget::Gpu { x, y, z } if b.solver.edge_layer().is_some() => {
                // Quadratic elements: the map runs on the CPU and its
                // result goes up (the device map is the linear one).
                let n = bound.len();
                let mut out = [vec![0f32; n], vec![0f32; n], vec![0f32; n]];
                let [ox, oy, oz] = &mut out;
                let u = [&b.u32[0][..], &b.u32[1][..], &b.u32[2][..]];
                bound.map(&b.mesh, u, [&mut *ox, &mut *oy, &mut *oz]);
                if let Some(layer) = b.solver.edge_layer() {
                    layer.add_to_map(bound, [ox, oy, oz]);
                }
                let gpu = self.gpu.clone().ok_or_else(|| {
                    ModelError(format!("{}: a GPU target needs the GPU backend", S::NAME))
                })?;
                for (buf, values) in [x, y, z].into_iter().zip(&out) {
                    gpu.write_buffer(buf, 0, bytemuck::cast_slice(values))
                        .map_err(|e| ModelError(format!("{}: {e}", S::NAME)))?;
                }
                self.unmapped = false;
                return Ok(());
            }
            DisplacementTarget::Gpu { x, y, z } => {
                self.map_on_device(binding.0 as usize, [x, y, z])?;
                self.unmapped = false;
                return Ok(());
            }
        };
        if [x.len(), y.len(), z.len()]
            .iter()
            .any(|&l| l != bound.len())
        {
            return Err(ModelError(format!(
                "displacement arrays hold {} values but the binding has {} points",
                x.len(),
                bound.len()
            )));
        }
        let u = [&b.u32[0][..], &b.u32[1][..], &b.u32[2][..]];
        bound.map(&b.mesh, u, [&mut *x, &mut *y, &mut *z]);
        if let Some(layer) = b.solver.edge_layer() {
            layer.add_to_map(bound, [x, y, z]);
        }
        self.unmapped = false;
        Ok(())
    }
}
