//! A symmetric block-sparse matrix with 3 × 3 blocks on the node graph of
//! a tetrahedral mesh (block `(i, j)` exists when nodes `i` and `j` share a
//! tetrahedron), assembled from per-tetrahedron 4 × 4 block contributions
//! (or `K × K` for elements of `K` nodes, such as 10-node quadratic
//! tetrahedra: [`BlockMatrix::on_elements`]) without locks, and multiplied
//! in parallel by rows.
//!
//! Assembly: every tetrahedron writes its 16 blocks into its own slots of
//! a scratch array, and each matrix block then sums the slots listed for it
//! (a fixed gather list built once), so rows can be assembled in parallel
//! with no two threads writing one block.

use crate::tet_mesh::TetMesh;
use glam::{DMat3, DVec3};
use rayon::prelude::*;

/// Below this many rows (nodes) the matrix–vector product and the solves'
/// vector operations ([`super::pcg::dot`]) run on one thread: their work
/// is then shorter than waking the pool's other threads.
pub const PARALLEL_ROWS: usize = 8192;

/// A 3 × 3-block sparse matrix on a mesh's node graph.
#[derive(Clone, Debug)]
pub struct BlockMatrix {
    /// Row `i`'s blocks are `row_start[i] .. row_start[i + 1]`.
    pub row_start: Vec<u32>,
    /// Column (node) of each block, ascending within a row.
    pub col: Vec<u32>,
    /// The blocks.
    pub blocks: Vec<DMat3>,
    /// Position of each row's diagonal block.
    diag: Vec<u32>,
    /// For tetrahedron `t`, local block `4a + b` lands in `blocks[slot[16 t + 4a + b]]`
    /// (`K a + b` and `K² t` for elements of `K` nodes).
    slot: Vec<u32>,
    /// Block `k`'s contributions are `scratch[gather[gather_start[k] .. gather_start[k + 1]]]`.
    gather_start: Vec<u32>,
    gather: Vec<u32>,
    /// Node `n`'s tetrahedron corners `4 t + a` are
    /// `corners[corner_start[n] .. corner_start[n + 1]]`.
    corner_start: Vec<u32>,
    corners: Vec<u32>,
}

impl BlockMatrix {
    /// The (zero) matrix on `mesh`'s node graph.
    pub fn on_mesh(mesh: &TetMesh) -> Self {
        Self::on_elements(mesh.nodes.len(), &mesh.tets)
    }

    /// The (zero) matrix on the node graph of `elements` of `K` nodes each
    /// over `n` nodes: per element, `K²` contributions to
    /// [`BlockMatrix::assemble`] (`K a + b` for its nodes `a`, `b`) and `K`
    /// per-corner values to [`BlockMatrix::sum_corners`].
    pub fn on_elements<const K: usize>(n: usize, elements: &[[u32; K]]) -> Self {
        let mut nbrs: Vec<Vec<u32>> = vec![Vec::new(); n];
        for tet in elements {
            for &a in tet {
                nbrs[a as usize].extend_from_slice(tet);
            }
        }
        let mut row_start = Vec::with_capacity(n + 1);
        let mut col = Vec::new();
        let mut diag = Vec::with_capacity(n);
        row_start.push(0);
        for (i, list) in nbrs.iter_mut().enumerate() {
            list.push(i as u32);
            list.sort_unstable();
            list.dedup();
            diag.push(col.len() as u32 + list.binary_search(&(i as u32)).unwrap_or(0) as u32);
            col.extend_from_slice(list);
            row_start.push(col.len() as u32);
        }
        let find = |i: u32, j: u32| -> u32 {
            let (a, b) = (
                row_start[i as usize] as usize,
                row_start[i as usize + 1] as usize,
            );
            a as u32 + col[a..b].binary_search(&j).expect("block of a tetrahedron") as u32
        };
        let mut slot = Vec::with_capacity(K * K * elements.len());
        for tet in elements {
            for &a in tet {
                for &b in tet {
                    slot.push(find(a, b));
                }
            }
        }
        // Invert `slot`: the scratch slots of each block.
        let mut count = vec![0u32; col.len() + 1];
        for &s in &slot {
            count[s as usize + 1] += 1;
        }
        for k in 0..col.len() {
            count[k + 1] += count[k];
        }
        let gather_start = count.clone();
        let mut gather = vec![0u32; slot.len()];
        for (i, &s) in slot.iter().enumerate() {
            gather[count[s as usize] as usize] = i as u32;
            count[s as usize] += 1;
        }
        let mut corner_start = vec![0u32; n + 1];
        for tet in elements {
            for &a in tet {
                corner_start[a as usize + 1] += 1;
            }
        }
        for i in 0..n {
            corner_start[i + 1] += corner_start[i];
        }
        let mut fill = corner_start.clone();
        let mut corners = vec![0u32; K * elements.len()];
        for (t, tet) in elements.iter().enumerate() {
            for (a, &node) in tet.iter().enumerate() {
                corners[fill[node as usize] as usize] = (K * t + a) as u32;
                fill[node as usize] += 1;
            }
        }
        Self {
            corner_start,
            corners,
            blocks: vec![DMat3::ZERO; col.len()],
            row_start,
            col,
            diag,
            slot,
            gather_start,
            gather,
        }
    }

    /// Rows (nodes).
    pub fn rows(&self) -> usize {
        self.row_start.len() - 1
    }

