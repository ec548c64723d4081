//! The corotational FEM fronts, through the `corotational-fem` plugin on a
//! block volume whose voxel centres are the proxy's nodes (`proxy = {
//! kind = "uniform", step }`, so `step` sets the resolution):
//!
//! - `fem_cantilever`: the 10 × 1 × 1 mm cantilever of
//!   `tests/reference/cantilever.json` (E = 1000 Pa, ν = 0.3, clamped at
//!   x = 0, tip traction in −z, small load so the answer is linear) — the
//!   tip's `u / P` against Timoshenko beam theory and against the finest,
//!   tightest solve, per proxy step × CG tolerance, static Newton;
//! - `fem_elastica`: the slender 8 × 1 × 0.5 mm beam loaded to
//!   PL²/EI = 3, 10, 30 from rest (large rotation), static Newton, tip
//!   position against the Euler elastica ([`super::elastica`]) with the
//!   beam's EI, per proxy step.
//!
//! The element families measured are [`ELEMENTS`]; each is one series per
//! tolerance (or load), so another element order is one more entry there.

use super::runner::{self, Plugins, Scene};
use super::{Front, Point, Tuning};
use crate::bench::BenchError;
use voxflex_core::glam::DVec3;

/// An element family of the FEM fronts.
pub(super) struct Family {
    /// The series label.
    pub name: &'static str,
    /// The `[model.params]` lines that select it.
    pub params: &'static str,
    /// Largest proxy measured (tetrahedra), full run and `--quick`: P2 has
    /// ~6× the nodes of P1 on one proxy (10,240 P2 tetrahedra take ~2 s a
    /// static solve with AMG, the reference's block-Jacobi ~4 s a CG
    /// solve), so its finest proxies would take the front's whole budget.
    max_tetrahedra: [usize; 2],
}

/// The element families of the FEM fronts. The last, the most accurate,
/// also gives the cantilever's "finest solve" reference, on its largest
/// proxy within its cap.
pub(super) const ELEMENTS: &[Family] = &[
    Family {
        name: "P1",
        params: "element = \"p1\"",
        max_tetrahedra: [usize::MAX, usize::MAX],
    },
    Family {
        name: "P2",
        params: "element = \"p2\"",
        max_tetrahedra: [12_000, 500],
    },
];

impl Family {
    /// The proxy steps of `steps` (voxels) this family measures on a block
    /// of `dims` voxels: those whose uniform proxy (5 tetrahedra per cell)
    /// is within the cap.
    pub(super) fn steps(&self, steps: &[usize], dims: [usize; 3], quick: bool) -> Vec<usize> {
        let cap = self.max_tetrahedra[quick as usize];
        steps
            .iter()
            .copied()
            .filter(|&s| 5 * dims.iter().map(|&d| (d - 1) / s).product::<usize>() <= cap)
            .collect()
    }
}

/// The plugin both fronts run.
const PLUGIN: &str = "corotational-fem";
/// Young's modulus (Pa) and Poisson ratio of both beams.
const E: f64 = 1000.0;
const NU: f64 = 0.3;
/// The default CG tolerance of `corotational-fem`.
const DEFAULT_TOL: f64 = 1e-6;
/// The default element family of `corotational-fem` (an [`ELEMENTS`] name).
/// Its default proxy is the plugin's own: the rows ringed are those whose
/// proxy has as many tetrahedra as the one the plugin builds with no
/// `proxy` key ([`default_tetrahedra`]).
pub(super) const DEFAULT_ELEMENT: &str = "P1";

/// The params of a static solve; no `proxy` key without `step`.
fn params(element: &str, step: Option<usize>, tol: f64, tight: bool) -> String {
    let mut p = step.map_or(String::new(), |step| {
        format!("proxy = {{ kind = \"uniform\", step = {step} }}\n")
    });
    p += &format!(
        "materials = [{{ range = [50, 200], youngs_modulus = {E}, poisson_ratio = {NU} }}]\n\
         solver = \"static\"\ncg_tolerance = {tol:e}\n"
    );
    if tight {
        p += "static_tolerance = 1e-8\ncg_max_iterations = 100000\npreconditioner = \"block-jacobi\"\n";
    }
    if !element.is_empty() {
        p += element;
        p.push('\n');
    }
    p
}

