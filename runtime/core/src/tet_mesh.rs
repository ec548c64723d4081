//! A tetrahedral mesh: nodes in world millimetres, tetrahedra as four node
//! indices, a material label per tetrahedron. The proxy of the mesh-based
//! deformation models (mass-spring, corotational FEM), generated from a
//! volume (`voxflex_mesh::proxy`) or read from a file.
//!
//! Every tetrahedron is stored positively oriented:
//! `(x1 − x0) · ((x2 − x0) × (x3 − x0)) > 0`; [`TetMesh::new`] swaps two
//! corners of a negatively oriented one.

use crate::error::MeshError;
use glam::DVec3;
use std::collections::HashMap;

/// Tetrahedra smaller than this fraction of their longest edge cubed are
/// degenerate (a regular tetrahedron has 0.118; the five-tetrahedra split
/// of a cube 0.167 and 0.333).
pub const MIN_SHAPE: f64 = 1e-6;

/// A tetrahedral mesh (rest configuration).
#[derive(Clone, Debug, PartialEq)]
pub struct TetMesh {
    /// Node positions, mm (world frame).
    pub nodes: Vec<DVec3>,
    /// Node indices of each tetrahedron, positively oriented.
    pub tets: Vec<[u32; 4]>,
    /// Material label of each tetrahedron.
    pub labels: Vec<u16>,
}

impl TetMesh {
    /// Checks and orients a mesh; `source_name` (a file name or the
    /// generator) goes into every error.
    pub fn new(
        source_name: &str,
        nodes: Vec<DVec3>,
        mut tets: Vec<[u32; 4]>,
        labels: Vec<u16>,
    ) -> Result<Self, MeshError> {
        let shape = |message: String| MeshError::Shape {
            source_name: source_name.to_string(),
            message,
        };
        if tets.is_empty() {
            return Err(shape("the mesh has no tetrahedron".into()));
        }
        if labels.len() != tets.len() {
            return Err(shape(format!(
                "{} labels for {} tetrahedra; give one label per tetrahedron",
                labels.len(),
                tets.len()
            )));
        }
        if let Some((node, p)) = nodes.iter().enumerate().find(|(_, p)| !p.is_finite()) {
            return Err(MeshError::NonFinite {
                source_name: source_name.to_string(),
                node,
                value: p.to_array(),
            });
        }
        for (t, tet) in tets.iter_mut().enumerate() {
            if let Some(&node) = tet.iter().find(|&&v| v as usize >= nodes.len()) {
                return Err(MeshError::BadIndex {
                    source_name: source_name.to_string(),
                    tet: t,
                    node,
                    nodes: nodes.len(),
                });
            }
            let x = tet.map(|v| nodes[v as usize]);
            let volume = signed_volume(x);
            let edge = (0..4)
                .flat_map(|a| (a + 1..4).map(move |b| (a, b)))
                .map(|(a, b)| (x[a] - x[b]).length())
                .fold(0.0, f64::max);
            if volume.abs() <= MIN_SHAPE * edge.powi(3) || edge == 0.0 {
                return Err(MeshError::Degenerate {
                    source_name: source_name.to_string(),
                    tet: t,
                    volume: volume.abs(),
                    edge,
                });
            }
            if volume < 0.0 {
                tet.swap(2, 3);
            }
        }
        Ok(Self {
            nodes,
            tets,
            labels,
        })
    }

    /// The corner positions (mm) of tetrahedron `t`.
    #[inline]
    pub fn corners(&self, t: usize) -> [DVec3; 4] {
        self.tets[t].map(|v| self.nodes[v as usize])
    }

    /// Volume of tetrahedron `t`, mm³.
    pub fn volume(&self, t: usize) -> f64 {
        signed_volume(self.corners(t))
    }

