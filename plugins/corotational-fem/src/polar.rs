//! The rotation of a deformation gradient, robust to inverted elements:
//! `F = U Σ Vᵀ` with `U`, `V` proper rotations and the sign of `det F` on
//! the smallest singular value (Irving, Teran & Fedkiw 2004), and
//! `R = U Vᵀ`.
//!
//! A plain polar decomposition returns a reflection for an inverted element
//! (`det F < 0`), and the element then pushes itself further inside out;
//! with the sign on the smallest singular value instead, `R` stays a
//! rotation and the elastic force `R K (Rᵀ x − X)` pushes the element back
//! through zero volume to its rest shape.
//!
//! The SVD comes from the symmetric eigenproblem of `Fᵀ F` (cyclic Jacobi
//! rotations, a handful of sweeps for 3 × 3): `V` its eigenvectors, `Σ²`
//! its eigenvalues, `U = F V Σ⁻¹` column by column, with the columns of
//! collapsed directions rebuilt orthogonal to the others. Where only `R`
//! is needed and the element is well-shaped ([`rotation`]), a scaled
//! Newton iteration gives the same factor for a third of the work.

use voxflex_core::glam::{DMat3, DVec3};

/// Eigen-decomposition of a symmetric 3 × 3 matrix: eigenvalues
/// (descending) and the matching orthonormal eigenvectors as columns, with
/// `det = +1`.
pub fn symmetric_eigen(a: DMat3) -> (DVec3, DMat3) {
    let mut m = a.to_cols_array_2d(); // m[col][row]; symmetric, so either way
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..16 {
        let off = m[0][1] * m[0][1] + m[0][2] * m[0][2] + m[1][2] * m[1][2];
        let diag = m[0][0] * m[0][0] + m[1][1] * m[1][1] + m[2][2] * m[2][2];
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let apq = m[p][q];
            if apq == 0.0 {
                continue;
            }
            // The Jacobi rotation that zeroes m[p][q].
            let theta = (m[q][q] - m[p][p]) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut m {
                let (mkp, mkq) = (row[p], row[q]);
                row[p] = c * mkp - s * mkq;
                row[q] = s * mkp + c * mkq;
            }
            let (row_p, row_q) = (m[p], m[q]);
            for k in 0..3 {
                m[p][k] = c * row_p[k] - s * row_q[k];
                m[q][k] = s * row_p[k] + c * row_q[k];
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    // `v[row][col]`: column `col` is an eigenvector.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| m[b][b].total_cmp(&m[a][a]));
    let col = |c: usize| DVec3::new(v[0][c], v[1][c], v[2][c]);
    let (c0, c1) = (col(order[0]), col(order[1]));
    // The third as the cross product: the basis is a proper rotation.
    let vecs = DMat3::from_cols(c0, c1, c0.cross(c1));
    let vals = DVec3::new(
        m[order[0]][order[0]],
        m[order[1]][order[1]],
        m[order[2]][order[2]],
    );
    (vals, vecs)
}

/// `F = U Σ Vᵀ` with `U`, `V` rotations and `Σ` descending except that its
/// last entry carries the sign of `det F`. Returns `(U, Σ, V)`.
pub fn signed_svd(f: DMat3) -> (DMat3, DVec3, DMat3) {
    let (s2, v) = symmetric_eigen(f.transpose() * f);
    let sigma = s2.max(DVec3::ZERO).to_array().map(f64::sqrt);
    let scale = sigma[0].max(f64::MIN_POSITIVE);
    // Columns of U for the directions that did not collapse.
    let u0 = if sigma[0] > 0.0 {
        (f * v.x_axis) / sigma[0]
    } else {
        DVec3::X
    };
    let u0 = u0.normalize_or(DVec3::X);
    let u1 = if sigma[1] > 1e-12 * scale {
        let c = (f * v.y_axis) / sigma[1];
        (c - u0 * u0.dot(c)).normalize_or(u0.any_orthonormal_vector())
    } else {
        u0.any_orthonormal_vector()
    };
    let u2 = u0.cross(u1);
    let u = DMat3::from_cols(u0, u1, u2);
    // With U and V proper rotations, Σ = Uᵀ F V: its last entry comes out
    // with the sign of det F.
    let s_last = u2.dot(f * v.z_axis);
    (u, DVec3::new(sigma[0], sigma[1], s_last), v)
}

/// Below this `det F / |F|³` (Frobenius) an element counts as nearly
/// collapsed or inverted and its rotation comes from the signed SVD; above
/// it, `F`'s condition number is at most ~10³ and the Newton iteration of
/// [`rotation`] converges in a handful of steps.
const WELL_SHAPED: f64 = 1e-6;

/// Newton steps of [`rotation`] before it falls back to the SVD.
const NEWTON_STEPS: usize = 16;

/// The rotation of `F` (always `det R = +1`).
///
/// For a well-shaped element (`det F > 0`, not near collapse: the usual
/// case) it is the polar factor, by Higham's scaled Newton iteration
/// `X ← (γ X + X⁻ᵀ / γ) / 2`, `γ = √(|X⁻¹| / |X|)` (Higham 1986), which
/// converges quadratically to the same `U Vᵀ` as the SVD at a third of
/// its cost; otherwise, and if the iteration stalls, `U Vᵀ` of the signed
/// SVD, which keeps inverted elements rotating back ([`signed_svd`]).
pub fn rotation(f: DMat3) -> DMat3 {
    polar_newton(f).unwrap_or_else(|| {
        let (u, _, v) = signed_svd(f);
        u * v.transpose()
    })
}

/// Squared Frobenius norm.
fn frobenius2(m: DMat3) -> f64 {
    m.x_axis.length_squared() + m.y_axis.length_squared() + m.z_axis.length_squared()
}

/// The polar factor of a well-shaped `f` by the scaled Newton iteration;
/// `None` for an inverted, nearly collapsed or non-finite `f`, or when it
/// has not converged in [`NEWTON_STEPS`].
fn polar_newton(f: DMat3) -> Option<DMat3> {
    let norm2 = frobenius2(f);
    let det = f.determinant();
    let well_shaped = det.is_finite() && det > WELL_SHAPED * norm2 * norm2.sqrt();
    if !well_shaped {
        return None;
    }
    let mut x = f;
    for _ in 0..NEWTON_STEPS {
        let y = x.inverse().transpose();
        let gamma = (frobenius2(y) / frobenius2(x)).sqrt().sqrt();
        let next = (x * gamma + y * (1.0 / gamma)) * 0.5;
        let change = frobenius2(next - x);
        x = next;
        if change <= 1e-28 * frobenius2(x) {
            return Some(x);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::glam::DQuat;

    fn close(a: DMat3, b: DMat3, tol: f64) -> bool {
        (a - b).to_cols_array().iter().all(|x| x.abs() <= tol)
    }

    fn pseudo_random(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    #[test]
    fn the_svd_reproduces_f_with_proper_rotations() {
        let mut seed = 9;
        for case in 0..2000 {
            let mut f = DMat3::from_cols_array(&[0.0; 9].map(|_| pseudo_random(&mut seed)));
            if case % 7 == 0 {
                // Rank-deficient and near-degenerate cases.
                f.z_axis = f.x_axis * 0.5 + f.y_axis * 1e-9 * (case as f64);
            }
            let (u, s, v) = signed_svd(f);
            assert!((u.determinant() - 1.0).abs() < 1e-9, "case {case}: det U");
            assert!((v.determinant() - 1.0).abs() < 1e-9, "case {case}: det V");
            assert!(close(u.transpose() * u, DMat3::IDENTITY, 1e-9));
            let back = u * DMat3::from_diagonal(s) * v.transpose();
            assert!(close(back, f, 1e-8), "case {case}: {f} vs {back}");
            assert!(s.x >= s.y && s.y >= s.z.abs() - 1e-9, "case {case}: {s}");
            if f.determinant().abs() > 1e-6 {
                assert_eq!(s.z < 0.0, f.determinant() < 0.0, "case {case}: sign");
            }
        }
    }

    #[test]
    fn the_newton_polar_factor_is_the_svds_rotation() {
        let mut seed = 3;
        let mut newton = 0;
        for case in 0..2000 {
            let f = DMat3::IDENTITY
                + DMat3::from_cols_array(&[0.0; 9].map(|_| pseudo_random(&mut seed)))
                    * (0.1 + 0.9 * (case % 10) as f64 / 10.0);
            let (u, _, v) = signed_svd(f);
            let want = u * v.transpose();
            if let Some(r) = polar_newton(f) {
                newton += 1;
                assert!(close(r, want, 1e-10), "case {case}: {r} vs {want}");
            }
            assert!(close(rotation(f), want, 1e-10), "case {case}");
        }
        // Most of these are well-shaped; the rest took the SVD.
        assert!(newton > 1000, "{newton} of 2000 by Newton");
        // Inverted and collapsed ones always take the SVD.
        assert!(polar_newton(DMat3::from_diagonal(DVec3::new(1.0, 1.0, -0.2))).is_none());
        assert!(polar_newton(DMat3::from_diagonal(DVec3::new(1.0, 1.0, 1e-9))).is_none());
        assert!(polar_newton(DMat3::ZERO).is_none());
    }

    #[test]
    fn rotations_are_recovered_and_inversion_keeps_a_rotation() {
        let q = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 1.3);
        let r = DMat3::from_quat(q);
        let stretch = DMat3::from_diagonal(DVec3::new(1.3, 0.8, 1.1));
        assert!(close(rotation(r * stretch), r, 1e-12));
        assert!(close(rotation(r), r, 1e-12));
        // Inverted: one axis flipped through zero. A polar decomposition
        // would give a reflection; this gives a rotation.
        let inverted = r * DMat3::from_diagonal(DVec3::new(1.0, 1.0, -0.2));
        let ri = rotation(inverted);
        assert!((ri.determinant() - 1.0).abs() < 1e-12);
        assert!(close(ri.transpose() * ri, DMat3::IDENTITY, 1e-12));
        // Collapsed to a plane and to a point.
        let flat = r * DMat3::from_diagonal(DVec3::new(1.0, 1.0, 0.0));
        assert!((rotation(flat).determinant() - 1.0).abs() < 1e-12);
        assert!((rotation(DMat3::ZERO).determinant() - 1.0).abs() < 1e-12);
    }
}