/// Clamp at x = 0 and a traction `t` (Pa, −z) on the face x = `l` of a
/// beam `w` × `h` (mm).
fn beam_interactions(l: f64, w: f64, h: f64, t: f64) -> Vec<(u64, String)> {
    vec![
        (
            0,
            format!(
                "kind = \"fix\"\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, {}, {}]",
                w + 0.01,
                h + 0.01
            ),
        ),
        (
            0,
            format!(
                "kind = \"load\"\nmin = [{}, -0.01, -0.01]\nmax = [{}, {}, {}]\ntraction = [0, 0, {}]",
                l - 0.01,
                l + 0.01,
                w + 0.01,
                h + 0.01,
                -t
            ),
        ),
    ]
}

/// Timoshenko's tip deflection per unit tip force (mm/µN) of a cantilever
/// of length `l`, width `w`, height `h` (mm): bending `L³/3EI` plus shear
/// `L/κGA` with Cowper's κ = 10(1+ν)/(12+11ν) for a rectangle.
pub(super) fn timoshenko(l: f64, w: f64, h: f64) -> f64 {
    let i = w * h.powi(3) / 12.0;
    let g = E / (2.0 * (1.0 + NU));
    let kappa = 10.0 * (1.0 + NU) / (12.0 + 11.0 * NU);
    l.powi(3) / (3.0 * E * i) + l / (kappa * g * w * h)
}

/// One static solve of a beam: the mean displacement of its tip face's
/// points and the run.
fn solve(
    plugins: &Plugins,
    volume: &voxflex_core::volume::Volume,
    params: String,
    l: f64,
    w: f64,
    h: f64,
    traction: f64,
) -> Result<(DVec3, DVec3, runner::Outcome), BenchError> {
    let tip = runner::lattice_points(volume, |p| (p.x - l).abs() < 1e-6);
    let run = runner::run(
        plugins,
        &Scene {
            plugin: PLUGIN,
            params,
            volume,
            points: &tip,
            interactions: beam_interactions(l, w, h, traction),
            frames: 1,
            dt_s: 1.0 / 30.0,
            settle: None,
        },
    )?;
    let n = tip.len() as f64;
    let rest = tip
        .iter()
        .map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .sum::<DVec3>()
        / n;
    let mean = run.u.iter().copied().sum::<DVec3>() / n;
    Ok((rest, mean, run))
}

fn fem_notes(run: &runner::Outcome) -> Vec<(&'static str, String)> {
    vec![
        ("tetrahedra", runner::note(&run.notes, "proxy_tetrahedra")),
        (
            "newton_iterations",
            runner::note(&run.notes, "newton_iterations"),
        ),
        (
            "cg_iterations",
            runner::note(&run.notes, "solver_iterations"),
        ),
        (
            "unconverged_solves",
            runner::note(&run.notes, "unconverged_solves"),
        ),
    ]
}

/// The tetrahedra of the proxy `corotational-fem` builds on `volume` with
/// no `proxy` key (its default element and node spacing), as the plugin
/// reports them.
fn default_tetrahedra(
    plugins: &Plugins,
    volume: &voxflex_core::volume::Volume,
    (l, w, h): (f64, f64, f64),
) -> Result<String, BenchError> {
    let (_, _, run) = solve(
        plugins,
        volume,
        params("", None, DEFAULT_TOL, false),
        l,
        w,
        h,
        1e-3,
    )?;
    Ok(runner::note(&run.notes, "proxy_tetrahedra"))
}

