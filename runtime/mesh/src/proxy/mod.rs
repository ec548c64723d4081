//! Tetrahedral proxies generated from a volume, for the mesh-based
//! deformation models.
//!
//! [`uniform_proxy`]: hexahedral cells every `step` voxels (the last cell
//! of an axis takes what is left), each split into five tetrahedra with the
//! sampling mesh's mirrored pattern
//! ([`voxflex_resample::sampling_mesh::CELL_TETS`]), so neighbouring cells
//! share face diagonals and the mesh is conforming. Node positions are
//! voxel centres, in world millimetres.
//!
//! **Features smaller than a cell** ([`cell_label`]): a cell is kept when
//! *any* voxel it owns is labelled, and takes the most frequent label
//! among its labelled voxels (ties to the lower label, i.e. the material
//! listed first); only cells with no labelled voxel at all (air) are left
//! out. A cell owns, along each axis, the voxels above its lower corner
//! plane up to and including its upper one (the first cell of an axis
//! owns its lower plane too), so every voxel has one owner, and cells of
//! one voxel keep the rule of before (the label of their upper corner):
//! a one-voxel gap of air still separates two pieces. So a one-voxel object or a one-voxel slab always
//! gets the cells around it — it is never bound to nothing. What can still
//! happen is that a minority material inside a cell (a thin plate of bone
//! in soft tissue) moves with the cell's majority material:
//! [`unrepresented_voxels`] counts those voxels, and the mesh models warn
//! with the count and report it as `labelled_voxels_lost`.
//!
//! [`octree_proxy`]: label-aware octree cells, 2:1 balanced, with
//! hanging-node constraints (see [`octree`]).

pub mod octree;

pub use octree::{HangingNode, OctreeProxy, octree_proxy};

use crate::error::MeshError;
use crate::grid::Grid;
use crate::tet_mesh::TetMesh;
use glam::DVec3;
use voxflex_resample::sampling_mesh::CELL_TETS;

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

/// The label of the cell spanning voxels `lo ..= hi` (voxel indices, per
/// axis, corners included): the most frequent label among its labelled
/// voxels, ties to the lower label; `None` when no voxel of it is labelled.
pub fn cell_label(
    lo: [usize; 3],
    hi: [usize; 3],
    label: &impl Fn([usize; 3]) -> Option<u16>,
) -> Option<u16> {
    // (label, count), few distinct labels per cell.
    let mut counts: Vec<(u16, u32)> = Vec::new();
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            for i in lo[0]..=hi[0] {
                let Some(l) = label([i, j, k]) else {
                    continue;
                };
                match counts.iter_mut().find(|(m, _)| *m == l) {
                    Some((_, n)) => *n += 1,
                    None => counts.push((l, 1)),
                }
            }
        }
    }
    counts
        .into_iter()
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
        .map(|(l, _)| l)
}

/// Labelled voxels of a grid of `dims` voxels that no cell of their label
/// covers: `cells` are `(lo, hi, label)` boxes of voxel indices (`lo ..=
/// hi`, corners included), `label(voxel)` a voxel's label. A voxel counts
/// as represented when any cell whose box holds it has its label (a voxel
/// on a face between cells of two materials is represented by either).
pub fn unrepresented_voxels(
    dims: [usize; 3],
    cells: impl IntoIterator<Item = ([usize; 3], [usize; 3], u16)>,
    label: &impl Fn([usize; 3]) -> Option<u16>,
) -> usize {
    let linear = |v: [usize; 3]| v[0] + dims[0] * (v[1] + dims[1] * v[2]);
    let mut covered = vec![false; dims.iter().product()];
    for (lo, hi, l) in cells {
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    if label([i, j, k]) == Some(l) {
                        covered[linear([i, j, k])] = true;
                    }
                }
            }
        }
    }
    let mut lost = 0;
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                lost += usize::from(label([i, j, k]).is_some() && !covered[linear([i, j, k])]);
            }
        }
    }
    lost
}

/// A conforming tetrahedral proxy of `grid` with cells of `step` voxels;
/// `label(voxel)` gives a voxel's material label or `None` outside the
/// model (voxel indices). A cell is kept when any voxel it owns is
/// labelled, with its most frequent label ([`cell_label`]; see the module).
pub fn uniform_proxy(
    grid: &Grid,
    step: usize,
    label: impl Fn([usize; 3]) -> Option<u16>,
) -> Result<TetMesh, MeshError> {
    uniform_cells(grid, step, &label).map(|(mesh, _)| mesh)
}

/// [`uniform_proxy`], and how many labelled voxels no cell of their label
/// covers ([`unrepresented_voxels`]: minority materials inside a cell).
pub fn uniform_proxy_with_losses(
    grid: &Grid,
    step: usize,
    label: impl Fn([usize; 3]) -> Option<u16>,
) -> Result<(TetMesh, usize), MeshError> {
    let (mesh, cells) = uniform_cells(grid, step, &label)?;
    Ok((mesh, unrepresented_voxels(grid.dims, cells, &label)))
}

