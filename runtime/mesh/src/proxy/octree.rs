//! A label-aware octree proxy (in the spirit of Li et al. 2013): cubic
//! cells that split while they hold more than one material label, are
//! larger than the configured size, or cross the volume's far faces; 2:1
//! balanced, each leaf split into five tetrahedra.
//!
//! **Decision: 2:1 balance plus constraints.** Where a leaf meets leaves of
//! half its size, the small leaves' corners on the big leaf's face (its
//! edge midpoints and face centre) are *hanging nodes*: the big leaf's
//! tetrahedra do not use them. Each is tied to the big leaf's own
//! interpolation — an edge midpoint to the edge's two ends, a face centre to
//! the two ends of the face diagonal the big leaf's split uses (the centre
//! lies on it) — so a field that sets hanging nodes from their masters is
//! continuous across the interface. The balance keeps every constraint one
//! level deep; a master that hangs on a still larger leaf is expanded into
//! its own masters.
//!
//! Cells live in voxel-index space: a cell `(x, y, z, s)` spans voxels
//! `x .. x + s` along x (and so on), with corners on voxel centres; its
//! label is the one label of the voxels it owns (`x ≤ i < x + s`).

use super::{CELL_TETS, cell_label};
use crate::error::MeshError;
use crate::grid::Grid;
use crate::tet_mesh::TetMesh;
use glam::DVec3;
use std::collections::HashMap;

/// A node tied to others: its displacement is `Σ weight · master`.
#[derive(Clone, Debug, PartialEq)]
pub struct HangingNode {
    /// The constrained node.
    pub node: u32,
    /// `(master node, weight)`; the weights sum to 1.
    pub masters: Vec<(u32, f32)>,
}

/// An octree proxy: the mesh, its leaves and its hanging-node constraints.
#[derive(Clone, Debug)]
pub struct OctreeProxy {
    /// The tetrahedra of every leaf.
    pub mesh: TetMesh,
    /// Leaves `(x, y, z, size)`, voxel indices.
    pub leaves: Vec<([usize; 3], usize)>,
    /// Constraints of the hanging nodes.
    pub hanging: Vec<HangingNode>,
}

impl OctreeProxy {
    /// Labelled voxels of the volume (`dims` voxels, `label(voxel)` as the
    /// proxy was built with) that no leaf of their label covers
    /// ([`super::unrepresented_voxels`]; leaves hold `x ..= x + s`).
    pub fn unrepresented_voxels(
        &self,
        dims: [usize; 3],
        label: &impl Fn([usize; 3]) -> Option<u16>,
    ) -> usize {
        let cells = self
            .leaves
            .iter()
            .enumerate()
            .map(|(i, &(x, s))| (x, x.map(|v| v + s), self.mesh.labels[5 * i]));
        super::unrepresented_voxels(dims, cells, label)
    }

    /// Sets every hanging node's value from its masters (`values` per node,
    /// one axis).
    pub fn constrain(&self, values: &mut [f32]) {
        for h in &self.hanging {
            values[h.node as usize] = h.masters.iter().map(|&(m, w)| w * values[m as usize]).sum();
        }
    }
}

/// The leaf size covering each unit cell (log2; `u8::MAX` where no leaf).
struct SizeMap {
    dims: [usize; 3],
    lg: Vec<u8>,
}

impl SizeMap {
    fn at(&self, c: [isize; 3]) -> Option<u8> {
        if (0..3).any(|a| c[a] < 0 || c[a] as usize >= self.dims[a]) {
            return None;
        }
        let l =
            self.lg[c[0] as usize + self.dims[0] * (c[1] as usize + self.dims[1] * c[2] as usize)];
        (l != u8::MAX).then_some(l)
    }

    fn fill(&mut self, x: [usize; 3], s: usize, lg: u8) {
        for k in x[2]..x[2] + s {
            for j in x[1]..x[1] + s {
                let row = self.dims[0] * (j + self.dims[1] * k);
                self.lg[row + x[0]..row + x[0] + s].fill(lg);
            }
        }
    }
}

