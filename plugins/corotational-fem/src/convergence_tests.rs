//! The static solve converges, or says so (issue 12): the slender
//! cantilever 8 × 1 × 0.5 mm under the default settings against the same
//! mesh solved to a tight tolerance with block Jacobi and a huge cap; the
//! static solve under large rotation against the Euler elastica; mirrored
//! loads give mirrored tips; unconverged solves are counted and a load the
//! static solve cannot carry is refused.

use crate::solver::{CorotationalFem, FemParams, PreconditionerKind, SolverKind};
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_mesh::mesh_model::elastica;
use voxflex_mesh::mesh_model::{ElasticMaterial, MeshModel};
use voxflex_mesh::proxy::uniform_proxy;

type Fem = MeshModel<CorotationalFem>;

/// Beam length, width (y) and thickness (z), mm.
const L: f64 = 8.0;
const W: f64 = 1.0;
const T: f64 = 0.5;

fn frame() -> FrameInfo {
    FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: 0.0,
    }
}

/// The beam meshed with cells of `h` mm (five tetrahedra each), E = 1000
/// Pa, ν = 0.3, clamped at x = 0, with a total force `p` µN in −z spread
/// over the face x = L as a traction.
fn beam(h: f64, p: f64, params: FemParams) -> Fem {
    beam_held(h, p, params, true)
}

