//! Corotational FEM benchmarks (`cargo bench -p voxflex-corotational-fem`).
//!
//! Prints, on this machine:
//! - the implicit step with exactly 20 CG iterations on ~20 k tetrahedra
//!   (a box of 20 × 20 × 10 cells), median of 15 steps, and its parts;
//! - the cantilever of `tests/reference/cantilever.json`: for each mesh
//!   level and CG tolerance, the static solve's time and its tip error
//!   against the independent linear solution on the same mesh and against
//!   beam theory (u = 4 for the load 1, scaled: the solve uses a small load
//!   so rotations stay negligible).
//!
//! `-- step` or `-- cantilever` runs one part.

use std::time::Instant;
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::mesh_model::{ElasticMaterial, MeshModel, cantilever};
use voxflex_core::proxy::uniform_proxy;
use voxflex_corotational_fem::{CorotationalFem, FemParams, SolverKind};

type Fem = MeshModel<CorotationalFem>;

fn frame(dt: f64) -> FrameInfo {
    FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: dt,
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn implicit_step() {
    // 20 × 20 × 10 cells of 2 mm, five tetrahedra each: 20,000.
    let grid = Grid::new([21, 21, 11], DVec3::splat(2.0), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).expect("box");
    let (nodes, tets) = (mesh.nodes.len(), mesh.tets.len());
    let params = FemParams {
        solver: SolverKind::Dynamic,
        cg_tolerance: 1e-30,
        cg_max_iterations: 20,
        ..FemParams::default()
    };
    let material = ElasticMaterial::new(3000.0, 0.45, 1e-6);
    let mut m =
        Fem::with_mesh(mesh, vec![material], DVec3::new(0.0, 0.0, -9810.0), params).expect("model");
    m.interact("kind = \"fix\"\nmin = [-1, -1, -1]\nmax = [0.5, 41, 21]")
        .unwrap();
    m.interact("kind = \"grab\"\npoint = [40, 20, 20]\nby = [0, 0, 15]\nframes = 30")
        .unwrap();
    let mut times = Vec::new();
    for i in 0..20 {
        let t = Instant::now();
        m.step(frame(1.0 / 30.0)).unwrap();
        if i >= 5 {
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    let r = m.last_solve();
    println!(
        "implicit step, {tets} tetrahedra, {nodes} nodes, {} CG iterations: {:.2} ms (median of {}, min {:.2}, max {:.2})",
        r.iterations,
        median(times.clone()),
        times.len(),
        times.iter().copied().fold(f64::INFINITY, f64::min),
        times.iter().copied().fold(0.0, f64::max),
    );
}

fn cantilever() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/reference/cantilever.json"
    );
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("reference")).expect("JSON");
    println!("cantilever (E = 1000, ν = 0.3, 10 × 1 × 1, tip traction; static solve, small load):");
    println!(
        "   r  tetrahedra  CG tolerance  time (ms)  CG iterations  tip u/P  rel. error vs same mesh  vs beam theory (4)"
    );
    for level in reference["levels"].as_array().unwrap() {
        let r = level["r"].as_u64().unwrap() as usize;
        let expected = level["tip_uz_mean"].as_f64().unwrap();
        for tolerance in [1e-3, 1e-6, 1e-9] {
            // The fastest of three solves (the first warms caches and threads).
            let runs: Vec<(f64, f64, u32, usize)> = (0..3).map(|_| solve(r, tolerance)).collect();
            let (ms, tip, iterations, tets) = runs
                .iter()
                .copied()
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap();
            println!(
                "{r:4}  {tets:10}  {tolerance:12.0e}  {ms:9.2}  {iterations:13}  {tip:7.4}  {:22.2e}  {:17.2} %",
                (tip - expected).abs() / expected.abs(),
                100.0 * (tip + 4.0).abs() / 4.0,
            );
        }
    }
}

/// One static cantilever solve at level `r`: (ms, mean tip u_z / P, CG
/// iterations, tetrahedra).
fn solve(r: usize, tolerance: f64) -> (f64, f64, u32, usize) {
    let params = FemParams {
        solver: SolverKind::Static,
        cg_tolerance: tolerance,
        cg_max_iterations: 100_000,
        static_iterations: 2,
        ..FemParams::default()
    };
    let p = 1e-4;
    let mut m = cantilever::model::<CorotationalFem>(r, p, params);
    let tets = m.mesh().unwrap().tets.len();
    let t = Instant::now();
    m.step(frame(0.0)).unwrap();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let tip = cantilever::tip_deflection(m.mesh().unwrap(), &m.state().unwrap().u) / p;
    (ms, tip, m.last_solve().iterations, tets)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let only = |k: &str| args.iter().any(|a| a == k);
    let all = !only("step") && !only("cantilever");
    println!(
        "voxflex-corotational-fem bench: threads {}",
        rayon::current_num_threads()
    );
    if all || only("step") {
        implicit_step();
    }
    if all || only("cantilever") {
        cantilever();
    }
}
