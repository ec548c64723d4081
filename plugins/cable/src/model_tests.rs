//! Tests of the cable against its exact length, the straight cable's
//! forces and finite differences of the shortening.

use super::*;

fn cable(params: &str, points: &[DVec3]) -> Cable {
    let mut c = Cable::new(CableParams::from_toml(params).unwrap());
    c.init(ActuatorGeometry {
        points,
        triangles: &[],
        gravity_m_s2: DVec3::new(0.0, 0.0, -9.81),
    })
    .unwrap();
    c
}

const PULL_AT_ORIGIN: &str = "pull_point_mm = [0, 0, 0]";

/// A finger-like bent cable: up from the base, then curling over.
fn bent() -> Vec<DVec3> {
    (0..9)
        .map(|i| {
            let a = 0.25 * i as f64;
            DVec3::new(
                3.0 * a.sin() + 0.1 * i as f64,
                0.5 * i as f64 - 1.0,
                2.0 + 3.0 * a.cos(),
            )
        })
        .collect()
}

#[test]
fn a_straight_cable_pulls_only_its_last_point_back_along_itself() {
    let e = DVec3::new(1.0, 2.0, 2.0) / 3.0;
    let points: Vec<DVec3> = [1.0, 2.5, 4.0, 7.0].iter().map(|&s| s * e).collect();
    let mut c = cable(PULL_AT_ORIGIN, &points);
    assert!((c.rest_length_mm().unwrap() - 7.0).abs() < 1e-12);
    let l = c.linearise(&points).unwrap();
    // Every interior point (and the first) is pulled equally both ways.
    for (i, d) in l.directions[..3].iter().enumerate() {
        assert!(d.length() < 1e-15, "point {i}: {d}");
    }
    // The last point is pulled back along the cable, towards the pull point.
    assert!(
        (l.directions[3] + e).length() < 1e-15,
        "{}",
        l.directions[3]
    );
    assert_eq!(l.measure, 0.0);
    assert!(l.loads.is_empty() && l.load_growth.is_empty());
    l.check(points.len(), "cable").unwrap();
}

#[test]
fn a_single_point_is_pulled_straight_towards_the_pull_point() {
    let pull = DVec3::new(1.0, -1.0, 0.0);
    let mut c = cable("pull_point_mm = [1, -1, 0]", &[DVec3::new(1.0, 3.0, 3.0)]);
    let l = c.linearise(&[DVec3::new(4.0, 3.0, 0.0)]).unwrap();
    assert!((l.directions[0] - (pull - DVec3::new(4.0, 3.0, 0.0)) / 5.0).length() < 1e-15);
    // Rest length 5, now 5: no shortening.
    assert!(l.measure.abs() < 1e-12, "{}", l.measure);
}

#[test]
fn directions_are_the_finite_difference_gradient_of_the_shortening() {
    let points = bent();
    let mut c = cable("pull_point_mm = [0.5, -3, 0]", &points);
    let x: Vec<DVec3> = points
        .iter()
        .enumerate()
        .map(|(i, &p)| p + 0.3 * DVec3::new((i as f64).cos(), (2.0 * i as f64).sin(), 0.2))
        .collect();
    let l = c.linearise(&x).unwrap();
    let h = 1e-5;
    for i in 0..x.len() {
        for axis in 0..3 {
            let mut y = x.clone();
            y[i][axis] += h;
            let up = c.linearise(&y).unwrap().measure;
            y[i][axis] -= 2.0 * h;
            let down = c.linearise(&y).unwrap().measure;
            let fd = (up - down) / (2.0 * h);
            let d = l.directions[i][axis];
            assert!((fd - d).abs() < 1e-7, "point {i} axis {axis}: {fd} vs {d}");
        }
    }
}

