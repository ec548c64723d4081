//! The `two_material` front: the `grab` front's beam and grab with a stiff
//! inclusion in it ([`Beam::two_material`]: a rod [`STIFFNESS_RATIO`] ×
//! stiffer than the beam, labelled by voxel value through the scene's
//! `materials` tables), whose interfaces lie on no cell face of the
//! measured proxy steps: a coarse proxy cell takes one material, so it
//! mis-assigns the voxels of the other (`voxels_lost`) — the material
//! resolution the one-material fronts cannot see.
//!
//! Reference: `corotational-fem` P2 static on the step-1 proxy (each cell
//! between neighbouring voxel centres, so the inclusion's faces lie on cell
//! faces; nodes 0.5 mm apart), tight tolerances. Its convergence is
//! checked against a second fine solve of the same body that shares none
//! of its discretisation: P1 on the step-1 proxy of the same beam labelled
//! on 0.5 mm voxels (8× the tetrahedra, the same node spacing); their gap
//! (`ref_gap_mm`, RMS; `ref_gap_max_mm`) bounds the reference's error and
//! sits in every row. Rows: FEM P1 and P2, static and dynamic (the
//! default solver), mass-spring implicit (its default integrator) and
//! ChainMail, as in the grab front ([`grab::rows`]).

use super::Front;
use super::beam::{
    Beam, GRAB_FRAMES, MATERIALS_TWO_CHAINMAIL, MATERIALS_TWO_MESH, STIFFNESS_RATIO,
};
use super::grab::{self, GrabProblem, MESH_MODELS, ModelSpec};
use super::runner::Plugins;
use crate::bench::BenchError;

/// Voxel size (mm) of the convergence check's label volume.
const CHECK_SPACING: f64 = 0.5;

/// The two-material front.
pub(super) fn front(plugins: &Plugins, quick: bool) -> Result<Front, BenchError> {
    let beam = Beam::two_material(quick, 1.0);
    let inclusion = beam
        .inclusion
        .ok_or_else(|| BenchError("the two-material beam has no inclusion".into()))?;
    let problem =
        GrabProblem::half_depth(&beam, quick, MATERIALS_TWO_MESH, MATERIALS_TWO_CHAINMAIL);
    let (m, l, w, by) = (beam.m, beam.length, beam.width, -problem.by.z);
    let defaults = grab::defaults(plugins, &problem)?;
    let reference = grab::fine_solve(plugins, &problem, &beam, "p2", 1)?;
    let fine = Beam::two_material(quick, CHECK_SPACING);
    let check = grab::fine_solve(plugins, &problem, &fine, "p1", 1)?;
    let (gap, gap_max) = grab::errors(&check.u, &reference.u);
    let ref_max = grab::largest(&reference.u);
    let models: Vec<&ModelSpec> = MESH_MODELS
        .iter()
        .filter(|s| s.series != "mass-spring explicit")
        .collect();
    let (out, default_rows) = grab::rows(
        plugins,
        &problem,
        &models,
        &defaults,
        &reference.u,
        &[
            ("ref_gap_mm", format!("{gap:.3e}")),
            ("ref_gap_max_mm", format!("{gap_max:.3e}")),
        ],
    )?;
    let settle = problem.settle;
    let [x0, y0, z0] = inclusion.lo;
    let [x1, y1, z1] = inclusion.hi;
    Ok(Front {
        key: "two_material",
        title: "two materials: FEM, mass-spring, ChainMail vs fine FEM".into(),
        error_label: "RMS |u − u_ref|, mm".into(),
        description: format!(
            "The grab front's {l} × {w} × {w} mm beam (voxels of 1 mm, E = 3000 Pa, ν = 0.3, \
             1000 kg/m³) with a stiff rod inside, the voxel centres in x ∈ ({x0}, {x1}], \
             y ∈ ({y0}, {y1}], z ∈ ({z0}, {z1}] mm: E × {STIFFNESS_RATIO} (same ν, density; \
             ChainMail constraint 0.3 of the spacing soft, 0.03 stiff), the two labelled by voxel \
             value through the `materials` tables as a scene labels a CT. Its faces lie on the \
             cell faces of step 1 and of no measured step (a cell takes its voxels' most \
             frequent material; `voxels_lost` counts the voxels a proxy gives the other \
             material). Clamped at x = 0; each of the {} voxel centres of the face x = {l} \
             grabbed and moved {by} mm in −z over {GRAB_FRAMES} frames of 1/30 s and held. \
             Reference: `corotational-fem` P2 static on the step-1 proxy (nodes 0.5 mm apart), \
             CG tolerance 1e-10, static tolerance 1e-8; largest displacement {ref_max:.3} mm, \
             run {:.0} ms. Its check: P1 static on the step-1 proxy of the same body labelled on \
             {CHECK_SPACING} mm voxels ({} tetrahedra against the reference's {}; run {:.0} ms) \
             lies {gap:.2e} mm RMS ({gap_max:.2e} mm max) from it (`ref_gap_mm`). Error: RMS over \
             all {} voxel centres of |u − u_ref| (mm; `max_mm` the largest). Dynamic models run on \
             until no point moves more than {} mm in {} frames (at most {} frames after the \
             grab); their time is the whole run. `step` is the proxy step in voxels (P2's node \
             spacing is step/2). Defaults (a row whose first frame is the plugin's with no key \
             but the materials): {}; ChainMail one element per voxel.",
            (m + 1) * (m + 1),
            reference.time_ms,
            check.notes.get("proxy_tetrahedra").copied().unwrap_or(0.0),
            reference
                .notes
                .get("proxy_tetrahedra")
                .copied()
                .unwrap_or(0.0),
            check.time_ms,
            beam.points.len(),
            settle.tolerance_mm,
            settle.check_every,
            settle.max_frames,
            grab::defaults_phrase(&default_rows),
        ),
        points: out,
    })
}
