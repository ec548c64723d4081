//! Mass-spring benchmarks (`cargo bench -p voxflex-mass-spring`).
//!
//! Prints, on this machine:
//! - the explicit sub-step on ~100 k springs (a box of 32 × 32 × 16 cells
//!   of the five-tetrahedra split): time per sub-step, from one frame of
//!   many sub-steps;
//! - the same on an octree proxy, whose hanging nodes pass their forces to
//!   their masters every sub-step;
//! - the cantilever of `tests/reference/cantilever.json` run to rest with
//!   the implicit integrator: time and tip deflection against the same-mesh
//!   linear FEM reference — the error a mass-spring model makes, which
//!   users trade against its speed.
//!
//! - a one-voxel slab in a 128³ volume: the step and the map per frame.
//!
//! `-- substep`, `-- octree`, `-- slab` or `-- cantilever` runs one part.

use std::time::Instant;
use voxflex_core::deformation::{DeformationModel, FrameInfo};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_mass_spring::{Integrator, MassSpring, SpringParams};
use voxflex_mesh::mesh_model::{ElasticMaterial, MeshModel, cantilever};
use voxflex_mesh::proxy::uniform_proxy;

type Springs = MeshModel<MassSpring>;

fn frame(dt: f64) -> FrameInfo {
    FrameInfo {
        frame: 0,
        frames: 1,
        dt_s: dt,
    }
}

fn substep() {
    // With the volume springs (the default) and without (`volume_stiffness
    // = 0`, the springs-only model of before), interleaved.
    for volume_stiffness in [1.0, 0.0, 1.0, 0.0] {
        substep_with(volume_stiffness);
    }
}

fn substep_with(volume_stiffness: f64) {
    let grid = Grid::new([33, 33, 17], DVec3::splat(2.0), DVec3::ZERO);
    let mesh = uniform_proxy(&grid, 1, |_| Some(0)).expect("box");
    let nodes = mesh.nodes.len();
    let material = ElasticMaterial::new(3000.0, 0.45, 1e-6);
    let mut m = Springs::with_mesh(
        mesh,
        vec![material],
        DVec3::new(0.0, 0.0, -9810.0),
        SpringParams {
            volume_stiffness,
            // the sub-step this bench times is the explicit one (the
            // default integrator is implicit: one step a frame)
            integrator: Integrator::Explicit,
            ..SpringParams::default()
        },
    )
    .expect("model");
    m.interact("kind = \"fix\"\nmin = [-1, -1, -1]\nmax = [0.5, 65, 33]")
        .unwrap();
    let springs = m.solver().unwrap().springs().ends.len();
    let tets = m.solver().unwrap().volume_springs().k.len();
    let dt = m.solver().unwrap().stable_dt() * 200.0;
    m.step(frame(dt)).unwrap(); // warm-up
    let mut per = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        m.step(frame(dt)).unwrap();
        per.push(t.elapsed().as_secs_f64() * 1e3 / m.last_solve().substeps as f64);
    }
    per.sort_by(f64::total_cmp);
    println!(
        "explicit sub-step, {springs} springs, {tets} volume springs (volume_stiffness = \
         {volume_stiffness}), {nodes} nodes: {:.3} ms (median of 5 frames of {} sub-steps; min {:.3})",
        per[2],
        m.last_solve().substeps,
        per[0]
    );
}

/// Explicit sub-steps on an octree proxy, whose hanging nodes pass their
/// forces to their masters every sub-step: the rings phantom (33³), soft
/// and hard rings, the hard one fixed, under gravity.
fn octree() {
    use voxflex_core::deformation::ExecutionBackend;
    let volume = voxflex_phantom::phantom("rings", [33, 33, 33]).expect("phantom");
    let mut m = Springs::from_toml(
        "proxy = { kind = \"octree\", max_cell = 8 }\n\
         materials = [{ name = \"soft\", range = [50, 150], youngs_modulus = 2000 },\n\
                      { name = \"hard\", range = [150, 256], youngs_modulus = 20000 }]\n\
         integrator = \"explicit\"\ngravity = [0, 0, -9810]",
    )
    .expect("params");
    m.init(volume.view(), ExecutionBackend::Cpu).expect("init");
    m.interact("kind = \"fix\"\nmaterial = \"hard\"")
        .expect("fix");
    m.step(frame(1.0 / 30.0)).expect("warm-up");
    let mut per = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        m.step(frame(1.0 / 30.0)).expect("step");
        per.push(t.elapsed().as_secs_f64() * 1e3 / m.last_solve().substeps as f64);
    }
    per.sort_by(f64::total_cmp);
    println!(
        "explicit sub-step on an octree proxy ({} nodes, {} tied to masters, {} springs): {:.3} ms \
         (median of 5 frames of {} sub-steps; min {:.3})",
        m.mesh().expect("mesh").nodes.len(),
        m.hanging().len(),
        m.solver().expect("solver").springs().ends.len(),
        per[2],
        m.last_solve().substeps,
        per[0]
    );
}