    /// Sets the matrix to `Σ_t contributions[t]` plus `diagonal[i] · I` on
    /// each diagonal block, where `contributions[16 t + 4a + b]` is
    /// tetrahedron `t`'s block for its corners `a`, `b` (see
    /// [`BlockMatrix::on_mesh`]).
    pub fn assemble(&mut self, contributions: &[DMat3], diagonal: Option<&[f64]>) {
        assert_eq!(
            contributions.len(),
            self.slot.len(),
            "K² blocks per element"
        );
        let (gs, g) = (&self.gather_start, &self.gather);
        self.blocks
            .par_iter_mut()
            .enumerate()
            .with_min_len(1024)
            .for_each(|(k, out)| {
                *out = g[gs[k] as usize..gs[k + 1] as usize]
                    .iter()
                    .fold(DMat3::ZERO, |acc, &i| acc + contributions[i as usize]);
            });
        if let Some(d) = diagonal {
            for (i, &k) in self.diag.iter().enumerate() {
                self.blocks[k as usize] += DMat3::from_diagonal(DVec3::splat(d[i]));
            }
        }
    }

    /// `y = A x`. Below [`PARALLEL_ROWS`] rows on the calling thread: an
    /// iterative solve calls this once per iteration between sequential
    /// steps (the IC(0) triangular solves), and splitting a small product
    /// woke the pool's other thread every time (on the 2,150-node
    /// pendulum, 1.5 ms of a 36 ms frame, docs/BENCHMARKS.md).
    pub fn mul(&self, x: &[DVec3], y: &mut [DVec3]) {
        let row = |(i, yi): (usize, &mut DVec3)| {
            let (a, b) = (self.row_start[i] as usize, self.row_start[i + 1] as usize);
            *yi = self.col[a..b]
                .iter()
                .zip(&self.blocks[a..b])
                .fold(DVec3::ZERO, |s, (&j, m)| s + *m * x[j as usize]);
        };
        if y.len() < PARALLEL_ROWS {
            y.iter_mut().enumerate().for_each(row);
        } else {
            y.par_iter_mut().enumerate().with_min_len(256).for_each(row);
        }
    }

    /// Sums per-corner values (`per_corner[4 t + a]` for corner `a` of
    /// tetrahedron `t`; `K t + a` for elements of `K` nodes) into their
    /// nodes: `out[n] = Σ` over `n`'s corners.
    pub fn sum_corners(&self, per_corner: &[DVec3], out: &mut [DVec3]) {
        let (cs, c) = (&self.corner_start, &self.corners);
        out.par_iter_mut()
            .enumerate()
            .with_min_len(1024)
            .for_each(|(n, o)| {
                *o = c[cs[n] as usize..cs[n + 1] as usize]
                    .iter()
                    .fold(DVec3::ZERO, |s, &i| s + per_corner[i as usize]);
            });
    }

    /// The diagonal block of row `i`.
    pub fn diagonal(&self, i: usize) -> DMat3 {
        self.blocks[self.diag[i] as usize]
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Two tetrahedra sharing a face (nodes 0 and 4 share none).
    pub(crate) fn two_tetrahedra() -> TetMesh {
        let nodes = vec![
            DVec3::ZERO,
            DVec3::X,
            DVec3::Y,
            DVec3::Z,
            DVec3::new(1.0, 1.0, 1.0),
        ];
        TetMesh::new("t", nodes, vec![[0, 1, 2, 3], [1, 2, 3, 4]], vec![0, 0]).unwrap()
    }

    #[test]
    fn assembly_matches_a_dense_sum() {
        let mesh = two_tetrahedra();
        let mut m = BlockMatrix::on_mesh(&mesh);
        assert_eq!(m.rows(), 5);
        // Node 0 and 4 share no tetrahedron.
        assert_eq!(m.col.len(), 25 - 2);
        let contrib: Vec<DMat3> = (0..32)
            .map(|i| DMat3::from_diagonal(DVec3::splat(i as f64 + 1.0)))
            .collect();
        m.assemble(&contrib, Some(&[10.0; 5]));
        let mut dense = [[0.0f64; 5]; 5];
        for (t, tet) in mesh.tets.iter().enumerate() {
            for a in 0..4 {
                for b in 0..4 {
                    dense[tet[a] as usize][tet[b] as usize] += (16 * t + 4 * a + b + 1) as f64;
                }
            }
        }
        for (i, row) in dense.iter_mut().enumerate() {
            row[i] += 10.0;
        }
        let x: Vec<DVec3> = (0..5).map(|i| DVec3::splat(i as f64 - 1.5)).collect();
        let mut y = vec![DVec3::ZERO; 5];
        m.mul(&x, &mut y);
        for i in 0..5 {
            let expect: f64 = (0..5).map(|j| dense[i][j] * x[j].x).sum();
            assert!(
                (y[i].x - expect).abs() < 1e-12,
                "row {i}: {} vs {expect}",
                y[i].x
            );
        }
        assert_eq!(m.diagonal(4).x_axis.x, dense[4][4]);
        // Node 1 is corner 1 of the first and corner 0 of the second
        // tetrahedron (after orientation, whichever corners they are).
        let per_corner: Vec<DVec3> = (0..8).map(|i| DVec3::splat((1 << i) as f64)).collect();
        let mut sums = vec![DVec3::ZERO; 5];
        m.sum_corners(&per_corner, &mut sums);
        for (n, s) in sums.iter().enumerate() {
            let expect: f64 = (0..8)
                .filter(|&i| mesh.tets[i / 4][i % 4] as usize == n)
                .map(|i| (1 << i) as f64)
                .sum();
            assert_eq!(s.x, expect, "node {n}");
        }
    }
}
