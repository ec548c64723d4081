//! The tip-loaded cantilever's Euler elastica (inextensible, dead load in
//! −z): `θ'' = −α cos θ` on `s ∈ [0, 1]` with `α = P L² / EI`, clamped
//! (`θ(0) = 0`) and moment-free at the tip (`θ'(1) = 0`), solved by
//! shooting on `θ'(0)` (bisection, RK4 with 4,000 steps) — the same
//! reference as corotational-fem's convergence tests.

/// The tip's `(x, z)` as fractions of the length (z downward negative).
pub(super) fn tip(alpha: f64) -> (f64, f64) {
    let shoot = |k0: f64| {
        // State: θ, θ', x, z.
        let f = |y: [f64; 4]| [y[1], -alpha * y[0].cos(), y[0].cos(), -y[0].sin()];
        let steps = 4000;
        let h = 1.0 / steps as f64;
        let mut y = [0.0, k0, 0.0, 0.0];
        let add = |y: [f64; 4], k: [f64; 4], c: f64| [0, 1, 2, 3].map(|i| y[i] + c * k[i]);
        for _ in 0..steps {
            let k1 = f(y);
            let k2 = f(add(y, k1, h / 2.0));
            let k3 = f(add(y, k2, h / 2.0));
            let k4 = f(add(y, k3, h));
            y = [0, 1, 2, 3].map(|i| y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
        }
        y
    };
    // θ'(1) < 0 at k0 = 0 and ≥ 0 at k0 = α.
    let (mut lo, mut hi) = (0.0, alpha);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if shoot(mid)[1] < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let y = shoot(0.5 * (lo + hi));
    (y[2], y[3])
}

#[cfg(test)]
mod tests {
    #[test]
    fn matches_small_load_theory_and_bisshopp_drucker() {
        // Small load: the linear beam's tip deflection α/3.
        let (x, z) = super::tip(0.01);
        assert!((z + 0.01 / 3.0).abs() < 1e-6 && (x - 1.0).abs() < 1e-4);
        // Bisshopp & Drucker (1945): PL²/EI = 1 → (1 − 0.05643, −0.30172).
        let (x, z) = super::tip(1.0);
        assert!(
            (x - 0.94357).abs() < 2e-5 && (z + 0.30172).abs() < 2e-5,
            "{x} {z}"
        );
    }
}
