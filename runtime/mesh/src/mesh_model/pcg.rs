//! Preconditioned conjugate gradients on a [`BlockMatrix`], restricted to
//! the free nodes of a [`Boundary`]: the imposed displacements (fixed,
//! driven) stay as given, hanging nodes follow their masters (the system
//! solved is `Pᵀ A P x = Pᵀ b` on the free nodes). The preconditioner is
//! block Jacobi (each free node's 3 × 3 diagonal block inverted: Jacobi
//! that also undoes the coupling of a node's own three axes) or
//! incomplete Cholesky on the block pattern ([`super::ichol`]), which
//! needs about half the iterations on slender bending problems (measured
//! on the cantilever benchmarks; its triangular solves run on one thread).
//! [`solve_preconditioned`] takes any SPD preconditioner, such as the
//! smoothed-aggregation multigrid V-cycle of [`super::amg`], whose
//! iteration count stays nearly flat under mesh refinement.
//!
//! A solve that stops above its tolerance is not an error: the caller
//! gets the residual, and [`warn_unconverged`] says what to change.
//!
//! Warm start: the solve starts from the `x` it is given (last frame's
//! answer), so a scene that barely changed converges in a few iterations.

use super::block_matrix::{BlockMatrix, PARALLEL_ROWS};
use super::boundary::Boundary;
use super::ichol::IncompleteCholesky;
use glam::{DMat3, DVec3};
use voxflex_core::ordered_reduce::ordered_reduce;

/// When to stop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CgSettings {
    /// Stop when `|r| ≤ tolerance · |b|` on the free nodes.
    pub tolerance: f64,
    /// Stop after this many iterations whatever the residual.
    pub max_iterations: u32,
}

/// The mesh solvers' default `cg_tolerance`.
pub fn default_tolerance() -> f64 {
    1e-6
}

/// The mesh solvers' default `cg_max_iterations` where it is not derived
/// from the problem size (mass-spring's implicit step).
pub fn default_max_iterations() -> u32 {
    200
}

/// The iteration cap derived from the problem size: `max(200, 3 n_free)`
/// with `n_free` free nodes, capped at 20,000 — CG in exact arithmetic
/// ends within `3 n_free` iterations (one per unknown), and a well
/// preconditioned solve needs far fewer; the ceiling bounds the time a
/// hopeless solve can take before it warns.
pub fn size_cap(free_nodes: usize) -> u32 {
    (3 * free_nodes).clamp(200, 20_000) as u32
}

/// The preconditioner of [`solve_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Preconditioner {
    /// Each free node's 3 × 3 diagonal block inverted.
    #[default]
    BlockJacobi,
    /// IC(0) on the block pattern ([`super::ichol`]); falls back to block
    /// Jacobi (with a warning) when the factorisation breaks down.
    IncompleteCholesky,
}

impl CgSettings {
    /// Settings from a scene's `cg_tolerance` and `cg_max_iterations`; the
    /// error names the key and the value.
    pub fn checked(tolerance: f64, max_iterations: u32) -> Result<Self, String> {
        if !(tolerance > 0.0 && tolerance < 1.0) {
            return Err(format!("cg_tolerance {tolerance} must lie in (0, 1)"));
        }
        if max_iterations == 0 {
            return Err("cg_max_iterations must be ≥ 1".into());
        }
        Ok(Self {
            tolerance,
            max_iterations,
        })
    }
}

/// How a solve ended.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CgOutcome {
    /// Iterations taken.
    pub iterations: u32,
    /// Final `|r| / |b|` on the free nodes (0 when `b` is 0 there).
    pub residual: f64,
}

impl CgOutcome {
    /// True when the solve reached `settings.tolerance`.
    pub fn converged(&self, settings: CgSettings) -> bool {
        self.residual <= settings.tolerance
    }
}

