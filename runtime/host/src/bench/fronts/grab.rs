//! The `grab` front: corotational FEM, mass-spring and ChainMail on the
//! same grab of the same soft beam, against a fine FEM solve.
//!
//! The beam is a block of 4m × m × m voxels of 1 mm (m = 12; 4 in
//! `--quick`), E = 3000 Pa, ν = 0.3, 1000 kg/m³, clamped at x = 0; every
//! voxel centre of the face x = 4m is grabbed and moved by `m/2` mm in −z
//! over 10 frames and held. The reference is `corotational-fem`'s static
//! solve on the proxy of step 1 (a node at every voxel centre) with tight
//! tolerances (CG 1e-10, static 1e-8). Error: the RMS (and max) over every voxel centre of the
//! distance between a model's displacement and the reference's, mm. FEM
//! runs both element families (P1, and P2 with its mid-edge nodes). The
//! dynamic models (FEM `solver = "dynamic"`, both mass-spring
//! integrators, ChainMail's relaxation) run on after the grab until no
//! point moves more than 1e-3 mm over 10 frames (capped; `settled` says
//! whether they got there); their time is the whole run to rest.

use super::beam::{Beam, GRAB_FRAMES, MATERIAL_CHAINMAIL, MATERIAL_MESH};
use super::fem;
use super::runner::{self, Plugins, Scene, Settle};
use super::{Front, Point, Tuning};
use crate::bench::BenchError;
use voxflex_core::glam::DVec3;
use voxflex_core::volume::Volume;

/// The models of a grab front: series label, plugin, params (given the
/// resolution), whether they need to settle, and the proxy steps measured.
pub(super) struct ModelSpec {
    /// The series label.
    pub series: &'static str,
    plugin: &'static str,
    /// Extra params lines (after proxy / materials).
    params: &'static str,
    dynamic: bool,
    /// The element family ([`fem::ELEMENTS`] name; `P1` for mass-spring,
    /// whose springs lie on the proxy's edges).
    element: &'static str,
    /// Proxy steps measured (voxels), full run and `--quick`, within the
    /// family's cap on tetrahedra ([`fem::Family::steps`]).
    steps: [&'static [usize]; 2],
    /// Its rows enter the plugin's combined front ([`super::Tuning`]): it
    /// runs the plugin's default solver or integrator.
    combined: bool,
}

/// P1 proxy steps (voxels): full run, `--quick` (both with the mesh
/// plugins' default spacings, 3 for the FEM and 4 for the springs, so
/// the quick fronts ring them too).
const P1_STEPS: [&[usize]; 2] = [&[6, 4, 3, 2], &[4, 3, 2]];
/// P2 proxy steps: its mid-edge nodes halve the node spacing, so a P2
/// step `s` has the nodes of a P1 step `s/2` (`--quick` leaves out step 2,
/// whose static solve would take most of the quick front in a debug build).
const P2_STEPS: [&[usize]; 2] = [&[12, 8, 6, 4], &[8, 4]];

/// Two runs are the same configuration when their bound points' first-frame
/// displacements agree within this fraction of the largest: far below what
/// separates two proxies, element orders or integrators (≥ 1e-2 here), far
/// above the CG's run-to-run rounding (parallel sums).
const SAME_RUN: f64 = 1e-4;

/// The mesh models of the `grab` front (the `two_material` front measures
/// the first four and the last).
pub(super) const MESH_MODELS: &[ModelSpec] = &[
    ModelSpec {
        series: "FEM static",
        plugin: "corotational-fem",
        params: "solver = \"static\"\nelement = \"p1\"",
        dynamic: false,
        element: "P1",
        steps: P1_STEPS,
        combined: false,
    },
    ModelSpec {
        series: "FEM dynamic",
        plugin: "corotational-fem",
        params: "element = \"p1\"",
        dynamic: true,
        element: "P1",
        steps: P1_STEPS,
        combined: true,
    },
    ModelSpec {
        series: "FEM static P2",
        plugin: "corotational-fem",
        params: "solver = \"static\"\nelement = \"p2\"",
        dynamic: false,
        element: "P2",
        steps: P2_STEPS,
        combined: false,
    },
    ModelSpec {
        series: "FEM dynamic P2",
        plugin: "corotational-fem",
        params: "element = \"p2\"",
        dynamic: true,
        element: "P2",
        steps: P2_STEPS,
        combined: true,
    },
    ModelSpec {
        series: "mass-spring explicit",
        plugin: "mass-spring",
        params: "integrator = \"explicit\"",
        dynamic: true,
        element: "P1",
        steps: P1_STEPS,
        combined: false,
    },
    ModelSpec {
        series: "mass-spring implicit",
        plugin: "mass-spring",
        params: "integrator = \"implicit\"",
        dynamic: true,
        element: "P1",
        steps: P1_STEPS,
        combined: true,
    },
];

impl ModelSpec {
    /// The proxy steps measured on a block of `dims` voxels.
    fn steps(&self, dims: [usize; 3], quick: bool) -> Result<Vec<usize>, BenchError> {
        let family = fem::ELEMENTS
            .iter()
            .find(|f| f.name == self.element)
            .ok_or_else(|| BenchError(format!("no element family {}", self.element)))?;
        Ok(family.steps(self.steps[quick as usize], dims, quick))
    }
}

/// Whether displacements `a` and `b` (mm) are the same run's ([`SAME_RUN`]).
fn same_run(a: &[DVec3], b: &[DVec3]) -> bool {
    let scale = b.iter().map(|d| d.length()).fold(0.0, f64::max);
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| (*x - *y).length() <= SAME_RUN * scale)
}

