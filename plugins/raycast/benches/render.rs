//! Ray-casting benchmarks (CPU path):
//! `cargo bench -p voxflex-raycast --bench render`.
//!
//! A 512 × 512 image of the 256³ i16 CT head phantom
//! (`phantom("head", [256, 256, 256])`, 0.78 × 0.94 × 0.86 mm voxels),
//! perspective (30° field of view) from azimuth 30°, elevation 15°, sample
//! distance 0.5 voxel, gradient shading on, early termination and
//! empty-space skipping on (the defaults):
//!
//! - `head256_ct_bone_512`: the `ct-bone` preset (goal ≤ 120 ms/frame on 2 cores);
//! - `head256_ct_bone_512_central`: the same with `gradient = "central"`
//!   (the default before issue 15; the default is Sobel);
//! - `head256_ct_bone_512_tricubic`: the same with `sampling = "tricubic"`;
//! - `head256_ct_soft_tissue_512`: the `ct-soft-tissue` preset;
//! - `head256_mip_512`: maximum intensity projection;
//! - `head256_macrocells`: the min/max of every 8³ macro cell (halo
//!   included) from the f32 values, what every volume update rebuilds;
//! - `head256_volume_update`: a whole-volume `set_volume` on the grid the
//!   renderer already holds (a deformed frame: conversion to f32, the
//!   gradient cache dropped, every macro cell rebuilt).
//!
//! Measured on the 2-core development machine (criterion median), quiet,
//! before issue 15 (central differences): ct-bone 58.6 ms, ct-soft-tissue
//! 142 ms, MIP 130 ms per frame. After (partial-volume phantom, Sobel
//! default, macro-cell halo), 2026-12-02 under load average 3–5 (so about
//! 2× a quiet machine; compare rows within a run): ct-bone 142 ms,
//! `_central` 118 ms, `_tricubic` 609 ms, ct-soft-tissue 390 ms, MIP 273 ms;
//! near-quiet (load 0.2–1.3) the same evening: ct-bone 63.4 ms, `_central`
//! 50.9 ms, `_tricubic` 253 ms, ct-soft-tissue 184 ms, MIP 127 ms.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use voxflex_core::deformation::{DirtyRegion, ExecutionBackend};
use voxflex_core::render::{ImageTarget, RenderVolume, Renderer};
use voxflex_raycast::macrocell::{IndexBox, MacroCells};
use voxflex_raycast::{RaycastRenderer, fit_camera};

fn bench(c: &mut Criterion) {
    let vol = voxflex_phantom::phantom("head", [256, 256, 256]).expect("head phantom");
    let cam = fit_camera(&vol.grid, 512, 512, 30.0, 15.0, Some(30.0));
    let mut out = vec![0u8; 512 * 512 * 4];
    let mut group = c.benchmark_group("raycast_cpu");
    group.sample_size(10);
    for (name, params) in [
        (
            "head256_ct_bone_512",
            "transfer_function = { preset = \"ct-bone\" }\nsample_distance = 0.5",
        ),
        (
            "head256_ct_bone_512_central",
            "transfer_function = { preset = \"ct-bone\" }\nsample_distance = 0.5\ngradient = \"central\"",
        ),
        (
            "head256_ct_bone_512_tricubic",
            "transfer_function = { preset = \"ct-bone\" }\nsample_distance = 0.5\nsampling = \"tricubic\"",
        ),
        (
            "head256_ct_soft_tissue_512",
            "transfer_function = { preset = \"ct-soft-tissue\" }\nsample_distance = 0.5",
        ),
        (
            "head256_mip_512",
            "mode = \"mip\"\ntransfer_function = { preset = \"ct-bone\" }\nsample_distance = 0.5",
        ),
    ] {
        let mut r = RaycastRenderer::create(params, None).expect("params");
        r.init(ExecutionBackend::Cpu).expect("init");
        r.set_volume(RenderVolume::Cpu(vol.view()), DirtyRegion::All)
            .expect("volume");
        let stats = r.render(&cam, ImageTarget::Cpu(&mut out)).expect("render");
        eprintln!("{name}: {stats:?}");
        group.bench_function(name, |b| {
            b.iter(|| black_box(r.render(&cam, ImageTarget::Cpu(&mut out)).expect("render")))
        });
    }
    let mut r = RaycastRenderer::create("", None).expect("params");
    r.init(ExecutionBackend::Cpu).expect("init");
    r.set_volume(RenderVolume::Cpu(vol.view()), DirtyRegion::All)
        .expect("volume");
    group.bench_function("head256_volume_update", |b| {
        b.iter(|| {
            r.set_volume(RenderVolume::Cpu(vol.view()), DirtyRegion::All)
                .expect("volume")
        })
    });
    let values = vol.view().data.to_f32_vec();
    let mut cells = MacroCells::new(vol.grid.dims, 8);
    let all = IndexBox::all(cells.counts);
    group.bench_function("head256_macrocells", |b| {
        b.iter(|| cells.rebuild(black_box(&values), all))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
