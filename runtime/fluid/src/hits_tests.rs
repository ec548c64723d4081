//! Tests of the row scan.

use super::*;
use crate::fill_rule::TriangleTest;
use crate::projection::signed_area2;

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
    let p = crate::projection::ProjectedSurface::new(&surface, DVec3::NEG_Z, n).expect("finite");
    let g = p.grid;
    assert_eq!(g.cell, DVec2::splat(0.5));
    let (mut inside_total, mut scanned_rows) = (0, 0);
    for (t, &ids) in surface.triangles.iter().enumerate() {
        let corners = ids.map(|v| p.uvh[v as usize]);
        let q = corners.map(|c| c.truncate());
        let test = TriangleTest::new(ids, q);
        let (pt, raster) = TriangleRaster::of(t, ids, corners, g.n);
        if pt.side == Side::Vertical {
            assert!(raster.is_none());
            continue; // zero projected area: no centre is its
        }
        let centre = |i: usize, j: usize| DVec2::new(i as f64, j as f64);
        let [j0, j1] = pt.rows.map(|j| j as usize);
        let [i0, i1] = pt.columns.map(|i| i as usize);
        for j in 0..n {
            let truth: Vec<usize> = (0..n).filter(|&i| test.contains(centre(i, j))).collect();
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
        let Some(mut r) = raster else {
            assert_eq!(pt.candidate_count(), 0);
            continue;
        };
        // the plane through the corners in mm, and barycentric coordinates
        // from areas in mm: the references the run is checked against
        let mm = corners.map(|c| ((c.truncate() + 0.5) * g.cell + g.origin).extend(c.z));
        let world = mm.map(|c| c.truncate());
        let n3 = (mm[1] - mm[0]).cross(mm[2] - mm[0]);
        let plane =
            |c: DVec2| mm[0].z - (n3.x * (c.x - world[0].x) + n3.y * (c.y - world[0].y)) / n3.z;
        let area2 = signed_area2(world[0], world[1], world[2]);
        // barycentric coordinates are as ill-conditioned as the triangle
        // is thin (a sliver's differ in their leading digits between any
        // two ways of computing them)
        let perimeter: f64 = (0..3).map(|k| world[k].distance(world[(k + 1) % 3])).sum();
        let tolerance = 1e-12 * (1.0 + perimeter * perimeter / area2.abs());
        for j in j0..j1 {
            let truth: Vec<usize> = (i0..i1).filter(|&i| test.contains(centre(i, j))).collect();
            let (run, bary) = r.run(j);
            if i1 - i0 <= DIRECT_TEST_COLUMNS {
                // the row test (whatever the row count) finds the same run
                assert_eq!(
                    r.run_with(&r.row_test(), j),
                    (run, bary),
                    "triangle {t} row {j}"
                );
            }
            let found: Vec<usize> = (run.first..run.first.saturating_add(run.len))
                .map(|i| i as usize)
                .collect();
            assert_eq!(found, truth, "triangle {t} row {j}: run");
            let [a, b] = r.scan(j);
            let scanned: Vec<usize> = (a..b).collect();
            assert_eq!(scanned, truth, "triangle {t} row {j}: span");
            scanned_rows += 1;
            for m in 0..run.len {
                let c = g.centre((run.first + m) as usize, j);
                let scale = 1.0 + plane(c).abs();
                assert!(
                    (run.height_at(m) - plane(c)).abs() < 1e-9 * scale,
                    "triangle {t} row {j}"
                );
                let b0 = signed_area2(c, world[1], world[2]) / area2;
                let b1 = signed_area2(world[0], c, world[2]) / area2;
                let at = |k: usize| bary.at_first[k] + m as f64 * bary.per_column[k];
                assert!(
                    (at(0) - b0).abs() < tolerance && (at(1) - b1).abs() < tolerance,
                    "triangle {t} row {j}"
                );
                assert_eq!(bary.corners, ids);
            }
        }
    }
    assert!(
        inside_total > 2000 && scanned_rows > 1000,
        "{inside_total} {scanned_rows}"
    );
}
