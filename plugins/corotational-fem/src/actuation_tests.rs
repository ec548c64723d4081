//! The actuation capability (`set_point_loads`, `compliance`) on the
//! cantilever: the compliance predicts what a static solve under the same
//! point loads does (small loads: the linear regime), it is symmetric
//! (Maxwell–Betti), clamped points do not move, and a mirrored load gives
//! the mirrored answer — for P1 and P2.

use crate::solver::{CorotationalFem, ElementKind, FemParams};
use crate::tests::{cantilever, map_on_cpu, static_params};
use voxflex_core::deformation::{BindingId, DeformationModel, FrameInfo, RestPoints};
use voxflex_core::glam::DVec3;

type Fem = voxflex_mesh::mesh_model::MeshModel<CorotationalFem>;

/// Points inside the beam (mm): the tip face's corners and centre, one
/// near mid-span, one at the clamp.
fn points() -> Vec<[f32; 3]> {
    vec![
        [10.0, 0.0, 0.0],
        [10.0, 1.0, 1.0],
        [10.0, 0.5, 0.5],
        [5.3, 0.4, 0.7],
        [0.0, 0.5, 0.5],
    ]
}

fn params(element: ElementKind) -> FemParams {
    FemParams {
        element,
        compliance_cg_tolerance: 1e-12,
        ..static_params(1e-12)
    }
}

/// The unloaded cantilever, initialised, with `points()` bound.
fn beam(element: ElementKind) -> (Fem, BindingId) {
    let mut m = cantilever(2, 0.0, params(element));
    let p = points();
    let id = m.bind(RestPoints::Points(&p)).unwrap();
    (m, id)
}

fn compliance(m: &mut Fem, id: BindingId, f: &[DVec3]) -> Vec<DVec3> {
    let mut u = vec![DVec3::ZERO; f.len()];
    m.compliance(id, f, &mut u).unwrap();
    u
}

fn tip_push(z: f64) -> Vec<DVec3> {
    let mut f = vec![DVec3::ZERO; points().len()];
    f[2] = DVec3::new(0.0, 0.0, z);
    f
}

fn compliance_predicts_a_small_load_step(element: ElementKind) {
    let (mut m, id) = beam(element);
    // 1e-3 µN on a beam of E = 1000 Pa deflects it by ~1e-3 mm: linear.
    let f = tip_push(-1e-3);
    let predicted = compliance(&mut m, id, &f);
    m.set_point_loads(id, &f).unwrap();
    m.step(FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: 0.0,
    })
    .unwrap();
    let got = map_on_cpu(&mut m, id, points().len());
    let tip = predicted[2].z;
    assert!(tip < 0.0, "{element:?}: the tip goes down, got {tip}");
    for (i, p) in predicted.iter().enumerate() {
        let g = DVec3::new(got[0][i] as f64, got[1][i] as f64, got[2][i] as f64);
        // The map adds P2's mid-edge layer, the compliance reads the
        // corners linearly: allow that interpolation's difference.
        let allowed = 2e-3 * tip.abs()
            + if element == ElementKind::P2 {
                0.05 * tip.abs()
            } else {
                0.0
            };
        assert!(
            (g - *p).length() <= allowed,
            "{element:?} point {i}: step {g} vs compliance {p}"
        );
    }
    assert!(
        predicted[4].length() < 1e-12,
        "the clamp moved: {}",
        predicted[4]
    );
}

#[test]
fn the_compliance_predicts_a_small_load_step_with_p1() {
    compliance_predicts_a_small_load_step(ElementKind::P1);
}

#[test]
fn the_compliance_predicts_a_small_load_step_with_p2() {
    compliance_predicts_a_small_load_step(ElementKind::P2);
}

