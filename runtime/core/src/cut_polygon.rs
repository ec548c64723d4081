//! A planar cut polygon (world mm), fanned into triangles from its first
//! corner, and the segment test every model's cut uses: a link, an edge or
//! a face-to-face segment is cut when it crosses one of the triangles.

use glam::DVec3;

/// A cut polygon as triangles, with its bounding box.
#[derive(Clone, Debug, PartialEq)]
pub struct CutPolygon {
    /// The fan's triangles, world mm.
    pub triangles: Vec<[DVec3; 3]>,
    /// Lower corner of the polygon's box, mm.
    pub lo: DVec3,
    /// Upper corner of the polygon's box, mm.
    pub hi: DVec3,
}

impl CutPolygon {
    /// The polygon with `corners` (≥ 3, world mm; validated by the
    /// interaction parser).
    pub fn new(corners: &[[f64; 3]]) -> Self {
        let p: Vec<DVec3> = corners.iter().map(|c| DVec3::from_array(*c)).collect();
        let triangles = (1..p.len().saturating_sub(1))
            .map(|i| [p[0], p[i], p[i + 1]])
            .collect();
        let lo = p.iter().copied().fold(DVec3::INFINITY, DVec3::min);
        let hi = p.iter().copied().fold(DVec3::NEG_INFINITY, DVec3::max);
        Self { triangles, lo, hi }
    }

    /// True when the corners (world mm) span an area: some triangle of the
    /// fan from the first corner is not degenerate (collinear or repeated
    /// corners span none, and such a polygon cuts nothing). Relative to the
    /// corners' extent, so it holds at any scale.
    pub fn spans_area(corners: &[[f64; 3]]) -> bool {
        let p: Vec<DVec3> = corners.iter().map(|c| DVec3::from_array(*c)).collect();
        let Some(&first) = p.first() else {
            return false;
        };
        let lo = p.iter().copied().fold(first, DVec3::min);
        let hi = p.iter().copied().fold(first, DVec3::max);
        let extent2 = (hi - lo).length_squared();
        extent2 > 0.0
            && p.windows(2)
                .skip(1)
                .any(|w| (w[0] - first).cross(w[1] - first).length() > 1e-9 * extent2)
    }

    /// True when segment `a → b` crosses the polygon.
    pub fn crosses(&self, a: DVec3, b: DVec3) -> bool {
        if a.min(b).cmpgt(self.hi).any() || a.max(b).cmplt(self.lo).any() {
            return false;
        }
        self.triangles
            .iter()
            .any(|t| segment_crosses_triangle(a, b, t))
    }
}

/// True when segment `a → b` crosses triangle `t` (Möller–Trumbore; the
/// segment's ends and the triangle's edges count as crossing).
pub fn segment_crosses_triangle(a: DVec3, b: DVec3, t: &[DVec3; 3]) -> bool {
    let d = b - a;
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return false;
    }
    let inv = 1.0 / det;
    let s = a - t[0];
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let h = e2.dot(q) * inv;
    (0.0..=1.0).contains(&h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_through_the_polygon_cross_and_others_do_not() {
        // The square x = 0, −1 ≤ y, z ≤ 1.
        let c = CutPolygon::new(&[
            [0.0, -1.0, -1.0],
            [0.0, 1.0, -1.0],
            [0.0, 1.0, 1.0],
            [0.0, -1.0, 1.0],
        ]);
        assert_eq!(c.triangles.len(), 2);
        let x = |v: f64, y: f64| DVec3::new(v, y, 0.3);
        assert!(c.crosses(x(-0.5, 0.2), x(0.5, 0.2)));
        assert!(!c.crosses(x(0.1, 0.2), x(0.5, 0.2)), "one side only");
        assert!(!c.crosses(x(-0.5, 1.5), x(0.5, 1.5)), "beside the polygon");
        assert!(
            !c.crosses(DVec3::new(-1.0, 0.0, 0.0), DVec3::new(-1.0, 0.5, 0.0)),
            "parallel"
        );
    }

    #[test]
    fn collinear_or_repeated_corners_span_no_area() {
        let square = [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 1.0, 1.0]];
        assert!(CutPolygon::spans_area(&square));
        assert!(CutPolygon::spans_area(&[
            [0.0, 0.0, 0.0],
            [0.0, 1e-6, 0.0],
            [0.0, 1e-6, 1e-6]
        ]));
        let line = [
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [2.0, 2.0, 2.0],
            [5.0, 5.0, 5.0],
        ];
        assert!(!CutPolygon::spans_area(&line));
        let repeated = [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [4.0, 0.0, 0.0]];
        assert!(!CutPolygon::spans_area(&repeated));
        assert!(!CutPolygon::spans_area(&[[1.0, 2.0, 3.0]; 3]));
        // The same line cuts nothing: no segment crosses it.
        let c = CutPolygon::new(&line);
        assert!(!c.crosses(DVec3::new(1.0, 0.0, 1.0), DVec3::new(1.0, 2.0, 1.0)));
    }
}
