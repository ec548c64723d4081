//! Conflicting constraints (fixed vs rigid vs grab) are measured, reported
//! in the notes and explained; a pull that can be met reports none.

use crate::model::ChainMail;
use crate::params::InteractionSpec;
use crate::tests::{grab, params, volume, worst_violation};

/// A 16 × 8 × 8 block of soft tissue (constraint 0.3, 1 mm elements)
/// with a rigid bar along x (`i` in 3..13, `j`, `k` in 3..5); `fix_low`
/// fixes the box `x ≤ 5 mm` (else `x ≥ 10 mm`), holding part of the bar,
/// and the bar is grabbed at the other end and pulled by `pull` mm along
/// z, one frame. `fix = false` leaves the box out.
fn bar(fix_low: bool, fix: bool, pull: f64) -> ChainMail {
    let rigid = |i: usize, j: usize, k: usize| {
        (3..13).contains(&i) && (3..5).contains(&j) && (3..5).contains(&k)
    };
    let v = volume([16, 8, 8], |i, j, k| if rigid(i, j, k) { 200 } else { 100 });
    let mats = "{ name = \"soft\", range = [50, 150], constraint = 0.3, elastic = 0.8 },\n\
                { name = \"bone\", range = [150, 256], constraint = 0, rigid = true }";
    let mut m = ChainMail::new(v.view(), params("block = [4, 4, 4]", mats)).unwrap();
    let (lo, hi, at) = if fix_low {
        ([-1.0, -1.0, -1.0], [5.0, 8.0, 8.0], [11, 4, 4])
    } else {
        ([10.0, -1.0, -1.0], [16.0, 8.0, 8.0], [4, 4, 4])
    };
    if fix {
        m.interact(&InteractionSpec::Fix {
            min: Some(lo),
            max: Some(hi),
            material: None,
        })
        .unwrap();
    }
    grab(&mut m, at, [0.0, 0.0, pull]);
    m
}

fn note(m: &ChainMail, key: &str) -> f64 {
    *m.notes()
        .get(key)
        .unwrap_or_else(|| panic!("no note `{key}` in {:?}", m.notes()))
}

#[test]
fn a_rigid_piece_held_by_a_fixed_box_and_grabbed_reports_the_tear() {
    for fix_low in [true, false] {
        let mut m = bar(fix_low, true, 3.0);
        for _ in 0..20 {
            m.step();
        }
        // The bar's free part follows the grab rigidly and its fixed part
        // stays: the rigid link across the box face (constraint 0) is
        // stretched by the whole pull, 3 mm.
        let scan = worst_violation(&m);
        let reported = note(&m, "max_constraint_violation_mm");
        assert!(
            (scan - 3.0).abs() < 1e-4,
            "fix_low {fix_low}: the full scan finds {scan} mm"
        );
        assert!(
            (reported - scan as f64).abs() < 1e-4,
            "fix_low {fix_low}: reported {reported} mm, the full scan {scan} mm"
        );
        // 4 rigid links cross the box face; soft links there tear too.
        assert!(note(&m, "conflicting_constraints") >= 4.0);
        for kind in ["conflict_fixed", "conflict_rigid", "conflict_grab"] {
            assert_eq!(note(&m, kind), 1.0, "fix_low {fix_low}: {kind}");
        }
        assert_eq!(note(&m, "conflict_frame"), 1.0);
        let w = m.conflict_warning().expect("a warning");
        assert!(
            w.contains("3.000 mm") && w.contains("fixed vs grab vs rigid"),
            "{w}"
        );
        // The link named lies on the box face (x = 5 | 6 or 9 | 10 mm).
        let face = if fix_low { "[5.0, " } else { "[10.0, " };
        assert!(w.contains(face), "{w}");
    }
}

#[test]
fn a_pull_the_slack_can_take_reports_no_conflict() {
    for fix_low in [true, false] {
        // Without the box, and with the box but a pull the soft layers
        // around the bar's fixed end cannot feel: nothing is violated.
        for (fix, pull) in [(false, 3.0), (true, 0.0)] {
            let mut m = bar(fix_low, fix, pull);
            for _ in 0..20 {
                m.step();
            }
            assert!(worst_violation(&m) <= 1e-5);
            assert_eq!(note(&m, "max_constraint_violation_mm"), 0.0);
            assert_eq!(note(&m, "conflicting_constraints"), 0.0);
            assert_eq!(note(&m, "conflict_frames"), 0.0);
            assert!(m.conflict_warning().is_none());
        }
    }
}
