//! The connected pieces of a proxy, and which of them nothing holds: after
//! a cut or carve, a piece with no fixed or grabbed node floats (it falls
//! under gravity, and a static solve has no unique answer for it).

use crate::proxy::HangingNode;
use crate::tet_mesh::TetMesh;

/// Pieces of `mesh` (tetrahedra sharing nodes, hanging nodes with their
/// masters) with no node for which `anchored(node)` holds: `(pieces,
/// nodes in them)`.
pub fn unanchored_pieces(
    mesh: &TetMesh,
    hanging: &[HangingNode],
    anchored: impl Fn(usize) -> bool,
) -> (usize, usize) {
    let mut parent: Vec<u32> = (0..mesh.nodes.len() as u32).collect();
    fn root(parent: &mut [u32], mut n: u32) -> u32 {
        while parent[n as usize] != n {
            let up = parent[parent[n as usize] as usize];
            parent[n as usize] = up;
            n = up;
        }
        n
    }
    let mut join = |a: u32, b: u32| {
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb) as usize] = ra.min(rb);
        }
    };
    for tet in &mesh.tets {
        for &n in &tet[1..] {
            join(tet[0], n);
        }
    }
    for h in hanging {
        for &(m, _) in &h.masters {
            join(h.node, m);
        }
    }
    let n = mesh.nodes.len();
    let mut held = vec![false; n];
    let mut size = vec![0usize; n];
    for node in 0..n {
        let r = root(&mut parent, node as u32) as usize;
        size[r] += 1;
        held[r] |= anchored(node);
    }
    (0..n)
        .filter(|&r| size[r] > 0 && !held[r])
        .fold((0, 0), |(p, c), r| (p + 1, c + size[r]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use crate::proxy::uniform_proxy;
    use glam::DVec3;

    #[test]
    fn pieces_without_an_anchor_are_counted() {
        // Two boxes of material with a gap between them.
        let grid = Grid::new([7, 3, 3], DVec3::ONE, DVec3::ZERO);
        let mesh = uniform_proxy(&grid, 1, |v| (v[0] != 3).then_some(0)).unwrap();
        let left = |n: usize| mesh.nodes[n].x < 3.0;
        assert_eq!(unanchored_pieces(&mesh, &[], |_| false).0, 2);
        let (pieces, nodes) = unanchored_pieces(&mesh, &[], |n| left(n) && mesh.nodes[n].x == 0.0);
        assert_eq!(pieces, 1);
        assert_eq!(nodes, mesh.nodes.iter().filter(|p| p.x >= 3.0).count());
        assert_eq!(unanchored_pieces(&mesh, &[], |_| true), (0, 0));
    }
}
