//! Actuators through the real path: the `cavity` and `cable` plugins
//! loaded from their `.so`, acting on `corotational-fem` loaded from its
//! own, driven by scenes run by the pipeline (issue 16).
//!
//! The finger is the built-in `phantom:finger` (80 × 16 × 16 mm, cavity
//! toward +z, clamped at x = −40), silicone of E = 50 kPa, ν = 0.3, on a
//! 2 mm proxy; its tip is the effector point `[39, 0, 0]`.

use std::path::{Path, PathBuf};
use voxflex_integration_tests::plugin_dir;
use voxflex_runtime::actuation::ActuationReport;
use voxflex_runtime::bench::lame::{LameSphere, run_lame};
use voxflex_runtime::pipeline::{RunOptions, run_scene};
use voxflex_runtime::scene::Scene;

const TIP: [f64; 3] = [39.0, 0.0, 0.0];

fn plugins() -> PathBuf {
    plugin_dir(&["corotational-fem", "mass-spring", "cavity", "cable"])
}

/// The finger scene: `source` (`phantom:finger` or a file), `model` and
/// its solver keys, then `tables` (actuators, effectors).
fn finger_scene(source: &str, model: &str, frames: u64, tables: &str) -> String {
    format!(
        r#"[scene]
frames = {frames}
backend = "cpu"
plugin_dirs = [{dir:?}]

[volume]
source = {source:?}
{dims}

[model]
plugin = "{model}"
[model.params]
proxy = {{ kind = "uniform", step = 2 }}
materials = [{{ range = [0.5, 1.5], youngs_modulus = 50e3, poisson_ratio = 0.3 }}]
{solver}

[[interaction]]
frame = 0
kind = "fix"
min = [-48, -13, -13]
max = [-37, 13, 13]

{tables}
"#,
        dir = plugins().display().to_string(),
        dims = if source.starts_with("phantom:") {
            "dims = [96, 24, 24]"
        } else {
            ""
        },
        solver = if model == "corotational-fem" {
            "solver = \"static\""
        } else {
            ""
        },
    )
}

/// Runs scene text in `work`; the actuation report, or the run's error.
fn run(text: &str, work: &Path, name: &str) -> Result<ActuationReport, String> {
    let path = work.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    let scene = Scene::parse(text, &path).map_err(|e| e.to_string())?;
    let m = run_scene(
        &scene,
        RunOptions {
            out_dir: Some(work.join(name)),
            force: true,
            progress: None,
        },
    )
    .map_err(|e| e.to_string())?;
    m.actuation.ok_or_else(|| "no actuation report".into())
}

/// The finger and its mirror image in z written as NIfTI files into
/// `work`. 25 voxels and 12 proxy cells across z: the lattice, the proxy
/// and its alternating five-tetrahedra split are their own mirror images,
/// so only the physics is mirrored (the cavity toward −z instead of +z).
fn finger_and_mirror(work: &Path) -> [PathBuf; 2] {
    let phantom = voxflex_phantom::phantom("finger", [96, 24, 25]).unwrap();
    let mut mirrored = phantom.clone();
    let [nx, ny, nz] = phantom.grid.dims;
    let src = phantom.data.as_slice().to_f32_vec();
    let flipped: Vec<u8> = (0..src.len())
        .map(|l| {
            let (i, j, k) = (l % nx, (l / nx) % ny, l / (nx * ny));
            src[i + nx * (j + ny * (nz - 1 - k))] as u8
        })
        .collect();
    mirrored.data = voxflex_core::volume::VoxelData::U8(flipped);
    [("finger", &phantom), ("mirrored", &mirrored)].map(|(n, v)| {
        let p = work.join(format!("{n}.nii"));
        if !p.exists() {
            voxflex_io::nifti::write_nifti(&p, v.view()).unwrap();
        }
        p
    })
}

/// Runs the finger scene (`phantom:finger`, corotational FEM) for
/// `frames` frames with `tables` in `work`.
fn finger(frames: u64, tables: &str, work: &Path, name: &str) -> Result<ActuationReport, String> {
    run(
        &finger_scene("phantom:finger", "corotational-fem", frames, tables),
        work,
        name,
    )
}

fn cavity(params: &str) -> String {
    format!(
        "[[actuator]]\nplugin = \"cavity\"\ncavity = {{ label = 2 }}\n[actuator.params]\n{params}\n"
    )
}

