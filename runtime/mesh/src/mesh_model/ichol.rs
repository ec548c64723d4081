//! Incomplete Cholesky with no fill (IC(0)) on the 3 × 3-block pattern of a
//! [`BlockMatrix`], restricted to the free nodes: `A ≈ L Lᵀ` with `L`
//! lower block-triangular and nonzero only where `A` has a block, so it
//! costs one matrix's memory. Block IC(0) on a block-closed pattern is the
//! scalar IC(0) of the same pattern, computed with 3 × 3 operations.
//!
//! Elasticity matrices are not M-matrices, so IC(0) can meet a pivot that
//! is not positive definite; the factorisation then restarts on
//! `A + σ diag(A)` with σ = 1e-3, 4e-3, … (Manteuffel's shift) and gives up
//! after [`SHIFTS`] tries (the caller falls back to block Jacobi).
//!
//! Frames: rows and columns are proxy node indices (three displacement
//! components each); the factor is unit-free like `A`.

use super::block_matrix::BlockMatrix;
use glam::{DMat3, DVec3};

/// Shifted restarts before the factorisation gives up.
pub const SHIFTS: u32 = 8;

/// `L` of `A ≈ L Lᵀ` on `A`'s pattern (lower blocks only), with the
/// inverses of its diagonal blocks.
#[derive(Clone, Debug)]
pub struct IncompleteCholesky {
    /// Row `i`'s lower blocks are `start[i] .. start[i + 1]` of `col`/`l`.
    start: Vec<u32>,
    /// Column (node) of each lower block, ascending; below the diagonal.
    col: Vec<u32>,
    /// The off-diagonal blocks `L_ij`, `j < i`.
    l: Vec<DMat3>,
    /// `L_ii⁻¹` (lower triangular); zero on nodes that are not free.
    diag_inv: Vec<DMat3>,
    /// The diagonal shift σ the factorisation needed (0 when none).
    pub shift: f64,
}

/// The lower Cholesky factor of a symmetric 3 × 3 block, `None` when the
/// block is not positive definite.
fn chol3(a: DMat3) -> Option<DMat3> {
    let m = |r: usize, c: usize| a.col(c)[r];
    let l00 = m(0, 0);
    // `> 0` also refuses NaN.
    if l00.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let l00 = l00.sqrt();
    let l10 = m(1, 0) / l00;
    let l20 = m(2, 0) / l00;
    let d1 = m(1, 1) - l10 * l10;
    if d1.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let l11 = d1.sqrt();
    let l21 = (m(2, 1) - l20 * l10) / l11;
    let d2 = m(2, 2) - l20 * l20 - l21 * l21;
    if d2.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let l22 = d2.sqrt();
    // Columns of the lower-triangular factor.
    Some(DMat3::from_cols(
        DVec3::new(l00, l10, l20),
        DVec3::new(0.0, l11, l21),
        DVec3::new(0.0, 0.0, l22),
    ))
}

impl IncompleteCholesky {
    /// Factors `a` on the free nodes (`free[i]`), shifting the diagonal if
    /// it must; `None` when even the last shift breaks down.
    pub fn new(a: &BlockMatrix, free: &[bool]) -> Option<Self> {
        let n = a.rows();
        // The lower pattern among free nodes.
        let mut start = Vec::with_capacity(n + 1);
        let mut col = Vec::new();
        let mut src = Vec::new();
        start.push(0u32);
        for i in 0..n {
            if free[i] {
                let (s, e) = (a.row_start[i] as usize, a.row_start[i + 1] as usize);
                for k in s..e {
                    let j = a.col[k] as usize;
                    if j < i && free[j] {
                        col.push(j as u32);
                        src.push(k);
                    }
                }
            }
            start.push(col.len() as u32);
        }
        let mut shift = 0.0;
        for attempt in 0..=SHIFTS {
            if let Some((l, diag_inv)) = factor(a, free, &start, &col, &src, shift) {
                return Some(Self {
                    start,
                    col,
                    l,
                    diag_inv,
                    shift,
                });
            }
            shift = 1e-3 * 4f64.powi(attempt as i32);
        }
        None
    }

    /// `z = (L Lᵀ)⁻¹ r` on the free nodes (zero elsewhere).
    pub fn apply(&self, r: &[DVec3], z: &mut [DVec3]) {
        let n = self.diag_inv.len();
        // Forward: L y = r.
        for i in 0..n {
            let (s, e) = (self.start[i] as usize, self.start[i + 1] as usize);
            let mut acc = r[i];
            for k in s..e {
                acc -= self.l[k] * z[self.col[k] as usize];
            }
            z[i] = self.diag_inv[i] * acc;
        }
        // Backward: Lᵀ z = y, column by column of Lᵀ (rows of L).
        for i in (0..n).rev() {
            let zi = self.diag_inv[i].transpose() * z[i];
            z[i] = zi;
            let (s, e) = (self.start[i] as usize, self.start[i + 1] as usize);
            for k in s..e {
                let j = self.col[k] as usize;
                z[j] -= self.l[k].transpose() * zi;
            }
        }
    }
}

