//! The tip-loaded cantilever's Euler elastica: the large-deflection
//! reference of corotational FEM's convergence tests and of the
//! `fem_elastica` front of `voxflex bench --fronts`. Lengths are fractions
//! of the beam's length; no frame beyond that (x along the beam from the
//! clamp, z the load's axis, downward negative).

/// The tip-loaded cantilever's Euler elastica (inextensible, dead load in
/// −z): `θ'' = −α cos θ` on `s ∈ [0, 1]` with `α = P L² / EI`, clamped
/// (`θ(0) = 0`) and moment-free at the tip (`θ'(1) = 0`), by shooting on
/// `θ'(0)` (bisection, RK4 with 4,000 steps). Returns the tip's `(x, z)`
/// as fractions of the length (z downward negative).
pub fn tip(alpha: f64) -> (f64, f64) {
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
    fn the_elastica_reference_matches_its_small_and_known_values() {
        // Small load: the linear beam's tip deflection α/3.
        let (x, z) = super::tip(0.01);
        assert!(
            (z + 0.01 / 3.0).abs() < 1e-6 && (x - 1.0).abs() < 1e-4,
            "{x} {z}"
        );
        // Bisshopp & Drucker (1945): PL²/EI = 1 puts the tip at
        // (1 − 0.05643, −0.30172) L, and PL²/EI = 10 at δ/L = 0.8106.
        let (x, z) = super::tip(1.0);
        assert!(
            (x - 0.94357).abs() < 2e-5 && (z + 0.30172).abs() < 2e-5,
            "{x} {z}"
        );
        let (_, z) = super::tip(10.0);
        assert!((z + 0.8106).abs() < 1e-4, "{z}");
    }
}
