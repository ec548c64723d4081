//! Tests of the fill rule and the row scan.

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

/// A small deterministic generator (no dependency for one test).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Triangles of every size — from below a column to across the grid,
/// slivers, corners on column centres and on the centres' rows — seen from
/// above: the row scan (both its direct test and its span) finds exactly the
/// centres the fill rule puts inside, and every such centre lies among the
/// triangle's candidates.
#[test]
fn the_row_scan_finds_exactly_the_centres_the_fill_rule_puts_inside() {
    let mut rng = Lcg(7);
    let n = 24;
    let mut vertices = vec![DVec3::ZERO, DVec3::new(12.0, 12.0, 1.0)]; // the grid: 0.5 mm cells
    let mut triangles = Vec::new();
    for t in 0..1000 {
        let size = [0.2, 1.0, 3.0, 12.0][t % 4];
        let snap = t % 3 == 0; // corners on the centres' lattice (…, 0.25, 0.75, …)
        let corner = |rng: &mut Lcg, vertices: &mut Vec<DVec3>, c: DVec2| {
            let mut p = c + DVec2::new(rng.next(), rng.next()) * size;
            if snap {
                p = ((p - 0.25) * 2.0).round() / 2.0 + 0.25;
            }
            let p = p.clamp(DVec2::ZERO, DVec2::splat(12.0));
            vertices.push(p.extend(rng.next()));
            (vertices.len() - 1) as u32
        };
        let c = DVec2::new(rng.next(), rng.next()) * 12.0;
        let a = corner(&mut rng, &mut vertices, c);
        let b = corner(&mut rng, &mut vertices, c);
        let d = if t % 7 == 0 {
            // a sliver: its third corner a nanometre off the first edge
            let (pa, pb) = (vertices[a as usize], vertices[b as usize]);
            let q = pa.lerp(pb, 0.37) + DVec3::new(1e-9, 1e-9, 0.0);
            vertices.push(q.min(DVec3::new(12.0, 12.0, 1.0)));
            (vertices.len() - 1) as u32
        } else {
            corner(&mut rng, &mut vertices, c)
        };
        triangles.push([a, b, d]);
    }
    let surface = voxflex_core::triangle_surface::TriangleSurface {
        vertices,
        triangles,
    };
    let p = ProjectedSurface::new(&surface, DVec3::NEG_Z, n);
    let g = p.grid;
    assert_eq!(g.cell, DVec2::splat(0.5));
    let inv = 1.0 / g.cell.x;
    let (mut inside_total, mut scanned_rows) = (0, 0);
    for t in 0..p.triangles.len() {
        let ids = surface.triangles[t];
        let q = ids.map(|v| p.uvh[v as usize].truncate());
        let test = TriangleTest::new(ids, q);
        let pt = p.triangles[t];
        if pt.side == Side::Vertical {
            continue; // zero projected area: no centre is its
        }
        let [j0, j1] = pt.rows.map(|j| j as usize);
        let [i0, i1] = pt.columns.map(|i| i as usize);
        for j in 0..n {
            let truth: Vec<usize> = (0..n).filter(|&i| test.contains(g.centre(i, j))).collect();
            inside_total += truth.len();
            if truth.is_empty() {
                continue;
            }
            assert!(
                (j0..j1).contains(&j) && truth.iter().all(|i| (i0..i1).contains(i)),
                "triangle {t}: row {j} has centres {truth:?} outside its candidates {:?}",
                (pt.columns, pt.rows)
            );
        }
        if pt.candidate_count() == 0 {
            continue;
        }
        let mut r = TriangleRaster::new(&p, t);
        for j in j0..j1 {
            let truth: Vec<usize> = (i0..i1)
                .filter(|&i| test.contains(g.centre(i, j)))
                .collect();
            let run = r.run(&g, inv, j);
            let found: Vec<usize> = (run.first..run.first.saturating_add(run.len))
                .map(|i| i as usize)
                .collect();
            assert_eq!(found, truth, "triangle {t} row {j}: run");
            let [a, b] = r.scan(&g, inv, j);
            let scanned: Vec<usize> = (a..b).collect();
            assert_eq!(scanned, truth, "triangle {t} row {j}: span");
            scanned_rows += 1;
            if run.len > 0 {
                let h = r.height.at(g.centre(run.first as usize + 1, j));
                assert!((run.height_at(1) - h).abs() < 1e-12, "triangle {t} row {j}");
            }
        }
    }
    assert!(
        inside_total > 2000 && scanned_rows > 1000,
        "{inside_total} {scanned_rows}"
    );
}
