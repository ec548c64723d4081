//! Tests of the cavity against exact volumes, finite differences of the
//! volume, and the fluid's weight `ρ g V`.

use super::*;
use std::collections::HashMap;

/// An icosphere of radius `r` (mm) about `c`, `levels` subdivisions of an
/// icosahedron, normals out.
fn icosphere(c: DVec3, r: f64, levels: usize) -> TriangleSurface {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<DVec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .map(|p| DVec3::from_array(p).normalize())
    .to_vec();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut split = |a: u32, b: u32, v: &mut Vec<DVec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push(((v[a as usize] + v[b as usize]) / 2.0).normalize());
                v.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let (ab, bc, ca) = (
                split(a, b, &mut v),
                split(b, c, &mut v),
                split(c, a, &mut v),
            );
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    TriangleSurface {
        vertices: v.into_iter().map(|p| c + r * p).collect(),
        triangles: tris,
    }
}

/// A deterministic, irregular wobble of every vertex (mm).
fn wobbled(s: &TriangleSurface, amount: f64) -> Vec<DVec3> {
    s.vertices
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            let k = i as f64;
            p + amount * DVec3::new((1.3 * k).sin(), (2.1 * k + 0.4).cos(), (0.7 * k).sin())
        })
        .collect()
}

const DOWN_Z: DVec3 = DVec3::new(0.0, 0.0, -9.81);

fn cavity(params: &str, s: &TriangleSurface, gravity: DVec3) -> Cavity {
    let mut c = Cavity::new(CavityParams::from_toml(params).unwrap());
    c.init(ActuatorGeometry {
        points: &s.vertices,
        triangles: &s.triangles,
        gravity_m_s2: gravity,
    })
    .unwrap();
    c
}

fn init_error(points: &[DVec3], triangles: &[[u32; 3]]) -> String {
    let mut c = Cavity::new(CavityParams::from_toml("").unwrap());
    c.init(ActuatorGeometry {
        points,
        triangles,
        gravity_m_s2: DOWN_Z,
    })
    .unwrap_err()
    .0
}

fn sum(v: &[DVec3]) -> DVec3 {
    v.iter().sum()
}

#[test]
fn the_test_icosphere_is_closed_and_close_to_its_ball() {
    let s = icosphere(DVec3::ZERO, 10.0, 3);
    s.check_closed("icosphere").unwrap();
    let ball = 4.0 / 3.0 * std::f64::consts::PI * 1000.0;
    let v = s.signed_volume();
    assert!(v > 0.97 * ball && v < ball, "{v} vs {ball}");
}

#[test]
fn directions_sum_to_zero_and_are_the_finite_difference_volume_gradient() {
    let s = icosphere(DVec3::new(1.0, -2.0, 3.0), 10.0, 2);
    let mut c = cavity("", &s, DOWN_Z);
    let x = wobbled(&s, 0.8);
    let l = c.linearise(&x).unwrap();
    let scale: f64 = l.directions.iter().map(|d| d.length()).sum();
    assert!(
        sum(&l.directions).length() < 1e-12 * scale,
        "{}",
        sum(&l.directions)
    );
    // The volume is linear in each single coordinate, so central
    // differences are exact up to rounding.
    let h = 1e-3;
    for i in (0..x.len()).step_by(7) {
        for axis in 0..3 {
            let mut y = x.clone();
            y[i][axis] += h;
            let up = c.linearise(&y).unwrap().measure;
            y[i][axis] -= 2.0 * h;
            let down = c.linearise(&y).unwrap().measure;
            let fd = (up - down) / (2.0 * h);
            let d = l.directions[i][axis];
            assert!(
                (fd - d).abs() < 1e-7 * (1.0 + d.abs()),
                "vertex {i} axis {axis}: {fd} vs {d}"
            );
        }
    }
}

#[test]
fn the_measure_is_zero_at_rest_and_the_volume_growth_after_scaling() {
    let s = icosphere(DVec3::new(4.0, 0.0, -1.0), 5.0, 2);
    let mut c = cavity("", &s, DOWN_Z);
    let v0 = c.rest_volume_mm3().unwrap();
    assert!((v0 - s.signed_volume()).abs() < 1e-12 * v0);
    assert_eq!(c.linearise(&s.vertices).unwrap().measure, 0.0);
    let centre = DVec3::new(4.0, 0.0, -1.0);
    for k in [0.9, 1.1, 1.5] {
        let x: Vec<DVec3> = s
            .vertices
            .iter()
            .map(|&p| centre + k * (p - centre))
            .collect();
        let m = c.linearise(&x).unwrap().measure;
        let expected = v0 * (k * k * k - 1.0);
        assert!((m - expected).abs() < 1e-9 * v0, "×{k}: {m} vs {expected}");
    }
    let notes = c.notes().unwrap();
    assert_eq!(notes["linearisations"], 4.0);
    assert!((notes["volume_growth_mm3"] - v0 * (1.5f64.powi(3) - 1.0)).abs() < 1e-9 * v0);
    assert!((notes["volume_mm3"] - v0 * 1.5f64.powi(3)).abs() < 1e-9 * v0);
}

