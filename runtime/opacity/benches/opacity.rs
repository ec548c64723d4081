//! Opacity-map growth benchmarks (CPU path):
//! `cargo bench -p voxflex-opacity --bench opacity`.
//!
//! - `seed_ball_256`: seeding (neighbourhood statistics and the volume's value
//!   range) in the volume below.
//! - `grow_ball_256`: growth to convergence from the centre of a 256³ i16
//!   volume holding a ball of radius 119 voxels (≈ 7.06 M voxels, value
//!   100) in 0, Gaussian noise σ 3 everywhere, default parameters.
//!
//! Before measuring, prints the run's steps, visits, useful fraction, the
//! useful fraction a dense sweep would have had, and the bytes per voxel of
//! the map and of the working state.

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use voxflex_opacity::Growth;
use voxflex_opacity::parity::noisy_ball_i16;
use voxflex_opacity::{CpuGrowth, GrowthParams, Seed};

fn bench(c: &mut Criterion) {
    let vol = noisy_ball_i16(256, 119.0, 3.0, 42);
    let seed = Seed::Voxel([128, 128, 128]);
    let params = GrowthParams::default();

    let mut g = CpuGrowth::new(vol.view(), &seed, params).expect("seed");
    let t = std::time::Instant::now();
    let rep = g.run(vol.view()).expect("grow");
    let dt = t.elapsed();
    let map = g.map();
    let raised = map.values.iter().filter(|&&q| q > map.outside).count();
    let above_half = map.values.iter().filter(|&&q| q >= 32768).count();
    eprintln!(
        "opacity grow_ball_256 (one run, {dt:.2?}): {} steps, {} visits, {} useful, useful fraction {:.3} \
         (a dense sweep: {:.4}); {} voxels raised, {} ≥ 0.5; map box {:?} = {} voxels, {:.2} bytes/voxel \
         of its box ({:.2} per raised voxel); working state {:.2} bytes per box voxel, {} regrows",
        rep.steps,
        rep.visits,
        rep.useful,
        rep.useful_fraction(),
        rep.dense_useful_fraction(vol.grid.len()),
        raised,
        above_half,
        map.dims,
        map.values.len(),
        map.bytes() as f64 / map.values.len() as f64,
        map.bytes() as f64 / raised as f64,
        g.working_bytes() as f64 / g.working_box().len() as f64,
        rep.regrows,
    );

    let mut group = c.benchmark_group("opacity_cpu");
    group.sample_size(10);
    group.bench_function("seed_ball_256", |b| {
        b.iter(|| black_box(CpuGrowth::new(vol.view(), &seed, params).expect("seed")))
    });
    group.bench_function("grow_ball_256", |b| {
        b.iter_batched(
            || CpuGrowth::new(vol.view(), &seed, params).expect("seed"),
            |mut g| {
                black_box(g.run(vol.view()).expect("grow"));
                g
            },
            BatchSize::PerIteration,
        )
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
