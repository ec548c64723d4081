//! The `cut` front: ChainMail, mass-spring and corotational FEM on the same
//! complete cut of a soft beam, against the analytic answer.
//!
//! The beam is a block of 4m × m × m voxels of 1 mm (m = 12; 4 in
//! `--quick`), one soft material (the `grab` front's), clamped at x = 0
//! (the face's voxel centres). At frame 0 a plane cuts the whole
//! cross-section at x = c = 2m + 2.37 mm — between two voxel centres, and
//! on no element layer or proxy node plane of any down-sampling or step
//! measured — and every voxel centre of the face x = 4m is grabbed and
//! moved by d = m/2 mm in +y over 10 frames and held. Nothing then joins
//! the two pieces: the right one is free but for the grab, so at rest it
//! has translated by d; the left one is held at x = 0 and nothing pulls it,
//! so it has not moved. Error: the RMS (and max) over every voxel centre of
//! |u − u_exact|, mm; `wrong_side` counts the voxel centres that moved
//! with the other piece (within |d|/10 of its motion), `blurred` those that
//! did not move with their own (farther than |d|/10), `far_rms_mm` is
//! the RMS over those more than 6 mm (the coarsest cell) from the plane
//! (how far the pieces are from rigid rest, apart from the cut's
//! sharpness). Every model runs on after the grab until no point moves
//! more than 1e-3 mm over 10 frames (capped); its time is the whole run.

use super::beam::{Beam, GRAB_FRAMES, MATERIAL_CHAINMAIL, MATERIAL_MESH};
use super::fem;
use super::runner::{self, Plugins, Scene};
use super::{Front, Point, Tuning};
use crate::bench::BenchError;
use voxflex_core::glam::DVec3;

/// The cut planes' offsets from the beam's middle, mm: fractions that put
/// them on no voxel centre, element layer or proxy node plane, one either
/// side of the half-voxel (the same voxels on each side of both, but each
/// proxy's tetrahedra split differently).
const CUT_OFFSETS_MM: [f64; 2] = [2.37, 2.63];

/// Voxel centres this far from the plane, mm, or farther, are "far":
/// outside every proxy cell (step ≤ 6) and element gap (downsample ≤ 4)
/// the plane crosses.
const FAR_MM: f64 = 6.0;

/// A voxel centre moved with a piece when its displacement lies within
/// this fraction of |d| of the piece's.
const WITH_MOTION: f64 = 0.1;

/// A mesh model of the front: series label, plugin, extra params (none:
/// the plugin's default solver).
struct MeshSpec {
    series: &'static str,
    plugin: &'static str,
}

const MESH_MODELS: &[MeshSpec] = &[
    MeshSpec {
        series: "FEM dynamic",
        plugin: "corotational-fem",
    },
    MeshSpec {
        series: "mass-spring",
        plugin: "mass-spring",
    },
];

/// The error of a run against the analytic answer.
#[derive(Clone, Copy, Debug, PartialEq)]
struct CutError {
    /// RMS over all voxel centres of |u − u_exact|, mm.
    rms_mm: f64,
    /// Largest |u − u_exact|, mm.
    max_mm: f64,
    /// Voxel centres that moved with the other piece (within
    /// [`WITH_MOTION`] of its motion).
    wrong_side: usize,
    /// Voxel centres that did not move with their own piece (farther than
    /// [`WITH_MOTION`] from its motion); the wrong-side ones included.
    blurred: usize,
    /// RMS over the voxel centres farther than [`FAR_MM`] from the plane,
    /// mm.
    far_rms_mm: f64,
}

/// The exact displacement of the voxel centre `p` (mm): `d` right of the
/// plane x = `c`, zero left of it; and the other piece's.
fn exact(p: [f32; 3], c: f64, d: DVec3) -> (DVec3, DVec3) {
    if p[0] as f64 > c {
        (d, DVec3::ZERO)
    } else {
        (DVec3::ZERO, d)
    }
}