fn tip(target: [f64; 3]) -> String {
    format!("[[effector]]\npoint = {TIP:?}\ntarget = {target:?}\n")
}

/// The tip's position after the run, mm.
fn tip_after(r: &ActuationReport) -> [f64; 3] {
    r.effectors[0].position_mm
}

/// A pressurised thick-walled sphere against Lamé's volume growth at two
/// mesh levels: both within 1 %, the finer closer.
#[test]
fn a_pressurised_thick_sphere_grows_as_lame_says() {
    let work = tempfile::tempdir().unwrap();
    let sphere = LameSphere::default();
    let dirs = vec![plugins()];
    let coarse = run_lame(&sphere, 2.0, 1, &dirs, work.path()).unwrap();
    let fine = run_lame(&sphere, 1.0, 1, &dirs, work.path()).unwrap();
    for r in [&coarse, &fine] {
        eprintln!(
            "Lamé: voxel {} mm, {} nodes: ΔV {:.3} mm³ vs {:.3} ({:+.2} %), {:.2} s",
            r.voxel_mm,
            r.nodes,
            r.volume_growth,
            r.analytic,
            100.0 * r.relative_error(),
            r.seconds
        );
        assert!(r.relative_error().abs() < 0.01, "{r:?}");
    }
    assert!(
        fine.relative_error().abs() < coarse.relative_error().abs(),
        "the finer mesh is closer: {fine:?} vs {coarse:?}"
    );
}

/// Inflating bends the finger toward its solid side (−z); the finger
/// mirrored in z (its cavity toward −z) bends the other way.
///
/// Not as far: a volume proxy's cell owns the voxels above its lower
/// corner plane (`voxflex_mesh::proxy`), so the hole a cavity leaves in
/// the proxy sits half a voxel low on either side and the mirrored
/// finger's wall is a voxel thinner (2 mm instead of 3 on its 2 mm
/// cells): measured 2.53 mm against 1.09 mm at 4 kPa (settled). The compliance
/// itself mirrors exactly (`corotational-fem`'s actuation tests).
#[test]
fn pressure_bends_the_finger_away_from_its_cavity_and_the_mirror_the_other_way() {
    let work = tempfile::tempdir().unwrap();
    let files = finger_and_mirror(work.path());
    let tables = format!(
        "{}{}",
        cavity("pressure_pa = [[0, 0], [4, 4000]]"),
        tip(TIP)
    );
    let [down, up] = [0, 1].map(|n| {
        let text = finger_scene(
            &files[n].display().to_string(),
            "corotational-fem",
            5,
            &tables,
        );
        tip_after(&run(&text, work.path(), &format!("f{n}")).unwrap())
    });
    eprintln!("tip at 4 kPa: {down:?}; mirrored: {up:?}");
    assert!(down[2] < -0.5, "the finger bends toward -z: {down:?}");
    assert!(up[2] > 0.3, "the mirror bends toward +z: {up:?}");
    let ratio = -down[2] / up[2];
    assert!(
        (1.0..3.0).contains(&ratio),
        "the mirror bends the other way, less by the proxy's thinner wall: {down:?} vs {up:?}"
    );
}

/// Inverse control to a point the finger reached under a known pressure
/// gets within 1 % of the finger's length (0.8 mm).
#[test]
fn an_inverse_finger_reaches_a_reachable_target_within_one_percent_of_its_length() {
    let work = tempfile::tempdir().unwrap();
    let direct = format!(
        "{}{}",
        cavity("pressure_pa = [[0, 0], [4, 3000]]"),
        tip(TIP)
    );
    let reached = tip_after(&finger(5, &direct, work.path(), "d").unwrap());
    // Every frame solves its responses; then every fourth (the secant
    // update corrects the reused ones in between): both reach it.
    let mut solves = Vec::new();
    for every in [1, 4] {
        let inverse = format!(
            "{}{}[actuation]\nresponse_refresh_frames = {every}\n",
            cavity("max_pressure_pa = 30000"),
            tip(reached)
        );
        let r = finger(15, &inverse, work.path(), &format!("i{every}")).unwrap();
        let d = r.effectors[0].distance_mm.last().copied().unwrap();
        eprintln!(
            "reachable target {reached:?}, responses every {every} frames: distance per frame \
             {:?}, pressure {:?}, {} compliance solves, {} reused",
            r.effectors[0].distance_mm,
            r.actuators[0].effort,
            r.compliance_solves,
            r.responses_reused
        );
        assert!(d < 0.8, "{d} mm from the target");
        assert_eq!(r.qp_failures, 0);
        solves.push((r.compliance_solves, r.responses_reused));
    }
    assert_eq!(solves[0].1, 0);
    assert!(
        solves[1].1 > 0 && solves[1].0 < solves[0].0,
        "reusing responses saves solves: {solves:?}"
    );
    let bad = format!(
        "{}{}[actuation]\nresponse_refresh_frames = 0\n",
        cavity("max_pressure_pa = 30000"),
        tip(reached)
    );
    let e = finger(1, &bad, work.path(), "bad").unwrap_err();
    assert!(e.contains("response_refresh_frames"), "{e}");
}

