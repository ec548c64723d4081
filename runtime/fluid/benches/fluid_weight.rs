//! Fluid-weight distribution time against grid size, with parallel
//! leveraging (α = 0.25, the paper's) and with one worker per triangle
//! (α = 0), on the icosphere (5,120 triangles) and the bunny (75,408,
//! scaled to 2 cm) of `shared/data`. The paper's CPU: 7.63 and 15.64 ms at 200²; its GPU 0.57
//! and 1.06 ms.
//!
//! The weigher is reused across iterations (its working memory kept), as
//! an actuator weighing its cavity every frame does. On the CPU the row
//! scan's tasks take whole triangles, so α only changes the reported `k`
//! there (`voxflex_fluid::schedule::TaskSplit`): the two series time the
//! same work, a check that it stays so. Per-stage times:
//! `cargo run --release -p voxflex-fluid --example fluid_stages`.
//!
//! `cargo bench -p voxflex-fluid --bench fluid_weight`

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use glam::DVec3;
use voxflex_fluid::test_surfaces::{BUNNY_GRAVITY, bunny_2cm, icosphere};
use voxflex_fluid::{FluidWeigher, FluidWeightParams};

fn bench(c: &mut Criterion) {
    let surfaces = [
        ("sphere", icosphere(), DVec3::new(0.0, 0.0, -9.81)),
        ("bunny", bunny_2cm(), BUNNY_GRAVITY),
    ];
    for (name, surface, gravity) in surfaces {
        let Some(s) = surface.expect("shared mesh") else {
            return;
        };
        let mut g = c.benchmark_group(format!("fluid_weight/{name}"));
        g.sample_size(20);
        for n in [30, 50, 100, 200, 500, 1000, 1500] {
            for (label, alpha) in [("leveraging", 0.25), ("per_triangle", 0.0)] {
                let p = FluidWeightParams {
                    columns_per_side: n,
                    gravity_m_s2: gravity,
                    leverage_alpha: alpha,
                    ..Default::default()
                };
                // one weigher per series, as an actuator keeps one per cavity
                let mut weigher = FluidWeigher::default();
                g.bench_with_input(BenchmarkId::new(label, n), &p, |b, p| {
                    b.iter(|| weigher.weigh(&s, p).expect("weights"))
                });
            }
        }
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