/// The step (voxels) of the ringed rows of `points` ("?" when none is).
fn default_step(points: &[Point]) -> String {
    points
        .iter()
        .find(|p| p.is_default)
        .and_then(|p| p.extra.iter().find(|(k, _)| *k == "step"))
        .map_or("?".into(), |(_, v)| v.clone())
}

/// The cantilever front.
pub(super) fn cantilever(plugins: &Plugins, quick: bool) -> Result<Front, BenchError> {
    let (l, w, h): (f64, f64, f64) = (10.0, 1.0, 1.0);
    // Voxels per mm; a proxy step of s voxels makes n / s cells per mm.
    let n: usize = if quick { 4 } else { 12 };
    // The quick steps hold the plugin's default (3).
    let steps: &[usize] = if quick {
        &[4, 3, 2, 1]
    } else {
        &[12, 8, 6, 4, 3, 2, 1]
    };
    let tols: &[f64] = if quick {
        &[1e-3, 1e-6]
    } else {
        &[1e-2, 1e-4, 1e-6, 1e-8]
    };
    let dims = [10 * n + 1, n + 1, n + 1];
    let volume = runner::block(dims, 1.0 / n as f64, 100);
    // A small load: the linear regime, where beam theory holds (u/P).
    let p = 1e-3;
    let theory = timoshenko(l, w, h);
    let last = &ELEMENTS[ELEMENTS.len() - 1];
    let finest_step = *last
        .steps(steps, dims, quick)
        .last()
        .ok_or_else(|| BenchError(format!("no {} proxy within its cap", last.name)))?;
    let (_, finest, _) = solve(
        plugins,
        &volume,
        params(last.params, Some(finest_step), 1e-10, true),
        l,
        w,
        h,
        p,
    )?;
    let finest = -finest.z / p;
    let last = last.name;
    let default_tets = default_tetrahedra(plugins, &volume, (l, w, h))?;
    let mut points = vec![];
    for family in ELEMENTS {
        let (name, extra) = (family.name, family.params);
        for &tol in tols {
            for step in family.steps(steps, dims, quick) {
                let (_, u, run) = solve(
                    plugins,
                    &volume,
                    params(extra, Some(step), tol, false),
                    l,
                    w,
                    h,
                    p,
                )?;
                let got = -u.z / p;
                let mut ex = vec![
                    ("step", step.to_string()),
                    ("cells_per_mm", format!("{}", n as f64 / step as f64)),
                    ("cg_tolerance", format!("{tol:e}")),
                    ("tip_u_per_p", format!("{got:.6}")),
                    (
                        "error_vs_finest",
                        format!("{:.3e}", (got - finest).abs() / finest),
                    ),
                ];
                ex.extend(fem_notes(&run));
                points.push(Point {
                    series: format!("{name} cg {tol:e}"),
                    config: format!("step {step}"),
                    time_ms: run.time_ms,
                    error: (got - theory).abs() / theory,
                    is_default: name == DEFAULT_ELEMENT
                        && tol == DEFAULT_TOL
                        && runner::note(&run.notes, "proxy_tetrahedra") == default_tets,
                    group: String::new(),
                    extra: ex,
                    tuning: (tol == DEFAULT_TOL).then(|| Tuning::new(PLUGIN, name, step)),
                });
            }
        }
    }
    let default_step = default_step(&points);
    Ok(Front {
        key: "fem_cantilever",
        title: "corotational FEM: cantilever tip vs Timoshenko".into(),
        error_label: "|tip u/P − Timoshenko| / Timoshenko".into(),
        description: format!(
            "The 10 × 1 × 1 mm cantilever (E = {E} Pa, ν = {NU}), clamped at x = 0, tip traction \
             {p} Pa in −z (linear regime), static Newton through the `corotational-fem` plugin, \
             on a block of {n} voxels per mm; `step` is the proxy step in voxels (cells per mm = \
             {n}/step; a step that does not divide the block leaves a thinner last cell, as the \
             plugin's proxy does). Error: tip `u/P` (mean over the tip face's voxel centres) against \
             Timoshenko beam theory {theory:.4} mm/µN (bending + shear, Cowper's κ); \
             `error_vs_finest` against the {last} solve at step {finest_step} with CG 1e-10 and static \
             tolerance 1e-8, block Jacobi (`u/P` = {finest:.6}). The default ({DEFAULT_ELEMENT} at proxy step \
             {default_step}, CG {DEFAULT_TOL:e}, the plugin's with no `proxy` key) is relative to \
             the voxel size: here {} cells per mm.",
            default_step
                .parse::<f64>()
                .map_or("?".into(), |s| format!("{}", n as f64 / s))
        ),
        points,
    })
}