#[test]
fn the_compliance_is_symmetric_and_mirrors_with_the_load() {
    for element in [ElementKind::P1, ElementKind::P2] {
        let (mut m, id) = beam(element);
        let f: Vec<DVec3> = (0..5)
            .map(|i| DVec3::new(0.3 * i as f64, -0.2, 1.0 - 0.4 * i as f64))
            .collect();
        let g: Vec<DVec3> = (0..5)
            .map(|i| DVec3::new(-0.5, 0.1 * i as f64, 0.7 - 0.1 * i as f64))
            .collect();
        let cf = compliance(&mut m, id, &f);
        let cg = compliance(&mut m, id, &g);
        let dot = |a: &[DVec3], b: &[DVec3]| a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum::<f64>();
        let (gcf, fcg) = (dot(&g, &cf), dot(&f, &cg));
        assert!(
            (gcf - fcg).abs() <= 1e-6 * gcf.abs().max(fcg.abs()),
            "{element:?}: gᵀCf {gcf} vs fᵀCg {fcg}"
        );
        let up = compliance(&mut m, id, &tip_push(1.0));
        let down = compliance(&mut m, id, &tip_push(-1.0));
        for (u, d) in up.iter().zip(&down) {
            assert!(
                (*u + *d).length() <= 1e-9 * u.length().max(1e-12),
                "{u} vs {d}"
            );
        }
    }
}

#[test]
fn wrong_lengths_and_non_finite_loads_are_refused() {
    let (mut m, id) = beam(ElementKind::P1);
    let e = m.set_point_loads(id, &[DVec3::ZERO]).unwrap_err();
    assert!(
        e.0.contains("1 point loads for a binding of 5 points"),
        "{e}"
    );
    let mut f = tip_push(1.0);
    f[0].x = f64::NAN;
    let e = m.set_point_loads(id, &f).unwrap_err();
    assert!(e.0.contains("bound point 0 is not finite"), "{e}");
    let mut out = vec![DVec3::ZERO; 2];
    assert!(m.compliance(id, &tip_push(1.0), &mut out).is_err());
    assert!(
        m.compliance(BindingId(9), &tip_push(1.0), &mut [DVec3::ZERO; 5])
            .is_err()
    );
}

/// `resolve` repeats the frame from its start with the loads as set now:
/// the same as stepping a fresh model with those loads.
#[test]
fn resolve_repeats_the_frame_with_the_new_loads() {
    let frame = FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: 0.0,
    };
    let (mut m, id) = beam(ElementKind::P1);
    assert!(
        DeformationModel::resolve(&mut m).is_err(),
        "nothing to repeat before a step"
    );
    m.set_point_loads(id, &tip_push(-1e-3)).unwrap();
    m.step(frame).unwrap();
    m.set_point_loads(id, &tip_push(-2e-3)).unwrap();
    assert!(DeformationModel::resolve(&mut m).unwrap().changed);
    let again = map_on_cpu(&mut m, id, points().len());
    let (mut fresh, fid) = beam(ElementKind::P1);
    fresh.set_point_loads(fid, &tip_push(-2e-3)).unwrap();
    fresh.step(frame).unwrap();
    let want = map_on_cpu(&mut fresh, fid, points().len());
    for a in 0..3 {
        for (g, w) in again[a].iter().zip(&want[a]) {
            assert!(
                (g - w).abs() <= 1e-6 * want[2][2].abs().max(1e-9),
                "{g} vs {w}"
            );
        }
    }
}

#[test]
fn a_repeated_compliance_solve_starts_from_the_last_answer() {
    for element in [ElementKind::P1, ElementKind::P2] {
        // The default compliance tolerance (1e-4): the start's rounding
        // is far below it.
        let mut m = cantilever(
            2,
            0.0,
            FemParams {
                element,
                ..static_params(1e-12)
            },
        );
        let id = m.bind(RestPoints::Points(&points())).unwrap();
        let iterations = |m: &mut Fem| m.notes().unwrap()["solver_iterations"];
        let f = tip_push(1.0);
        let first = compliance(&mut m, id, &f);
        let after_first = iterations(&mut m);
        assert!(after_first > 0.0, "{element:?}: the first solve iterates");
        // The same load again, and a scaled one: both lie in the span of
        // the kept answers, so the Galerkin start is the answer.
        let again = compliance(&mut m, id, &f);
        let scaled = compliance(&mut m, id, &tip_push(-2.5));
        assert_eq!(
            iterations(&mut m),
            after_first,
            "{element:?}: a load in the kept span needs no iteration"
        );
        for ((a, b), c) in first.iter().zip(&again).zip(&scaled) {
            assert!((*a - *b).length() <= 1e-9 * a.length().max(1e-12));
            assert!((*c + 2.5 * *a).length() <= 1e-9 * a.length().max(1e-12));
        }
    }
}