/// An unreachable target ends at the closest configuration the actuator
/// can give: no farther than the nearest point of a brute-force sweep of
/// the pressure (0 … 3 kPa, ramped over 30 frames and held for 10 so
/// the follower load settles).
#[test]
fn an_unreachable_target_ends_at_the_closest_configuration_of_a_pressure_sweep() {
    let work = tempfile::tempdir().unwrap();
    let target = [30.0, 0.0, -20.0];
    let sweep = format!(
        "{}{}",
        cavity("pressure_pa = [[0, 0], [30, 3000]]"),
        tip(target)
    );
    let s = finger(40, &sweep, work.path(), "s").unwrap();
    let closest = s.effectors[0]
        .distance_mm
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let inverse = format!("{}{}", cavity("max_pressure_pa = 3000"), tip(target));
    let r = finger(40, &inverse, work.path(), "u").unwrap();
    let d = r.effectors[0].distance_mm.last().copied().unwrap();
    eprintln!(
        "unreachable target: inverse ends {d} mm away, the sweep's closest {closest} mm; \
         inverse distances {:?}, pressures {:?}; trust shrinks {}, secant updates {}",
        r.effectors[0].distance_mm, r.actuators[0].effort, r.trust_shrinks, r.secant_updates
    );
    assert!(closest > 5.0, "the target must be unreachable: {closest}");
    assert!(d <= closest + 0.05, "inverse {d} mm vs sweep {closest} mm");
}

/// Water's weight pulls the hydraulic finger down: at the same pressure
/// its tip ends lower than the pneumatic one's, and the fluid weighs
/// ρ g V on the cavity.
#[test]
fn the_hydraulic_finger_carries_its_waters_weight() {
    let work = tempfile::tempdir().unwrap();
    let tips = ["\"air\"", "\"water\""].map(|fluid| {
        let tables = format!(
            "{}{}",
            cavity(&format!(
                "fluid = {fluid}\npressure_pa = [[0, 0], [4, 2000]]"
            )),
            tip(TIP)
        );
        let r = finger(5, &tables, work.path(), fluid.trim_matches('"')).unwrap();
        (tip_after(&r), r.actuators[0].notes.clone())
    });
    let (air, water) = (&tips[0], &tips[1]);
    eprintln!("tip, air {:?}; water {:?}", air.0, water.0);
    assert!(water.0[2] < air.0[2] - 0.5, "water's weight lowers the tip");
    let weight = water.1["fluid_weight_uN"];
    let volume = water.1["volume_mm3"];
    assert!(
        (weight - 1000.0 * 9.81 * volume * 1e-3).abs() < 0.01 * weight,
        "weight {weight} µN for {volume} mm³"
    );
    assert_eq!(air.1["fluid_weight_uN"], 0.0);
}