    /// Node indices of tetrahedron `t`'s face opposite its corner `opp`,
    /// in corner order.
    pub fn face(&self, t: usize, opp: usize) -> [u32; 3] {
        let tet = self.tets[t];
        let mut f = [0u32; 3];
        for (m, c) in (0..4).filter(|&c| c != opp).enumerate() {
            f[m] = tet[c];
        }
        f
    }

    /// The faces used by exactly one tetrahedron (the mesh's surface), each
    /// as `(tetrahedron, its corner opposite the face)`, ascending; `Err`
    /// with a face (sorted node indices) used more than twice (the mesh is
    /// not a manifold).
    pub fn surface(&self) -> Result<Vec<(u32, u8)>, [u32; 3]> {
        let mut uses: HashMap<[u32; 3], (u32, u32, u8)> = HashMap::new();
        for t in 0..self.tets.len() {
            for opp in 0..4 {
                let mut f = self.face(t, opp);
                f.sort_unstable();
                uses.entry(f).or_insert((0, t as u32, opp as u8)).0 += 1;
            }
        }
        if let Some((f, _)) = uses.iter().find(|&(_, u)| u.0 > 2) {
            return Err(*f);
        }
        let mut faces: Vec<(u32, u8)> = uses
            .into_values()
            .filter(|u| u.0 == 1)
            .map(|(_, t, opp)| (t, opp))
            .collect();
        faces.sort_unstable();
        Ok(faces)
    }

    /// The faces used by exactly one tetrahedron (the mesh's surface), each
    /// as sorted node indices, ascending; `Err` with a face used more than
    /// twice (the mesh is not a manifold).
    pub fn boundary_faces(&self) -> Result<Vec<[u32; 3]>, [u32; 3]> {
        let mut faces: Vec<[u32; 3]> = self
            .surface()?
            .into_iter()
            .map(|(t, opp)| {
                let mut f = self.face(t as usize, opp as usize);
                f.sort_unstable();
                f
            })
            .collect();
        faces.sort_unstable();
        Ok(faces)
    }

    /// Axis-aligned bounds of the nodes, mm.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.nodes.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        )
    }
}

/// `(x1 − x0) · ((x2 − x0) × (x3 − x0)) / 6`, mm³.
#[inline]
pub fn signed_volume(x: [DVec3; 4]) -> f64 {
    (x[1] - x[0]).dot((x[2] - x[0]).cross(x[3] - x[0])) / 6.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit() -> (Vec<DVec3>, Vec<[u32; 4]>) {
        (
            vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
            vec![[0, 1, 2, 3]],
        )
    }

    #[test]
    fn orients_and_refuses_bad_meshes_with_what_is_wrong() {
        let (nodes, _) = unit();
        let m = TetMesh::new("t", nodes.clone(), vec![[0, 1, 3, 2]], vec![0]).unwrap();
        assert!((m.volume(0) - 1.0 / 6.0).abs() < 1e-15);
        assert_eq!(m.boundary_faces().unwrap().len(), 4);
        let e = TetMesh::new("a.msh", nodes.clone(), vec![[0, 1, 2, 7]], vec![0]).unwrap_err();
        assert!(
            e.to_string().contains("a.msh: tetrahedron 0 names node 7"),
            "{e}"
        );
        let mut bad = nodes.clone();
        bad[2].y = f64::NAN;
        let e = TetMesh::new("a.msh", bad, vec![[0, 1, 2, 3]], vec![0]).unwrap_err();
        assert!(e.to_string().contains("node 2 has a non-finite"), "{e}");
        let mut flat = nodes.clone();
        flat[3] = DVec3::new(0.5, 0.5, 1e-9);
        let e = TetMesh::new("a.msh", flat, vec![[0, 1, 2, 3]], vec![0]).unwrap_err();
        assert!(e.to_string().contains("degenerate"), "{e}");
        let e = TetMesh::new("a.msh", nodes, vec![[0, 1, 2, 3]], vec![]).unwrap_err();
        assert!(e.to_string().contains("0 labels for 1 tetrahedra"), "{e}");
    }
}
