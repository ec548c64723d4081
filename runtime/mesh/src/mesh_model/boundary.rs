//! Boundary conditions of a mesh model, as the solvers see them for one
//! step: which nodes are fixed, which are driven to a displacement, the
//! hanging-node ties of an octree proxy, and the external nodal forces.

use crate::proxy::HangingNode;
use crate::tet_mesh::TetMesh;
use glam::DVec3;

/// The boundary conditions of one step. Node indices are the proxy's;
/// displacements in mm, forces in µN (g·mm/s²).
#[derive(Clone, Debug, Default)]
pub struct Boundary {
    /// Per node: held at zero displacement.
    pub fixed: Vec<bool>,
    /// Nodes driven to a displacement this step (grabs), mm.
    pub driven: Vec<(u32, DVec3)>,
    /// Hanging nodes: each takes `Σ w · master` (octree proxies).
    pub hanging: Vec<HangingNode>,
    /// External force per node (gravity, loads), µN.
    pub force: Vec<DVec3>,
    /// Gravity's acceleration (mm/s²); `force` holds it as lumped masses
    /// ([`super::lumped_masses`]) times this. Quadratic elements, whose
    /// mass sits mostly on the mid-edge nodes, take it back out and spread
    /// it their own way.
    pub gravity: DVec3,
    /// The boundary faces a traction loads (their corners) and the total
    /// force on each (µN, area × traction, ramped), already in `force` as a
    /// third on each corner (the consistent load of linear elements);
    /// quadratic elements move it onto the faces' edges.
    pub faces: Vec<([u32; 3], DVec3)>,
}

impl Boundary {
    /// Free boundary conditions for `nodes` nodes.
    pub fn new(nodes: usize) -> Self {
        Self {
            fixed: vec![false; nodes],
            driven: Vec::new(),
            hanging: Vec::new(),
            force: vec![DVec3::ZERO; nodes],
            gravity: DVec3::ZERO,
            faces: Vec::new(),
        }
    }

    /// Per node: its displacement is imposed (fixed, driven or hanging), so
    /// the solver does not solve for it.
    pub fn constrained(&self) -> Vec<bool> {
        let mut c = self.fixed.clone();
        for &(n, _) in &self.driven {
            c[n as usize] = true;
        }
        for h in &self.hanging {
            c[h.node as usize] = true;
        }
        c
    }

    /// Sets the imposed displacements in `u`: zero on fixed nodes, the
    /// target on driven ones, then every hanging node from its masters.
    pub fn impose(&self, u: &mut [DVec3]) {
        for (n, f) in self.fixed.iter().enumerate() {
            if *f {
                u[n] = DVec3::ZERO;
            }
        }
        for &(n, d) in &self.driven {
            u[n as usize] = d;
        }
        self.tie(u);
    }

    /// Sets every hanging node of `v` from its masters (`v = P v`).
    pub fn tie(&self, v: &mut [DVec3]) {
        for h in &self.hanging {
            v[h.node as usize] = h
                .masters
                .iter()
                .map(|&(m, w)| w as f64 * v[m as usize])
                .sum();
        }
    }

    /// Moves what acts on hanging nodes to their masters and clears it
    /// (`f ← Pᵀ f`), the transpose of [`Boundary::tie`].
    pub fn untie(&self, f: &mut [DVec3]) {
        for h in self.hanging.iter().rev() {
            let v = std::mem::take(&mut f[h.node as usize]);
            for &(m, w) in &h.masters {
                f[m as usize] += w as f64 * v;
            }
        }
    }
}

/// The hanging-node ties as tables for GPU kernels: per node, the masters
/// it is tied to (`tie_*`, for hanging nodes) and the hanging nodes it
/// carries (`untie_*`, for masters), each list a range of `(node, weight as
/// f32 bits)` pairs. The lists never come out empty (a kernel buffer needs
/// a word), so `*_start` is what delimits them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TieTables {
    /// Node `n`'s masters are `tie_list[tie_start[n] .. tie_start[n + 1]]`.
    pub tie_start: Vec<u32>,
    /// `(master, weight bits)`.
    pub tie_list: Vec<[u32; 2]>,
    /// The hanging nodes master `n` carries are
    /// `untie_list[untie_start[n] .. untie_start[n + 1]]`.
    pub untie_start: Vec<u32>,
    /// `(hanging node, weight bits)`.
    pub untie_list: Vec<[u32; 2]>,
}