/// Warns (`tracing::warn!`) when `out` stopped above its tolerance, naming
/// the residual, the tolerance, the iterations and `keys` (what the scene
/// can change, e.g. "raise cg_max_iterations or use preconditioner =
/// \"incomplete-cholesky\""); returns whether it converged.
pub fn warn_unconverged(
    solver: &str,
    what: &str,
    out: CgOutcome,
    settings: CgSettings,
    keys: &str,
) -> bool {
    if out.converged(settings) {
        return true;
    }
    tracing::warn!(
        residual = out.residual,
        tolerance = settings.tolerance,
        iterations = out.iterations,
        "{solver}: the {what} linear solve stopped unconverged: relative residual {:.3e} above \
         cg_tolerance {:.1e} after {} iterations (cg_max_iterations {}); {keys}",
        out.residual,
        settings.tolerance,
        out.iterations,
        settings.max_iterations
    );
    false
}

/// Entries per partial sum of [`dot`].
const DOT_CHUNK: usize = 2048;

/// `Σ aᵢ · bᵢ`, rounded the same way whatever the thread count and
/// however the threads share the work
/// ([`voxflex_core::ordered_reduce`]: partial sums of fixed chunks of
/// [`DOT_CHUNK`] entries, in parallel for long vectors, added in chunk
/// order). Rayon's own parallel `sum` splits where a thread steals work,
/// so its rounding — and through it the CG iteration counts and the last
/// bits of a solve — changed from run to run of the same scene.
pub fn dot(a: &[DVec3], b: &[DVec3]) -> f64 {
    let partial = |r: std::ops::Range<usize>| -> f64 {
        a[r.clone()].iter().zip(&b[r]).map(|(p, q)| p.dot(*q)).sum()
    };
    let parallel = a.len() >= PARALLEL_ROWS;
    ordered_reduce(
        a.len().min(b.len()),
        DOT_CHUNK,
        parallel,
        partial,
        0.0,
        |s, p| s + p,
    )
}

/// Solves `A x = b` for the free nodes (`free[i]`), from the given `x`,
/// with block Jacobi.
pub fn solve(
    a: &BlockMatrix,
    bc: &Boundary,
    free: &[bool],
    b: &[DVec3],
    x: &mut [DVec3],
    settings: CgSettings,
) -> CgOutcome {
    solve_with(a, bc, free, b, x, settings, Preconditioner::BlockJacobi)
}

/// The preconditioner, built.
enum Built {
    Jacobi(Vec<DMat3>),
    Ic(IncompleteCholesky),
}

impl Built {
    fn new(a: &BlockMatrix, free: &[bool], kind: Preconditioner) -> Self {
        if kind == Preconditioner::IncompleteCholesky {
            if let Some(ic) = IncompleteCholesky::new(a, free) {
                return Self::Ic(ic);
            }
            // Not an error: the solve still converges (or warns that
            // it did not); an indefinite matrix lands here.
            tracing::debug!(
                "incomplete Cholesky broke down on this matrix (even with a diagonal shift); \
                 this solve uses block Jacobi"
            );
        }
        Self::Jacobi(
            (0..a.rows())
                .map(|i| {
                    let d = a.diagonal(i);
                    if free[i] && d.determinant().abs() > f64::MIN_POSITIVE {
                        d.inverse()
                    } else {
                        DMat3::ZERO
                    }
                })
                .collect(),
        )
    }

    fn apply(&self, r: &[DVec3], z: &mut [DVec3]) {
        match self {
            Self::Jacobi(inv) => {
                for ((zi, ri), m) in z.iter_mut().zip(r).zip(inv) {
                    *zi = *m * *ri;
                }
            }
            Self::Ic(ic) => ic.apply(r, z),
        }
    }
}

/// Zeroes the entries of `v` whose node is not free (`free[i]`).
pub fn restrict(v: &mut [DVec3], free: &[bool]) {
    for (vi, &f) in v.iter_mut().zip(free) {
        if !f {
            *vi = DVec3::ZERO;
        }
    }
}