/// [`beam`], clamped or not.
fn beam_held(h: f64, p: f64, params: FemParams, clamped: bool) -> Fem {
    let cells = [L / h, W / h, T / h].map(|c| c.round() as usize + 1);
    let grid = Grid::new(cells, DVec3::splat(h), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
    let mut m = Fem::with_mesh(
        mesh,
        vec![ElasticMaterial::new(1000.0, 0.3, 1e-6)],
        DVec3::ZERO,
        params,
    )
    .unwrap();
    if clamped {
        m.interact("kind = \"fix\"\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, 1.01, 0.51]")
            .unwrap();
    }
    m.interact(&format!(
        "kind = \"load\"\nmin = [7.99, -0.01, -0.01]\nmax = [8.01, 1.01, 0.51]\ntraction = [0, 0, {}]",
        -p / (W * T)
    ))
    .unwrap();
    m
}

/// The mean position (mm) of the nodes on the face x = L.
fn tip(m: &Fem) -> DVec3 {
    let mesh = m.mesh().unwrap();
    let u = &m.state().unwrap().u;
    let (sum, n) = mesh
        .nodes
        .iter()
        .zip(u)
        .filter(|(x, _)| (x.x - L).abs() < 1e-9)
        .fold((DVec3::ZERO, 0), |(s, n), (x, d)| (s + *x + *d, n + 1));
    sum / n as f64
}

fn static_default() -> FemParams {
    FemParams {
        solver: SolverKind::Static,
        ..FemParams::default()
    }
}

fn tight_block_jacobi() -> FemParams {
    FemParams {
        solver: SolverKind::Static,
        cg_tolerance: 1e-11,
        cg_max_iterations: Some(100_000),
        preconditioner: PreconditionerKind::BlockJacobi,
        static_tolerance: 1e-10,
        ..FemParams::default()
    }
}

#[test]
fn the_slender_cantilever_converges_with_the_default_settings() {
    // A small load (tip deflection ~1 % of the length): the linear regime.
    let p = 0.01;
    for h in [0.25, 0.125] {
        let mut m = beam(h, p, static_default());
        m.step(frame()).unwrap();
        let mut reference = beam(h, p, tight_block_jacobi());
        reference.step(frame()).unwrap();
        let (got, want) = (tip(&m).z - T / 2.0, tip(&reference).z - T / 2.0);
        assert!(want < -0.01, "h = {h}: the reference deflects ({want} mm)");
        assert!(
            (got - want).abs() <= 1e-4 * want.abs(),
            "h = {h}: tip deflection {got:.6e} mm against the converged {want:.6e} mm \
             ({:.1} %)",
            100.0 * got / want
        );
        // Converged to the static tolerance, every linear solve to the
        // tolerance it was held to (Newton directions near convergence
        // stop early: inexact Newton).
        let notes = m.notes().unwrap();
        assert!(notes["newton_force_residual"] <= 1e-6, "h = {h}: {notes:?}");
        assert_eq!(notes["unconverged_solves"], 0.0, "h = {h}: {notes:?}");
    }
}

#[test]
fn the_static_solve_follows_the_elastica_under_large_rotation() {
    let h = 0.25;
    // EI of this mesh: P1 tetrahedra lock in bending, so the mesh is
    // stiffer than the beam; its small-load response (δ = P L³ / 3 EI)
    // measures the bending stiffness it has, which removes the
    // discretisation's stiffness error from the comparison.
    let small = 1e-4;
    let mut m = beam(h, small, static_default());
    m.step(frame()).unwrap();
    let delta = T / 2.0 - tip(&m).z;
    let ei = small * L.powi(3) / (3.0 * delta);
    let beam_ei = 1000.0 * W * T.powi(3) / 12.0;
    assert!(
        ei > beam_ei && ei < 3.0 * beam_ei,
        "EI of the mesh {ei} vs beam {beam_ei}"
    );
    for alpha in [3.0, 10.0, 30.0] {
        assert_follows_elastica("P1", h, ei, alpha, static_default(), 0.02);
    }
}

/// Loads the beam (cells `h` mm) to `P L² / EI = alpha` with bending
/// stiffness `ei` (µN·mm²) and asserts its tip is within `tol` L of the
/// elastica's on both axes, with the Newton loop and every linear solve
/// converged.
fn assert_follows_elastica(label: &str, h: f64, ei: f64, alpha: f64, params: FemParams, tol: f64) {
    let p = alpha * ei / (L * L);
    let mut m = beam(h, p, params);
    m.step(frame()).unwrap();
    let (ex, ez) = elastica::tip(alpha);
    let got = tip(&m);
    let (dx, dz) = (got.x / L - ex, (got.z - T / 2.0) / L - ez);
    let notes = m.notes().unwrap();
    eprintln!(
        "{label} α = {alpha}: tip ({:.4}, {:.4}) L vs elastica ({ex:.4}, {ez:.4}) L; {notes:?}",
        got.x / L,
        (got.z - T / 2.0) / L
    );
    assert!(
        dx.abs() <= tol && dz.abs() <= tol,
        "{label} α = {alpha}: tip ({:.4}, {:.4}) L, elastica ({ex:.4}, {ez:.4}) L",
        got.x / L,
        (got.z - T / 2.0) / L
    );
    assert!(notes["newton_force_residual"] <= 1e-6, "{notes:?}");
    assert_eq!(notes["unconverged_solves"], 0.0, "{notes:?}");
}

#[test]
fn p2_follows_the_elastica_with_the_beams_own_bending_stiffness() {
    // Quadratic tetrahedra do not lock: no EI measured from the mesh, the
    // beam's own EI = E W T³ / 12, under large rotation (static Newton
    // with the per-Gauss-point twist tangent).
    let h = 0.25;
    let ei = 1000.0 * W * T.powi(3) / 12.0;
    let params = FemParams {
        element: crate::ElementKind::P2,
        ..static_default()
    };
    for alpha in [3.0, 10.0] {
        assert_follows_elastica("P2", h, ei, alpha, params.clone(), 0.01);
    }
}

#[test]
fn loads_of_opposite_sign_give_mirrored_tips() {
    let h = 0.25;
    let p = 0.5;
    let mut down = beam(h, p, static_default());
    down.step(frame()).unwrap();
    let mut up = beam(h, -p, static_default());
    up.step(frame()).unwrap();
    let (a, b) = (tip(&down), tip(&up));
    let deflection = T / 2.0 - a.z;
    assert!(deflection > 1.0, "a large deflection ({deflection} mm)");
    assert!(
        (a.x - b.x).abs() <= 1e-5 * deflection
            && (a.z - T / 2.0 + b.z - T / 2.0).abs() <= 1e-5 * deflection
            && (a.y - b.y).abs() <= 1e-5 * deflection,
        "down {a}, up {b}"
    );
}

#[test]
fn a_load_the_static_solve_cannot_carry_is_refused_naming_what_to_change() {
    // A beam that nothing holds has no static equilibrium under a load:
    // the solve gives up with an error, not a wrong state.
    let params = FemParams {
        static_iterations: 3,
        ..static_default()
    };
    let mut m = beam_held(0.5, 0.1, params, false);
    let e = m.step(frame()).unwrap_err().0;
    assert!(
        e.contains("did not converge")
            && e.contains("static_iterations")
            && e.contains("solver = \"dynamic\"")
            && e.contains("frames"),
        "{e}"
    );
    let u = &m.state().unwrap().u;
    assert!(u.iter().all(|v| v.is_finite()));
}

#[test]
fn an_unconverged_linear_solve_is_counted_in_the_notes() {
    let params = FemParams {
        cg_max_iterations: Some(3),
        preconditioner: PreconditionerKind::BlockJacobi,
        ..FemParams::default()
    };
    let mut m = beam(0.25, 0.01, params);
    m.step(FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: 1.0 / 30.0,
    })
    .unwrap();
    let notes = m.notes().unwrap();
    assert_eq!(notes["unconverged_solves"], 1.0, "{notes:?}");
    assert!(notes["worst_residual"] > 1e-6, "{notes:?}");
    assert_eq!(notes["worst_residual"], notes["last_residual"], "{notes:?}");
}