/// Builds the octree proxy of `grid`: leaves of at most `max_cell` voxels
/// (rounded down to a power of two), `label(voxel)` the material of a voxel
/// or `None` outside the model.
pub fn octree_proxy(
    grid: &Grid,
    max_cell: usize,
    label: impl Fn([usize; 3]) -> Option<u16>,
) -> Result<OctreeProxy, MeshError> {
    let name = format!("octree proxy (cells up to {max_cell} voxels)");
    super::check_sizes(&name, "max_cell", max_cell, grid)?;
    let max_cell = 1usize << max_cell.ilog2();
    let cells = grid.dims.map(|d| d - 1);
    let root = cells.iter().copied().max().unwrap_or(1).next_power_of_two();
    // The cell `(x, s)`'s voxels up to the volume's far faces where it
    // touches them (voxel indices, inclusive), else its own `x + s − 1`.
    let far = |x: [usize; 3], s: usize| {
        std::array::from_fn(|a| {
            if x[a] + s == cells[a] {
                cells[a]
            } else {
                x[a] + s - 1
            }
        })
    };
    // Leaves with their labels, from recursive splitting.
    let mut leaves: Vec<([usize; 3], usize, u16)> = Vec::new();
    let mut stack = vec![([0usize; 3], root)];
    while let Some((x, s)) = stack.pop() {
        if (0..3).any(|a| x[a] >= cells[a]) {
            continue;
        }
        let crosses = (0..3).any(|a| x[a] + s > cells[a]);
        let purity = match if crosses || s > max_cell {
            None
        } else {
            pure_label(x, s, &label)
        } {
            // Empty voxels it owns, but labelled ones on the volume's far
            // faces, which it touches and no cell owns: split, so a
            // one-voxel object there keeps its unit cells.
            Some(None) if cell_label(x, far(x, s), &label).is_some() => None,
            p => p,
        };
        match purity {
            Some(Some(l)) => leaves.push((x, s, l)),
            Some(None) => {}
            None if s == 1 => {
                // A unit cell of mixed voxels keeps the label of its first
                // (the voxel it owns); on the volume's far faces it also
                // owns the voxels there, and is kept when any is labelled,
                // with their most frequent label (the uniform proxy's rule).
                if let Some(l) = label(x).or_else(|| cell_label(x, far(x, 1), &label)) {
                    leaves.push((x, 1, l));
                }
            }
            None => {
                let h = s / 2;
                for o in 0..8 {
                    stack.push((
                        [
                            x[0] + (o & 1) * h,
                            x[1] + (o >> 1 & 1) * h,
                            x[2] + (o >> 2) * h,
                        ],
                        h,
                    ));
                }
            }
        }
    }
    if leaves.is_empty() {
        return Err(MeshError::Shape {
            source_name: name,
            message: "no voxel has a label; check the material ranges".into(),
        });
    }
    balance(&mut leaves, cells);
    let grid_name = name.clone();
    build_mesh(grid, &grid_name, leaves)
}

/// `Some(label)` when every voxel of the cell has the same label (`None`
/// for all unlabelled), `None` when they differ.
fn pure_label(
    x: [usize; 3],
    s: usize,
    label: &impl Fn([usize; 3]) -> Option<u16>,
) -> Option<Option<u16>> {
    let first = label(x);
    for k in x[2]..x[2] + s {
        for j in x[1]..x[1] + s {
            for i in x[0]..x[0] + s {
                if label([i, j, k]) != first {
                    return None;
                }
            }
        }
    }
    Some(first)
}

/// Splits leaves until no two leaves that touch (by face, edge or corner)
/// differ by more than a factor of two in size.
fn balance(leaves: &mut Vec<([usize; 3], usize, u16)>, cells: [usize; 3]) {
    let mut map = SizeMap {
        dims: cells,
        lg: vec![u8::MAX; cells.iter().product()],
    };
    for &(x, s, _) in leaves.iter() {
        map.fill(x, s, s.ilog2() as u8);
    }
    loop {
        let mut split = Vec::new();
        for (n, &(x, s, _)) in leaves.iter().enumerate() {
            if s < 4 {
                continue;
            }
            let lg = s.ilog2() as u8;
            // The unit cells just outside the leaf, all around it.
            let (lo, hi) = (x.map(|v| v as isize - 1), x.map(|v| (v + s) as isize));
            let mut needs = false;
            'scan: for k in lo[2]..=hi[2] {
                for j in lo[1]..=hi[1] {
                    for i in lo[0]..=hi[0] {
                        let inside = i > lo[0]
                            && i < hi[0]
                            && j > lo[1]
                            && j < hi[1]
                            && k > lo[2]
                            && k < hi[2];
                        if inside {
                            continue;
                        }
                        if map.at([i, j, k]).is_some_and(|l| l + 1 < lg) {
                            needs = true;
                            break 'scan;
                        }
                    }
                }
            }
            if needs {
                split.push(n);
            }
        }
        if split.is_empty() {
            return;
        }
        for &n in split.iter().rev() {
            let (x, s, l) = leaves.swap_remove(n);
            let h = s / 2;
            for o in 0..8 {
                let c = [
                    x[0] + (o & 1) * h,
                    x[1] + (o >> 1 & 1) * h,
                    x[2] + (o >> 2) * h,
                ];
                map.fill(c, h, h.ilog2() as u8);
                leaves.push((c, h, l));
            }
        }
    }
}

