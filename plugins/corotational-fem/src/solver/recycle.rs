//! Warm starts for the compliance solves: the Galerkin projection of a new
//! right-hand side onto the span of recent solutions.
//!
//! An actuator asks for `K⁻¹ b` with its own `b` every frame, and from one
//! frame to the next both `K` (the tangent at the new shape) and `b` (its
//! forces at the new shape) change a little. Starting the PCG from the
//! `K`-orthogonal projection of the answer onto the last few answers,
//! `x₀ = Q Qᵀ b` with `Qᵀ K Q = I`, is the best start in that span (it
//! minimises the `K`-norm of the error there), so each solve only has to
//! remove the frame's change. The projection costs one product with `K`
//! per kept solution; a solution whose direction the others already hold
//! (to rounding) is left out instead of breaking the basis.

use std::collections::VecDeque;
use voxflex_core::glam::DVec3;
use voxflex_mesh::mesh_model::pcg::dot;

/// Below this fraction of its own `K`-norm² a kept solution is dependent on
/// the ones before it and adds no direction.
const DEPENDENT: f64 = 1e-10;

/// The last solutions of the compliance solves (displacements, mm per µN
/// of load, on the solver's nodes), newest first.
#[derive(Debug, Default)]
pub(super) struct Recycler {
    kept: VecDeque<Vec<DVec3>>,
    capacity: usize,
}

fn axpy(y: &mut [DVec3], a: f64, x: &[DVec3]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * *xi;
    }
}

impl Recycler {
    /// Keeps up to `capacity` solutions.
    pub(super) fn new(capacity: usize) -> Self {
        Self {
            kept: VecDeque::with_capacity(capacity),
            capacity,
        }
    }

    /// The start `x₀ = Q Qᵀ b` for the right-hand side `b` (already
    /// restricted as the solve's operator sees it), with `apply(v, out)`
    /// the solve's operator `K` on the free nodes. Zero without kept
    /// solutions of `b`'s length.
    pub(super) fn start(
        &self,
        b: &[DVec3],
        apply: &mut dyn FnMut(&[DVec3], &mut [DVec3]),
    ) -> Vec<DVec3> {
        let n = b.len();
        let mut x = vec![DVec3::ZERO; n];
        let mut basis: Vec<(Vec<DVec3>, Vec<DVec3>)> = Vec::with_capacity(self.kept.len());
        for kept in self.kept.iter().filter(|k| k.len() == n) {
            let mut v = kept.clone();
            let mut kv = vec![DVec3::ZERO; n];
            apply(&v, &mut kv);
            let own = dot(&v, &kv);
            let positive = own.is_finite() && own > 0.0;
            if !positive {
                continue;
            }
            for (q, kq) in &basis {
                let c = dot(kq, &v);
                axpy(&mut v, -c, q);
                axpy(&mut kv, -c, kq);
            }
            let norm2 = dot(&v, &kv);
            let independent = norm2 > DEPENDENT * own;
            if !independent {
                continue;
            }
            let s = 1.0 / norm2.sqrt();
            v.iter_mut().for_each(|e| *e *= s);
            kv.iter_mut().for_each(|e| *e *= s);
            axpy(&mut x, dot(&v, b), &v);
            basis.push((v, kv));
        }
        x
    }

    /// Keeps the solution `x`, dropping the oldest beyond the capacity.
    pub(super) fn keep(&mut self, x: &[DVec3]) {
        if self.capacity == 0 {
            return;
        }
        if self.kept.len() == self.capacity {
            self.kept.pop_back();
        }
        self.kept.push_front(x.to_vec());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small SPD operator: tridiagonal (−1, 3, −1) on each component.
    fn apply(v: &[DVec3], out: &mut [DVec3]) {
        let n = v.len();
        for i in 0..n {
            let mut s = 3.0 * v[i];
            if i > 0 {
                s -= v[i - 1];
            }
            if i + 1 < n {
                s -= v[i + 1];
            }
            out[i] = s;
        }
    }

    fn vector(seed: f64, n: usize) -> Vec<DVec3> {
        (0..n)
            .map(|i| {
                let t = seed + i as f64;
                DVec3::new(t.sin(), (1.3 * t).cos(), (0.7 * t).sin())
            })
            .collect()
    }

    #[test]
    fn a_right_hand_side_in_the_kept_span_starts_at_its_answer() {
        let n = 12;
        let (x1, x2) = (vector(0.1, n), vector(2.3, n));
        let mut r = Recycler::new(4);
        r.keep(&x1);
        r.keep(&x2);
        // A duplicate adds no direction and must not break the basis.
        r.keep(&x1);
        let want: Vec<DVec3> = x1
            .iter()
            .zip(&x2)
            .map(|(a, b)| 2.0 * *a - 0.5 * *b)
            .collect();
        let mut b = vec![DVec3::ZERO; n];
        apply(&want, &mut b);
        let x0 = r.start(&b, &mut apply);
        for (g, w) in x0.iter().zip(&want) {
            assert!((*g - *w).length() < 1e-10, "{g} against {w}");
        }
    }

    #[test]
    fn the_start_is_never_worse_than_zero_in_the_energy_norm() {
        let n = 12;
        let mut r = Recycler::new(2);
        r.keep(&vector(0.4, n));
        r.keep(&vector(5.0, n));
        r.keep(&vector(9.0, n)); // pushes the first out
        let want = vector(1.7, n);
        let mut b = vec![DVec3::ZERO; n];
        apply(&want, &mut b);
        let x0 = r.start(&b, &mut apply);
        let energy = |x: &[DVec3]| {
            let e: Vec<DVec3> = x.iter().zip(&want).map(|(a, b)| *a - *b).collect();
            let mut ke = vec![DVec3::ZERO; n];
            apply(&e, &mut ke);
            dot(&e, &ke)
        };
        assert!(energy(&x0) <= energy(&vec![DVec3::ZERO; n]) * (1.0 + 1e-12));
        // Nothing kept of this length: zero.
        assert!(
            r.start(&b[..5], &mut apply)
                .iter()
                .all(|v| *v == DVec3::ZERO)
        );
    }
}
