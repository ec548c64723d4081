//! `voxflex bench --fronts --quick` through the CLI: every front's CSV,
//! SVG and the summary are written, every error is finite, and the errors
//! fall with resolution where theory says they must — the corotational
//! FEM cantilever against Timoshenko beam theory and against its finest
//! solve, the large deflection against the elastica, the grab against the
//! fine FEM solve, P2 at least as close as P1 on the same proxy — that
//! each mesh model's ringed default is the configuration the plugin runs
//! by default, that ChainMail's cut at one element per voxel leaves every
//! voxel on its own piece's side and beats its down-sampled cuts against
//! the analytic answer, that trilinear resampling beats tetrahedral
//! against the f64 reference under every field, and that the two-material
//! grab's fine reference is converged, its coarse proxies mis-assign
//! voxels, and its errors grow with the voxels they mis-assign.

use std::collections::BTreeMap;
use voxflex_integration_tests::*;

/// A front's CSV as rows of column → value.
fn rows(dir: &std::path::Path, front: &str) -> Vec<BTreeMap<String, String>> {
    let text = std::fs::read_to_string(dir.join(format!("{front}.csv")))
        .unwrap_or_else(|e| panic!("{front}.csv: {e}"));
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    lines
        .map(|l| {
            let cells: Vec<&str> = l.split(',').collect();
            assert_eq!(cells.len(), header.len(), "{front}.csv row {l}");
            header
                .iter()
                .cloned()
                .zip(cells.iter().map(|c| c.to_string()))
                .collect()
        })
        .collect()
}

fn num(r: &BTreeMap<String, String>, k: &str) -> f64 {
    r[k].parse()
        .unwrap_or_else(|_| panic!("{k} = {:?} is not a number in {r:?}", r[k]))
}

/// The errors of `series`, ordered by the numeric column `by`, ascending.
fn series(rows: &[BTreeMap<String, String>], name: &str, by: &str, err: &str) -> Vec<(f64, f64)> {
    let mut v: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r["series"] == name)
        .map(|r| (num(r, by), num(r, err)))
        .collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    assert!(v.len() >= 2, "series {name}: {v:?}");
    v
}

fn falls(what: &str, v: &[(f64, f64)]) {
    for w in v.windows(2) {
        assert!(
            w[1].1 < w[0].1,
            "{what}: error {} at {} does not fall below {} at {} ({v:?})",
            w[1].1,
            w[1].0,
            w[0].1,
            w[0].0
        );
    }
}