/// Which of the two mirrored splits a leaf takes: `(x/s + y/s + z/s + 1)
/// mod 2`. Leaves of one size alternate, as in the sampling mesh, so equal
/// neighbours share face diagonals; the `+ 1` makes the two half-size
/// leaves that straddle a big leaf's face diagonal split their faces along
/// that same diagonal (without it, always across it), which is what lets a
/// constrained field stay continuous at a level change.
fn split_parity(x: [usize; 3], s: usize) -> usize {
    (x[0] / s + x[1] / s + x[2] / s + 1) & 1
}

/// The corner (voxel indices) `corner` (`cx + 2 cy + 4 cz`) of a cell.
fn corner_of(x: [usize; 3], s: usize, corner: u8) -> [usize; 3] {
    let o = [corner & 1, (corner >> 1) & 1, corner >> 2].map(usize::from);
    [x[0] + o[0] * s, x[1] + o[1] * s, x[2] + o[2] * s]
}

fn build_mesh(
    grid: &Grid,
    name: &str,
    mut leaves: Vec<([usize; 3], usize, u16)>,
) -> Result<OctreeProxy, MeshError> {
    leaves.sort_unstable();
    let mut id: HashMap<[usize; 3], u32> = HashMap::new();
    let mut nodes = Vec::new();
    let mut tets = Vec::new();
    let mut labels = Vec::new();
    for &(x, s, l) in &leaves {
        let parity = split_parity(x, s);
        for corners in &CELL_TETS[parity] {
            tets.push(corners.map(|c| {
                let v = corner_of(x, s, c);
                *id.entry(v).or_insert_with(|| {
                    nodes.push(grid.index_to_world(DVec3::new(
                        v[0] as f64,
                        v[1] as f64,
                        v[2] as f64,
                    )));
                    nodes.len() as u32 - 1
                })
            }));
            labels.push(l);
        }
    }
    // Hanging nodes: nodes at a leaf's edge midpoints or face centres.
    let mut direct: HashMap<u32, Vec<(u32, f32)>> = HashMap::new();
    for &(x, s, _) in &leaves {
        if s < 2 {
            continue;
        }
        let h = s / 2;
        let parity = split_parity(x, s);
        // Edges: pairs of corners differing in one bit.
        for a in 0..8u8 {
            for bit in [1u8, 2, 4] {
                let b = a | bit;
                if b == a {
                    continue;
                }
                let (pa, pb) = (corner_of(x, s, a), corner_of(x, s, b));
                let mid = [0, 1, 2].map(|k| (pa[k] + pb[k]) / 2);
                if let Some(&m) = id.get(&mid) {
                    direct
                        .entry(m)
                        .or_insert_with(|| vec![(id[&pa], 0.5), (id[&pb], 0.5)]);
                }
            }
        }
        // Faces: the centre lies on the face diagonal of the split.
        for axis in 0..3 {
            for side in 0..2 {
                let on_face: Vec<u8> = (0..8u8).filter(|c| (c >> axis) & 1 == side).collect();
                let centre: [usize; 3] =
                    std::array::from_fn(|k| x[k] + if k == axis { side as usize * s } else { h });
                let Some(&m) = id.get(&centre) else {
                    continue;
                };
                // The diagonal: the two face corners that every face
                // triangle of the split on this face uses.
                let tris: Vec<Vec<u8>> = CELL_TETS[parity]
                    .iter()
                    .map(|t| {
                        t.iter()
                            .copied()
                            .filter(|c| on_face.contains(c))
                            .collect::<Vec<u8>>()
                    })
                    .filter(|f| f.len() == 3)
                    .collect();
                let diag: Vec<u8> = on_face
                    .iter()
                    .copied()
                    .filter(|c| tris.iter().all(|t| t.contains(c)))
                    .collect();
                if let [d0, d1] = diag[..] {
                    let (p0, p1) = (corner_of(x, s, d0), corner_of(x, s, d1));
                    direct
                        .entry(m)
                        .or_insert_with(|| vec![(id[&p0], 0.5), (id[&p1], 0.5)]);
                }
            }
        }
    }
    // Expand masters that hang themselves (chains across several levels).
    let mut hanging: Vec<HangingNode> = direct
        .keys()
        .map(|&node| {
            let mut masters: Vec<(u32, f32)> = Vec::new();
            let mut work = vec![(node, 1.0f32)];
            while let Some((n, w)) = work.pop() {
                match direct.get(&n) {
                    Some(ms) => work.extend(ms.iter().map(|&(m, mw)| (m, w * mw))),
                    None if n != node => match masters.iter_mut().find(|(m, _)| *m == n) {
                        Some(e) => e.1 += w,
                        None => masters.push((n, w)),
                    },
                    None => {}
                }
            }
            masters.sort_unstable_by_key(|m| m.0);
            HangingNode { node, masters }
        })
        .collect();
    hanging.sort_unstable_by_key(|h| h.node);
    let mesh = TetMesh::new(name, nodes, tets, labels)?;
    Ok(OctreeProxy {
        mesh,
        leaves: leaves.into_iter().map(|(x, s, _)| (x, s)).collect(),
        hanging,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::barycentric::BarycentricBinding;

    /// A 33³ volume: a small ball of label 2 inside label 1, air in one
    /// corner octant.
    fn phantom_label(v: [usize; 3]) -> Option<u16> {
        let d2 = (0..3).map(|a| (v[a] as f64 - 20.0).powi(2)).sum::<f64>();
        if v[0] < 8 && v[1] < 8 && v[2] < 8 {
            None
        } else if d2 < 16.0 {
            Some(2)
        } else {
            Some(1)
        }
    }

    fn proxy() -> OctreeProxy {
        let grid = Grid::new([33, 33, 33], DVec3::splat(0.5), DVec3::ZERO);
        octree_proxy(&grid, 16, phantom_label).unwrap()
    }

    #[test]
    fn leaves_are_pure_balanced_and_coarse_where_the_tissue_is_uniform() {
        let p = proxy();
        let uniform = crate::proxy::uniform_proxy(
            &Grid::new([33, 33, 33], DVec3::splat(0.5), DVec3::ZERO),
            1,
            phantom_label,
        )
        .unwrap();
        assert!(
            p.mesh.tets.len() * 10 < uniform.tets.len(),
            "{} tets",
            p.mesh.tets.len()
        );
        // Labels are pure.
        for (&(x, s), l) in p.leaves.iter().zip(p.mesh.labels.chunks(5)) {
            if s > 1 {
                assert_eq!(pure_label(x, s, &phantom_label), Some(Some(l[0])));
            }
        }
        // 2:1 balance between touching leaves.
        for &(a, sa) in &p.leaves {
            for &(b, sb) in &p.leaves {
                let touch = (0..3).all(|k| a[k] <= b[k] + sb && b[k] <= a[k] + sa);
                if touch {
                    assert!(
                        sa <= 2 * sb && sb <= 2 * sa,
                        "{a:?}/{sa} touches {b:?}/{sb}"
                    );
                }
            }
        }
        assert!(!p.hanging.is_empty());
        assert!(
            p.hanging
                .iter()
                .all(|h| (h.masters.iter().map(|m| m.1).sum::<f32>() - 1.0).abs() < 1e-6)
        );
    }

    #[test]
    fn a_constrained_field_is_continuous_across_level_changes() {
        let p = proxy();
        let m = &p.mesh;
        // Arbitrary (non-affine) node values, hanging nodes constrained.
        let mut u: Vec<f32> = m
            .nodes
            .iter()
            .map(|q| (q.x * 1.3).sin() as f32 + (q.y * q.z * 0.2).cos() as f32)
            .collect();
        p.constrain(&mut u);
        // Sample pairs of points just either side of every face between a
        // big and a small leaf: both sides must interpolate the same value.
        let mut pts = Vec::new();
        for &(x, s) in &p.leaves {
            for &(y, t) in &p.leaves {
                if s != 2 * t {
                    continue;
                }
                for (axis, face) in (0..3).flat_map(|a| [(a, x[a] + s), (a, x[a])]) {
                    // The small leaf on the far side of that face of the big one.
                    if y[axis] != face && y[axis] + t != face {
                        continue;
                    }
                    let inside = (0..3)
                        .filter(|&k| k != axis)
                        .all(|k| y[k] >= x[k] && y[k] + t <= x[k] + s);
                    if !inside {
                        continue;
                    }
                    for f in [0.13, 0.37, 0.71] {
                        let mut c = [0.0; 3];
                        for k in 0..3 {
                            c[k] = y[k] as f64 + f * t as f64;
                        }
                        let mut a = c;
                        let mut b = c;
                        a[axis] = face as f64 - 1e-4;
                        b[axis] = face as f64 + 1e-4;
                        pts.push(DVec3::from_array(a) * 0.5);
                        pts.push(DVec3::from_array(b) * 0.5);
                    }
                }
            }
        }
        assert!(pts.len() > 50, "{} samples", pts.len());
        let bind = BarycentricBinding::bind(m, pts.len(), |i| pts[i]);
        let mut out = [
            vec![0f32; pts.len()],
            vec![0f32; pts.len()],
            vec![0f32; pts.len()],
        ];
        let [ox, oy, oz] = &mut out;
        bind.map(m, [&u, &u, &u], [ox, oy, oz]);
        for pair in out[0].chunks(2) {
            assert!(
                (pair[0] - pair[1]).abs() < 2e-3,
                "jump {} vs {}",
                pair[0],
                pair[1]
            );
        }
    }
}
