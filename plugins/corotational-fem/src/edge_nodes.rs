//! The mid-edge nodes of the quadratic elements (`element = "p2"`): the
//! solver owns them, so the shared [`MeshModel`](voxflex_mesh::mesh_model::MeshModel)
//! (proxy, boundary conditions, bindings, cuts) keeps working on the
//! proxy's corners only.
//!
//! - **Nodes**: one per unique edge of the proxy, numbered after the
//!   corners (`corners + edge`), at the edge's midpoint (straight edges).
//! - **Boundary conditions** from the corners' ([`EdgeNodes::boundary`]):
//!   an edge node is fixed when both its ends are, driven to the mean of
//!   its ends' targets when both are imposed (fixed or grabbed), and tied
//!   to the mean of its ends (their masters, for hanging corners of an
//!   octree proxy) when either end hangs, so the tie stays one level deep
//!   (what the GPU tie tables expect); otherwise it is free.
//! - **Loads**: a traction's faces ([`Boundary::faces`]) go to the faces'
//!   edges, a third each (the consistent load of a 6-node triangle, whose
//!   corners take none); gravity is spread by the quadratic elements'
//!   lumped masses; any other nodal force stays on its corner.
//! - **Masses**: HRZ lumping (the consistent mass's diagonal scaled to the
//!   element's mass), `ρV/36` per corner and `4ρV/27` per edge node of
//!   each tetrahedron (row sums would give the corners negative masses).
//! - **State**: the solver keeps the full state; a corner whose
//!   displacement or velocity changed outside the solver (a fix, a
//!   program's `set_displacements`) resets its edges' nodes to the mean of
//!   their ends, and after each step the corners go back to the model's
//!   state and each edge's deviation from its ends' mean to the map
//!   ([`EdgeLayer`]).

use crate::quadratic::Quadratic;
use std::collections::HashMap;
use voxflex_core::glam::DVec3;
use voxflex_core::tet_mesh::TetMesh;
use voxflex_mesh::mesh_model::edge_layer::TET_EDGES;
use voxflex_mesh::mesh_model::{Boundary, EdgeLayer, ElasticMaterial, NodeState, lumped_masses};
use voxflex_mesh::proxy::HangingNode;

/// The mid-edge node layer of a proxy.
#[derive(Clone, Debug)]
pub struct EdgeNodes {
    /// Corner (proxy) nodes.
    corners: usize,
    /// Each edge's ends (corner indices, ascending).
    pub edges: Vec<[u32; 2]>,
    /// Edge index by its ends (ascending).
    lookup: HashMap<[u32; 2], u32>,
    /// Per tetrahedron, its edges in [`TET_EDGES`] order.
    pub tet_edges: Vec<[u32; 6]>,
    /// The model's (linear) lumped masses of the corners, g: gravity's
    /// share of [`Boundary::force`] is these times [`Boundary::gravity`].
    linear_masses: Vec<f64>,
    /// HRZ-lumped masses of corners then edge nodes, g.
    pub masses: Vec<f64>,
    /// Displacements and velocities of corners then edge nodes.
    pub state: NodeState,
    /// Per edge, its node's displacement minus its ends' mean, mm.
    deviation: Vec<DVec3>,
}

impl EdgeNodes {
    /// The layer of `mesh`, whose tetrahedron `t` has material
    /// `materials[mesh.labels[t]]`.
    pub fn new(mesh: &TetMesh, materials: &[ElasticMaterial]) -> Self {
        let corners = mesh.nodes.len();
        let mut edges = Vec::new();
        let mut lookup = HashMap::new();
        let tet_edges = mesh
            .tets
            .iter()
            .map(|tet| {
                TET_EDGES.map(|[a, b]| {
                    let key = ordered(tet[a], tet[b]);
                    *lookup.entry(key).or_insert_with(|| {
                        edges.push(key);
                        edges.len() as u32 - 1
                    })
                })
            })
            .collect::<Vec<_>>();
        let mut masses = vec![0.0; corners + edges.len()];
        for (t, tet) in mesh.tets.iter().enumerate() {
            let m = materials[mesh.labels[t] as usize].density * mesh.volume(t);
            for &n in tet {
                masses[n as usize] += m / 36.0;
            }
            for &e in &tet_edges[t] {
                masses[corners + e as usize] += 4.0 * m / 27.0;
            }
        }
        let n = masses.len();
        Self {
            corners,
            deviation: vec![DVec3::ZERO; edges.len()],
            edges,
            lookup,
            tet_edges,
            linear_masses: lumped_masses(mesh, materials),
            masses,
            state: NodeState::at_rest(n),
        }
    }

    /// Corner nodes plus edge nodes.
    pub fn len(&self) -> usize {
        self.corners + self.edges.len()
    }

