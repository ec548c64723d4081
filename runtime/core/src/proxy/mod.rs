//! Tetrahedral proxies generated from a volume, for the mesh-based
//! deformation models.
//!
//! [`uniform_proxy`]: hexahedral cells every `step` voxels (the last cell
//! of an axis takes what is left), each split into five tetrahedra with the
//! sampling mesh's mirrored pattern
//! ([`crate::resample::sampling_mesh::CELL_TETS`]), so neighbouring cells
//! share face diagonals and the mesh is conforming. A cell takes the label
//! of the voxel nearest its centre, and cells without a label (air) are
//! left out. Node positions are voxel centres, in world millimetres.
//!
//! [`octree_proxy`]: label-aware octree cells, 2:1 balanced, with
//! hanging-node constraints (see [`octree`]).

pub mod octree;

pub use octree::{HangingNode, OctreeProxy, octree_proxy};

use crate::error::MeshError;
use crate::grid::Grid;
use crate::resample::sampling_mesh::CELL_TETS;
use crate::tet_mesh::TetMesh;
use glam::DVec3;

/// Voxel indices of the cell corners along one axis of `n` voxels: every
/// `step`, and the last voxel.
fn ticks(n: usize, step: usize) -> Vec<usize> {
    let mut t: Vec<usize> = (0..n.saturating_sub(1)).step_by(step).collect();
    t.push(n - 1);
    t
}

/// Refuses a cell size (`key`, voxels) of 0 and a volume with fewer than 2
/// voxels along an axis, naming the generator `name`.
fn check_sizes(name: &str, key: &str, size: usize, grid: &Grid) -> Result<(), MeshError> {
    let message = if size == 0 {
        format!("`{key}` must be at least 1 voxel")
    } else if grid.dims.iter().any(|&d| d < 2) {
        format!(
            "the volume ({:?} voxels) needs at least 2 voxels along every axis",
            grid.dims
        )
    } else {
        return Ok(());
    };
    Err(MeshError::Shape {
        source_name: name.to_string(),
        message,
    })
}

/// A conforming tetrahedral proxy of `grid` with cells of `step` voxels;
/// `label(voxel)` gives a voxel's material label or `None` outside the
/// model (voxel indices).
pub fn uniform_proxy(
    grid: &Grid,
    step: usize,
    label: impl Fn([usize; 3]) -> Option<u16>,
) -> Result<TetMesh, MeshError> {
    let name = format!("uniform proxy (step {step})");
    check_sizes(&name, "step", step, grid)?;
    let t = grid.dims.map(|d| ticks(d, step));
    let nodes_per = t.clone().map(|v| v.len());
    let node_id = |c: [usize; 3]| c[0] + nodes_per[0] * (c[1] + nodes_per[1] * c[2]);
    let mut used: Vec<u32> = vec![u32::MAX; nodes_per.iter().product()];
    let mut nodes = Vec::new();
    let mut tets = Vec::new();
    let mut labels = Vec::new();
    for k in 0..nodes_per[2] - 1 {
        for j in 0..nodes_per[1] - 1 {
            for i in 0..nodes_per[0] - 1 {
                let c = [i, j, k];
                let centre = [0, 1, 2].map(|a| (t[a][c[a]] + t[a][c[a] + 1]).div_ceil(2));
                let Some(l) = label(centre) else {
                    continue;
                };
                for corners in &CELL_TETS[(i + j + k) & 1] {
                    let tet = corners.map(|corner| {
                        let o = [corner & 1, (corner >> 1) & 1, corner >> 2].map(usize::from);
                        let n = node_id([i + o[0], j + o[1], k + o[2]]);
                        if used[n] == u32::MAX {
                            used[n] = nodes.len() as u32;
                            let v = [0, 1, 2].map(|a| t[a][c[a] + o[a]] as f64);
                            nodes.push(grid.index_to_world(DVec3::from_array(v)));
                        }
                        used[n]
                    });
                    tets.push(tet);
                    labels.push(l);
                }
            }
        }
    }
    if tets.is_empty() {
        return Err(MeshError::Shape {
            source_name: name,
            message: "no cell has a labelled voxel at its centre; check the material ranges".into(),
        });
    }
    TetMesh::new(&name, nodes, tets, labels)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_uniform_proxy_is_conforming_and_fills_the_box() {
        let grid = Grid::new(
            [10, 7, 6],
            DVec3::new(0.5, 1.0, 2.0),
            DVec3::new(3.0, -1.0, 0.0),
        );
        let m = uniform_proxy(&grid, 2, |_| Some(1)).unwrap();
        // Cells 5 × 3 × 3 (x: 0 2 4 6 8 9; y: 0 2 4 6; z: 0 2 4 5).
        assert_eq!(m.tets.len(), 5 * 3 * 3 * 5);
        assert_eq!(m.nodes.len(), 6 * 4 * 4);
        let volume: f64 = (0..m.tets.len()).map(|t| m.volume(t)).sum();
        let size = DVec3::new(9.0 * 0.5, 6.0 * 1.0, 5.0 * 2.0);
        assert!((volume - size.x * size.y * size.z).abs() < 1e-9);
        // Every face is shared by two tetrahedra or lies on the box.
        let faces = m.boundary_faces().unwrap();
        let area: f64 = faces
            .iter()
            .map(|f| {
                let p = f.map(|v| m.nodes[v as usize]);
                (p[1] - p[0]).cross(p[2] - p[0]).length() / 2.0
            })
            .sum();
        let surface = 2.0 * (size.x * size.y + size.y * size.z + size.x * size.z);
        assert!((area - surface).abs() < 1e-9, "{area} vs {surface}");
        assert!((0..m.tets.len()).all(|t| m.volume(t) > 0.0));
    }

    #[test]
    fn unlabelled_cells_are_left_out_and_unused_nodes_dropped() {
        let grid = Grid::new([9, 9, 9], DVec3::ONE, DVec3::ZERO);
        // Only the lower-x half is tissue.
        let m = uniform_proxy(&grid, 4, |v| (v[0] < 4).then_some(3)).unwrap();
        assert_eq!(m.tets.len(), 4 * 5);
        assert_eq!(m.nodes.len(), 2 * 3 * 3);
        assert!(m.labels.iter().all(|&l| l == 3));
        assert!(m.nodes.iter().all(|p| p.x <= 4.0));
        let e = uniform_proxy(&grid, 4, |_| None).unwrap_err();
        assert!(
            e.to_string().contains("no cell has a labelled voxel"),
            "{e}"
        );
        assert!(uniform_proxy(&grid, 0, |_| Some(0)).is_err());
    }
}