/// The RMS and the largest distance between displacements `u` and
/// `reference` (mm).
pub(super) fn errors(u: &[DVec3], reference: &[DVec3]) -> (f64, f64) {
    let (mut sum, mut max) = (0.0, 0.0f64);
    for (a, b) in u.iter().zip(reference) {
        let d = (*a - *b).length();
        sum += d * d;
        max = max.max(d);
    }
    ((sum / u.len().max(1) as f64).sqrt(), max)
}

/// A grab of a beam: its end face moved by `by` over [`GRAB_FRAMES`] and
/// held, dynamic runs settling as `settle` says; what the `grab` and
/// `two_material` fronts share.
pub(super) struct GrabProblem<'a> {
    /// The beam (volume, probe points).
    pub beam: &'a Beam,
    /// The grab, mm.
    pub by: DVec3,
    /// How dynamic runs come to rest.
    pub settle: Settle,
    /// The mesh models' `materials` line(s).
    pub mesh_materials: &'a str,
    /// ChainMail's `materials` line(s).
    pub chainmail_materials: &'a str,
    /// The `--quick` sizes (fewer proxy steps and down-samplings).
    pub quick: bool,
}

impl<'a> GrabProblem<'a> {
    /// The fronts' grab: the end face moved half the beam's depth in −z,
    /// dynamic runs settling for up to 600 frames.
    pub fn half_depth(
        beam: &'a Beam,
        quick: bool,
        mesh_materials: &'a str,
        chainmail_materials: &'a str,
    ) -> Self {
        Self {
            beam,
            by: DVec3::new(0.0, 0.0, -0.5 * beam.m as f64),
            settle: beam.settle(quick, 600),
            mesh_materials,
            chainmail_materials,
            quick,
        }
    }
}

/// The largest displacement of a solve, mm.
pub(super) fn largest(u: &[DVec3]) -> f64 {
    u.iter().map(|d| d.length()).fold(0.0, f64::max)
}

/// A run of the grab on `volume` (the beam's, or the same body's on finer
/// voxels), tracking `points` (world mm).
pub(super) fn grab_scene<'a>(
    volume: &'a Volume,
    points: &'a [[f32; 3]],
    interactions: Vec<(u64, String)>,
    plugin: &'a str,
    params: String,
    settle: Option<Settle>,
) -> Scene<'a> {
    Scene {
        plugin,
        params,
        volume,
        points,
        interactions,
        frames: GRAB_FRAMES,
        dt_s: 1.0 / 30.0,
        settle,
    }
}