/// The right-hand side `b` as the solves' operator sees it: hanging
/// nodes' loads moved onto their masters, constrained nodes' zeroed.
pub fn reduced_rhs(bc: &Boundary, free: &[bool], b: &[DVec3]) -> Vec<DVec3> {
    let mut rhs = b.to_vec();
    bc.untie(&mut rhs);
    restrict(&mut rhs, free);
    rhs
}

/// `out = A v` as the solves iterate with it: untied and restricted like
/// [`reduced_rhs`] (`v` tied, zero on constrained nodes).
pub fn apply_reduced(
    a: &BlockMatrix,
    bc: &Boundary,
    free: &[bool],
    v: &[DVec3],
    out: &mut [DVec3],
) {
    a.mul(v, out);
    bc.untie(out);
    restrict(out, free);
}

/// Solves `A x = b` for the free nodes (`free[i]`), from the given `x`,
/// with the given preconditioner.
pub fn solve_with(
    a: &BlockMatrix,
    bc: &Boundary,
    free: &[bool],
    b: &[DVec3],
    x: &mut [DVec3],
    settings: CgSettings,
    preconditioner: Preconditioner,
) -> CgOutcome {
    let mut pre: Option<Built> = None;
    solve_preconditioned(a, bc, free, b, x, settings, &mut |r, z| {
        pre.get_or_insert_with(|| Built::new(a, free, preconditioner))
            .apply(r, z)
    })
}