    /// True when the proxy has no node.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The quadratic elements of `mesh` on this layer.
    pub fn elements(&self, mesh: &TetMesh, materials: &[ElasticMaterial]) -> Vec<Quadratic> {
        (0..mesh.tets.len())
            .map(|t| {
                let edge_nodes = self.tet_edges[t].map(|e| (self.corners + e as usize) as u32);
                Quadratic::new(mesh, t, edge_nodes, &materials[mesh.labels[t] as usize])
            })
            .collect()
    }

    /// The boundary conditions on corners and edge nodes from the model's
    /// on the corners (see the module docs).
    pub fn boundary(&self, bc: &Boundary) -> Boundary {
        let (nc, n) = (self.corners, self.len());
        let mut full = Boundary::new(n);
        full.fixed[..nc].copy_from_slice(&bc.fixed);
        full.driven.clone_from(&bc.driven);
        full.hanging.clone_from(&bc.hanging);
        full.gravity = bc.gravity;
        // Imposed corner targets, and hanging corners' masters.
        let mut target: Vec<Option<DVec3>> =
            bc.fixed.iter().map(|&f| f.then_some(DVec3::ZERO)).collect();
        for &(c, d) in &bc.driven {
            target[c as usize] = Some(d);
        }
        let mut masters: HashMap<u32, &[(u32, f32)]> = HashMap::new();
        for h in &bc.hanging {
            masters.insert(h.node, &h.masters);
        }
        for (e, [a, b]) in self.edges.iter().enumerate() {
            let node = (nc + e) as u32;
            if masters.contains_key(a) || masters.contains_key(b) {
                let mut tie: Vec<(u32, f32)> = Vec::new();
                for end in [a, b] {
                    match masters.get(end) {
                        Some(list) => tie.extend(list.iter().map(|&(m, w)| (m, 0.5 * w))),
                        None => tie.push((*end, 0.5)),
                    }
                }
                full.hanging.push(HangingNode { node, masters: tie });
                continue;
            }
            match (target[*a as usize], target[*b as usize]) {
                (Some(_), Some(_)) if bc.fixed[*a as usize] && bc.fixed[*b as usize] => {
                    full.fixed[nc + e] = true;
                }
                (Some(p), Some(q)) => full.driven.push((node, (p + q) * 0.5)),
                _ => {}
            }
        }
        // Forces: gravity and tractions moved to where P2 puts them.
        for c in 0..nc {
            full.force[c] = bc.force[c] - self.linear_masses[c] * bc.gravity;
        }
        for (f, m) in full.force.iter_mut().zip(&self.masses) {
            *f += *m * bc.gravity;
        }
        for (face, force) in &bc.faces {
            // A face whose edges are not all edges of this proxy (none
            // should be) keeps its linear load.
            let edges = [[0, 1], [1, 2], [0, 2]]
                .map(|[a, b]| self.lookup.get(&ordered(face[a], face[b])).copied());
            if edges.iter().any(Option::is_none) || face.iter().any(|&c| c as usize >= nc) {
                continue;
            }
            for &c in face {
                full.force[c as usize] -= *force / 3.0;
            }
            for e in edges.into_iter().flatten() {
                full.force[nc + e as usize] += *force / 3.0;
            }
        }
        full
    }

    /// Takes the model's corner state into the full one; the edge nodes of
    /// a corner that changed outside the solver restart at their ends' mean.
    pub fn sync(&mut self, state: &NodeState) {
        let nc = self.corners;
        let mut changed = vec![false; nc];
        for (c, changed) in changed.iter_mut().enumerate() {
            if self.state.u[c] != state.u[c] || self.state.v[c] != state.v[c] {
                self.state.u[c] = state.u[c];
                self.state.v[c] = state.v[c];
                *changed = true;
            }
        }
        if !changed.contains(&true) {
            return;
        }
        for (e, [a, b]) in self.edges.iter().enumerate() {
            let (a, b) = (*a as usize, *b as usize);
            if changed[a] || changed[b] {
                self.state.u[nc + e] = (self.state.u[a] + self.state.u[b]) * 0.5;
                self.state.v[nc + e] = (self.state.v[a] + self.state.v[b]) * 0.5;
            }
        }
    }

    /// Hands the corners back to the model's state and keeps each edge's
    /// deviation for the map.
    pub fn finish(&mut self, state: &mut NodeState) {
        let nc = self.corners;
        state.u.copy_from_slice(&self.state.u[..nc]);
        state.v.copy_from_slice(&self.state.v[..nc]);
        let u = &self.state.u;
        for (d, (e, [a, b])) in self.deviation.iter_mut().zip(self.edges.iter().enumerate()) {
            *d = u[nc + e] - (u[*a as usize] + u[*b as usize]) * 0.5;
        }
    }

    /// The layer as `map` reads it.
    pub fn layer(&self) -> EdgeLayer<'_> {
        EdgeLayer {
            tet_edges: &self.tet_edges,
            deviation: &self.deviation,
        }
    }
}

/// An edge's ends, ascending.
fn ordered(a: u32, b: u32) -> [u32; 2] {
    [a.min(b), a.max(b)]
}