/// Compares the displacements `u` of `points` (mm) with the analytic
/// answer for a cut at x = `c` and a grab by `d`.
fn cut_error(points: &[[f32; 3]], u: &[DVec3], c: f64, d: DVec3) -> CutError {
    let (mut sum, mut max, mut wrong, mut blurred) = (0.0, 0.0f64, 0, 0);
    let (mut far_sum, mut far_n) = (0.0, 0usize);
    let near = WITH_MOTION * d.length();
    for (p, u) in points.iter().zip(u) {
        let (own, other) = exact(*p, c, d);
        let e = (*u - own).length();
        sum += e * e;
        max = max.max(e);
        wrong += usize::from((*u - other).length() <= near);
        blurred += usize::from(e > near);
        if (p[0] as f64 - c).abs() > FAR_MM {
            far_sum += e * e;
            far_n += 1;
        }
    }
    CutError {
        rms_mm: (sum / points.len().max(1) as f64).sqrt(),
        max_mm: max,
        wrong_side: wrong,
        blurred,
        far_rms_mm: (far_sum / far_n.max(1) as f64).sqrt(),
    }
}

/// The proxy a run built, as the plugin reports it (nodes, tetrahedra):
/// a row is the plugin's default when its proxy is the one the plugin
/// builds with no `proxy` key (each plugin has its own default spacing).
fn proxy_of(run: &runner::Outcome) -> (String, String) {
    (
        runner::note(&run.notes, "proxy_nodes"),
        runner::note(&run.notes, "proxy_tetrahedra"),
    )
}

