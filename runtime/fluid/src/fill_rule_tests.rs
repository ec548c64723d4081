//! Tests of the fill rule.

use super::*;

fn square_split(diagonal_02: bool) -> [TriangleTest; 2] {
    // unit square 0=(0,0) 1=(1,0) 2=(1,1) 3=(0,1), both halves CCW
    let q = [DVec2::ZERO, DVec2::X, DVec2::ONE, DVec2::Y];
    let tri = |ids: [u32; 3]| TriangleTest::new(ids, ids.map(|i| q[i as usize]));
    if diagonal_02 {
        [tri([0, 1, 2]), tri([0, 2, 3])]
    } else {
        [tri([0, 1, 3]), tri([1, 2, 3])]
    }
}

#[test]
fn every_point_of_a_tiled_square_falls_in_exactly_one_half() {
    let pts =
        (0..=8).flat_map(|i| (0..=8).map(move |j| DVec2::new(i as f64 / 8.0, j as f64 / 8.0)));
    for diag in [true, false] {
        let halves = square_split(diag);
        for p in pts.clone() {
            let inside = halves.iter().filter(|t| t.barycentric(p).is_some()).count();
            // The square's own boundary belongs to it or to a neighbour;
            // inside the open square exactly one half claims the point.
            let interior = p.x > 0.0 && p.x < 1.0 && p.y > 0.0 && p.y < 1.0;
            if interior {
                assert_eq!(inside, 1, "{p} (diagonal 0–2: {diag})");
            } else {
                assert!(inside <= 1, "{p}");
            }
        }
    }
}

/// A fan of triangles around a shared vertex (integer coordinates, so
/// the vertex and the spokes' midpoints lie exactly on the edges), with
/// every rotation of the vertex numbering: the centre vertex and each
/// spoke's midpoint belong to exactly one triangle.
#[test]
fn a_shared_vertex_and_its_spokes_belong_to_exactly_one_triangle() {
    let rim = [
        DVec2::new(2.0, 0.0),
        DVec2::new(2.0, 2.0),
        DVec2::new(-1.0, 2.0),
        DVec2::new(-2.0, 0.0),
        DVec2::new(-2.0, -2.0),
        DVec2::new(1.0, -2.0),
    ];
    for shift in 0..7u32 {
        // vertex ids: the centre gets `shift`, the rim the others in turn
        let id = |v: usize| (v as u32 + shift) % 7;
        let points: Vec<DVec2> = std::iter::once(DVec2::ZERO).chain(rim).collect();
        let fan: Vec<TriangleTest> = (0..6)
            .map(|r| {
                let ids = [0, 1 + r, 1 + (r + 1) % 6].map(id);
                let q = [0, 1 + r, 1 + (r + 1) % 6].map(|v| points[v]);
                TriangleTest::new(ids, q)
            })
            .collect();
        let mut probes = vec![DVec2::ZERO];
        probes.extend(rim.iter().map(|&p| p / 2.0));
        for p in probes {
            let claims = fan.iter().filter(|t| t.contains(p)).count();
            assert_eq!(claims, 1, "{p} (numbering shift {shift})");
        }
    }
}

#[test]
fn barycentric_coordinates_rebuild_the_point() {
    let q = [
        DVec2::new(0.0, 0.0),
        DVec2::new(4.0, 1.0),
        DVec2::new(1.0, 3.0),
    ];
    for ids in [[0u32, 1, 2], [2, 1, 0]] {
        let t = TriangleTest::new(ids, ids.map(|i| q[i as usize]));
        let p = DVec2::new(1.5, 1.2);
        let b = t.barycentric(p).unwrap();
        let corners = ids.map(|i| q[i as usize]);
        let back = corners[0] * b[0] + corners[1] * b[1] + corners[2] * b[2];
        assert!((back - p).length() < 1e-12, "{ids:?}: {back}");
        assert!(t.barycentric(DVec2::new(3.0, 3.0)).is_none());
    }
}
