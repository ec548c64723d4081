//! Resampling throughput against the machine's copy bandwidth (CPU path):
//! `cargo bench -p voxflex-resample --bench throughput`.
//!
//! For each case it prints the full-resample time (min and median of
//! `VOXFLEX_BENCH_REPEAT` calls, default 5, after one warm-up call that
//! sizes the output), output voxels per second, and the bytes a resample
//! must move at the least — source values and the 12-byte displacement
//! field read once, the f32 output written once — per second, against the
//! copy bandwidth measured in the same process (a 256 MiB `copy_from_slice`
//! on every rayon thread, read + write bytes, best of five). The last
//! column is a hash of the output bits, so two builds can be compared for
//! identical results. `cpu ms` is the least CPU time (all threads) of a
//! call: on a machine shared with other jobs it moves less than wall time.
//!
//! Cases (`VOXFLEX_BENCH_CASES`, comma-separated, default all):
//! - `twist64`: a 64³ volume under the same twist (fits the caches);
//! - `twist256`: 256³ i16 head phantom, 1 mm voxels, 40° twist about z plus
//!   a small shear (the criterion bench's `full_twist_256`);
//! - `affine256`: the same volume under a 10° rotation, ×1.05 and a 3 mm
//!   shift (`voxflex bench --accuracy`'s affine field);
//! - `identity256`: the same volume, zero displacements;
//! - `ct512`: a 512 × 512 × 133 i16 head phantom (0.7 × 0.7 × 1.25 mm,
//!   a CT series' shape) under a 30° twist about z over its z extent.
//!
//! `VOXFLEX_BENCH_MODE=tetrahedral` switches the interpolant (default
//! trilinear).

use rayon::prelude::*;
use std::time::{Duration, Instant};
use voxflex_core::deformation::DirtyRegion;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::Volume;
use voxflex_resample::parity::{Field, affine, head_i16, twist_z};
use voxflex_resample::{Interpolation, ResampleParams, Resampler};

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Best copy bandwidth (read + write bytes per second) of a 256 MiB copy
/// split over the rayon threads.
fn copy_bandwidth() -> f64 {
    let n = 64usize << 20;
    let src: Vec<f32> = (0..n).into_par_iter().map(|i| i as f32).collect();
    let mut dst = vec![0f32; n];
    let mut best = f64::MAX;
    for _ in 0..5 {
        let t0 = Instant::now();
        dst.par_chunks_mut(1 << 18)
            .zip(src.par_chunks(1 << 18))
            .for_each(|(d, s)| d.copy_from_slice(s));
        best = best.min(t0.elapsed().as_secs_f64());
    }
    std::hint::black_box(&dst);
    2.0 * (n * 4) as f64 / best
}

struct Case {
    name: &'static str,
    volume: Volume,
    field: Field,
}

fn cases() -> Vec<Case> {
    let want: Vec<String> = std::env::var("VOXFLEX_BENCH_CASES")
        .map(|v| v.split(',').map(str::to_owned).collect())
        .unwrap_or_default();
    let on = |n: &str| want.is_empty() || want.iter().any(|w| w == n);
    let mut out = Vec::new();
    if on("twist64") {
        let g = Grid::centred([64, 64, 64], DVec3::ONE);
        let (tw, _) = twist_z(g.centre(), 40f64.to_radians() / 63.0);
        out.push(Case {
            name: "twist64",
            volume: head_i16(&g),
            field: Field::from_map(&g, move |p| tw(p) + DVec3::new(0.0, 0.0, 0.05 * p.x)),
        });
    }
    let g = Grid::centred([256, 256, 256], DVec3::ONE);
    if on("twist256") || on("affine256") || on("identity256") {
        let vol = head_i16(&g);
        if on("twist256") {
            let (tw, _) = twist_z(g.centre(), 40f64.to_radians() / 255.0);
            out.push(Case {
                name: "twist256",
                volume: vol.clone(),
                field: Field::from_map(&g, move |p| tw(p) + DVec3::new(0.0, 0.0, 0.05 * p.x)),
            });
        }
        if on("affine256") {
            let (m, _) = affine(g.centre(), DVec3::Z, 10.0, 1.05, DVec3::new(3.0, 0.0, 0.0));
            out.push(Case {
                name: "affine256",
                volume: vol.clone(),
                field: Field::from_map(&g, m),
            });
        }
        if on("identity256") {
            out.push(Case {
                name: "identity256",
                volume: vol,
                field: Field::zero(&g),
            });
        }
    }
    if on("ct512") {
        let g = Grid::centred([512, 512, 133], DVec3::new(0.7, 0.7, 1.25));
        let extent = 132.0 * 1.25;
        let (tw, _) = twist_z(g.centre(), 30f64.to_radians() / extent);
        out.push(Case {
            name: "ct512",
            volume: head_i16(&g),
            field: Field::from_map(&g, tw),
        });
    }
    out
}

