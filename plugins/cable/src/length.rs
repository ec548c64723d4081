//! The cable's length and its gradient, as pure functions of the points.
//!
//! The cable runs from the fixed pull point `q` through the points
//! `p₀, p₁, …, p_{n−1}` on the body, so its length is
//!
//! `L(x) = |p₀ − q| + Σᵢ |p_{i+1} − pᵢ|`
//!
//! and, with `u(d) = d / |d|`, `∂L/∂pᵢ = u(pᵢ − p_{i−1}) − u(p_{i+1} − pᵢ)`
//! (`p_{−1} = q`; the second term absent for the last point). A
//! zero-length segment has no direction: it contributes nothing (`u = 0`,
//! a subgradient) rather than NaN.

use voxflex_core::glam::DVec3;

/// `L(x)`, mm: the length from `pull` through every point in order.
pub fn cable_length(pull: DVec3, points: &[DVec3]) -> f64 {
    let mut previous = pull;
    let mut length = 0.0;
    for &p in points {
        length += p.distance(previous);
        previous = p;
    }
    length
}

/// `−∂L/∂pᵢ` per point: the force (µN) per µN of tension on each point,
/// which is also the gradient of the shortening `L₀ − L`. Each segment
/// pulls its two ends towards each other with unit vectors; a zero-length
/// segment pulls nothing.
pub fn shortening_gradient(pull: DVec3, points: &[DVec3]) -> Vec<DVec3> {
    let mut out = vec![DVec3::ZERO; points.len()];
    let mut previous = pull;
    for (i, &p) in points.iter().enumerate() {
        let towards_previous = (previous - p).normalize_or_zero();
        out[i] += towards_previous;
        if i > 0 {
            out[i - 1] -= towards_previous;
        }
        previous = p;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_add_up_segment_by_segment() {
        let pull = DVec3::new(0.0, 0.0, -1.0);
        let points = [
            DVec3::ZERO,
            DVec3::new(3.0, 4.0, 0.0),
            DVec3::new(3.0, 4.0, 2.0),
        ];
        assert_eq!(cable_length(pull, &points), 1.0 + 5.0 + 2.0);
        assert_eq!(cable_length(pull, &points[..1]), 1.0);
        assert_eq!(cable_length(pull, &[]), 0.0);
    }

    #[test]
    fn a_zero_length_segment_pulls_nothing_instead_of_nan() {
        let pull = DVec3::ZERO;
        let points = [DVec3::X, DVec3::X, DVec3::new(1.0, 2.0, 0.0)];
        let g = shortening_gradient(pull, &points);
        assert!(g.iter().all(|v| v.is_finite()), "{g:?}");
        // Point 0: pulled back to the pull point (−x); the doubled point
        // adds nothing; point 1 is pulled up by the last segment (+y);
        // the last point down towards point 1.
        assert_eq!(g, vec![-DVec3::X, DVec3::Y, -DVec3::Y]);
    }
}