/// The interactive static solve (`static_lag`, one Newton iteration a
/// frame) under a held load, both ways: it lags, counts and warns about
/// the frames that end above the tolerance, and catches up with the
/// converged solve's tip (mirrored for the mirrored load).
#[test]
fn the_lagged_static_solve_catches_up_with_the_converged_one_both_ways() {
    let (h, p) = (0.5, 0.05);
    let lagged = FemParams {
        static_lag: true,
        static_iterations: 1,
        ..static_default()
    };
    let mut tips = vec![];
    for sign in [1.0, -1.0] {
        let mut settled = beam(h, sign * p, static_default());
        settled.step(frame()).unwrap();
        let want = tip(&settled);
        let mut m = beam(h, sign * p, lagged.clone());
        let mut frames = 0;
        loop {
            m.step(FrameInfo {
                frame: frames,
                frames: 100,
                dt_s: 0.0,
            })
            .unwrap();
            frames += 1;
            let notes = m.notes().unwrap();
            if notes["newton_force_residual"] <= lagged.static_tolerance || frames == 100 {
                break;
            }
        }
        let notes = m.notes().unwrap();
        let got = tip(&m);
        let deflection = (want.z - T / 2.0).abs();
        eprintln!(
            "sign {sign}: caught up in {frames} frames, {} lagged; tip {got} against {want}",
            notes["lagged_frames"]
        );
        assert!(frames > 1 && frames < 100, "{frames} frames");
        assert_eq!(notes["lagged_frames"], (frames - 1) as f64);
        assert_eq!(notes["newton_iterations"], frames as f64);
        assert!(
            (got - want).length() <= 1e-4 * deflection,
            "{got} against {want}"
        );
        tips.push(got);
    }
    // Opposite ways, by the same amount to the mesh's own asymmetry (its
    // five-tetrahedra cells are not mirror images in z).
    let (a, b) = (tips[0].z - T / 2.0, tips[1].z - T / 2.0);
    assert!(a < 0.0 && b > 0.0 && (a + b).abs() <= 1e-3 * b, "{a} {b}");
}

#[test]
fn static_lag_needs_the_static_solver() {
    let params = FemParams {
        static_lag: true,
        ..FemParams::default()
    };
    let grid = Grid::new([3, 3, 3], DVec3::ONE, DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).unwrap();
    let e = Fem::with_mesh(
        mesh,
        vec![ElasticMaterial::new(1000.0, 0.3, 1e-6)],
        DVec3::ZERO,
        params,
    )
    .err()
    .expect("refused")
    .0;
    assert!(
        e.contains("static_lag") && e.contains("solver = \"static\""),
        "{e}"
    );
}