#[test]
fn the_measure_is_the_shortening_and_the_notes_report_it() {
    let points = [DVec3::new(0.0, 0.0, 2.0), DVec3::new(0.0, 0.0, 5.0)];
    let mut c = cable(PULL_AT_ORIGIN, &points);
    // Pull the tip 1 mm down: 1 mm shorter.
    let l = c
        .linearise(&[points[0], DVec3::new(0.0, 0.0, 4.0)])
        .unwrap();
    assert!((l.measure - 1.0).abs() < 1e-12);
    // Bend the tip sideways: the last segment becomes 5 mm long.
    let l = c
        .linearise(&[points[0], DVec3::new(3.0, 0.0, 6.0)])
        .unwrap();
    assert!((l.measure + 2.0).abs() < 1e-12, "{}", l.measure);
    let notes = c.notes().unwrap();
    assert_eq!(notes["rest_length_mm"], 5.0);
    assert!((notes["length_mm"] - 7.0).abs() < 1e-12);
    assert!((notes["shortening_mm"] + 2.0).abs() < 1e-12);
    assert_eq!((notes["linearisations"], notes["points"]), (2.0, 2.0));
}

#[test]
fn bounds_and_schedules_follow_the_parameters() {
    let points = [DVec3::Z];
    let frame = |n| FrameInfo {
        frame: n,
        frames: 40,
        dt_s: 0.05,
    };
    let mut c = cable(
        "pull_point_mm = [0, 0, 0]\ntension_uN = [[0, 0], [20, 4e5]]\nmax_tension_uN = 5e5\n\
         max_shortening_mm = 8",
        &points,
    );
    assert_eq!(c.command(frame(5)).unwrap(), ActuatorCommand::Effort(1e5));
    let l = c.linearise(&points).unwrap();
    assert_eq!(
        (l.effort_bounds, l.measure_bounds),
        ([0.0, 5e5], [f64::NEG_INFINITY, 8.0])
    );
    let mut c = cable(
        "pull_point_mm = [0, 0, 0]\nshortening_mm = [[0, 0], [10, 3]]",
        &points,
    );
    assert_eq!(c.command(frame(5)).unwrap(), ActuatorCommand::Measure(1.5));
    assert_eq!(c.command(frame(39)).unwrap(), ActuatorCommand::Measure(3.0));
    let mut c = cable(PULL_AT_ORIGIN, &points);
    assert_eq!(c.command(frame(0)).unwrap(), ActuatorCommand::Free);
}

fn init_error(points: &[DVec3], triangles: &[[u32; 3]]) -> String {
    let mut c = Cable::new(CableParams::from_toml("pull_point_mm = [0, 0, 1]").unwrap());
    c.init(ActuatorGeometry {
        points,
        triangles,
        gravity_m_s2: DVec3::ZERO,
    })
    .unwrap_err()
    .0
}

#[test]
fn bad_geometry_is_refused_saying_what_is_wrong() {
    assert!(init_error(&[], &[]).contains("no points"));
    let e = init_error(&[DVec3::X, DVec3::new(0.0, f64::NAN, 0.0)], &[]);
    assert!(e.contains("point 1") && e.contains("finite"), "{e}");
    let e = init_error(&[DVec3::Z, DVec3::X], &[]);
    assert!(e.contains("point 0") && e.contains("pull point"), "{e}");
    let e = init_error(&[DVec3::X, DVec3::Y, DVec3::ZERO], &[[0, 1, 2]]);
    assert!(e.contains("1 triangles"), "{e}");
}

#[test]
fn bad_positions_and_order_are_refused() {
    let mut c = Cable::new(CableParams::from_toml(PULL_AT_ORIGIN).unwrap());
    assert!(
        c.linearise(&[DVec3::X])
            .unwrap_err()
            .0
            .contains("before init")
    );
    let mut c = cable(PULL_AT_ORIGIN, &[DVec3::X, DVec3::Y]);
    let e = c.linearise(&[DVec3::X]).unwrap_err().0;
    assert!(e.contains("1 positions for 2"), "{e}");
    let e = c.linearise(&[DVec3::X, DVec3::INFINITY]).unwrap_err().0;
    assert!(e.contains("point 1"), "{e}");
}