/// One factorisation attempt of `a + shift · diag(a)`; `None` at a pivot
/// that is not positive definite.
fn factor(
    a: &BlockMatrix,
    free: &[bool],
    start: &[u32],
    col: &[u32],
    src: &[usize],
    shift: f64,
) -> Option<(Vec<DMat3>, Vec<DMat3>)> {
    let n = a.rows();
    let mut l = vec![DMat3::ZERO; col.len()];
    let mut diag_inv = vec![DMat3::ZERO; n];
    // Row i's position of column j, for the current row (u32::MAX: none).
    let mut at = vec![u32::MAX; n];
    for i in 0..n {
        if !free[i] {
            continue;
        }
        let (s, e) = (start[i] as usize, start[i + 1] as usize);
        for k in s..e {
            at[col[k] as usize] = k as u32;
        }
        // L_ij = (A_ij − Σ_{k<j} L_ik L_jkᵀ) L_jj⁻ᵀ, in ascending j.
        for k in s..e {
            let j = col[k] as usize;
            let mut v = a.blocks[src[k]];
            for q in start[j] as usize..start[j + 1] as usize {
                let m = at[col[q] as usize];
                if m != u32::MAX && (m as usize) < k {
                    v -= l[m as usize] * l[q].transpose();
                }
            }
            l[k] = v * diag_inv[j].transpose();
        }
        let mut d = a.diagonal(i);
        d += DMat3::from_diagonal(DVec3::new(d.x_axis.x, d.y_axis.y, d.z_axis.z) * shift);
        for lk in &l[s..e] {
            d -= *lk * lk.transpose();
        }
        diag_inv[i] = chol3(d)?.inverse();
        for &c in &col[s..e] {
            at[c as usize] = u32::MAX;
        }
    }
    if diag_inv.iter().any(|m| !m.is_finite()) {
        return None;
    }
    Some((l, diag_inv))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small mesh whose assembled matrix is SPD and has every block of
    /// its pattern dense (so IC(0) is the exact Cholesky when the pattern
    /// is complete).
    fn matrix() -> (BlockMatrix, usize) {
        let mesh = super::super::block_matrix::tests::two_tetrahedra();
        let mut a = BlockMatrix::on_mesh(&mesh);
        let mut seed = 3u64;
        let mut rand = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        // Per tetrahedron B Bᵀ of a random 12 × 12 B: SPD blocks.
        let mut contrib = vec![DMat3::ZERO; 32];
        for t in 0..2 {
            let b: Vec<f64> = (0..144).map(|_| rand()).collect();
            for p in 0..4 {
                for q in 0..4 {
                    let mut m = DMat3::ZERO;
                    for r in 0..3 {
                        for c in 0..3 {
                            let v: f64 = (0..12)
                                .map(|k| b[12 * (3 * p + r) + k] * b[12 * (3 * q + c) + k])
                                .sum();
                            m.col_mut(c)[r] = v;
                        }
                    }
                    contrib[16 * t + 4 * p + q] = m;
                }
            }
        }
        a.assemble(&contrib, Some(&[0.5; 5]));
        (a, 5)
    }

    #[test]
    fn on_a_complete_pattern_it_is_the_exact_inverse() {
        // Nodes 0..4 without node 4 (the only pair missing a block is
        // 0-4): the free 4 × 4 block pattern is complete.
        let (a, n) = matrix();
        let free = [true, true, true, true, false];
        let ic = IncompleteCholesky::new(&a, &free).unwrap();
        assert_eq!(ic.shift, 0.0);
        let r: Vec<DVec3> = (0..n)
            .map(|i| DVec3::new(i as f64, 1.0 - i as f64, 0.5))
            .collect();
        let mut z = vec![DVec3::ZERO; n];
        ic.apply(&r, &mut z);
        assert_eq!(z[4], DVec3::ZERO, "a node that is not free stays zero");
        // A z = r on the free rows (node 4's column is zero in z).
        let mut az = vec![DVec3::ZERO; n];
        a.mul(&z, &mut az);
        for i in 0..4 {
            assert!(
                (az[i] - r[i]).length() < 1e-9,
                "row {i}: {} vs {}",
                az[i],
                r[i]
            );
        }
    }

    #[test]
    fn an_indefinite_matrix_is_refused() {
        let (mut a, _) = matrix();
        for b in a.blocks.iter_mut() {
            *b = -*b;
        }
        assert!(IncompleteCholesky::new(&a, &[true; 5]).is_none());
    }
}
