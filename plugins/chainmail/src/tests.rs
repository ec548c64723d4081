//! Model tests: each checks a property the papers claim, and can fail.

use crate::lattice::LINKS;
use crate::model::ChainMail;
use crate::params::{ChainMailParams, InteractionSpec};
use crate::relax::energy;
use proptest::prelude::*;
use std::collections::BinaryHeap;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::{Volume, VoxelData};
use voxflex_phantom::phantom;

/// A u8 volume of `dims` with 1 mm voxels, values from `f(i, j, k)`.
pub(crate) fn volume(dims: [usize; 3], f: impl Fn(usize, usize, usize) -> u8) -> Volume {
    let grid = Grid::new(dims, DVec3::ONE, DVec3::ZERO);
    let mut data = Vec::with_capacity(grid.len());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                data.push(f(i, j, k));
            }
        }
    }
    Volume {
        grid,
        data: VoxelData::U8(data),
    }
}

pub(crate) fn params(extra: &str, materials: &str) -> ChainMailParams {
    ChainMailParams::from_toml(&format!("{extra}\nmaterials = [{materials}]")).unwrap()
}

pub(crate) fn grab(m: &mut ChainMail, at: [usize; 3], by: [f64; 3]) {
    let p = m.lattice().world(at).to_array();
    m.interact(&InteractionSpec::Grab {
        point: p,
        by: Some(by),
        to: None,
        path: None,
        frames: 1,
    })
    .unwrap();
}

/// Largest violation of any link constraint (mm; ≤ 0 when all hold).
pub(crate) fn worst_violation(m: &ChainMail) -> f32 {
    let lat = m.lattice();
    let mut worst = f32::NEG_INFINITY;
    for n in 0..lat.len() {
        if !lat.present(n) {
            continue;
        }
        let c = lat.coords(n);
        for l in 0..LINKS.len() {
            if let Some(e) = lat.neighbour(n, c, l).filter(|&e| lat.present(e)) {
                let link = lat.link(n, e);
                let (un, ue) = (m.displacement(n), m.displacement(e));
                for a in 0..3 {
                    worst = worst.max((un[a] - ue[a]).abs() - link.d[a]);
                }
            }
        }
    }
    worst
}

/// The configuration every correct propagation reaches from rest after one
/// grab of element `g` by `by` (isotropic constraints): on each axis, every
/// element moves by `max(0, |by| − s)` towards `by`, where `s` is the least
/// total slack (sum of link constraints, mm) of a path from `g` — Dijkstra.
fn expected(m: &ChainMail, g: usize, by: [f64; 3]) -> Vec<[f64; 3]> {
    let lat = m.lattice();
    let mut dist = vec![f64::INFINITY; lat.len()];
    let mut heap = BinaryHeap::new();
    dist[g] = 0.0;
    heap.push((std::cmp::Reverse(0u64), g));
    // Slack sums are multiples of 1/64 mm here, so integer keys are exact.
    while let Some((std::cmp::Reverse(dq), n)) = heap.pop() {
        let d = dq as f64 / 4096.0;
        if d > dist[n] {
            continue;
        }
        let c = lat.coords(n);
        for l in 0..LINKS.len() {
            if let Some(e) = lat.neighbour(n, c, l).filter(|&e| lat.present(e)) {
                let nd = d + lat.link(n, e).d[0] as f64;
                if nd < dist[e] {
                    dist[e] = nd;
                    heap.push((std::cmp::Reverse((nd * 4096.0).round() as u64), e));
                }
            }
        }
    }
    dist.iter()
        .map(|&s| by.map(|b| b.signum() * (b.abs() - s).max(0.0)))
        .collect()
}

