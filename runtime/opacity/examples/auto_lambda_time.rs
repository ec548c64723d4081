//! Where the automatic λ's time goes: the path-cost scan that chooses λ
//! (`auto_lambda::choose_lambda`), the scan with the map written from its
//! costs as `grow_roi` runs it (`auto_lambda::auto_map`), the map again
//! at the λ chosen from a scan run only that far (`auto_lambda::map_at`:
//! what a session pays for an automatic-λ map on each new volume), and
//! one growth at the λ chosen (CPU) for comparison, from the liver seed of
//! `phantom:abdomen`; then how far the scan's map lies from that growth's
//! and whether the scan's region sizes equal the growth's.
//!
//! ```sh
//! cargo run --release -p voxflex-opacity --example auto_lambda_time -- [--dims 240,188,160] [--repeat 9]
//! ```
//!
//! Prints, per grid, the minimum and median of `--repeat` interleaved runs
//! of each, and every trial's size next to a growth's at that λ.

use std::time::{Duration, Instant};
use voxflex_opacity::auto_lambda::{auto_map, choose_lambda, map_at};
use voxflex_opacity::runner::voxels_above_half;
use voxflex_opacity::{CpuRunner, GrowRunner, GrowthLimits, GrowthParams, ScanInput, Seed};
use voxflex_phantom::abdomen::SEEDS;
use voxflex_phantom::abdomen_labelled;

fn arg(name: &str) -> Option<String> {
    let a: Vec<String> = std::env::args().collect();
    a.iter().position(|x| x == name).map(|i| a[i + 1].clone())
}

fn stats(mut t: Vec<Duration>) -> String {
    t.sort();
    format!(
        "min {:.1} ms, median {:.1} ms",
        t[0].as_secs_f64() * 1e3,
        t[t.len() / 2].as_secs_f64() * 1e3
    )
}

fn main() {
    let grids: Vec<[usize; 3]> = match arg("--dims") {
        Some(d) => {
            let v: Vec<usize> = d.split(',').map(|x| x.parse().expect("--dims")).collect();
            vec![[v[0], v[1], v[2]]]
        }
        None => vec![[120, 94, 80], [240, 188, 160]],
    };
    let repeat: usize = arg("--repeat").map_or(9, |r| r.parse().expect("--repeat"));
    let (_, _, p) = SEEDS.iter().find(|s| s.0 == "liver").unwrap();
    for dims in grids {
        let ph = abdomen_labelled(dims);
        let v = ph.volume.view();
        let input = ScanInput {
            volume: v,
            values: v,
            limits: GrowthLimits::default(),
            seed: Seed::World(*p),
        };
        let params = GrowthParams::default();
        let mut runner = CpuRunner {
            volume: v,
            values: v,
            seed: Seed::World(*p),
        };
        let (mut scan, mut grow, mut whole, mut again) = (vec![], vec![], vec![], vec![]);
        let (mut lambda, mut trials) = (0.0, vec![]);
        for _ in 0..repeat {
            let t = Instant::now();
            (lambda, trials) = choose_lambda(input, params).unwrap();
            scan.push(t.elapsed());
            let t = Instant::now();
            runner
                .grow(GrowthParams { lambda, ..params }, None)
                .unwrap();
            grow.push(t.elapsed());
            let t = Instant::now();
            let a = auto_map(input, params).unwrap();
            whole.push(t.elapsed());
            assert_eq!(a.search.lambda, lambda);
            let t = Instant::now();
            let m = map_at(input, params, lambda).unwrap();
            again.push(t.elapsed());
            assert_eq!(m.map, a.grown.map);
        }
        println!("abdomen {dims:?}, liver seed: λ = {lambda}");
        println!("  scan (choose λ):        {}", stats(scan));
        println!("  one growth at that λ:   {}", stats(grow));
        println!("  scan + its map (grow_roi): {}", stats(whole));
        println!("  scan to that λ + its map (map_at): {}", stats(again));
        let written = auto_map(input, params).unwrap().grown.map.dense(dims);
        let grown = runner
            .grow(GrowthParams { lambda, ..params }, None)
            .unwrap()
            .map
            .dense(dims);
        let differ = written.iter().zip(&grown).filter(|(a, b)| a != b).count();
        let most = written
            .iter()
            .zip(&grown)
            .map(|(a, b)| a.abs_diff(*b))
            .max();
        let side = written
            .iter()
            .zip(&grown)
            .filter(|&(a, b)| (*a >= 32768) != (*b >= 32768))
            .count();
        println!(
            "  scan's map against the growth's: {differ} voxels differ (at most {} units), \
             {side} on the other side of ½",
            most.unwrap_or(0)
        );
        for t in &trials {
            let g = runner
                .grow(
                    GrowthParams {
                        lambda: t.lambda,
                        ..params
                    },
                    None,
                )
                .unwrap();
            println!(
                "  λ {:>6.3}: scan {:>8} voxels ≥ ½ ({}, {} visits), growth {:>8}",
                t.lambda,
                t.voxels,
                if t.aborted { "cut short" } else { "complete" },
                t.visits,
                voxels_above_half(&g.map)
            );
        }
    }
}