#[test]
fn quick_fronts_are_written_finite_and_converge() {
    plugin_dir(&["corotational-fem", "mass-spring", "chainmail", "raycast"]);
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("fronts");
    let o = voxflex(
        &[
            "bench",
            "--fronts",
            "--quick",
            "--out",
            out.to_str().unwrap(),
        ],
        tmp.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let md = std::fs::read_to_string(out.join("front.md")).expect("front.md");
    for front in [
        "fem_cantilever",
        "fem_elastica",
        "grab",
        "two_material",
        "cut",
        "resample",
        "roi",
        "render",
    ] {
        let svg = std::fs::read_to_string(out.join(format!("{front}.svg"))).expect("svg");
        assert!(
            svg.starts_with("<svg") && svg.contains("run time, ms"),
            "{front}.svg"
        );
        assert!(
            md.contains(&format!("(`{front}`)")),
            "front.md lacks {front}"
        );
        let rows = rows(&out, front);
        assert!(rows.len() >= 4, "{front}: {} rows", rows.len());
        for r in &rows {
            let (e, t) = (num(r, "error"), num(r, "time_ms"));
            assert!(e.is_finite() && e >= 0.0 && t > 0.0, "{front}: {r:?}");
        }
    }

    // P1 cantilever at CG 1e-6: refining the proxy approaches beam theory
    // and the finest solve (linear tetrahedra lock; they converge from
    // the stiff side).
    let c = rows(&out, "fem_cantilever");
    falls(
        "cantilever vs Timoshenko",
        &series(&c, "P1 cg 1e-6", "cells_per_mm", "error"),
    );
    falls(
        "cantilever vs finest",
        &series(&c, "P1 cg 1e-6", "cells_per_mm", "error_vs_finest"),
    );
    for r in c.iter().filter(|r| r["series"] == "P1 cg 1e-6") {
        let u = num(r, "tip_u_per_p");
        assert!(u > 0.0 && u < 4.0306, "P1 is stiffer than the beam: {r:?}");
    }
    // Large deflection: halving the cell halves the distance to the
    // elastica, at every load.
    let e = rows(&out, "fem_elastica");
    for alpha in ["3", "10", "30"] {
        let mut v = series(&e, &format!("P1 PL²/EI = {alpha}"), "cell_mm", "error");
        v.reverse(); // coarse to fine
        let v: Vec<(f64, f64)> = v.into_iter().map(|(h, e)| (-h, e)).collect();
        falls(&format!("elastica at PL²/EI = {alpha}"), &v);
    }
    // The grab: the static FEM approaches the fine FEM solve.
    let g = rows(&out, "grab");
    let mut v = series(&g, "FEM static", "step", "error");
    v.reverse();
    falls("grab, FEM static", &v);
    // Quadratic tetrahedra hold the linear ones' displacements and more:
    // on the same proxy, P2 is at least as close to the fine solve as P1.
    let p1 = series(&g, "FEM static", "step", "error");
    let p2 = series(&g, "FEM static P2", "step", "error");
    let mut common = 0;
    for (step, e1) in &p1 {
        if let Some((_, e2)) = p2.iter().find(|(s, _)| s == step) {
            common += 1;
            assert!(e2 <= e1, "grab at step {step}: P2 {e2} vs P1 {e1}");
        }
    }
    assert!(common > 0, "no step with both P1 and P2: {p1:?} {p2:?}");
    // The ringed default of each mesh plugin is the configuration the
    // plugin runs with no key but its materials (the bench compares first
    // frames), measured once.
    for model in ["FEM", "mass-spring"] {
        let d: Vec<_> = g
            .iter()
            .filter(|r| r["series"].starts_with(model) && r["default"] == "true")
            .map(|r| format!("{} {}", r["series"], r["config"]))
            .collect();
        assert_eq!(d.len(), 1, "{model} defaults in the grab front: {d:?}");
    }
    // ChainMail's kinematic answer follows the grab through the beam: its
    // error stays below the grab's 2 mm (a torn beam moves only its face).
    for r in g.iter().filter(|r| r["series"].starts_with("ChainMail")) {
        assert!(num(r, "error") < 0.5, "ChainMail: {r:?}");
    }
    // Two materials: the two fine solves (P2 on the step-1 proxy, P1 on the
    // same body's half-voxel proxy) agree far closer than any mesh row
    // comes to them, so the reference is converged at the rows' scale;
    // every mesh proxy measured gives some voxels of the stiff inclusion
    // to the other material (its faces lie on no cell face); the FEM rows
    // that lose the most voxels are farther from the reference than those
    // that lose the fewest, whatever their element (material resolution
    // sets the error: the full front's P2 is no closer than P1 on the same
    // proxy); the finest P1 proxy is closer than the coarsest; and the
    // ringed defaults are the plugins' own.
    let t = rows(&out, "two_material");
    let mesh: Vec<_> = t
        .iter()
        .filter(|r| !r["series"].starts_with("ChainMail"))
        .collect();
    let closest = mesh
        .iter()
        .map(|r| num(r, "error"))
        .fold(f64::MAX, f64::min);
    for r in &t {
        assert!(
            num(r, "ref_gap_mm") < 0.2 * closest,
            "two materials: the fine solves differ by {} mm, the closest row is {closest} mm off",
            r["ref_gap_mm"]
        );
    }
    for r in &mesh {
        assert!(num(r, "voxels_lost") > 0.0, "two materials: {r:?}");
    }
    let fem: Vec<_> = mesh
        .iter()
        .filter(|r| r["series"].starts_with("FEM"))
        .collect();
    let lost =
        |f: fn(f64, f64) -> f64, init| fem.iter().map(|r| num(r, "voxels_lost")).fold(init, f);
    let (most, fewest) = (lost(f64::max, 0.0), lost(f64::min, f64::MAX));
    assert!(
        most > fewest,
        "two materials: every proxy loses {most} voxels"
    );
    let err_at = |n: f64| -> Vec<f64> {
        fem.iter()
            .filter(|r| num(r, "voxels_lost") == n)
            .map(|r| num(r, "error"))
            .collect()
    };
    let (far, near) = (err_at(most), err_at(fewest));
    let nearest_of_far = far.iter().copied().fold(f64::MAX, f64::min);
    let farthest_of_near = near.iter().copied().fold(0.0, f64::max);
    assert!(
        nearest_of_far > farthest_of_near,
        "two materials: FEM rows losing {most} voxels ({far:?}) vs {fewest} ({near:?})"
    );
    let p1 = series(&t, "FEM static", "step", "error");
    let (finest, coarsest) = (p1[0], p1[p1.len() - 1]);
    assert!(
        finest.1 < coarsest.1,
        "two materials, FEM static P1: step {} ({}) vs step {} ({})",
        finest.0,
        finest.1,
        coarsest.0,
        coarsest.1
    );
    for model in ["FEM", "mass-spring"] {
        let d: Vec<_> = t
            .iter()
            .filter(|r| r["series"].starts_with(model) && r["default"] == "true")
            .map(|r| format!("{} {}", r["series"], r["config"]))
            .collect();
        assert_eq!(
            d.len(),
            1,
            "{model} defaults in the two-material front: {d:?}"
        );
    }
    // The cut: ChainMail with one element per voxel cuts between two voxel
    // layers, so every voxel centre ends on its own piece's side; down-
    // sampled, the voxels between the element layers astride the plane
    // take a blend of both pieces' motion, and the error grows.
    let cut = rows(&out, "cut");
    let groups: std::collections::BTreeSet<&str> =
        cut.iter().map(|r| r["cut_x_mm"].as_str()).collect();
    assert!(groups.len() >= 2, "cut: plane positions {groups:?}");
    for g in groups {
        let rows: Vec<_> = cut.iter().filter(|r| r["cut_x_mm"] == g).cloned().collect();
        let chainmail = series(&rows, "ChainMail c = 0.3", "downsample", "error");
        let (one, coarser) = chainmail.split_first().unwrap();
        assert_eq!(one.0, 1.0, "{g}: {chainmail:?}");
        for r in rows.iter().filter(|r| r["series"].starts_with("ChainMail")) {
            if num(r, "downsample") == 1.0 {
                assert_eq!(
                    num(r, "blurred"),
                    0.0,
                    "{g}: ChainMail one element per voxel: {r:?}"
                );
            } else {
                assert!(
                    num(r, "blurred") > 0.0,
                    "{g}: ChainMail down-sampled: {r:?}"
                );
            }
        }
        for c in coarser {
            assert!(
                one.1 < c.1,
                "{g}: ChainMail at downsample 1 ({}) is not below downsample {} ({})",
                one.1,
                c.0,
                c.1
            );
        }
        // The mesh models' cut separates the pieces: away from the plane
        // both are at rigid rest; the voxel centres their carrying
        // tetrahedra put across the plane are bound to their own side
        // (`cut_voxels_rebound`), so none ends on the wrong piece, and
        // what the model says it left across (`cut_voxels_across`,
        // warned) is exactly what the analytic answer finds there.
        for r in rows
            .iter()
            .filter(|r| !r["series"].starts_with("ChainMail"))
        {
            assert!(num(r, "far_rms_mm") < 0.1, "{g}: {r:?}");
            assert_eq!(
                num(r, "cut_voxels_across"),
                num(r, "wrong_side"),
                "{g}: the model's own count of voxels cut onto the wrong piece: {r:?}"
            );
            assert_eq!(num(r, "wrong_side"), 0.0, "{g}: a voxel-sharp cut: {r:?}");
        }
        assert!(
            rows.iter()
                .filter(|r| !r["series"].starts_with("ChainMail"))
                .any(|r| num(r, "cut_voxels_rebound") > 0.0),
            "{g}: no mesh-model cut carried a voxel across: the checks above prove nothing"
        );
    }
    // Resampling: trilinear beats tetrahedral under every field and size.
    let rs = rows(&out, "resample");
    for field in ["affine", "twist", "bend"] {
        let tet = series(&rs, &format!("tetrahedral {field}"), "size", "error");
        let tri = series(&rs, &format!("trilinear {field}"), "size", "error");
        for (a, b) in tet.iter().zip(&tri) {
            assert!(
                b.1 < a.1,
                "{field} at {}³: trilinear {} vs tetrahedral {}",
                a.0,
                b.1,
                a.1
            );
        }
    }
    // ROI: 1 − Dice lies in [0, 1].
    for r in rows(&out, "roi") {
        let d = num(&r, "dice");
        assert!(
            (0.0..=1.0).contains(&d) && (num(&r, "error") - (1.0 - d)).abs() < 1e-3,
            "{r:?}"
        );
    }
    render_converges_and_filters_help(&out);
    combined_fronts_are_ratios_over_the_models_fronts(&out, &md);
}

/// The combined fronts: one per mesh model, over every front it appears
/// in; each row's time and error are geometric means of ratios to each
/// front's best (so ≥ 1), with a ratio pair from every front combined;
/// the configurations some front lacks are listed as left out.
fn combined_fronts_are_ratios_over_the_models_fronts(out: &std::path::Path, md: &str) {
    for (key, fronts) in [
        (
            "combined_fem",
            &[
                "fem_cantilever",
                "fem_elastica",
                "grab",
                "two_material",
                "cut",
            ][..],
        ),
        ("combined_mass_spring", &["grab", "two_material", "cut"][..]),
    ] {
        assert!(md.contains(&format!("(`{key}`)")), "front.md lacks {key}");
        let section = &md[md.find(&format!("(`{key}`)")).unwrap()..];
        assert!(
            section.contains(&format!("combined over {}", fronts.join(", "))),
            "{key}: {}",
            &section[..section.len().min(600)]
        );
        let svg = std::fs::read_to_string(out.join(format!("{key}.svg"))).expect("svg");
        assert!(svg.contains("time / front"), "{key}.svg");
        let rows = rows(out, key);
        assert!(!rows.is_empty(), "{key}: no configuration in every front");
        for r in &rows {
            let (e, t) = (num(r, "error"), num(r, "time_ms"));
            assert!(e >= 1.0 - 1e-9 && t >= 1.0 - 1e-9, "{key}: {r:?}");
            let by = &r["time_error_by_front"];
            for f in fronts {
                assert!(
                    by.contains(&format!("{f} ×")),
                    "{key}: {f} missing in {r:?}"
                );
            }
        }
    }
    // FEM P2 is not in the cut front: left out, and said so.
    assert!(
        md.contains("P2 step 8 (not in") || md.contains("P2 step 4 (not in"),
        "front.md does not list the P2 configurations left out"
    );
}

/// The render front: every error finite; for each option set the error
/// falls as the step falls; the best filters (tricubic + Sobel, what the
/// reference uses at a tiny step) are at least as close as central
/// differences + trilinear at every step; one ringed default.
fn render_converges_and_filters_help(out: &std::path::Path) {
    let r = rows(out, "render");
    assert_eq!(r.len(), 24, "6 option sets × 4 steps");
    for row in &r {
        let (e, m, t) = (num(row, "error"), num(row, "max_abs"), num(row, "time_ms"));
        assert!(
            e.is_finite() && e > 0.0 && m >= e && m <= 1.0 && t > 0.0,
            "{row:?}"
        );
    }
    let names: std::collections::BTreeSet<&str> = r.iter().map(|x| x["series"].as_str()).collect();
    for name in &names {
        falls(
            &format!("render {name}"),
            &series(&r, name, "step_voxels", "error")
                .into_iter()
                .rev()
                .map(|(s, e)| (-s, e))
                .collect::<Vec<_>>(),
        );
    }
    let plain = series(&r, "central trilinear", "step_voxels", "error");
    let best = series(&r, "tricubic sobel", "step_voxels", "error");
    for ((s, e0), (_, e1)) in plain.iter().zip(&best) {
        assert!(
            e1 <= e0,
            "step {s}: tricubic + sobel {e1} vs central + trilinear {e0}"
        );
    }
    let d: Vec<_> = r.iter().filter(|x| x["default"] == "true").collect();
    assert_eq!(d.len(), 1, "one ringed default: {d:?}");
}