/// The hydraulic finger with `backend = "gpu"` (lavapipe in CI): the
/// cavity plugin weighs its water with the WGSL kernels on the host's
/// device, and the run ends where the CPU run ends — the same weight, the
/// same tip (the model's own GPU path rounds in f32, so within 1e-3 mm).
#[test]
fn the_hydraulic_finger_weighs_its_water_on_the_gpu_as_on_the_cpu() {
    if voxflex_runtime::gpu_context::testing::test_gpu().is_none() {
        return;
    }
    let work = tempfile::tempdir().unwrap();
    let tables = format!(
        "{}{}",
        cavity("fluid = \"water\"\npressure_pa = [[0, 0], [2, 2000]]"),
        tip(TIP)
    );
    // a 4 mm proxy: the model's GPU solve on a software adapter is slow
    let scene = finger_scene("phantom:finger", "corotational-fem", 3, &tables)
        .replace("step = 2", "step = 4");
    let [cpu, gpu] = ["cpu", "gpu"].map(|backend| {
        let text = scene.replace("backend = \"cpu\"", &format!("backend = {backend:?}"));
        run(&text, work.path(), backend).unwrap()
    });
    let (c, g) = (&cpu.actuators[0].notes, &gpu.actuators[0].notes);
    assert_eq!((c["weighed_on_gpu"], g["weighed_on_gpu"]), (0.0, 1.0));
    let (wc, wg) = (c["fluid_weight_uN"], g["fluid_weight_uN"]);
    assert!(
        wc > 0.0 && (wc - wg).abs() < 1e-4 * wc,
        "weight {wc} (CPU) vs {wg} µN (GPU)"
    );
    let (tc, tg) = (tip_after(&cpu), tip_after(&gpu));
    let gap = (0..3).map(|i| (tc[i] - tg[i]).abs()).fold(0.0, f64::max);
    assert!(gap < 1e-3, "tip {tc:?} (CPU) vs {tg:?} (GPU)");
}

/// A cable along the finger's top pulled through a point at its base
/// bends it toward +z.
#[test]
fn a_cable_along_the_top_bends_the_finger_up() {
    let work = tempfile::tempdir().unwrap();
    let points: Vec<[f64; 3]> = (0..8)
        .map(|i| [-30.0 + 10.0 * i as f64, 0.0, 6.5])
        .collect();
    let tables = format!(
        "[[actuator]]\nplugin = \"cable\"\npoints = {points:?}\n[actuator.params]\n\
         pull_point_mm = [-45, 0, 6.5]\ntension_uN = [[0, 0], [4, 20000]]\n{}",
        tip(TIP)
    );
    let r = finger(5, &tables, work.path(), "c").unwrap();
    let t = tip_after(&r);
    eprintln!("cable: tip {t:?}, shortening {:?}", r.actuators[0].measure);
    assert!(t[2] > 0.5, "{t:?}");
    assert!(r.actuators[0].measure.last().unwrap() > &0.0);
}

/// A model without a compliance solve (mass-spring) takes a scripted
/// pressure, but inverse control on it is refused, by name, before the
/// first frame; a cavity label no voxel carries is refused naming it.
#[test]
fn inverse_control_without_a_compliance_and_a_missing_cavity_label_are_refused_by_name() {
    let work = tempfile::tempdir().unwrap();
    let direct = run(
        &finger_scene(
            "phantom:finger",
            "mass-spring",
            2,
            &cavity("pressure_pa = [[0, 1000]]"),
        ),
        work.path(),
        "md",
    )
    .unwrap();
    assert!(direct.actuators[0].measure[1] > 0.0, "{direct:?}");
    let tables = format!(
        "{}{}",
        cavity("max_pressure_pa = 5000"),
        tip([39.0, 0.0, -2.0])
    );
    let e = run(
        &finger_scene("phantom:finger", "mass-spring", 1, &tables),
        work.path(),
        "m",
    )
    .unwrap_err();
    assert!(e.contains("mass-spring: no compliance solve"), "{e}");
    let tables = "[[actuator]]\nplugin = \"cavity\"\ncavity = { label = 7 }\n";
    let e = finger(1, tables, work.path(), "l").unwrap_err();
    assert!(e.contains("label = 7"), "{e}");
}

