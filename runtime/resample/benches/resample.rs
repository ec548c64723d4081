//! Resampling benchmarks (CPU path): `cargo bench -p voxflex-resample --bench resample`.
//!
//! - `full_twist_256`: 256³ i16 head phantom, 1 mm voxels, a 40° twist about
//!   z plus a small shear: every cell moves, full resample.
//! - `dirty_5pct_256`: the same volume; each iteration toggles a smooth
//!   bump confined to a 94³-voxel box (5 % of the volume) and resamples only
//!   the dirty region (the result equals a full resample bit for bit).

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use voxflex_core::deformation::DirtyRegion;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_resample::parity::{Field, bump, head_i16, twist_z};
use voxflex_resample::{ResampleParams, Resampler};

fn grid() -> Grid {
    Grid::centred([256, 256, 256], DVec3::ONE)
}

fn twist(g: &Grid) -> Field {
    let (tw, _) = twist_z(g.centre(), 40f64.to_radians() / 255.0);
    Field::from_map(g, move |p| tw(p) + DVec3::new(0.0, 0.0, 0.05 * p.x))
}

fn bench(c: &mut Criterion) {
    let g = grid();
    let vol = head_i16(&g);
    let params = ResampleParams {
        background: -1000.0,
        ..Default::default()
    };
    let base = twist(&g);
    let mut group = c.benchmark_group("resample_cpu");
    group.sample_size(10);

    let mut r = Resampler::new(params);
    group.bench_function("full_twist_256", |b| {
        b.iter(|| {
            black_box(
                r.resample_cpu(vol.view(), base.as_ref(), None, DirtyRegion::All)
                    .unwrap(),
            );
        })
    });

    // Two fields differing only inside a 94³ box (a 47-voxel bump).
    let at = DVec3::new(30.0, -20.0, 10.0);
    let radius = 47.0;
    let bumped = {
        let m = Field::from_map(&g, bump(at, radius, DVec3::new(3.0, -2.0, 4.0)));
        let mut f = base.clone();
        for l in 0..g.len() {
            f.x[l] += m.x[l];
            f.y[l] += m.y[l];
            f.z[l] += m.z[l];
        }
        f
    };
    let dirty = DirtyRegion::Box {
        min: at - DVec3::splat(radius),
        max: at + DVec3::splat(radius),
    };
    let mut r = Resampler::new(params);
    r.resample_cpu(vol.view(), base.as_ref(), None, DirtyRegion::All)
        .unwrap();
    let fields = [&bumped, &base];
    let mut n = 0usize;
    let mut touched = 0u64;
    group.bench_function("dirty_5pct_256", |b| {
        b.iter(|| {
            n += 1;
            let rep = r
                .resample_cpu(vol.view(), fields[n % 2].as_ref(), None, dirty)
                .unwrap();
            assert!(!rep.full);
            touched = rep.voxels_touched;
            black_box(rep);
        })
    });
    group.finish();
    eprintln!(
        "dirty_5pct_256: {touched} voxels touched per call ({:.1} % of {})",
        100.0 * touched as f64 / r.cpu_values().map_or(1, |v| v.len()) as f64,
        g.len()
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