/// Solves `A x = b` for the free nodes (`free[i]`), from the given `x`,
/// with the preconditioner `precondition(r, z)` (`z = M⁻¹ r`; `M` must be
/// symmetric positive definite on the free nodes, zero elsewhere), such as
/// an [`super::amg::Amg`] V-cycle. It is first called only when the start
/// is not already converged, so a setup done on the first call is skipped
/// when no iteration is needed.
pub fn solve_preconditioned(
    a: &BlockMatrix,
    bc: &Boundary,
    free: &[bool],
    b: &[DVec3],
    x: &mut [DVec3],
    settings: CgSettings,
    precondition: &mut dyn FnMut(&[DVec3], &mut [DVec3]),
) -> CgOutcome {
    let n = a.rows();
    let restrict = |v: &mut [DVec3]| restrict(v, free);
    let rhs = reduced_rhs(bc, free, b);
    let b_norm = dot(&rhs, &rhs).sqrt();
    bc.tie(x);
    let mut r = vec![DVec3::ZERO; n];
    a.mul(x, &mut r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = *bi - *ri;
    }
    bc.untie(&mut r);
    restrict(&mut r);
    let scale = if b_norm > 0.0 { b_norm } else { 1.0 };
    let mut residual = dot(&r, &r).sqrt() / scale;
    if residual <= settings.tolerance || b_norm == 0.0 && residual == 0.0 {
        return CgOutcome {
            iterations: 0,
            residual,
        };
    }
    let mut z = vec![DVec3::ZERO; n];
    precondition(&r, &mut z);
    let mut p = z.clone();
    bc.tie(&mut p);
    let mut q = vec![DVec3::ZERO; n];
    let mut rz = dot(&r, &z);
    let mut iterations = 0;
    while iterations < settings.max_iterations {
        iterations += 1;
        apply_reduced(a, bc, free, &p, &mut q);
        let pq = dot(&p, &q);
        if pq <= 0.0 || !pq.is_finite() {
            // Not positive definite along p (or breakdown): stop here.
            break;
        }
        let alpha = rz / pq;
        for ((xi, pi), (ri, qi)) in x.iter_mut().zip(&p).zip(r.iter_mut().zip(&q)) {
            *xi += alpha * *pi;
            *ri -= alpha * *qi;
        }
        residual = dot(&r, &r).sqrt() / scale;
        if residual <= settings.tolerance {
            break;
        }
        precondition(&r, &mut z);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for (pi, zi) in p.iter_mut().zip(&z) {
            *pi = *zi + beta * *pi;
        }
        bc.tie(&mut p);
    }
    bc.tie(x);
    CgOutcome {
        iterations,
        residual,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tet_mesh::TetMesh;

    /// A 1-D chain of springs along x embedded as blocks: solves a fixed
    /// end and a pulled end exactly.
    #[test]
    fn a_constrained_chain_is_solved_to_tolerance() {
        let nodes: Vec<DVec3> = (0..6)
            .map(|i| DVec3::new(i as f64, (i % 2) as f64, 0.0))
            .collect();
        let tets = vec![[0, 1, 2, 3], [2, 3, 4, 5]];
        let mut nodes3 = nodes.clone();
        nodes3[3].z = 1.0;
        nodes3[5].z = -1.0;
        let mesh = TetMesh::new("chain", nodes3, tets, vec![0, 0]).unwrap();
        let mut a = BlockMatrix::on_mesh(&mesh);
        // A graph Laplacian of the tetrahedra's edges plus a little mass.
        let mut contrib = vec![DMat3::ZERO; 32];
        for t in 0..2 {
            for i in 0..4 {
                for j in 0..4 {
                    let v = if i == j { 3.0 } else { -1.0 };
                    contrib[16 * t + 4 * i + j] = DMat3::from_diagonal(DVec3::splat(v));
                }
            }
        }
        a.assemble(&contrib, Some(&[0.01; 6]));
        let mut bc = Boundary::new(6);
        bc.fixed[0] = true;
        bc.driven.push((5, DVec3::new(1.0, 0.0, 0.0)));
        let free: Vec<bool> = bc.constrained().iter().map(|c| !c).collect();
        let b = vec![DVec3::new(0.0, 0.0, 0.5); 6];
        for pre in [
            Preconditioner::BlockJacobi,
            Preconditioner::IncompleteCholesky,
        ] {
            let mut x = vec![DVec3::ZERO; 6];
            bc.impose(&mut x);
            let settings = CgSettings {
                tolerance: 1e-12,
                max_iterations: 100,
            };
            let out = solve_with(&a, &bc, &free, &b, &mut x, settings, pre);
            assert!(out.converged(settings), "{pre:?}: {out:?}");
            // The residual on free nodes is zero, the imposed values untouched.
            let mut ax = vec![DVec3::ZERO; 6];
            a.mul(&x, &mut ax);
            for i in 1..5 {
                assert!((ax[i] - b[i]).length() < 1e-9, "{pre:?}: node {i}");
            }
            assert_eq!(x[0], DVec3::ZERO);
            assert_eq!(x[5], DVec3::new(1.0, 0.0, 0.0));
        }
    }

    /// The dot product is the same float, bit for bit, on 1, 2, 3 and 8
    /// threads: the partial sums of fixed chunks added in chunk order
    /// (written out here), for a vector below and one above the parallel
    /// threshold.
    #[test]
    fn dot_rounds_alike_on_any_thread_count() {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            // Magnitudes spread over six decades, so the order of additions
            // shows in the last bits.
            ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10f64.powi((s % 6) as i32)
        };
        for n in [PARALLEL_ROWS / 2 + 17, 25 * DOT_CHUNK + 999] {
            let a: Vec<DVec3> = (0..n).map(|_| DVec3::new(next(), next(), next())).collect();
            let b: Vec<DVec3> = (0..n).map(|_| DVec3::new(next(), next(), next())).collect();
            let mut want = 0.0f64;
            for (x, y) in a.chunks(DOT_CHUNK).zip(b.chunks(DOT_CHUNK)) {
                want += x.iter().zip(y).map(|(p, q)| p.dot(*q)).sum::<f64>();
            }
            for threads in [1, 2, 3, 8] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                for _ in 0..3 {
                    let got = pool.install(|| dot(&a, &b));
                    assert_eq!(got.to_bits(), want.to_bits(), "n {n}, {threads} threads");
                }
            }
        }
    }

    #[test]
    fn the_size_cap_grows_with_the_free_nodes_within_its_bounds() {
        assert_eq!(size_cap(10), 200);
        assert_eq!(size_cap(1000), 3000);
        assert_eq!(size_cap(1_000_000), 20_000);
    }
}