/// The uniform proxy and its kept cells `(lo, hi, label)` (voxel indices,
/// corners included).
#[allow(clippy::type_complexity)]
fn uniform_cells(
    grid: &Grid,
    step: usize,
    label: &impl Fn([usize; 3]) -> Option<u16>,
) -> Result<(TetMesh, Vec<([usize; 3], [usize; 3], u16)>), MeshError> {
    let name = format!("uniform proxy (step {step})");
    check_sizes(&name, "step", step, grid)?;
    let t = grid.dims.map(|d| ticks(d, step));
    let nodes_per = t.clone().map(|v| v.len());
    let node_id = |c: [usize; 3]| c[0] + nodes_per[0] * (c[1] + nodes_per[1] * c[2]);
    let mut used: Vec<u32> = vec![u32::MAX; nodes_per.iter().product()];
    let mut nodes = Vec::new();
    let mut tets = Vec::new();
    let mut labels = Vec::new();
    let mut cells = Vec::new();
    for k in 0..nodes_per[2] - 1 {
        for j in 0..nodes_per[1] - 1 {
            for i in 0..nodes_per[0] - 1 {
                let c = [i, j, k];
                let lo = [0, 1, 2].map(|a| t[a][c[a]]);
                let hi = [0, 1, 2].map(|a| t[a][c[a] + 1]);
                // The voxels it owns: above its lower corner plane up to
                // its upper one (the first cell of an axis owns both).
                let own = [0, 1, 2].map(|a| lo[a] + usize::from(c[a] > 0));
                let Some(l) = cell_label(own, hi, label) else {
                    continue;
                };
                cells.push((lo, hi, l));
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
            message: "no voxel has a label; check the material ranges".into(),
        });
    }
    Ok((TetMesh::new(&name, nodes, tets, labels)?, cells))
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
        assert!(e.to_string().contains("no voxel has a label"), "{e}");
        assert!(uniform_proxy(&grid, 0, |_| Some(0)).is_err());
    }

    /// Issue 12 (8): a one-voxel object anywhere in the volume (every
    /// offset within its cell, cell corners and the far faces included)
    /// keeps cells of its material around it, in the uniform proxy and the
    /// octree: its voxel centre lies inside the proxy and nothing is
    /// counted lost. (The centre-voxel rule before kept a cell only for
    /// the one offset at its centre.)
    #[test]
    fn a_one_voxel_object_keeps_its_cells_at_every_position() {
        use crate::barycentric::BarycentricBinding;
        let grid = Grid::new(
            [9, 9, 9],
            DVec3::new(1.0, 0.5, 2.0),
            DVec3::new(-3.0, 1.0, 7.0),
        );
        for l in 0..grid.len() {
            let at = grid.unlinear(l);
            let label = |v: [usize; 3]| (v == at).then_some(2);
            let p = grid.index_to_world(DVec3::from_array(at.map(|c| c as f64)));
            let (uniform, lost) = uniform_proxy_with_losses(&grid, 4, label).unwrap();
            assert_eq!(lost, 0, "uniform, voxel {at:?}");
            assert!(uniform.labels.iter().all(|&l| l == 2));
            let octree = octree_proxy(&grid, 4, label).unwrap();
            assert_eq!(octree.unrepresented_voxels(grid.dims, &label), 0);
            for (name, mesh) in [("uniform", &uniform), ("octree", &octree.mesh)] {
                let b = BarycentricBinding::bind(mesh, 1, |_| p);
                assert_eq!(b.outside, 0, "{name}: voxel {at:?} outside the proxy");
            }
        }
    }

    /// A cell takes the most frequent label of its labelled voxels (ties
    /// to the lower); voxels of a minority label inside it are counted,
    /// those on a face shared with a cell of their label are not.
    #[test]
    fn minority_labels_are_counted_lost_and_majorities_win() {
        let grid = Grid::new([9, 9, 9], DVec3::ONE, DVec3::ZERO);
        // Soft tissue (0) everywhere, bone (1) at two voxels: one inside
        // the cell [0, 4]³, one on the face x = 4 between two soft cells.
        let label = |v: [usize; 3]| Some(u16::from(v == [2, 2, 2] || v == [4, 1, 1]));
        let (m, lost) = uniform_proxy_with_losses(&grid, 4, label).unwrap();
        assert!(m.labels.iter().all(|&l| l == 0));
        assert_eq!(lost, 2);
        // Air does not vote: one bone voxel in an empty cell keeps it as bone.
        let label = |v: [usize; 3]| (v == [2, 2, 2]).then_some(1);
        let (m, lost) = uniform_proxy_with_losses(&grid, 4, label).unwrap();
        assert_eq!((m.tets.len(), lost), (5, 0));
        assert!(m.labels.iter().all(|&l| l == 1));
        // A tie goes to the lower label.
        let label = |v: [usize; 3]| Some(u16::from(v[0] >= 2) * 3 + 1);
        assert_eq!(cell_label([0; 3], [3, 0, 0], &label), Some(1));
        assert_eq!(cell_label([0; 3], [4, 0, 0], &label), Some(4));
        assert_eq!(cell_label([0; 3], [4, 4, 4], &|_| None), None);
    }
}