/// A static `corotational-fem` solve of the grab with tight tolerances (CG
/// 1e-10, static 1e-8), `element` (`p1`, `p2`) on the proxy of `step`, on
/// `beam` (the problem's or the same body on finer voxels), tracking the
/// problem's probe points.
pub(super) fn fine_solve(
    plugins: &Plugins,
    problem: &GrabProblem,
    beam: &Beam,
    element: &str,
    step: usize,
) -> Result<runner::Outcome, BenchError> {
    let params = format!(
        "proxy = {{ kind = \"uniform\", step = {step} }}\n{}\nsolver = \"static\"\n\
         element = \"{element}\"\ncg_tolerance = 1e-10\nstatic_tolerance = 1e-8\n\
         cg_max_iterations = 100000",
        problem.mesh_materials
    );
    runner::run(
        plugins,
        &grab_scene(
            &beam.volume,
            &problem.beam.points,
            beam.fix_and_grab(problem.by),
            "corotational-fem",
            params,
            None,
        ),
    )
}

/// The mesh plugins' own defaults: each one's first frame with no key but
/// the materials (which also warms the plugins up before a reference).
pub(super) fn defaults(
    plugins: &Plugins,
    problem: &GrabProblem,
) -> Result<Vec<(&'static str, Vec<DVec3>)>, BenchError> {
    let mut out = vec![];
    for plugin in ["corotational-fem", "mass-spring"] {
        out.push((
            plugin,
            first_frame(plugins, problem, plugin, problem.mesh_materials.to_string())?,
        ));
    }
    Ok(out)
}

/// The displacements after the first frame of `plugin` with `params`.
fn first_frame(
    plugins: &Plugins,
    problem: &GrabProblem,
    plugin: &str,
    params: String,
) -> Result<Vec<DVec3>, BenchError> {
    let beam = problem.beam;
    let one = Scene {
        frames: 1,
        ..grab_scene(
            &beam.volume,
            &beam.points,
            beam.fix_and_grab(problem.by),
            plugin,
            params,
            None,
        )
    };
    Ok(runner::run(plugins, &one)?.u)
}

