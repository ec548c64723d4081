//! Cutting a tetrahedral proxy by duplicating nodes.
//!
//! An interior face is cut when the segment between its two tetrahedra's
//! centroids (current positions) crosses the cut polygon. Around each node
//! of a cut face, the tetrahedra that use the node are grouped by the
//! uncut faces they share through it; each group beyond the first gets its
//! own copy of the node, so the two sides of the cut no longer share it and
//! separate. Where the polygon ends inside the mesh, the star of a node at
//! the crack's tip stays connected around the tip and the node is not
//! split: the cut opens up to its edge and no further.

use crate::cut_polygon::CutPolygon;
use crate::tet_mesh::TetMesh;
use glam::DVec3;
use std::collections::HashMap;

/// What a cut did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MeshCut {
    /// Interior faces cut.
    pub faces: usize,
    /// For each node appended to the mesh, the node it copies.
    pub origin: Vec<u32>,
}

/// Corner indices of the face opposite each corner of a tetrahedron.
const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]];

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// Cuts `mesh` (nodes at current positions `x`, mm) along `cut`: appends
/// the duplicated nodes (at their original's rest position) and renumbers
/// the tetrahedra that move to them.
pub fn cut_mesh(mesh: &mut TetMesh, x: &[DVec3], cut: &CutPolygon) -> MeshCut {
    let centroid = |t: usize| mesh.tets[t].iter().map(|&n| x[n as usize]).sum::<DVec3>() / 4.0;
    // Interior faces: sorted node triple → (tet, tet).
    let mut faces: HashMap<[u32; 3], (u32, u32)> = HashMap::new();
    for (t, tet) in mesh.tets.iter().enumerate() {
        for f in FACES {
            let mut key = f.map(|c| tet[c]);
            key.sort_unstable();
            faces
                .entry(key)
                .and_modify(|e| e.1 = t as u32)
                .or_insert((t as u32, u32::MAX));
        }
    }
    // Incidences `4 t + corner` joined through uncut faces.
    let mut parent: Vec<u32> = (0..4 * mesh.tets.len() as u32).collect();
    let corner_of = |t: u32, n: u32| -> u32 {
        4 * t
            + mesh.tets[t as usize]
                .iter()
                .position(|&m| m == n)
                .expect("node of tet") as u32
    };
    let mut cut_nodes = Vec::new();
    let mut cut_faces = 0;
    for (key, &(a, b)) in &faces {
        if b == u32::MAX {
            continue;
        }
        if cut.crosses(centroid(a as usize), centroid(b as usize)) {
            cut_faces += 1;
            cut_nodes.extend_from_slice(key);
            continue;
        }
        for &n in key {
            let (ra, rb) = (
                find(&mut parent, corner_of(a, n)),
                find(&mut parent, corner_of(b, n)),
            );
            parent[ra as usize] = rb;
        }
    }
    let mut out = MeshCut {
        faces: cut_faces,
        origin: Vec::new(),
    };
    if cut_faces == 0 {
        return out;
    }
    cut_nodes.sort_unstable();
    cut_nodes.dedup();
    // The incidences of each cut node, by group.
    let mut incidences: HashMap<u32, Vec<u32>> = HashMap::new();
    for (t, tet) in mesh.tets.iter().enumerate() {
        for (c, &n) in tet.iter().enumerate() {
            if cut_nodes.binary_search(&n).is_ok() {
                incidences.entry(n).or_default().push((4 * t + c) as u32);
            }
        }
    }
    let mut nodes: Vec<u32> = incidences.keys().copied().collect();
    nodes.sort_unstable();
    for n in nodes {
        let mut groups: Vec<(u32, Vec<u32>)> = Vec::new();
        for &i in &incidences[&n] {
            let root = find(&mut parent, i);
            match groups.iter_mut().find(|g| g.0 == root) {
                Some(g) => g.1.push(i),
                None => groups.push((root, vec![i])),
            }
        }
        // The first group keeps the node; each other gets a copy.
        for (_, group) in groups.into_iter().skip(1) {
            let copy = mesh.nodes.len() as u32;
            mesh.nodes.push(mesh.nodes[n as usize]);
            out.origin.push(n);
            for i in group {
                mesh.tets[i as usize / 4][i as usize % 4] = copy;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::proxy::uniform_proxy;

    fn slab() -> TetMesh {
        // 4 × 2 × 2 cells of 1 mm.
        let grid = Grid::new([5, 3, 3], DVec3::ONE, DVec3::ZERO);
        uniform_proxy(&grid, 1, |_| Some(0)).unwrap()
    }

    #[test]
    fn a_cut_through_the_whole_slab_separates_it_in_two() {
        let mut mesh = slab();
        let before = mesh.nodes.len();
        let x = mesh.nodes.clone();
        // The plane x = 2, larger than the slab.
        let cut = CutPolygon::new(&[
            [2.0, -1.0, -1.0],
            [2.0, 3.0, -1.0],
            [2.0, 3.0, 3.0],
            [2.0, -1.0, 3.0],
        ]);
        let r = cut_mesh(&mut mesh, &x, &cut);
        assert!(r.faces > 0);
        // The 9 nodes of the plane x = 2 are doubled.
        assert_eq!(r.origin.len(), 9);
        assert_eq!(mesh.nodes.len(), before + 9);
        assert!(r.origin.iter().all(|&n| mesh.nodes[n as usize].x == 2.0));
        // No tetrahedron on one side shares a node with one on the other.
        let side = |t: &[u32; 4]| t.iter().map(|&n| mesh.nodes[n as usize].x).sum::<f64>() < 8.0;
        let left: std::collections::HashSet<u32> = mesh
            .tets
            .iter()
            .filter(|t| side(t))
            .flatten()
            .copied()
            .collect();
        assert!(
            mesh.tets
                .iter()
                .filter(|t| !side(t))
                .flatten()
                .all(|n| !left.contains(n))
        );
        // Still a valid, positively oriented mesh of the same volume.
        let volume: f64 = (0..mesh.tets.len()).map(|t| mesh.volume(t)).sum();
        assert!((volume - 16.0).abs() < 1e-9);
    }

    #[test]
    fn a_partial_cut_keeps_the_crack_tip_joined() {
        let mut mesh = slab();
        let x = mesh.nodes.clone();
        // The plane x = 2 for y below 1 only: the nodes at y = 1 and 2 are
        // on or beyond the tip and stay shared.
        let cut = CutPolygon::new(&[
            [2.0, -1.0, -1.0],
            [2.0, 1.0, -1.0],
            [2.0, 1.0, 3.0],
            [2.0, -1.0, 3.0],
        ]);
        let r = cut_mesh(&mut mesh, &x, &cut);
        assert!(r.faces > 0);
        assert!(!r.origin.is_empty());
        assert!(
            r.origin.iter().all(|&n| mesh.nodes[n as usize].y < 1.0),
            "only nodes below the tip split"
        );
        let none = CutPolygon::new(&[[9.0, 0.0, 0.0], [9.0, 1.0, 0.0], [9.0, 1.0, 1.0]]);
        let x = mesh.nodes.clone();
        assert_eq!(cut_mesh(&mut mesh, &x, &none), MeshCut::default());
    }
}
