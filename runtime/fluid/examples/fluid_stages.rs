//! Where a fluid weighing's time goes: the four stages of
//! [`FluidWeighing`] (project, intersect, match sections, distribute)
//! timed separately on the shared icosphere and bunny, one reused
//! [`Scratch`] per series, medians of many repeats.
//!
//! `cargo run --release -p voxflex-fluid --example fluid_stages [-- GRID…]`
//! (default grids 30 200 500 1500, both surfaces; α = 0.25;
//! `-- 200 bunny` for one).

use glam::DVec3;
use std::time::{Duration, Instant};
use voxflex_fluid::test_surfaces::{BUNNY_GRAVITY, bunny_2cm, icosphere};
use voxflex_fluid::{FluidWeighing, FluidWeightParams, Scratch};

/// Median and minimum, ms.
fn median(mut t: Vec<Duration>) -> (f64, f64) {
    t.sort_unstable();
    (t[t.len() / 2].as_secs_f64() * 1e3, t[0].as_secs_f64() * 1e3)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let grids: Vec<usize> = args.iter().filter_map(|a| a.parse().ok()).collect();
    let only: Vec<&String> = args
        .iter()
        .filter(|a| a.parse::<usize>().is_err())
        .collect();
    let grids = if grids.is_empty() {
        vec![30, 200, 500, 1500]
    } else {
        grids
    };
    let surfaces = [
        ("sphere", icosphere(), DVec3::new(0.0, 0.0, -9.81)),
        ("bunny", bunny_2cm(), BUNNY_GRAVITY),
    ];
    println!(
        "surface grid: project / intersect / sections / distribute = total (ms, medians; minima)"
    );
    for (name, surface, gravity) in surfaces {
        if !only.is_empty() && !only.iter().any(|o| *o == name) {
            continue;
        }
        let Some(s) = surface.expect("shared mesh") else {
            eprintln!("no shared data");
            return;
        };
        for &n in &grids {
            let p = FluidWeightParams {
                columns_per_side: n,
                gravity_m_s2: gravity,
                ..Default::default()
            };
            let mut scratch = Scratch::default();
            let repeats = if n >= 1000 { 20 } else { 200 };
            let mut t = [(); 5].map(|_| Vec::with_capacity(repeats));
            for _ in 0..repeats {
                let t0 = Instant::now();
                let mut w = FluidWeighing::project(&s, &p, &mut scratch).expect("weights");
                let t1 = Instant::now();
                w.intersect();
                let t2 = Instant::now();
                w.match_sections();
                let t3 = Instant::now();
                std::hint::black_box(w.distribute());
                let t4 = Instant::now();
                for (v, d) in t
                    .iter_mut()
                    .zip([t1 - t0, t2 - t1, t3 - t2, t4 - t3, t4 - t0])
                {
                    v.push(d);
                }
            }
            let m = t.map(median);
            let row = |f: fn(&(f64, f64)) -> f64| {
                m.iter()
                    .map(f)
                    .map(|x| format!("{x:.3}"))
                    .collect::<Vec<_>>()
            };
            let (med, min) = (row(|x| x.0), row(|x| x.1));
            println!(
                "{name} {n}²: {} / {} / {} / {} = {}   (minima {} / {} / {} / {} = {})",
                med[0], med[1], med[2], med[3], med[4], min[0], min[1], min[2], min[3], min[4]
            );
        }
    }
}