/// The cut front.
pub(super) fn front(plugins: &Plugins, quick: bool) -> Result<Front, BenchError> {
    // The quick steps hold both mesh plugins' defaults (3 and 4).
    let steps: &[usize] = if quick { &[4, 3, 2] } else { &[6, 4, 3, 2] };
    let downsamples: &[usize] = if quick { &[2, 1] } else { &[4, 3, 2, 1] };
    let beam = Beam::new(quick);
    let settle = beam.settle(quick, 1500);
    let (m, l, w) = (beam.m, beam.length, beam.width);
    let d = DVec3::new(0.0, 0.5 * m as f64, 0.0);
    let (volume, points) = (&beam.volume, &beam.points);
    let mut out = vec![];
    let cuts: Vec<f64> = CUT_OFFSETS_MM.iter().map(|o| 0.5 * l + o).collect();
    for &c in &cuts {
        let group = format!("cut at x = {c:.2} mm");
        let mut interactions = beam.fix_and_grab(d);
        // The cut after the grabs (same frame, before any step): the grabbed
        // piece is never without an anchor.
        interactions.push((
            0,
            format!(
                "kind = \"cut\"\npolygon = [[{c}, -1, -1], [{c}, {0}, -1], [{c}, {0}, {0}], \
                 [{c}, -1, {0}]]",
                w + 1.0
            ),
        ));
        let scene = |plugin, params: String| Scene {
            plugin,
            params,
            volume,
            points,
            interactions: interactions.clone(),
            frames: GRAB_FRAMES,
            dt_s: 1.0 / 30.0,
            settle: Some(settle),
        };
        let mut push = |series: &str,
                        config: String,
                        run: &runner::Outcome,
                        is_default: bool,
                        tuning: Option<Tuning>,
                        mut extra: Vec<(&'static str, String)>| {
            let e = cut_error(points, &run.u, c, d);
            let mut ex = vec![
                ("cut_x_mm", format!("{c:.2}")),
                ("rms_mm", format!("{:.3e}", e.rms_mm)),
                ("max_mm", format!("{:.4}", e.max_mm)),
                ("wrong_side", e.wrong_side.to_string()),
                ("blurred", e.blurred.to_string()),
                ("far_rms_mm", format!("{:.4}", e.far_rms_mm)),
                ("frames", run.frames.to_string()),
                ("settled", run.settled.to_string()),
            ];
            ex.append(&mut extra);
            out.push(Point {
                series: series.to_string(),
                config,
                time_ms: run.time_ms,
                // Below the settle tolerance the runs cannot tell answers
                // apart: they stop once nothing moves more than that.
                error: e.rms_mm.max(settle.tolerance_mm),
                is_default,
                group: group.clone(),
                extra: ex,
                tuning,
            });
        };
        for spec in MESH_MODELS {
            let default_proxy = proxy_of(&runner::run(
                plugins,
                &scene(spec.plugin, MATERIAL_MESH.into()),
            )?);
            for &step in steps {
                let params = format!(
                    "proxy = {{ kind = \"uniform\", step = {step} }}\n{}",
                    MATERIAL_MESH
                );
                let run = runner::run(plugins, &scene(spec.plugin, params))?;
                let extra = vec![
                    ("step", step.to_string()),
                    ("tetrahedra", runner::note(&run.notes, "proxy_tetrahedra")),
                    ("proxy_nodes", runner::note(&run.notes, "proxy_nodes")),
                    ("substeps", runner::note(&run.notes, "substeps")),
                    ("downsample", String::new()),
                    ("removed_tetrahedra", String::new()),
                    (
                        "cut_voxels_across",
                        runner::note(&run.notes, "cut_voxels_across"),
                    ),
                    (
                        "cut_voxels_rebound",
                        runner::note(&run.notes, "cut_voxels_rebound"),
                    ),
                ];
                push(
                    spec.series,
                    format!("step {step}"),
                    &run,
                    proxy_of(&run) == default_proxy,
                    // The plugin's default element (no `element` key).
                    Some(Tuning::new(spec.plugin, fem::DEFAULT_ELEMENT, step)),
                    extra,
                );
            }
        }
        // ChainMail's default down-sampling, as the plugin reports it after a
        // run whose params leave it out; that run is the default's row.
        let default_run = runner::run(plugins, &scene("chainmail", MATERIAL_CHAINMAIL.into()))?;
        let default_downsample = default_run
            .notes
            .get("downsample")
            .map(|&v| v as usize)
            .ok_or_else(|| crate::bench::err("chainmail reports no `downsample` note"))?;
        for &ds in downsamples {
            let explicit;
            let run = if ds == default_downsample {
                &default_run
            } else {
                explicit = runner::run(
                    plugins,
                    &scene(
                        "chainmail",
                        format!("{}\ndownsample = {ds}", MATERIAL_CHAINMAIL),
                    ),
                )?;
                &explicit
            };
            let extra = vec![
                ("step", String::new()),
                ("tetrahedra", String::new()),
                ("proxy_nodes", String::new()),
                ("substeps", String::new()),
                ("downsample", ds.to_string()),
                (
                    "removed_tetrahedra",
                    runner::note(&run.notes, "removed_tetrahedra"),
                ),
                ("cut_voxels_across", String::new()),
                ("cut_voxels_rebound", String::new()),
            ];
            push(
                "ChainMail c = 0.3",
                format!("downsample {ds}"),
                run,
                ds == default_downsample,
                None,
                extra,
            );
        }
    }
    let cuts_text = cuts
        .iter()
        .map(|c| format!("x = {c:.2}"))
        .collect::<Vec<_>>()
        .join(" and ");
    Ok(Front {
        key: "cut",
        title: "the same cut: ChainMail, mass-spring, FEM vs rigid pieces".into(),
        error_label: "RMS |u − u_exact|, mm".into(),
        description: format!(
            "A {l} × {w} × {w} mm beam (voxels of 1 mm, E = 3000 Pa, ν = 0.3, 1000 kg/m³; \
             ChainMail constraint 0.3 of the spacing), clamped at x = 0 and cut through its whole \
             cross-section at frame 0 by the plane {cuts_text} mm (one problem each: between the \
             same two voxel layers, on no element layer or proxy node plane, splitting the \
             proxies' tetrahedra differently); then each of the {} voxel centres of the face \
             x = {l} grabbed and moved {} mm in +y over {GRAB_FRAMES} frames of 1/30 s and held. \
             Analytic answer: the piece right of the plane translates rigidly by the grab, the \
             voxel centres left of it stay still. Error: RMS over all {} voxel centres of \
             |u − u_exact| (mm), ranked and drawn no lower than the settle tolerance ({} mm: \
             below it the runs, which stop once nothing moves more than that, cannot tell answers \
             apart; `rms_mm` is the RMS as measured, `max_mm` the largest; `wrong_side` the voxel centres that moved \
             with the other piece, within |d|/10 of its motion; `blurred` those farther than \
             |d|/10 from their own piece's, the wrong-side ones included; `far_rms_mm` the RMS \
             more than {FAR_MM} mm from the plane). Every model runs on until no point moves more than {} mm in {} \
             frames (at most {} frames after the grab); its time is the whole run. `step` is the \
             proxy step in voxels (the mesh models' default solver, default step ringed), \
             `downsample` ChainMail's voxels per element (default ringed); `proxy_nodes` counts \
             the nodes after the cut duplicated those on it; `cut_voxels_rebound` the voxel \
             centres a mesh model's cut found carried by a tetrahedron across the plane and bound \
             to one of their own side, `cut_voxels_across` those it left there; \
             `removed_tetrahedra` the sampling-mesh tetrahedra ChainMail's cut removed (tissue \
             no longer drawn).",
            (m + 1) * (m + 1),
            d.length(),
            points.len(),
            settle.tolerance_mm,
            settle.tolerance_mm,
            settle.check_every,
            settle.max_frames
        ),
        points: out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exact_answer_moves_only_the_right_piece() {
        let d = DVec3::new(0.0, 6.0, 0.0);
        let points = [[10.0, 0.0, 0.0], [11.0, 3.0, 0.0], [30.0, 1.0, 1.0]];
        let c = 10.37;
        // The analytic answer itself: no error, nobody blurred or on the
        // wrong side.
        let u: Vec<DVec3> = points.iter().map(|p| exact(*p, c, d).0).collect();
        assert_eq!(u, vec![DVec3::ZERO, d, d]);
        let e = cut_error(&points, &u, c, d);
        assert_eq!(
            (e.rms_mm, e.max_mm, e.wrong_side, e.blurred, e.far_rms_mm),
            (0.0, 0.0, 0, 0, 0.0)
        );
        // The voxel just right of the plane left half way behind: blurred,
        // on neither side, 3 mm off.
        let mut u2 = u.clone();
        u2[1] = 0.5 * d;
        let e = cut_error(&points, &u2, c, d);
        assert_eq!((e.wrong_side, e.blurred), (0, 1));
        assert!((e.max_mm - 3.0).abs() < 1e-12);
        assert!((e.rms_mm - (9.0f64 / 3.0).sqrt()).abs() < 1e-12);
        // Only the point 19.63 mm from the plane is far.
        assert_eq!(e.far_rms_mm, 0.0);
        // Left behind with the still piece: on the wrong side, and far.
        u2[2] = 0.05 * d;
        let e = cut_error(&points, &u2, c, d);
        assert_eq!((e.wrong_side, e.blurred), (1, 2));
        assert!((e.far_rms_mm - 5.7).abs() < 1e-12);
    }

    #[test]
    fn the_cut_plane_is_on_no_element_layer_or_node_plane() {
        for m in [4usize, 12] {
            for o in CUT_OFFSETS_MM {
                let c = 2.0 * m as f64 + o;
                for k in 1..=6 {
                    let r = c / k as f64;
                    assert!((r - r.round()).abs() > 1e-3, "c = {c} on a multiple of {k}");
                }
            }
        }
    }
}
