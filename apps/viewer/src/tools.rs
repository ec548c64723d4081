//! The cut and carve tools' geometry: the cut plane drawn as a line on a
//! slice (the plane through the line, perpendicular to the slice) as the
//! quad the model's `Cut` takes, and the carve brush's stroke spacing.

use crate::protocol::SliceFrame;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;

/// The unit normal of a slice's plane (world frame).
pub fn slice_normal(frame: &SliceFrame) -> DVec3 {
    let s = &frame.slice;
    let o = s.point_to_world(0.0, 0.0);
    let u = s.point_to_world(1.0, 0.0) - o;
    let v = s.point_to_world(0.0, 1.0) - o;
    u.cross(v).normalize_or_zero()
}

/// Half the diagonal of `grid`'s box (mm): a quad this far either side of
/// a slice spans the whole volume along its normal.
pub fn half_extent_mm(grid: &Grid) -> f64 {
    let d = grid.spacing
        * DVec3::new(
            grid.dims[0] as f64,
            grid.dims[1] as f64,
            grid.dims[2] as f64,
        );
    d.length()
}

/// The cut quad (world mm, 4 corners in order) for a line from `a` to `b`
/// (world mm, in a slice's plane) on a slice of unit normal `normal`:
/// the segment swept `half` mm either side of the slice along its normal.
pub fn cut_quad(a: DVec3, b: DVec3, normal: DVec3, half: f64) -> Vec<[f64; 3]> {
    let h = normal * half;
    [a - h, b - h, b + h, a + h]
        .iter()
        .map(|p| p.to_array())
        .collect()
}

/// Whether a carve drag at `p` has moved far enough from the last carve
/// at `last` (half the brush radius, mm) to carve again.
pub fn carve_again(last: Option<DVec3>, p: DVec3, radius_mm: f64) -> bool {
    last.is_none_or(|l| (p - l).length() >= 0.5 * radius_mm)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_quad_holds_the_line_and_stands_on_the_slice() {
        let (a, b) = (DVec3::new(-10.0, 5.0, 3.0), DVec3::new(20.0, -5.0, 3.0));
        let q: Vec<DVec3> = cut_quad(a, b, DVec3::Z, 50.0)
            .into_iter()
            .map(DVec3::from_array)
            .collect();
        assert_eq!(q.len(), 4);
        // Planar, its plane holds the line and the slice normal.
        let n = (q[1] - q[0]).cross(q[3] - q[0]).normalize();
        assert!(n.dot(DVec3::Z).abs() < 1e-12, "perpendicular to the slice");
        for p in [a, b, (a + b) / 2.0, q[2]] {
            assert!((p - q[0]).dot(n).abs() < 1e-9);
        }
        assert!((q[3].z - q[0].z - 100.0).abs() < 1e-12);
    }

    #[test]
    fn a_carve_stroke_carves_every_half_radius() {
        let r = 8.0;
        assert!(carve_again(None, DVec3::ZERO, r));
        assert!(!carve_again(Some(DVec3::ZERO), DVec3::X * 3.9, r));
        assert!(carve_again(Some(DVec3::ZERO), DVec3::X * 4.0, r));
    }
}