fn max_error(m: &ChainMail, want: &[[f64; 3]]) -> f64 {
    let lat = m.lattice();
    (0..lat.len())
        .filter(|&n| lat.present(n))
        .map(|n| {
            let u = m.displacement(n);
            (0..3)
                .map(|a| (u[a] as f64 - want[n][a]).abs())
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

#[test]
fn homogeneous_cube_parallel_equals_sequential() {
    // Odd and wide enough along x for the 8-slot windows of both colours.
    let v = volume([37, 20, 17], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.25 }";
    let by = [20.0, -18.0, 16.5];
    let mut results = vec![];
    for config in [
        "algorithm = \"sequential\"",
        "algorithm = \"parallel\"",
        "schedule = \"frontier\"",
    ] {
        let mut m = ChainMail::new(
            v.view(),
            params(&format!("{config}\nblock = [4, 4, 4]"), mats),
        )
        .unwrap();
        grab(&mut m, [0, 0, 0], by);
        let r = m.deform_to_rest(10_000, 0);
        assert!(m.at_rest() || r.relaxation_iterations == 0);
        // The pull reaches every element.
        let lat = m.lattice();
        let far = lat.linear([36, 19, 16]);
        assert!(m.displacement(far)[0] > 0.0, "{:?}", m.displacement(far));
        results.push(
            (0..lat.len())
                .map(|n| m.displacement(n))
                .collect::<Vec<_>>(),
        );
    }
    for (name, r) in [("blocks", &results[1]), ("frontier", &results[2])] {
        let worst = results[0]
            .iter()
            .zip(r)
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0f32, f32::max);
        // 1 mm voxels: 1e-5 voxel = 1e-5 mm.
        assert!(
            worst <= 1e-5,
            "parallel ({name}) and sequential differ by {worst} mm"
        );
    }
}

#[test]
fn a_grabbed_face_in_a_block_of_its_own_pulls_its_neighbours() {
    // 17 elements along the axis in blocks of 8: the face at index 16 is a
    // block one element thick, every element of it held. Before the grab
    // seeded the blocks across its borders, the parallel propagation never
    // left that block (the face moved alone and the links to it tore;
    // found by `voxflex bench --fronts`). The same along x and along z.
    let mats = "{ range = [0, 256], constraint = 0.3 }";
    for axis in [0usize, 2] {
        let (mut dims, mut block) = ([5usize; 3], [4usize; 3]);
        dims[axis] = 17;
        block[axis] = 8;
        let pull = 2 - axis; // z for the x face, x for the z face
        let v = volume(dims, |_, _, _| 1);
        let mut results = vec![];
        for config in ["algorithm = \"sequential\"", "algorithm = \"parallel\""] {
            let extra = format!("{config}\nblock = {block:?}");
            let mut m = ChainMail::new(v.view(), params(&extra, mats)).unwrap();
            let mut by = [0.0; 3];
            by[pull] = -2.0;
            for a in 0..5 {
                for b in 0..5 {
                    let mut at = [a; 3];
                    at[(axis + 1) % 3] = a;
                    at[(axis + 2) % 3] = b;
                    at[axis] = 16;
                    grab(&mut m, at, by);
                }
            }
            m.deform_to_rest(10_000, 0);
            let lat = m.lattice();
            let mut next = [2; 3];
            next[axis] = 15;
            // The face's neighbour follows within one link's slack.
            let u = m.displacement(lat.linear(next))[pull];
            assert!(
                (u + 1.7).abs() < 1e-5,
                "{config}, axis {axis}: the face's neighbour moved {u} mm, not −1.7"
            );
            results.push(
                (0..lat.len())
                    .map(|n| m.displacement(n))
                    .collect::<Vec<_>>(),
            );
        }
        let worst = results[0]
            .iter()
            .zip(&results[1])
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0f32, f32::max);
        assert!(
            worst <= 1e-5,
            "axis {axis}: parallel and sequential differ by {worst} mm"
        );
    }
}

#[test]
fn heterogeneous_ring_needs_timestamps() {
    // The ring of the heterogeneous paper's Fig. 5: a soft half and a hard
    // half. Constraints are multiples of 1/64 of a spacing so that link
    // times are exact.
    let v = phantom("rings", [50, 50, 50]).unwrap();
    let mats = "{ name = \"soft\", range = [50, 150], constraint = 0.25 },\n\
                { name = \"hard\", range = [150, 256], constraint = 0.0625 }";
    // Grab the hard half next to the interface (x = 0, y = 30 mm) and pull
    // along z, so the shortest path in links and the path of least slack
    // part ways.
    let point = [1.0, 30.0, 0.0];
    let by = [0.0, 0.0, 12.0];
    let mut errors = vec![];
    for config in [
        "algorithm = \"parallel\"",
        "algorithm = \"sequential\"",
        "schedule = \"frontier\"",
    ] {
        let mut m = ChainMail::new(
            v.view(),
            params(&format!("{config}\nblock = [8, 8, 8]"), mats),
        )
        .unwrap();
        m.interact(&InteractionSpec::Grab {
            point,
            by: Some(by),
            to: None,
            path: None,
            frames: 1,
        })
        .unwrap();
        m.deform_to_rest(100_000, 0);
        let g = m.lattice().nearest(DVec3::from_array(point)).unwrap();
        let want = expected(&m, g, by);
        errors.push((max_error(&m, &want), worst_violation(&m)));
    }
    let (par, seq) = (errors[0], errors[1]);
    for (name, p) in [("blocks", par), ("frontier", errors[2])] {
        assert!(
            p.0 <= 1e-4 && p.1 <= 1e-5,
            "timestamps ({name}): max error {} mm, worst violation {} mm",
            p.0,
            p.1
        );
    }
    assert!(
        seq.0 > 0.05,
        "plain breadth-first propagation reached the expected configuration (error {} mm); the test shows nothing",
        seq.0
    );
}

#[test]
fn rigid_material_moves_rigidly() {
    // A rigid 4³ block inside soft tissue.
    let inside = |i: usize, j: usize, k: usize| {
        (4..8).contains(&i) && (4..8).contains(&j) && (3..7).contains(&k)
    };
    let v = volume(
        [12, 12, 10],
        |i, j, k| if inside(i, j, k) { 200 } else { 100 },
    );
    let mats = "{ range = [50, 150], constraint = 0.3, elastic = 0.7 },\n\
                { range = [150, 256], constraint = 0.3, rigid = true }";
    let mut m = ChainMail::new(v.view(), params("block = [4, 4, 4]", mats)).unwrap();
    m.interact(&InteractionSpec::Fix {
        min: Some([0.0, 0.0, 0.0]),
        max: Some([11.0, 11.0, 0.0]),
        material: None,
    })
    .unwrap();
    grab(&mut m, [5, 5, 5], [2.0, 3.0, 4.0]);
    let r = m.deform_to_rest(10_000, 2_000);
    assert!(r.propagation_iterations > 0 && r.relaxation_iterations > 0);
    let lat = m.lattice();
    let block: Vec<usize> = (0..lat.len())
        .filter(|&n| {
            let c = lat.coords(n);
            inside(c[0], c[1], c[2])
        })
        .collect();
    let u0 = m.displacement(block[0]);
    assert!(u0[2] > 3.9, "the block moved with the grab: {u0:?}");
    for &n in &block {
        let u = m.displacement(n);
        for a in 0..3 {
            assert!((u[a] - u0[a]).abs() <= 1e-5, "element {n}: {u:?} vs {u0:?}");
        }
    }
    // The fixed floor did not move (the pull is larger than the soft
    // layer's slack, so those links cannot all hold: fixed and grabbed
    // elements win).
    assert_eq!(m.displacement(lat.linear([6, 6, 0])), [0.0; 3]);
}

#[test]
fn relaxation_never_raises_the_energy() {
    let v = volume([14, 12, 10], |i, _, _| if i < 7 { 100 } else { 200 });
    let mats = "{ range = [50, 150], constraint = 0.4, elastic = 1.0 },\n\
                { range = [150, 256], constraint = 0.1, elastic = 0.6 }";
    let mut m = ChainMail::new(v.view(), params("block = [4, 4, 4]", mats)).unwrap();
    m.interact(&InteractionSpec::Fix {
        min: Some([0.0, 0.0, 0.0]),
        max: Some([0.0, 11.0, 9.0]),
        material: None,
    })
    .unwrap();
    // Less than the slack to the fixed wall, so every constraint can hold.
    grab(&mut m, [13, 6, 5], [2.0, 1.5, -1.5]);
    m.deform_to_rest(10_000, 0);
    assert!(worst_violation(&m) <= 1e-5);
    let mut e = energy(m.lattice(), m.state());
    let e0 = e;
    for _ in 0..200 {
        m.settle(0, 1);
        let next = energy(m.lattice(), m.state());
        assert!(next <= e * (1.0 + 1e-6), "energy rose from {e} to {next}");
        assert!(worst_violation(&m) <= 1e-5, "relaxation broke a constraint");
        e = next;
    }
    assert!(
        e < 0.9 * e0,
        "relaxation did not lower the energy: {e0} → {e}"
    );
}

#[test]
fn two_grabs_in_one_frame_both_propagate() {
    let v = volume([30, 6, 6], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.2 }";
    let mut m = ChainMail::new(
        v.view(),
        params(
            "block = [8, 4, 4]\nrelaxation_iterations = 0\npropagation_iterations = 100",
            mats,
        ),
    )
    .unwrap();
    grab(&mut m, [0, 3, 3], [-2.0, 0.0, 0.0]);
    grab(&mut m, [29, 3, 3], [2.0, 0.0, 0.0]);
    assert!(m.step());
    let lat = m.lattice();
    let left = m.displacement(lat.linear([3, 3, 3]))[0];
    let right = m.displacement(lat.linear([26, 3, 3]))[0];
    // 2 mm pulls, 0.2 mm of slack per link: 1.4 mm three links in.
    assert!(
        (left + 1.4).abs() < 1e-5 && (right - 1.4).abs() < 1e-5,
        "left {left}, right {right}"
    );
    // The middle is out of both waves' reach (ten links each).
    assert_eq!(m.displacement(lat.linear([15, 3, 3])), [0.0; 3]);
}

#[test]
fn a_moving_grab_starts_a_new_wave_each_frame() {
    let v = volume([16, 4, 4], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.1 }";
    let mut m = ChainMail::new(
        v.view(),
        params(
            "relaxation_iterations = 0\npropagation_iterations = 50",
            mats,
        ),
    )
    .unwrap();
    let p = m.lattice().world([0, 2, 2]).to_array();
    m.interact(&InteractionSpec::Grab {
        point: p,
        by: Some([-4.0, 0.0, 0.0]),
        to: None,
        path: None,
        frames: 4,
    })
    .unwrap();
    let lat_far = m.lattice().linear([10, 2, 2]);
    let mut last = 0.0;
    for _ in 0..4 {
        assert!(m.step());
        let u = m.displacement(lat_far)[0];
        assert!(u <= last, "the pull only grows: {u} after {last}");
        last = u;
    }
    // 4 mm pull, 0.1 mm slack per link, 10 links: 3 mm.
    assert!((last + 3.0).abs() < 1e-5, "{last}");
    assert!(worst_violation(&m) <= 1e-5);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    /// After propagation converges, every link constraint holds, for random
    /// heterogeneous (isotropic) materials and random grabs. Two cases it
    /// found are kept in `proptest-regressions/tests.txt` (run first): a
    /// second grab on a block face whose neighbour block was never woken,
    /// and a second wave that left a free link violated (repair waves).
    /// Passed 100,000 cases with both fixes.
    #[test]
    fn propagation_restores_every_constraint(
        labels in proptest::collection::vec(0u8..3, 9 * 8 * 7),
        at in (0usize..9, 0usize..8, 0usize..7),
        by in prop::array::uniform3(-6.0f64..6.0),
        second in proptest::option::of(((0usize..9, 0usize..8, 0usize..7), prop::array::uniform3(-4.0f64..4.0))),
        frontier in any::<bool>(),
    ) {
        let dims = [9, 8, 7];
        let v = volume(dims, |i, j, k| 10 + 100 * labels[i + 9 * (j + 8 * k)]);
        let mats = "{ range = [0, 50], constraint = 0.05 },\n\
                    { range = [50, 150], constraint = 0.2 },\n\
                    { range = [150, 256], constraint = 0.5 }";
        let schedule = if frontier { "frontier" } else { "blocks" };
        let extra = format!("block = [4, 4, 4]\nschedule = \"{schedule}\"");
        let mut m = ChainMail::new(v.view(), params(&extra, mats)).unwrap();
        grab(&mut m, [at.0, at.1, at.2], by);
        if let Some((p, b)) = second {
            // A second deformation from the deformed state (a newer wave);
            // the first element is let go so no two held elements conflict.
            m.deform_to_rest(100_000, 0);
            m.interact(&InteractionSpec::Release).unwrap();
            grab(&mut m, [p.0, p.1, p.2], b);
        }
        m.deform_to_rest(100_000, 0);
        let w = worst_violation(&m);
        prop_assert!(w <= 1e-5, "worst violation {w} mm");
    }
}

#[test]
fn fixing_a_material_holds_every_element_of_it() {
    let v = volume([12, 6, 6], |i, _, _| if i < 6 { 200 } else { 100 });
    let mats = "{ name = \"bone\", range = [150, 256], constraint = 0, rigid = true },\n\
                { name = \"soft\", range = [50, 150], constraint = 0.5 }";
    let mut m = ChainMail::new(v.view(), params("", mats)).unwrap();
    m.interact(&InteractionSpec::from_toml("kind = \"fix\"\nmaterial = \"bone\"").unwrap())
        .unwrap();
    assert!(
        m.interact(&InteractionSpec::from_toml("kind = \"fix\"\nmaterial = \"bon\"").unwrap())
            .unwrap_err()
            .0
            .contains("`bon`")
    );
    grab(&mut m, [11, 3, 3], [4.0, 0.0, 0.0]);
    m.deform_to_rest(10_000, 100);
    let lat = m.lattice();
    for n in 0..lat.len() {
        if lat.coords(n)[0] < 6 {
            assert_eq!(m.displacement(n), [0.0; 3]);
        }
    }
    assert!(m.displacement(lat.linear([8, 3, 3]))[0] > 0.0);
}

#[test]
fn a_cut_stops_propagation_and_a_partial_cut_is_gone_around() {
    let v = volume([20, 8, 8], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.1 }";
    let build = || ChainMail::new(v.view(), params("relaxation_iterations = 0", mats)).unwrap();
    // A plane between x = 9 and x = 10 (element centres at integer mm).
    let through =
        "kind = \"cut\"\npolygon = [[9.5, -1, -1], [9.5, 9, -1], [9.5, 9, 9], [9.5, -1, 9]]";
    // The same plane, but only for y ≥ 3: links below stay.
    let partial =
        "kind = \"cut\"\npolygon = [[9.5, 3, -1], [9.5, 9, -1], [9.5, 9, 9], [9.5, 3, 9]]";
    let far = |m: &ChainMail| m.displacement(m.lattice().linear([5, 7, 4]))[0];
    let pulled = |cut: Option<&str>| {
        let mut m = build();
        if let Some(c) = cut {
            m.interact(&InteractionSpec::from_toml(c).unwrap()).unwrap();
        }
        grab(&mut m, [19, 7, 4], [4.0, 0.0, 0.0]);
        m.deform_to_rest(10_000, 0);
        assert!(m.displacement(m.lattice().linear([15, 7, 4]))[0] > 0.0);
        far(&m)
    };
    let (uncut, cut, around) = (pulled(None), pulled(Some(through)), pulled(Some(partial)));
    assert!(uncut > 2.0, "without a cut the far side follows: {uncut}");
    assert_eq!(cut, 0.0, "a cut through the bar leaves the far side still");
    assert!(
        around > 0.0 && around < uncut - 0.3,
        "a partial cut is gone around (a longer path, less pull): {around} vs {uncut}"
    );
}

#[test]
fn carving_removes_elements_from_the_model() {
    let v = volume([10, 10, 10], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.1 }";
    let mut m = ChainMail::new(v.view(), params("", mats)).unwrap();
    let before = m.lattice().element_count();
    m.interact(
        &InteractionSpec::from_toml("kind = \"carve\"\ncentre = [5, 5, 5]\nradius = 2.5").unwrap(),
    )
    .unwrap();
    let lat = m.lattice();
    assert!(!lat.present(lat.linear([5, 5, 5])));
    assert!(lat.present(lat.linear([5, 5, 8])));
    // 81 lattice points lie within 2.5 of a lattice point.
    assert_eq!(before - lat.element_count(), 81);
    assert!(InteractionSpec::from_toml("kind = \"carve\"\ncentre = [5, 5, 5]").is_err());
}

/// Before `init`, `interact` is a dry run (what `voxflex validate` uses):
/// a bad interaction is refused with the parser's message, a good one is
/// accepted, and nothing is built.
#[test]
fn interact_before_init_only_validates() {
    use voxflex_core::deformation::DeformationModel;
    let mut p =
        crate::ChainMailPlugin::new(params("", "{ range = [0, 256], constraint = 0.1 }"), None);
    let e = p
        .interact("kind = \"grab\"\npont = [0, 0, 0]\nby = [1, 0, 0]")
        .unwrap_err()
        .0;
    assert!(e.contains("pont"), "{e}");
    let e = p
        .interact("kind = \"cut\"\npolygon = [[0, 0, 0], [1, 1, 1], [2, 2, 2]]")
        .unwrap_err()
        .0;
    assert!(e.contains("spans no area"), "{e}");
    p.interact("kind = \"grab\"\npoint = [0, 0, 0]\nby = [1, 0, 0]")
        .unwrap();
    assert!(p.model().is_none(), "nothing built, nothing applied");
}

/// As the mesh models do: a carve of every element is refused (and leaves
/// the model whole), one that removes nothing warns and changes nothing.
#[test]
fn carving_every_element_is_refused_like_the_mesh_models() {
    let v = volume([6, 6, 6], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.1 }";
    let mut m = ChainMail::new(v.view(), params("", mats)).unwrap();
    let before = m.lattice().element_count();
    let all = InteractionSpec::from_toml("kind = \"carve\"\nmin = [-1, -1, -1]\nmax = [9, 9, 9]")
        .unwrap();
    let e = m.interact(&all).unwrap_err().0;
    assert!(
        e.contains("chainmail carve") && e.contains("every element"),
        "{e}"
    );
    assert_eq!(m.lattice().element_count(), before, "nothing removed");
    let none =
        InteractionSpec::from_toml("kind = \"carve\"\ncentre = [50, 50, 50]\nradius = 1").unwrap();
    m.interact(&none).unwrap();
    assert_eq!(m.lattice().element_count(), before);
}

/// A grab point far outside the body still takes the nearest element, but
/// is counted (with its distance) in the notes; one inside is not.
#[test]
fn a_grab_far_from_the_body_is_reported_in_the_notes() {
    let v = volume([6, 6, 6], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.1 }";
    let mut m = ChainMail::new(v.view(), params("", mats)).unwrap();
    grab(&mut m, [2, 2, 2], [0.5, 0.0, 0.0]);
    assert!(!m.notes().contains_key("grabs_far_from_body"));
    m.interact(
        &InteractionSpec::from_toml("kind = \"grab\"\npoint = [105, 2, 2]\nby = [1, 0, 0]")
            .unwrap(),
    )
    .unwrap();
    let notes = m.notes();
    assert_eq!(notes["grabs_far_from_body"], 1.0);
    // The nearest element is (5, 2, 2): 100 mm away.
    assert!((notes["grab_far_max_mm"] - 100.0).abs() < 1e-9, "{notes:?}");
}

/// Regression (`voxflex bench --stress`, seed 13, chainmail scene 101): with
/// the frontier schedule, a carve that removed elements still on the
/// work-list made the next iteration look up the link of an absent element
/// (index out of bounds, a panic at the plugin boundary).
#[test]
fn carving_elements_on_the_frontier_work_list_is_safe() {
    for schedule in ["frontier", "blocks"] {
        let v = volume([12, 6, 6], |_, _, _| 1);
        let mats = "{ range = [0, 256], constraint = 0.2, elastic = 0.3 }";
        let extra = format!(
            "schedule = \"{schedule}\"\npropagation_iterations = 1\nrelaxation_iterations = 1"
        );
        let mut m = ChainMail::new(v.view(), params(&extra, mats)).unwrap();
        grab(&mut m, [0, 3, 3], [20.0, 0.0, 0.0]);
        assert!(m.step(), "{schedule}");
        let before = m.lattice().element_count();
        // The wave has left the grab by one link: carve where it runs
        // (elements whose current position is in the ball).
        m.interact(
            &InteractionSpec::from_toml("kind = \"carve\"\ncentre = [1, 3, 3]\nradius = 1.5")
                .unwrap(),
        )
        .unwrap();
        for _ in 0..20 {
            m.step();
        }
        assert!(
            m.lattice().element_count() < before,
            "{schedule}: nothing carved"
        );
        for n in 0..v.grid.len() {
            let u = m.displacement(n);
            assert!(u.iter().all(|c| c.is_finite()), "{schedule}: {u:?}");
        }
    }
}

#[test]
fn cuts_and_carves_of_a_down_sampled_model_reach_the_sampling_mesh() {
    let v = volume([21, 21, 21], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.1 }";
    let mut m = ChainMail::new(v.view(), params("downsample = 2", mats)).unwrap();
    assert_eq!(m.lattice().dims, [11, 11, 11]);
    let cells = 20 * 20 * 20;
    let mut bits = vec![0u8; cells];
    assert!(!m.removed_tetrahedra(&mut []));
    // A cut across the plane x = 9.5 mm, between source voxels 9 and 10
    // (elements 4 and 5 sit at voxels 8 and 10).
    m.interact(
        &InteractionSpec::from_toml(
            "kind = \"cut\"\npolygon = [[9.5, -1, -1], [9.5, 21, -1], [9.5, 21, 21], [9.5, -1, 21]]",
        )
        .unwrap(),
    )
    .unwrap();
    assert!(m.removed_tetrahedra(&mut []));
    assert!(m.removed_tetrahedra(&mut bits));
    let marked: Vec<usize> = (0..cells).filter(|&c| bits[c] != 0).collect();
    // Every marked cell touches the edge from voxel 9 to 10 along x, and
    // every row of cells across the plane has one.
    assert!(marked.iter().all(|&c| c % 20 == 9));
    assert_eq!(marked.len(), 20 * 20);
    // The notes count the removed tetrahedra and say the down-sampling.
    let notes = m.notes();
    let removed: u32 = bits.iter().map(|b| b.count_ones()).sum();
    assert_eq!(notes["removed_tetrahedra"], removed as f64, "{notes:?}");
    assert_eq!(notes["downsample"], 2.0);
    // Carving a ball removes the tetrahedra around the voxels inside it.
    let mut m = ChainMail::new(v.view(), params("downsample = 2", mats)).unwrap();
    m.interact(
        &InteractionSpec::from_toml("kind = \"carve\"\ncentre = [15, 15, 15]\nradius = 1.5")
            .unwrap(),
    )
    .unwrap();
    let mut bits = vec![0u8; cells];
    assert!(m.removed_tetrahedra(&mut bits));
    let centre = 15 + 20 * (15 + 20 * 15);
    assert_eq!(bits[centre], 0b1_1111);
    assert_eq!(bits[0], 0);
}

#[test]
fn memory_per_element_is_within_the_budget() {
    // Counted from the arrays: 2 × (3 displacements + key) × 4 B, plus the
    // material, cut-link and interior bytes; the budget is 40 B.
    let v = volume([16, 12, 10], |_, _, _| 100);
    let mats = "{ range = [50, 150], constraint = 0.3 }";
    let m = ChainMail::new(v.view(), params("block = [4, 4, 4]", mats)).unwrap();
    let b = m.bytes_per_element();
    assert!((35.0..=40.0).contains(&b), "{b} bytes per element");
}

/// The block schedule's propagation (one copy, moves written after each
/// scan, vector windows that skip elements no arrival beats) against the
/// frontier schedule's (two copies, element by element): the same keys and
/// displacements, bit for bit, after every iteration — through two
/// materials, holes, a cut and a fixed box, pulled both ways along x.
#[test]
fn block_propagation_matches_the_element_frontier_iteration_by_iteration() {
    let v = volume([37, 21, 17], |i, j, k| {
        let r2 = (i as i64 - 18).pow(2) + (j as i64 - 10).pow(2) + (k as i64 - 8).pow(2);
        match (r2, (i * 7 + j * 3 + k) % 89) {
            (_, 0) => 0,
            (r2, _) if r2 < 30 => 200,
            _ => 100,
        }
    });
    let mats = "{ range = [50, 150], constraint = 0.2, elastic = 0.7 }, \
                { range = [150, 256], constraint = [0.05, 0.1, 0.02], elastic = 1.0 }";
    for (at, by) in [
        ([3, 15, 9], [-6.0, 5.0, 4.0]),
        ([33, 15, 9], [6.0, 5.0, 4.0]),
    ] {
        let make = |schedule: &str| {
            let extra = format!("schedule = \"{schedule}\"\nblock = [8, 4, 4]");
            let mut m = ChainMail::new(v.view(), params(&extra, mats)).unwrap();
            for spec in [
                "kind = \"fix\"\nmin = [16, 0, 0]\nmax = [20, 4, 16]",
                "kind = \"cut\"\npolygon = [[12.5, 8, -1], [12.5, 21, -1], [12.5, 21, 17], [12.5, 8, 17]]",
            ] {
                m.interact(&InteractionSpec::from_toml(spec).unwrap())
                    .unwrap();
            }
            grab(&mut m, at, by);
            m.start_deformation();
            m
        };
        let (mut blocks, mut frontier) = (make("blocks"), make("frontier"));
        let mut iterations = 0;
        loop {
            let (a, b) = (blocks.propagate(1), frontier.propagate(1));
            assert_eq!(
                a, b,
                "pull at {at:?}, iteration {iterations}: one stopped first"
            );
            if a == 0 {
                break;
            }
            iterations += 1;
            let (sa, sb) = (blocks.state(), frontier.state());
            for n in 0..blocks.lattice().len() {
                let (ua, ub) = (sa.get(sa.cur, n), sb.get(sb.cur, n));
                assert!(
                    ua.map(f32::to_bits) == ub.map(f32::to_bits)
                        && sa.key(sa.cur, n) == sb.key(sb.cur, n),
                    "pull at {at:?}, iteration {iterations}, element {:?}: {ua:?} vs {ub:?}",
                    blocks.lattice().coords(n)
                );
            }
        }
        assert!(iterations > 10, "pull at {at:?}: {iterations} iterations");
        assert!(blocks.counts().updates > 1000);
    }
}

/// The default relaxation (automatic over-relaxation) lowers the energy
/// of eq. (7) as far as the papers' plain relaxation in a third of the
/// sweeps — the papers' test at 32³, its corner pulled far enough to move
/// every element, and the opposite corner pulled the opposite way (on an
/// even lattice mirroring swaps the red and black elements).
#[test]
fn the_default_relaxation_reaches_the_plain_energy_in_a_third_of_the_sweeps() {
    let n = 32;
    let v = volume([n; 3], |_, _, _| 1);
    let mats = "{ range = [0, 256], constraint = 0.1 }";
    for mirrored in [false, true] {
        let (at, sign) = if mirrored {
            ([n - 1; 3], 1.0)
        } else {
            ([0; 3], -1.0)
        };
        let pull = sign * 0.1 * (3 * n) as f64 * 1.5;
        let relaxed = |relaxation: &str, sweeps: u64| {
            let mut m = ChainMail::new(v.view(), params(relaxation, mats)).unwrap();
            grab(&mut m, at, [pull; 3]);
            m.start_deformation();
            assert!(m.propagate(u64::MAX) > 0);
            assert_eq!(m.relax(sweeps), sweeps, "at rest too early");
            energy(m.lattice(), m.state())
        };
        let plain = relaxed("over_relaxation = 1.0", 150);
        let default = relaxed("", 50);
        assert!(
            default <= plain,
            "mirrored {mirrored}: default after 50 sweeps {default:.4e}, plain after 150 {plain:.4e}"
        );
    }
}
