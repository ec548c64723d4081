//! The run-time/error front of the element choice on issue 12's slender
//! cantilever: the beam 8 × 1 × 0.5 mm (x × y × z), E = 1000 Pa, ν = 0.3,
//! meshed with cubes of `h` mm (five tetrahedra each), clamped at x = 0
//! and loaded by a total force `P` in −z spread over the face x = 8 as a
//! traction, solved statically; its tip deflection against Timoshenko beam
//! theory. [`front_point`] is one row of the table in docs/BENCHMARKS.md
//! (`cargo bench -p voxflex-corotational-fem --bench corotational -- front`)
//! and what `voxflex bench`'s fronts can call per element and resolution.

use crate::solver::{CorotationalFem, ElementKind, FemParams, SolverKind};
use std::time::Instant;
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_mesh::mesh_model::{ElasticMaterial, MeshModel};
use voxflex_mesh::proxy::uniform_proxy;

/// Beam length (x), width (y) and thickness (z), mm.
pub const LENGTH: f64 = 8.0;
/// Beam width (y), mm.
pub const WIDTH: f64 = 1.0;
/// Beam thickness (z), mm.
pub const THICKNESS: f64 = 0.5;
/// Young's modulus, Pa.
pub const YOUNGS_MODULUS: f64 = 1000.0;
/// Poisson ratio.
pub const POISSON_RATIO: f64 = 0.3;
/// The front's tip force, µN: a deflection of 0.2 % of the length, where
/// the corotational solve is linear to well under 0.01 %.
pub const FRONT_LOAD: f64 = 1e-3;

/// The cantilever with cubes of `h` mm, a tip force `p` µN in −z, and the
/// solver's `params` (not solved yet). `h` must divide 0.5 mm.
pub fn cantilever(
    h: f64,
    p: f64,
    params: FemParams,
) -> Result<MeshModel<CorotationalFem>, ModelError> {
    let cells = [LENGTH / h, WIDTH / h, THICKNESS / h];
    if h.is_nan()
        || h <= 0.0
        || cells
            .iter()
            .any(|c| (c - c.round()).abs() > 1e-9 || *c < 1.0)
    {
        return Err(ModelError(format!(
            "cantilever: cell size {h} mm must divide {THICKNESS} mm"
        )));
    }
    let grid = Grid::new(
        cells.map(|c| c.round() as usize + 1),
        DVec3::splat(h),
        DVec3::ZERO,
    );
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).map_err(|e| ModelError(e.to_string()))?;
    let material = ElasticMaterial::new(YOUNGS_MODULUS, POISSON_RATIO, 1e-6);
    let mut m = MeshModel::with_mesh(mesh, vec![material], DVec3::ZERO, params)?;
    let (l, w, t) = (LENGTH, WIDTH, THICKNESS);
    m.interact(&format!(
        "kind = \"fix\"\nmin = [-0.01, -0.01, -0.01]\nmax = [0.01, {}, {}]",
        w + 0.01,
        t + 0.01
    ))?;
    m.interact(&format!(
        "kind = \"load\"\nmin = [{}, -0.01, -0.01]\nmax = [{}, {}, {}]\ntraction = [0, 0, {}]",
        l - 0.01,
        l + 0.01,
        w + 0.01,
        t + 0.01,
        -p / (w * t)
    ))?;
    Ok(m)
}

/// The mean displacement (mm) of the proxy nodes on the face x = L.
pub fn tip_displacement(m: &MeshModel<CorotationalFem>) -> DVec3 {
    let (Some(mesh), Some(state)) = (m.mesh(), m.state()) else {
        return DVec3::NAN;
    };
    let (sum, n) = mesh
        .nodes
        .iter()
        .zip(&state.u)
        .filter(|(x, _)| (x.x - LENGTH).abs() < 1e-9)
        .fold((DVec3::ZERO, 0), |(s, n), (_, d)| (s + *d, n + 1));
    sum / n as f64
}

/// Timoshenko's tip deflection (mm, positive down) of the cantilever under
/// a tip force `p` µN: `P L³ / 3EI + P L / κGA` with the rectangle's shear
/// coefficient `κ = 10 (1 + ν) / (12 + 11 ν)` (Cowper 1966).
pub fn timoshenko_tip(p: f64) -> f64 {
    let (e, nu) = (YOUNGS_MODULUS, POISSON_RATIO);
    let i = WIDTH * THICKNESS.powi(3) / 12.0;
    let g = e / (2.0 * (1.0 + nu));
    let kappa = 10.0 * (1.0 + nu) / (12.0 + 11.0 * nu);
    p * LENGTH.powi(3) / (3.0 * e * i) + p * LENGTH / (kappa * g * WIDTH * THICKNESS)
}

/// One point of the front.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrontPoint {
    /// The element.
    pub element: ElementKind,
    /// Cube edge of the proxy, mm.
    pub cell_mm: f64,
    /// Tetrahedra of the proxy.
    pub tetrahedra: usize,
    /// Nodes solved for (corners, plus edge nodes for P2).
    pub nodes: usize,
    /// Wall time of building the solver and the static solve, s.
    pub seconds: f64,
    /// Tip deflection (mm, positive down).
    pub tip_mm: f64,
    /// Its relative error against [`timoshenko_tip`] (−0.1 = 10 % too
    /// stiff).
    pub error: f64,
}

/// Solves the cantilever with cubes of `h` mm and `element` under
/// [`FRONT_LOAD`] with the static solver's defaults (CPU), timing the
/// build and the solve.
pub fn front_point(element: ElementKind, h: f64) -> Result<FrontPoint, ModelError> {
    let params = FemParams {
        element,
        solver: SolverKind::Static,
        ..FemParams::default()
    };
    let start = Instant::now();
    let mut m = cantilever(h, FRONT_LOAD, params)?;
    m.step(FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: 0.0,
    })?;
    let seconds = start.elapsed().as_secs_f64();
    let tip_mm = -tip_displacement(&m).z;
    let beam = timoshenko_tip(FRONT_LOAD);
    let solver = m.solver().expect("built");
    Ok(FrontPoint {
        element,
        cell_mm: h,
        tetrahedra: solver.elements(),
        nodes: solver
            .edge_nodes()
            .map_or(m.mesh().map_or(0, |x| x.nodes.len()), |l| l.len()),
        seconds,
        tip_mm,
        error: tip_mm / beam - 1.0,
    })
}