/// The elastica front.
pub(super) fn elastica(plugins: &Plugins, quick: bool) -> Result<Front, BenchError> {
    let (l, w, h): (f64, f64, f64) = (8.0, 1.0, 0.5);
    let n: usize = if quick { 4 } else { 8 };
    // The grab fronts' P1 steps (6, 4, 3, 2) among them, so that the
    // combined front ([`super::combined`]) compares those.
    let steps: &[usize] = if quick { &[2, 1] } else { &[8, 6, 4, 3, 2, 1] };
    let dims = [8 * n + 1, n + 1, n / 2 + 1];
    let volume = runner::block(dims, 1.0 / n as f64, 100);
    let ei = E * w * h.powi(3) / 12.0;
    let default_tets = default_tetrahedra(plugins, &volume, (l, w, h))?;
    let mut points = vec![];
    for family in ELEMENTS {
        let (name, extra) = (family.name, family.params);
        for alpha in [3.0, 10.0, 30.0] {
            let (ex, ez) = voxflex_mesh::mesh_model::elastica::tip(alpha);
            let p = alpha * ei / (l * l);
            for step in family.steps(steps, dims, quick) {
                let (rest, u, run) = solve(
                    plugins,
                    &volume,
                    params(extra, Some(step), DEFAULT_TOL, false),
                    l,
                    w,
                    h,
                    p / (w * h),
                )?;
                let tip = rest + u;
                let (gx, gz) = (tip.x / l, (tip.z - h / 2.0) / l);
                let error = ((gx - ex).powi(2) + (gz - ez).powi(2)).sqrt();
                let mut extra = vec![
                    ("step", step.to_string()),
                    ("cell_mm", format!("{}", step as f64 / n as f64)),
                    ("pl2_over_ei", format!("{alpha}")),
                    ("tip_x_over_l", format!("{gx:.5}")),
                    ("tip_z_over_l", format!("{gz:.5}")),
                    ("elastica_x_over_l", format!("{ex:.5}")),
                    ("elastica_z_over_l", format!("{ez:.5}")),
                ];
                extra.extend(fem_notes(&run));
                points.push(Point {
                    series: format!("{name} PL²/EI = {alpha}"),
                    config: format!("step {step}"),
                    time_ms: run.time_ms,
                    error,
                    is_default: name == DEFAULT_ELEMENT
                        && runner::note(&run.notes, "proxy_tetrahedra") == default_tets,
                    group: format!("PL²/EI = {alpha}"),
                    extra,
                    tuning: Some(Tuning::new(PLUGIN, name, step)),
                });
            }
        }
    }
    Ok(Front {
        key: "fem_elastica",
        title: "corotational FEM: large deflection vs the elastica".into(),
        error_label: "|tip − elastica| / L".into(),
        description: format!(
            "The slender 8 × 1 × 0.5 mm beam (E = {E} Pa, ν = {NU}), clamped at x = 0, loaded \
             from rest to PL²/EI = 3, 10, 30 (EI = E w h³/12 = {ei:.4} µN·mm², the beam's, not \
             the mesh's) by a tip traction, static Newton with the default tolerances, on a \
             block of {n} voxels per mm (cell = step/{n} mm). Error: distance of the tip face's \
             mean position from the Euler elastica's tip, over the length."
        ),
        points,
    })
}
