//! The frame the column grid lives in: two axes across the columns, one up.

use glam::DVec3;

/// An orthonormal, right-handed frame `(e1, e2, up)` with `up` against
/// gravity. World points (mm) map to `(u, v, h)`: `u = e1·p`, `v = e2·p`
/// across the columns, `h = up·p` the height.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GravityFrame {
    /// First axis across the columns (unit, world frame).
    pub e1: DVec3,
    /// Second axis across the columns (unit, world frame).
    pub e2: DVec3,
    /// Up: `−gravity / |gravity|` (unit, world frame).
    pub up: DVec3,
}

impl GravityFrame {
    /// The frame of a non-zero gravity vector (any unit). For gravity
    /// along −z it is the world frame itself.
    pub fn new(gravity: DVec3) -> Self {
        let up = -gravity.normalize();
        let e1 = up.any_orthonormal_vector();
        // e1 × (up × e1) = up for unit e1 ⟂ up: right-handed.
        let e2 = up.cross(e1);
        Self { e1, e2, up }
    }

    /// `(u, v, h)` of world point `p` (mm).
    #[inline]
    pub fn to_frame(&self, p: DVec3) -> DVec3 {
        DVec3::new(self.e1.dot(p), self.e2.dot(p), self.up.dot(p))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_frame_is_right_handed_with_up_against_gravity() {
        for g in [
            DVec3::new(0.0, 0.0, -9.81),
            DVec3::new(0.0, 9.81, 0.0),
            DVec3::new(1.0, -2.0, 3.0),
        ] {
            let f = GravityFrame::new(g);
            assert!((f.up + g.normalize()).length() < 1e-12);
            assert!((f.e1.cross(f.e2) - f.up).length() < 1e-12);
            assert!(f.e1.dot(f.e2).abs() < 1e-12 && f.e1.dot(f.up).abs() < 1e-12);
        }
    }
}