#[test]
fn bounds_follow_the_parameters() {
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::ONE, 1);
    let mut c = cavity(
        "max_pressure_pa = 2e4\nvolume_growth_mm3 = [-0.5, 3]",
        &s,
        DOWN_Z,
    );
    let l = c.linearise(&s.vertices).unwrap();
    assert_eq!(
        (l.effort_bounds, l.measure_bounds),
        ([0.0, 2e4], [-0.5, 3.0])
    );
    l.check(s.vertices.len(), "cavity").unwrap();
}

#[test]
fn water_in_a_box_weighs_rho_g_v_on_its_floor_and_grows_with_its_volume() {
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::new(10.0, 8.0, 5.0), 3);
    let mut c = cavity("fluid = \"water\"\ncolumns_per_side = 40", &s, DOWN_Z);
    let l = c.linearise(&s.vertices).unwrap();
    l.check(s.vertices.len(), "cavity").unwrap();
    // 1000 kg/m³ · 9.81 m/s² · 400 mm³ · 1e-3 = 3924 µN, straight down.
    let w = sum(&l.loads);
    assert!((w - DVec3::new(0.0, 0.0, -3924.0)).length() < 1e-8, "{w}");
    for (p, load) in s.vertices.iter().zip(&l.loads) {
        if p.z > 0.0 {
            assert_eq!(*load, DVec3::ZERO, "only the floor carries the water");
        }
        assert!(load.x == 0.0 && load.y == 0.0 && load.z <= 0.0);
    }
    for (g, load) in l.load_growth.iter().zip(&l.loads) {
        assert!((*g * 400.0 - *load).length() < 1e-12 * (1.0 + load.length()));
    }
    // One mm³ more weighs ρg = 9.81 µN (1 mg of water).
    assert!((sum(&l.load_growth) - DVec3::new(0.0, 0.0, -9.81)).length() < 1e-12 * 9.81);
    let notes = c.notes().unwrap();
    assert!((notes["fluid_weight_uN"] - 3924.0).abs() < 1e-8);
    assert_eq!(
        (notes["weighings"], notes["irregular_columns_max"]),
        (1.0, 0.0)
    );
}

#[test]
fn a_denser_fluid_under_sideways_gravity_weighs_along_gravity() {
    let s = icosphere(DVec3::new(0.0, 5.0, 0.0), 10.0, 3);
    let g = DVec3::new(0.0, -3.0, 0.0);
    let mut c = cavity(
        "fluid = \"water\"\ndensity_kg_m3 = 1200\ncolumns_per_side = 120",
        &s,
        g,
    );
    let x = wobbled(&s, 0.2);
    let l = c.linearise(&x).unwrap();
    let w = sum(&l.loads);
    let notes = c.notes().unwrap();
    let (fluid_v, total) = (notes["fluid_volume_mm3"], notes["fluid_weight_uN"]);
    assert!(
        (w - DVec3::new(0.0, -total, 0.0)).length() < 1e-9 * total,
        "{w} vs {total}"
    );
    assert!((total - 1200.0 * 3.0 * fluid_v * 1e-3).abs() < 1e-9 * total);
    // The columns hold the surface's volume to the grid's accuracy.
    let v = c.notes().unwrap()["volume_mm3"];
    assert!((fluid_v - v).abs() < 5e-3 * v, "{fluid_v} vs {v}");
    for (g, load) in l.load_growth.iter().zip(&l.loads) {
        assert!((*g * fluid_v - *load).length() < 1e-12 * (1.0 + load.length()));
    }
}

#[test]
fn air_and_weightless_water_carry_no_loads() {
    let s = icosphere(DVec3::ZERO, 3.0, 1);
    for (params, gravity) in [
        ("", DOWN_Z),
        ("fluid = \"air\"", DOWN_Z),
        ("fluid = \"water\"", DVec3::ZERO),
    ] {
        let mut c = cavity(params, &s, gravity);
        let l = c.linearise(&s.vertices).unwrap();
        assert!(l.loads.is_empty() && l.load_growth.is_empty(), "{params}");
        let notes = c.notes().unwrap();
        assert_eq!((notes["weighings"], notes["fluid_weight_uN"]), (0.0, 0.0));
    }
}