impl TieTables {
    /// The tables of `hanging` over `nodes` nodes.
    pub fn new(hanging: &[HangingNode], nodes: usize) -> Self {
        let mut masters = vec![Vec::new(); nodes];
        let mut carried = vec![Vec::new(); nodes];
        for h in hanging {
            for &(m, w) in &h.masters {
                masters[h.node as usize].push([m, w.to_bits()]);
                carried[m as usize].push([h.node, w.to_bits()]);
            }
        }
        let csr = |lists: Vec<Vec<[u32; 2]>>| {
            let mut start = vec![0u32];
            let mut list = Vec::new();
            for l in lists {
                list.extend(l);
                start.push(list.len() as u32);
            }
            list.push([0, 0]);
            (start, list)
        };
        let ((tie_start, tie_list), (untie_start, untie_list)) = (csr(masters), csr(carried));
        Self {
            tie_start,
            tie_list,
            untie_start,
            untie_list,
        }
    }
}

/// The longest rest edge (mm) of the tetrahedra that use `node`: how far a
/// point inside the mesh can lie from its nearest node there, the reach
/// beyond which a grab's point is outside the body
/// ([`crate::interaction::FarGrabs`]). 0 for a node no tetrahedron uses.
pub fn reach_at(mesh: &TetMesh, node: u32) -> f64 {
    mesh.tets
        .iter()
        .filter(|t| t.contains(&node))
        .flat_map(|t| {
            let p = t.map(|n| mesh.nodes[n as usize]);
            [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)].map(|(a, b)| (p[a] - p[b]).length())
        })
        .fold(0.0, f64::max)
}

/// Nodal forces (µN) of a uniform traction `t` (Pa) on the boundary faces
/// of `mesh` whose centroids lie in the box `[lo, hi]` (mm): each face of
/// area `A` gives `A t / 3` to each corner (the consistent load of linear
/// elements). Returns the forces added and how many faces carried load.
pub fn traction_forces(mesh: &TetMesh, lo: DVec3, hi: DVec3, t: DVec3, out: &mut [DVec3]) -> usize {
    let faces = traction_faces(mesh, lo, hi, t);
    for (f, force) in &faces {
        for &n in f {
            out[n as usize] += *force / 3.0;
        }
    }
    faces.len()
}

/// The boundary faces of `mesh` whose centroids lie in the box `[lo, hi]`
/// (mm) and the total force (µN) a uniform traction `t` (Pa) puts on each:
/// area × `t` ([`Boundary::faces`]).
pub fn traction_faces(mesh: &TetMesh, lo: DVec3, hi: DVec3, t: DVec3) -> Vec<([u32; 3], DVec3)> {
    let Ok(faces) = mesh.boundary_faces() else {
        return Vec::new();
    };
    let mut loaded = Vec::new();
    for f in faces {
        let p = f.map(|n| mesh.nodes[n as usize]);
        let c = (p[0] + p[1] + p[2]) / 3.0;
        if c.cmplt(lo).any() || c.cmpgt(hi).any() {
            continue;
        }
        let area = (p[1] - p[0]).cross(p[2] - p[0]).length() / 2.0;
        loaded.push((f, t * area));
    }
    loaded
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reach_is_the_longest_edge_at_the_node() {
        let mesh = TetMesh {
            nodes: vec![
                DVec3::ZERO,
                DVec3::new(2.0, 0.0, 0.0),
                DVec3::new(0.0, 1.0, 0.0),
                DVec3::new(0.0, 0.0, 1.0),
                DVec3::new(9.0, 9.0, 9.0),
            ],
            tets: vec![[0, 1, 2, 3]],
            labels: vec![0],
        };
        assert!((reach_at(&mesh, 2) - 5f64.sqrt()).abs() < 1e-12);
        assert_eq!(reach_at(&mesh, 4), 0.0, "unused node");
    }

    #[test]
    fn untie_is_the_transpose_of_tie() {
        let mut b = Boundary::new(4);
        b.hanging.push(HangingNode {
            node: 3,
            masters: vec![(0, 0.25), (1, 0.75)],
        });
        let x = [
            DVec3::new(1.0, 2.0, 3.0),
            DVec3::new(-1.0, 0.5, 2.0),
            DVec3::new(4.0, 4.0, 4.0),
            DVec3::new(9.0, 9.0, 9.0),
        ];
        let y = [
            DVec3::new(0.3, 0.1, -2.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(2.0, -1.0, 0.0),
            DVec3::new(5.0, 6.0, 7.0),
        ];
        let (mut px, mut pty) = (x, y);
        b.tie(&mut px);
        b.untie(&mut pty);
        // ⟨P x, y⟩ = ⟨x, Pᵀ y⟩ for x that P leaves unchanged off the tie.
        let dot =
            |a: &[DVec3; 4], b: &[DVec3; 4]| a.iter().zip(b).map(|(p, q)| p.dot(*q)).sum::<f64>();
        assert!((dot(&px, &y) - dot(&x, &pty)).abs() < 1e-12);
        assert_eq!(pty[3], DVec3::ZERO);
    }
}