/// A one-voxel slab in air (issue 12, item 8: "a 1-voxel slab runs at
/// 45 ms/frame"): a 128³ volume of 1 mm voxels, tissue only at z = 64,
/// uniform proxy of step 4, every voxel bound; per frame the solver's step
/// and the map of all 128³ voxels, timed apart, under gravity with the
/// slab's edge x = 0 fixed.
fn slab() {
    use voxflex_core::deformation::{DisplacementTarget, ExecutionBackend, RestPoints};
    use voxflex_core::volume::{Volume, VoxelData};
    let n = 128;
    let grid = Grid::new([n, n, n], DVec3::ONE, DVec3::ZERO);
    let mut data = vec![0f32; grid.len()];
    for j in 0..n {
        for i in 0..n {
            data[grid.linear(i, j, 64)] = 100.0;
        }
    }
    let volume = Volume::new(grid, VoxelData::F32(data)).expect("volume");
    for integrator in ["explicit", "implicit"] {
        let mut m = Springs::from_toml(&format!(
            "proxy = {{ kind = \"uniform\", step = 4 }}\n\
             materials = [{{ range = [50, 200], youngs_modulus = 3000 }}]\n\
             gravity = [0, 0, -9810]\nintegrator = \"{integrator}\""
        ))
        .expect("params");
        let t = Instant::now();
        m.init(volume.view(), ExecutionBackend::Cpu).expect("init");
        let id = m.bind(RestPoints::Lattice(grid)).expect("bind");
        let setup = t.elapsed().as_secs_f64() * 1e3;
        m.interact("kind = \"fix\"\nmin = [-1, -1, -1]\nmax = [0.5, 200, 200]")
            .expect("fix");
        let (mut x, mut y, mut z) = (
            vec![0f32; grid.len()],
            vec![0f32; grid.len()],
            vec![0f32; grid.len()],
        );
        let (mut step, mut map) = (Vec::new(), Vec::new());
        for _ in 0..6 {
            let t = Instant::now();
            m.step(frame(1.0 / 30.0)).expect("step");
            step.push(t.elapsed().as_secs_f64() * 1e3);
            let t = Instant::now();
            m.map(
                id,
                DisplacementTarget::Cpu {
                    x: &mut x,
                    y: &mut y,
                    z: &mut z,
                },
            )
            .expect("map");
            map.push(t.elapsed().as_secs_f64() * 1e3);
        }
        step.sort_by(f64::total_cmp);
        map.sort_by(f64::total_cmp);
        let mesh = m.mesh().expect("mesh");
        println!(
            "1-voxel slab, 128³ voxels, uniform step 4 ({} nodes, {} tetrahedra), {integrator}: \
             proxy and binding {setup:.0} ms; per frame: step {:.2} ms ({} sub-steps), map {:.2} ms \
             (medians of 6)",
            mesh.nodes.len(),
            mesh.tets.len(),
            step[3],
            m.last_solve().substeps,
            map[3]
        );
    }
}

fn cantilever() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/reference/cantilever.json"
    );
    let reference: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).expect("reference")).expect("JSON");
    println!(
        "cantilever (E = 1000, 10 × 1 × 1, tip traction, small load; implicit steps to rest):"
    );
    println!(
        "   r  springs  CG tolerance  time to rest (ms)  steps  tip u/P  error vs same-mesh FEM"
    );
    for level in reference["levels"].as_array().unwrap() {
        let r = level["r"].as_u64().unwrap() as usize;
        if r > 4 {
            continue;
        }
        let expected = level["tip_uz_mean"].as_f64().unwrap();
        for tolerance in [1e-3, 1e-6] {
            let params = SpringParams {
                integrator: Integrator::Implicit,
                cg_tolerance: tolerance,
                cg_max_iterations: 10_000,
                mass_damping: 200.0,
                damping_ratio: 1.0,
                ..SpringParams::default()
            };
            let p = 1e-4;
            let mut m = cantilever::model::<MassSpring>(r, p, params);
            let springs = m.solver().unwrap().springs().ends.len();
            let t = Instant::now();
            let mut steps = 0;
            // To rest: until a step moves no node by more than 1e-9 of the load's scale.
            let mut last = 0.0;
            while steps < 5000 {
                m.step(frame(0.01)).unwrap();
                steps += 1;
                let tip = tip(&m) / p;
                if (tip - last).abs() < 1e-7 * tip.abs() {
                    break;
                }
                last = tip;
            }
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let tip = tip(&m) / p;
            // The whole displacement field against the FEM one, where the
            // reference carries it: RMS and largest node error, relative
            // to the largest FEM displacement.
            let field = level.get("displacements").map(|d| {
                let d = d.as_array().unwrap();
                let mesh = m.mesh().unwrap();
                let u = &m.state().unwrap().u;
                let (mut sum, mut worst, mut largest) = (0.0, 0.0f64, 0.0f64);
                for (x, un) in mesh.nodes.iter().zip(u) {
                    let e = &d[cantilever::reference_node(*x, r)];
                    let e = DVec3::new(
                        e[0].as_f64().unwrap(),
                        e[1].as_f64().unwrap(),
                        e[2].as_f64().unwrap(),
                    );
                    let err = (*un / p - e).length();
                    sum += err * err;
                    worst = worst.max(err);
                    largest = largest.max(e.length());
                }
                let rms = (sum / u.len() as f64).sqrt();
                format!(
                    "   field: RMS {:.1} %, max {:.1} %",
                    100.0 * rms / largest,
                    100.0 * worst / largest
                )
            });
            println!(
                "{r:4}  {springs:7}  {tolerance:12.0e}  {ms:17.1}  {steps:5}  {tip:7.4}  {:20.1} %{}",
                100.0 * (tip - expected) / expected.abs(),
                field.unwrap_or_default()
            );
        }
    }
}

/// Mean u_z of the nodes at x = 10.
fn tip(m: &Springs) -> f64 {
    cantilever::tip_deflection(m.mesh().unwrap(), &m.state().unwrap().u)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let only = |k: &str| args.iter().any(|a| a == k);
    let all = !only("substep") && !only("octree") && !only("cantilever") && !only("slab");
    println!(
        "voxflex-mass-spring bench: threads {}",
        rayon::current_num_threads()
    );
    if all || only("substep") {
        substep();
    }
    if all || only("slab") {
        slab();
    }
    if all || only("octree") {
        octree();
    }
    if all || only("cantilever") {
        cantilever();
    }
}