/// A grab front's rows: every mesh model of `models` on its proxy steps,
/// then ChainMail down-sampled by each of [`downsamples`], each against
/// `reference`; a mesh row is its plugin's default when its first frame is
/// that of `defaults` ([`defaults`]). Every row gets the `common` columns
/// last. Returns the rows and the default rows' names.
pub(super) fn rows(
    plugins: &Plugins,
    problem: &GrabProblem,
    models: &[&ModelSpec],
    defaults: &[(&'static str, Vec<DVec3>)],
    reference: &[DVec3],
    common: &[(&'static str, String)],
) -> Result<(Vec<Point>, Vec<String>), BenchError> {
    let beam = problem.beam;
    let scene = |plugin, params: String, settle: Option<Settle>| {
        grab_scene(
            &beam.volume,
            &beam.points,
            beam.fix_and_grab(problem.by),
            plugin,
            params,
            settle,
        )
    };
    let mut default_rows = vec![];
    let mut out = vec![];
    let mut push = |series: &str,
                    config: String,
                    run: &runner::Outcome,
                    is_default: bool,
                    tuning: Option<Tuning>,
                    mut extra: Vec<(&'static str, String)>| {
        let (rms, max) = errors(&run.u, reference);
        let mut ex = vec![
            ("max_mm", format!("{max:.4}")),
            ("frames", run.frames.to_string()),
            ("settled", run.settled.to_string()),
            (
                "ms_per_frame",
                format!("{:.3}", run.time_ms / run.frames.max(1) as f64),
            ),
        ];
        ex.append(&mut extra);
        ex.extend(common.iter().cloned());
        out.push(Point {
            series: series.to_string(),
            config,
            time_ms: run.time_ms,
            error: rms,
            is_default,
            group: String::new(),
            extra: ex,
            tuning,
        });
    };
    for spec in models {
        for step in spec.steps(beam.volume.grid.dims, problem.quick)? {
            let params = format!(
                "proxy = {{ kind = \"uniform\", step = {step} }}\n{}\n{}",
                problem.mesh_materials, spec.params
            );
            let run = runner::run(
                plugins,
                &scene(
                    spec.plugin,
                    params.clone(),
                    spec.dynamic.then_some(problem.settle),
                ),
            )?;
            let first = first_frame(plugins, problem, spec.plugin, params)?;
            let is_default = defaults
                .iter()
                .any(|(plugin, u)| *plugin == spec.plugin && same_run(&first, u));
            if is_default {
                default_rows.push(format!("{} at step {step}", spec.series));
            }
            let extra = vec![
                ("step", step.to_string()),
                ("tetrahedra", runner::note(&run.notes, "proxy_tetrahedra")),
                (
                    "voxels_lost",
                    runner::note(&run.notes, "labelled_voxels_lost"),
                ),
                ("substeps", runner::note(&run.notes, "substeps")),
                (
                    "unconverged_solves",
                    runner::note(&run.notes, "unconverged_solves"),
                ),
            ];
            let tuning = spec
                .combined
                .then(|| Tuning::new(spec.plugin, spec.element, step));
            push(
                spec.series,
                format!("step {step}"),
                &run,
                is_default,
                tuning,
                extra,
            );
        }
    }
    for &d in downsamples(problem.quick) {
        let params = format!("{}\ndownsample = {d}", problem.chainmail_materials);
        let run = runner::run(plugins, &scene("chainmail", params, Some(problem.settle)))?;
        let extra = vec![
            ("downsample", d.to_string()),
            (
                "relaxation_sweeps",
                runner::note(&run.notes, "relaxation_sweeps"),
            ),
        ];
        push(
            "ChainMail c = 0.3",
            format!("downsample {d}"),
            &run,
            d == 1,
            None,
            extra,
        );
    }
    Ok((out, default_rows))
}

/// The default rows as a phrase for a front's description.
pub(super) fn defaults_phrase(default_rows: &[String]) -> String {
    if default_rows.is_empty() {
        "none measured".to_string()
    } else {
        default_rows.join(", ")
    }
}

/// ChainMail's down-sampling factors measured: full run, `--quick`.
fn downsamples(quick: bool) -> &'static [usize] {
    if quick { &[2, 1] } else { &[4, 3, 2, 1] }
}

/// The grab front.
pub(super) fn front(plugins: &Plugins, quick: bool) -> Result<Front, BenchError> {
    let beam = Beam::new(quick);
    let problem = GrabProblem::half_depth(&beam, quick, MATERIAL_MESH, MATERIAL_CHAINMAIL);
    let (m, l, w, by) = (beam.m, beam.length, beam.width, -problem.by.z);
    let defaults = defaults(plugins, &problem)?;
    let reference = fine_solve(plugins, &problem, &beam, "p1", 1)?;
    let ref_max = largest(&reference.u);
    let models: Vec<&ModelSpec> = MESH_MODELS.iter().collect();
    let (out, default_rows) = rows(plugins, &problem, &models, &defaults, &reference.u, &[])?;
    let settle = problem.settle;
    Ok(Front {
        key: "grab",
        title: "the same grab: FEM, mass-spring, ChainMail vs fine FEM".into(),
        error_label: "RMS |u − u_ref|, mm".into(),
        description: format!(
            "A {l} × {w} × {w} mm beam (voxels of 1 mm, E = 3000 Pa, ν = 0.3, 1000 kg/m³; ChainMail \
             constraint 0.3 of the spacing), clamped at x = 0; each of the {} voxel centres of \
             the face x = {l} grabbed and moved {by} mm in −z over {GRAB_FRAMES} frames of 1/30 s \
             and held. Reference: `corotational-fem` static on the step-1 proxy (a node at every \
             voxel centre), CG tolerance 1e-10, static tolerance 1e-8; its largest displacement is \
             {ref_max:.3} mm, its run {:.0} ms. Error: RMS over all {} voxel centres of \
             |u − u_ref| (mm; `max_mm` the largest). Dynamic models run on until no point moves \
             more than {} mm in {} frames (at most {} frames after the grab); their time is the \
             whole run. `step` is the proxy step in voxels (mm here; P2 adds a node mid-edge, \
             so its node spacing is step/2). Defaults (a row whose first frame is the plugin's \
             with no key but the materials): {}; ChainMail one element per voxel.",
            (m + 1) * (m + 1),
            reference.time_ms,
            beam.points.len(),
            settle.tolerance_mm,
            settle.check_every,
            settle.max_frames,
            defaults_phrase(&default_rows),
        ),
        points: out,
    })
}