#[test]
fn overlapping_chambers_are_counted_as_irregular_columns() {
    // Two closed boxes overlapping over x ∈ [5, 10]: there every column
    // crosses bottom, bottom, top, top.
    let a = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::splat(10.0), 1);
    let b = TriangleSurface::tiled_box(DVec3::new(5.0, 0.0, 0.0), DVec3::new(15.0, 10.0, 10.0), 1);
    let n = a.vertices.len() as u32;
    let s = TriangleSurface {
        vertices: [a.vertices, b.vertices].concat(),
        triangles: [
            a.triangles,
            b.triangles.iter().map(|t| t.map(|v| v + n)).collect(),
        ]
        .concat(),
    };
    let mut c = cavity("fluid = \"water\"\ncolumns_per_side = 30", &s, DOWN_Z);
    c.linearise(&s.vertices).unwrap();
    c.linearise(&s.vertices).unwrap();
    let notes = c.notes().unwrap();
    // 10 of the 30 columns along x (centres 0.25 + 0.5 k mm), all 30 along y.
    assert_eq!(notes["irregular_columns_max"], 300.0);
    assert_eq!(
        (notes["irregular_weighings"], notes["weighings"]),
        (2.0, 2.0)
    );
}

#[test]
fn schedules_give_the_command_of_each_frame() {
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::ONE, 1);
    let frame = |n| FrameInfo {
        frame: n,
        frames: 50,
        dt_s: 0.02,
    };
    for (params, at_5, at_20) in [
        (
            "pressure_pa = [[0, 0], [10, 1000]]",
            ActuatorCommand::Effort(500.0),
            ActuatorCommand::Effort(1000.0),
        ),
        (
            "volume_mm3 = [[0, 0], [10, 8]]",
            ActuatorCommand::Measure(4.0),
            ActuatorCommand::Measure(8.0),
        ),
        ("", ActuatorCommand::Free, ActuatorCommand::Free),
    ] {
        let mut c = cavity(params, &s, DOWN_Z);
        assert_eq!(c.command(frame(5)).unwrap(), at_5, "{params}");
        assert_eq!(c.command(frame(20)).unwrap(), at_20, "{params}");
    }
}

#[test]
fn bad_geometry_is_refused_saying_what_is_wrong() {
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::ONE, 1);
    let e = init_error(&s.vertices, &[]);
    assert!(e.contains("no triangles"), "{e}");
    let mut out_of_range = s.triangles.clone();
    out_of_range[3][1] = 99;
    let e = init_error(&s.vertices, &out_of_range);
    assert!(e.contains("cavity") && e.contains("vertex 99"), "{e}");
    let e = init_error(&s.vertices, &s.triangles[1..]);
    assert!(e.contains("cavity") && e.contains("not closed"), "{e}");
    let inverted: Vec<[u32; 3]> = s.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect();
    let e = init_error(&s.vertices, &inverted);
    assert!(e.contains("reverse the triangles' winding"), "{e}");
    let mut nan = s.vertices.clone();
    nan[2].y = f64::NAN;
    let e = init_error(&nan, &s.triangles);
    assert!(e.contains("cavity") && e.contains("non-finite"), "{e}");
}

#[test]
fn bad_positions_gravity_and_order_are_refused() {
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::ONE, 1);
    let mut c = Cavity::new(CavityParams::from_toml("fluid = \"water\"").unwrap());
    let e = c.linearise(&s.vertices).unwrap_err().0;
    assert!(e.contains("before init"), "{e}");
    let e = c
        .init(ActuatorGeometry {
            points: &s.vertices,
            triangles: &s.triangles,
            gravity_m_s2: DVec3::new(0.0, f64::INFINITY, 0.0),
        })
        .unwrap_err()
        .0;
    assert!(e.contains("gravity"), "{e}");
    let mut c = cavity("", &s, DOWN_Z);
    let e = c.linearise(&s.vertices[1..]).unwrap_err().0;
    assert!(e.contains("7 positions for 8"), "{e}");
    let mut x = s.vertices.clone();
    x[4] = DVec3::NAN;
    let e = c.linearise(&x).unwrap_err().0;
    assert!(e.contains("vertex 4"), "{e}");
}

#[test]
fn a_collapsed_water_cavity_is_refused() {
    let s = TriangleSurface::tiled_box(DVec3::ZERO, DVec3::ONE, 1);
    let mut c = cavity("fluid = \"water\"", &s, DOWN_Z);
    let flat: Vec<DVec3> = s
        .vertices
        .iter()
        .map(|p| DVec3::new(p.x, p.y, 0.0))
        .collect();
    let e = c.linearise(&flat).unwrap_err().0;
    assert!(e.contains("collapsed"), "{e}");
}
