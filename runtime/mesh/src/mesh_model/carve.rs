//! Carving a proxy: the tetrahedra whose centroid (current positions) lies
//! in a region are removed, and with them the nodes no tetrahedron uses
//! any more.
//!
//! **Decision:** removed, not softened. A common shortcut keeps carved
//! elements with a near-zero "ersatz" stiffness so no index changes; here
//! the mesh is compacted instead, so the solver's work and the `.vtu`
//! export shrink with the tissue, and no ill-conditioned stiffness ratio
//! reaches the linear solver. The model renumbers its per-node state and
//! rebinds the points that were inside removed tetrahedra
//! ([`crate::barycentric::BarycentricBinding::after_removal`]).

use crate::interaction::CarveRegion;
use crate::tet_mesh::TetMesh;
use glam::DVec3;

/// Marks a removed tetrahedron or node in [`Carved`]'s index maps.
pub const GONE: u32 = u32::MAX;

/// A proxy after a carve, and how its indices moved.
#[derive(Clone, Debug)]
pub struct Carved {
    /// The mesh without the carved tetrahedra and the nodes only they used.
    pub mesh: TetMesh,
    /// Per old tetrahedron: its index in `mesh`, or [`GONE`].
    pub tet_index: Vec<u32>,
    /// Per old node: its index in `mesh`, or [`GONE`].
    pub node_index: Vec<u32>,
    /// Tetrahedra removed.
    pub removed: usize,
}

/// Removes from `mesh` the tetrahedra whose centroid, at node positions `x`
/// (mm, current), lies in `region`, and the nodes left unused.
pub fn carve_mesh(mesh: &TetMesh, x: &[DVec3], region: &CarveRegion) -> Carved {
    let (lo, hi) = region.bounds();
    let keep: Vec<bool> = mesh
        .tets
        .iter()
        .map(|tet| {
            let c = tet.iter().map(|&n| x[n as usize]).sum::<DVec3>() * 0.25;
            !(c.cmpge(lo).all() && c.cmple(hi).all() && region.contains(c))
        })
        .collect();
    let mut tet_index = vec![GONE; mesh.tets.len()];
    let mut used = vec![false; mesh.nodes.len()];
    let mut kept = 0u32;
    for (t, tet) in mesh.tets.iter().enumerate() {
        if keep[t] {
            tet_index[t] = kept;
            kept += 1;
            for &n in tet {
                used[n as usize] = true;
            }
        }
    }
    let mut node_index = vec![GONE; mesh.nodes.len()];
    let mut nodes = Vec::new();
    for (n, &u) in used.iter().enumerate() {
        if u {
            node_index[n] = nodes.len() as u32;
            nodes.push(mesh.nodes[n]);
        }
    }
    let mut tets = Vec::with_capacity(kept as usize);
    let mut labels = Vec::with_capacity(kept as usize);
    for (t, tet) in mesh.tets.iter().enumerate() {
        if keep[t] {
            tets.push(tet.map(|n| node_index[n as usize]));
            labels.push(mesh.labels[t]);
        }
    }
    Carved {
        mesh: TetMesh {
            nodes,
            tets,
            labels,
        },
        tet_index,
        node_index,
        removed: mesh.tets.len() - kept as usize,
    }
}

/// `values` per old node, kept for the nodes that remain (in their new
/// order).
pub fn keep_nodes<T: Clone>(values: &[T], node_index: &[u32]) -> Vec<T> {
    values
        .iter()
        .zip(node_index)
        .filter(|(_, n)| **n != GONE)
        .map(|(v, _)| v.clone())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::proxy::uniform_proxy;

    #[test]
    fn a_carve_removes_the_tetrahedra_inside_and_their_unused_nodes() {
        let grid = Grid::new([5, 5, 5], DVec3::ONE, DVec3::ZERO);
        let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
        let region = CarveRegion::Ball {
            centre: DVec3::splat(2.0),
            radius: 1.2,
        };
        let carved = carve_mesh(&mesh, &mesh.nodes, &region);
        assert!(carved.removed > 0 && carved.removed < mesh.tets.len());
        assert_eq!(carved.mesh.tets.len(), mesh.tets.len() - carved.removed);
        // The centre node is used only by tetrahedra around it: gone.
        let centre = mesh
            .nodes
            .iter()
            .position(|&p| p == DVec3::splat(2.0))
            .unwrap();
        assert_eq!(carved.node_index[centre], GONE);
        // Every kept tetrahedron is the same one, renumbered, with the same
        // corners; none has its centroid in the ball.
        for (t, &new) in carved.tet_index.iter().enumerate() {
            let c = mesh.corners(t);
            let inside = region.contains(c.iter().sum::<DVec3>() * 0.25);
            assert_eq!(new == GONE, inside, "tetrahedron {t}");
            if new != GONE {
                assert_eq!(carved.mesh.corners(new as usize), c);
                assert_eq!(carved.mesh.labels[new as usize], mesh.labels[t]);
            }
        }
        // Every remaining node is used, and kept positions follow.
        let mut used = vec![false; carved.mesh.nodes.len()];
        for tet in &carved.mesh.tets {
            for &n in tet {
                used[n as usize] = true;
            }
        }
        assert!(used.iter().all(|&u| u));
        assert_eq!(
            keep_nodes(&mesh.nodes, &carved.node_index),
            carved.mesh.nodes
        );
    }
}
