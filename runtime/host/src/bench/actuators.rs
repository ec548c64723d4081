//! `voxflex bench --actuators`: the soft-robot figures of issue 16,
//! through the real path (scenes run by the pipeline, the `cavity` and
//! `corotational-fem` plugins loaded from their libraries):
//!
//! - the thick-walled sphere against Lamé at two mesh levels (error
//!   against run time, [`super::lame`]);
//! - the four-cavity hydraulic pendulum under inverse control (the
//!   paper's Fig. 6): time per frame — four fluid weighings, the
//!   compliance solves, the QP, the static solve and its settling — and
//!   how closely the tip follows its moving target.

use super::lame::{LameSphere, run_lame};
use super::{BenchError, BenchOptions, err};
use crate::pipeline::{RunOptions, run_scene};
use crate::scene::Scene;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One pendulum configuration of the bench: the proxy step (voxels of
/// 1.2 mm: 2 is the scene's 5,311 nodes, 3 the paper's ~2 k-node class),
/// whether each frame settles its follower forces (the default) or lags
/// them by a frame (`[actuation] settle_iterations = 0`), how often the
/// inverse step solves its responses (`response_refresh_frames`), and
/// whether the model's static solve itself lags (`static_lag` with one
/// Newton iteration a frame).
#[derive(Clone, Copy, Debug)]
struct Variant {
    step: usize,
    lagged: bool,
    responses_every: u32,
    static_lag: bool,
}

const fn variant(step: usize, lagged: bool, responses_every: u32) -> Variant {
    Variant {
        step,
        lagged,
        responses_every,
        static_lag: false,
    }
}

/// The configurations measured, interleaved within each repeat.
const VARIANTS: [Variant; 7] = [
    variant(2, false, 1),
    variant(2, true, 1),
    variant(3, false, 1),
    variant(3, true, 1),
    variant(3, false, 8),
    variant(3, true, 8),
    Variant {
        static_lag: true,
        ..variant(3, true, 8)
    },
];

/// The pendulum scene (`configs/soft-pendulum.toml`'s physics) for
/// `frames` frames in configuration `v`, plugins from `dirs`, outputs
/// into `out`.
fn pendulum_scene(frames: u64, v: Variant, dirs: &[PathBuf], out: &Path) -> String {
    let dirs: Vec<String> = dirs
        .iter()
        .map(|d| format!("{:?}", d.display().to_string()))
        .collect();
    let cavity = |name: &str, label: u32| {
        format!(
            "[[actuator]]\nplugin = \"cavity\"\nname = \"{name}\"\ncavity = {{ label = {label} }}\n\
             [actuator.params]\nfluid = \"water\"\nmax_pressure_pa = 20000\n\n"
        )
    };
    format!(
        r#"[scene]
name = "bench-pendulum"
backend = "cpu"
frames = {frames}
plugin_dirs = [{dirs}]

[volume]
source = "phantom:pendulum"
dims = [30, 30, 74]

[model]
plugin = "corotational-fem"
[model.params]
solver = "static"
{lag}proxy = {{ kind = "uniform", step = {step} }}
materials = [{{ range = [0.5, 1.5], youngs_modulus = 50e3, poisson_ratio = 0.3, density = 1070 }}]

[[interaction]]
frame = 0
kind = "fix"
min = [-20, -20, 38.5]
max = [20, 20, 45]

{a}{b}{c}{d}[[effector]]
point = [0, 0, -39]
path = [[0, 0, 0, -39.3], [10, 1.5, 0, -39.3], [20, 0, 1.5, -39.3], [30, -1.5, 0, -39.3], [40, 0, -1.5, -39.3]]

[actuation]
settle_iterations = {settle}
response_refresh_frames = {every}

[output]
dir = {out:?}
"#,
        dirs = dirs.join(", "),
        a = cavity("+x", 2),
        b = cavity("+y", 3),
        c = cavity("-x", 4),
        d = cavity("-y", 5),
        out = out.display().to_string(),
        step = v.step,
        settle = if v.lagged { 0 } else { 30 },
        lag = if v.static_lag {
            "static_lag = true\nstatic_iterations = 1\n"
        } else {
            ""
        },
        every = v.responses_every,
    )
}

/// One pendulum run's figures.
struct PendulumRun {
    nodes: f64,
    ms_per_frame: f64,
    settle_mean: f64,
    compliance_per_frame: f64,
    weighing_ms: f64,
    median_distance: f64,
    worst_distance: f64,
    /// Median over frames of the follower forces' change over the frame.
    median_force_change: f64,
}

fn run_pendulum(
    frames: u64,
    v: Variant,
    dirs: &[PathBuf],
    work: &Path,
) -> Result<PendulumRun, BenchError> {
    let out = work.join("pendulum");
    let path = work.join("pendulum.toml");
    let text = pendulum_scene(frames, v, dirs, &out);
    std::fs::write(&path, &text).map_err(err)?;
    let scene = Scene::parse(&text, &path).map_err(err)?;
    let m = run_scene(
        &scene,
        RunOptions {
            out_dir: Some(out),
            force: true,
            progress: None,
        },
    )
    .map_err(err)?;
    let a = m
        .actuation
        .ok_or_else(|| err("the pendulum reported no actuation"))?;
    let model = m.stages.get("model").ok_or_else(|| err("no model stage"))?;
    let note = |k: &str| model.notes.get(k).and_then(|v| v.as_f64()).unwrap_or(0.0);
    let (weighings, weighing_s) = a.actuators.iter().fold((0.0, 0.0), |(n, s), x| {
        (
            n + x.notes.get("weighings").copied().unwrap_or(0.0),
            s + x.notes.get("weighing_s").copied().unwrap_or(0.0),
        )
    });
    let mut d = a.effectors[0].distance_mm.clone();
    d.sort_by(f64::total_cmp);
    let mut change = a.force_change.clone();
    change.sort_by(f64::total_cmp);
    Ok(PendulumRun {
        nodes: note("proxy_nodes"),
        ms_per_frame: model.wall_ms / frames as f64,
        settle_mean: a.settle_iterations.iter().map(|&i| i as f64).sum::<f64>() / frames as f64,
        compliance_per_frame: a.compliance_solves as f64 / frames as f64,
        weighing_ms: 1e3 * weighing_s / weighings.max(1.0),
        median_distance: d[d.len() / 2],
        worst_distance: d[d.len() - 1],
        median_force_change: change[change.len() / 2],
    })
}

/// Runs the actuator figures; the report as text.
pub fn run(args: &BenchOptions) -> Result<String, BenchError> {
    let dirs = crate::plugin_loader::search_path(&args.plugin_dirs);
    let work = std::env::temp_dir().join(format!("voxflex-bench-actuators-{}", std::process::id()));
    std::fs::create_dir_all(&work).map_err(err)?;
    let mut out = String::new();
    let sphere = LameSphere::default();
    let _ = writeln!(
        out,
        "Thick-walled sphere vs Lamé (a = {} mm, b = {} mm, E = {} Pa, ν = {}, p = {} Pa):",
        sphere.inner_mm,
        sphere.outer_mm,
        sphere.youngs_modulus,
        sphere.poisson_ratio,
        sphere.pressure_pa
    );
    let _ = writeln!(
        out,
        "  voxel mm  nodes    ΔV mm³    Lamé mm³   error     run s"
    );
    for voxel in [2.0, 1.0] {
        let r = run_lame(&sphere, voxel, 1, &dirs, &work).map_err(err)?;
        let _ = writeln!(
            out,
            "  {:<8}  {:<7}  {:<8.4}  {:<9.4}  {:+.2} %  {:.2}",
            r.voxel_mm,
            r.nodes,
            r.volume_growth,
            r.analytic,
            100.0 * r.relative_error(),
            r.seconds
        );
    }
    let frames = if args.quick { 5 } else { 40 };
    let mut runs: Vec<Vec<PendulumRun>> = VARIANTS.iter().map(|_| Vec::new()).collect();
    for _ in 0..args.repeat.max(1) {
        for (v, r) in VARIANTS.iter().zip(&mut runs) {
            r.push(run_pendulum(frames, *v, &dirs, &work)?);
        }
    }
    let _ = writeln!(
        out,
        "Pendulum, four water cavities at 200² columns, inverse control ({frames} frames, {} runs \
         each, interleaved):\n  \
         step  nodes  settling          responses  ms/frame min  median  frames/s  \
         repeats/frame  compliance/frame  weighing ms  force change  tip median mm  tip worst mm",
        args.repeat.max(1)
    );
    for (v, r) in VARIANTS.iter().zip(&mut runs) {
        r.sort_by(|a, b| a.ms_per_frame.total_cmp(&b.ms_per_frame));
        let (best, median) = (&r[0], &r[r.len() / 2]);
        let _ = writeln!(
            out,
            "  {:<4}  {:<5}  {:<16}  {:<9}  {:<12.1}  {:<6.1}  {:<8.1}  {:<13.1}  {:<16.1}  \
             {:<11.3}  {:<12.2e}  {:<13.3}  {:.3}",
            v.step,
            best.nodes,
            match (v.lagged, v.static_lag) {
                (true, true) => "lagged + solve",
                (true, false) => "lagged (0)",
                _ => "settled (1e-4)",
            },
            format!("every {}", v.responses_every),
            best.ms_per_frame,
            median.ms_per_frame,
            1e3 / median.ms_per_frame,
            median.settle_mean,
            median.compliance_per_frame,
            median.weighing_ms,
            median.median_force_change,
            median.median_distance,
            median.worst_distance,
        );
    }
    let _ = std::fs::remove_dir_all(&work);
    Ok(out)
}