/// CPU time of every thread of this process so far (Linux: the sum of
/// `/proc/self/task/*/schedstat`; elsewhere zero) — on a machine shared with
/// other jobs it is steadier than wall time.
fn cpu_time() -> Duration {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else {
        return Duration::ZERO;
    };
    let ns: u64 = dir
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum();
    Duration::from_nanos(ns)
}

fn hash(v: &[f32]) -> u64 {
    // FNV-1a over the bits.
    v.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, x| {
        (h ^ x.to_bits() as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

fn main() {
    // `RUST_LOG=voxflex_resample=trace` prints each call's stage times.
    tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .init();
    let repeat = env_usize("VOXFLEX_BENCH_REPEAT", 5).max(1);
    let interpolation = match std::env::var("VOXFLEX_BENCH_MODE").as_deref() {
        Ok("tetrahedral") => Interpolation::Tetrahedral,
        _ => Interpolation::Trilinear,
    };
    let copy = copy_bandwidth();
    println!(
        "threads {}, {interpolation}; copy bandwidth {:.1} GB/s (read + write, 256 MiB)",
        rayon::current_num_threads(),
        copy / 1e9
    );
    println!(
        "{:<12} {:>11} {:>9} {:>9} {:>9} {:>10} {:>8} {:>7} {:>18}",
        "case",
        "out voxels",
        "min ms",
        "med ms",
        "cpu ms",
        "Mvoxel/s",
        "GB/s",
        "% copy",
        "output hash"
    );
    for c in cases() {
        let params = ResampleParams {
            background: -1000.0,
            interpolation,
            ..Default::default()
        };
        let mut r = Resampler::new(params);
        let run = |r: &mut Resampler| {
            let (c0, t0) = (cpu_time(), Instant::now());
            r.resample_cpu(c.volume.view(), c.field.as_ref(), None, DirtyRegion::All)
                .expect("resample");
            (t0.elapsed(), cpu_time().saturating_sub(c0))
        };
        run(&mut r);
        let (mut times, mut cpu): (Vec<Duration>, Vec<Duration>) =
            (0..repeat).map(|_| run(&mut r)).unzip();
        times.sort();
        cpu.sort();
        let out = r.cpu_values().expect("cpu output");

        let n_out = out.len();
        let bytes_in = c.volume.data.as_slice().as_bytes().len() + 12 * c.volume.grid.len();
        let bytes = (bytes_in + 4 * n_out) as f64;
        let (min, med) = (times[0].as_secs_f64(), times[times.len() / 2].as_secs_f64());
        println!(
            "{:<12} {:>11} {:>9.1} {:>9.1} {:>9.1} {:>10.0} {:>8.1} {:>6.1}% {:>18x}",
            c.name,
            n_out,
            min * 1e3,
            med * 1e3,
            cpu[0].as_secs_f64() * 1e3,
            n_out as f64 / min / 1e6,
            bytes / min / 1e9,
            100.0 * bytes / min / copy,
            hash(out)
        );
    }
}