/// The finger's cavity given as a mesh file (OBJ, the box the label fills)
/// bends the finger as the label's surface does.
#[test]
fn a_cavity_mesh_file_acts_like_the_label_it_outlines() {
    let work = tempfile::tempdir().unwrap();
    let lo = voxflex_core::glam::DVec3::new(-32.0, -4.0, -1.0);
    let hi = voxflex_core::glam::DVec3::new(36.0, 4.0, 5.0);
    let surface = voxflex_core::triangle_surface::TriangleSurface::tiled_box(lo, hi, 8);
    let mut obj = String::new();
    for v in &surface.vertices {
        obj += &format!("v {} {} {}\n", v.x, v.y, v.z);
    }
    for t in &surface.triangles {
        obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    let path = work.path().join("cavity.obj");
    std::fs::write(&path, obj).unwrap();
    let tips = [
        "cavity = { label = 2 }".to_string(),
        format!("cavity = {{ file = {:?} }}", path.display().to_string()),
    ]
    .map(|geometry| {
        let tables = format!(
            "[[actuator]]\nplugin = \"cavity\"\n{geometry}\n[actuator.params]\n\
             pressure_pa = [[0, 0], [4, 3000]]\n{}",
            tip(TIP)
        );
        let r = finger(5, &tables, work.path(), "g").unwrap();
        tip_after(&r)[2]
    });
    eprintln!(
        "tip z at 3 kPa: label {} mm, OBJ file {} mm",
        tips[0], tips[1]
    );
    assert!(tips[1] < -0.3, "{tips:?}");
    assert!((tips[1] - tips[0]).abs() < 0.1 * tips[0].abs(), "{tips:?}");
}

/// The paper's cylinder inflated by 15 ml, of air and of water: the host
/// finds the pressure that reaches the scripted volume for both, and the
/// water's weight (ρ g V on the cavity) lowers the pressure it takes.
#[test]
fn the_cylinder_takes_fifteen_millilitres_of_air_or_of_water() {
    let work = tempfile::tempdir().unwrap();
    let runs = ["air", "water"].map(|fluid| {
        let text = format!(
            r#"[scene]
frames = 18
backend = "cpu"
plugin_dirs = [{dir:?}]
[volume]
source = "phantom:cylinder"
dims = [48, 48, 68]
[model]
plugin = "corotational-fem"
[model.params]
solver = "static"
proxy = {{ kind = "uniform", step = 2 }}
materials = [{{ range = [0.5, 1.5], youngs_modulus = 100e3, poisson_ratio = 0.3 }}]
[[interaction]]
frame = 0
kind = "fix"
min = [-25, -25, -35]
max = [25, 25, -28.5]
[[actuator]]
plugin = "cavity"
cavity = {{ label = 2 }}
[actuator.params]
fluid = "{fluid}"
volume_mm3 = [[0, 0], [14, 15000]]
"#,
            dir = plugins().display().to_string()
        );
        run(&text, work.path(), fluid).unwrap()
    });
    let (air, water) = (&runs[0].actuators[0], &runs[1].actuators[0]);
    let (va, vw) = (air.measure.last().unwrap(), water.measure.last().unwrap());
    let (pa, pw) = (air.effort.last().unwrap(), water.effort.last().unwrap());
    eprintln!("15 ml: air {va} mm³ at {pa} Pa; water {vw} mm³ at {pw} Pa");
    for v in [va, vw] {
        assert!((v - 15000.0).abs() < 0.02 * 15000.0, "{v} mm³");
    }
    // The water's weight presses the cavity's floor into the base below
    // it, which opens the cavity a little: the same 15 ml takes less
    // pressure (measured: 8 Pa of 16.1 kPa).
    assert!(
        pw < pa,
        "water's weight helps: {pa} Pa of air vs {pw} Pa of water"
    );
    let (weight, volume) = (water.notes["fluid_weight_uN"], water.notes["volume_mm3"]);
    assert!(
        (weight - 9.81 * volume).abs() < 0.01 * weight,
        "{weight} µN for {volume} mm³"
    );
    assert_eq!(runs[0].qp_failures + runs[1].qp_failures, 0);
}

/// `[actuation] settle_iterations = 0` (interactive): each frame applies
/// the pressure's forces as they were at its start, so a held pressure
/// reaches the settled answer over frames instead of within each; it
/// repeats no step, and `force_change` says how far behind each frame was
/// — on the finger (bending toward −z) and on its mirror image (+z).
/// A bad value names its key; the table without actuators is refused.
#[test]
fn lagged_follower_forces_reach_the_settled_bend_over_frames() {
    let work = tempfile::tempdir().unwrap();
    let held = format!(
        "{}{}",
        cavity("pressure_pa = [[0, 0], [2, 3000]]"),
        tip(TIP)
    );
    let lagged_tables = format!("{held}[actuation]\nsettle_iterations = 0\n");
    // The finger bends toward −z, its mirror toward +z: both catch up.
    for (n, file) in finger_and_mirror(work.path()).iter().enumerate() {
        let file = file.display().to_string();
        let run_with = |tables: &str, name: &str| {
            let text = finger_scene(&file, "corotational-fem", 24, tables);
            run(&text, work.path(), &format!("{name}{n}")).unwrap()
        };
        let settled = run_with(&held, "settled");
        let lagged = run_with(&lagged_tables, "lagged");
        eprintln!(
            "{file}: settled tip {:?} ({:?} repeats), lagged tip {:?}, force change per frame \
             {:?}",
            tip_after(&settled),
            settled.settle_iterations,
            tip_after(&lagged),
            lagged.force_change
        );
        assert!(settled.settle_iterations.iter().any(|&n| n > 0));
        assert!(lagged.settle_iterations.iter().all(|&n| n == 0));
        // While the pressure ramps the lag is visible…
        assert!(
            lagged.force_change[1] > settled.force_change[1],
            "{lagged:?}"
        );
        // …and twenty frames after it stopped ramping it has caught up
        // (measured on the finger: 1 % behind after ten, 4e-5 after
        // twenty-two).
        let (a, b) = (tip_after(&settled)[2], tip_after(&lagged)[2]);
        let away = if n == 0 { -a } else { a };
        assert!(
            away > 0.3,
            "the settled finger bends away from its cavity: {a}"
        );
        assert!(
            (a - b).abs() <= 1e-3 * a.abs(),
            "settled {a} mm, lagged {b} mm"
        );
        assert!(*lagged.force_change.last().unwrap() < 1e-3, "{lagged:?}");
    }

    let bad = format!("{held}[actuation]\nsettle_tolerance = 2\n");
    let e = finger(1, &bad, work.path(), "bad").unwrap_err();
    assert!(
        e.contains("settle_tolerance") && e.contains("(0, 1)"),
        "{e}"
    );
    let orphan = "[actuation]\nsettle_iterations = 0\n";
    let e = finger(1, orphan, work.path(), "orphan").unwrap_err();
    assert!(e.contains("no [[actuator]]"), "{e}");
}

/// Under inverse control the fluid decides the reach, as the paper shows:
/// a target 2 mm below the finger's rest tip is reached by the pneumatic
/// finger within 1 % of its length (inflating bends it down; one actuator
/// traces a curve, which passes 0.57 mm from this point), while the hydraulic one already hangs
/// lower under its water's weight with no pressure at all — a pressure
/// only bends it further — so the target is out of its reach and it ends
/// at its unpressurised sag, the closest it can be.
#[test]
fn hydraulic_and_pneumatic_fingers_differ_in_reach_under_inverse_control() {
    let work = tempfile::tempdir().unwrap();
    let target = [TIP[0], TIP[1], TIP[2] - 2.0];
    let [air, water] = ["\"air\"", "\"water\""].map(|fluid| {
        let tables = format!(
            "{}{}",
            cavity(&format!("fluid = {fluid}\nmax_pressure_pa = 30000")),
            tip(target)
        );
        finger(
            15,
            &tables,
            work.path(),
            &format!("reach-{}", fluid.trim_matches('"')),
        )
        .unwrap()
    });
    let last = |r: &ActuationReport| {
        (
            *r.effectors[0].distance_mm.last().unwrap(),
            *r.actuators[0].effort.last().unwrap(),
        )
    };
    let ((d_air, p_air), (d_water, p_water)) = (last(&air), last(&water));
    eprintln!(
        "target {target:?}: air ends {d_air:.3} mm away at {p_air:.0} Pa (tip {:?}); water \
         {d_water:.3} mm away at {p_water:.0} Pa (tip {:?})",
        tip_after(&air),
        tip_after(&water)
    );
    assert!(d_air < 0.8, "the pneumatic finger reaches it: {d_air} mm");
    assert!(p_air > 100.0, "by inflating: {p_air} Pa");
    assert!(
        tip_after(&water)[2] < target[2] - 0.5,
        "the water's weight alone takes the hydraulic tip below the target: {:?}",
        tip_after(&water)
    );
    assert!(
        p_water < 0.05 * p_air,
        "so its closest is (about) no pressure: {p_water} Pa against air's {p_air} Pa"
    );
    assert!(d_water > d_air + 0.5, "water {d_water} mm, air {d_air} mm");
}
