//! Reading an oblique volume: time and placement error of each
//! `oblique` choice (`cargo bench -p voxflex-io --bench oblique`).
//!
//! The file: a 256 × 256 × 160 i16 NRRD (0.8 × 0.8 × 1.5 mm voxels) whose
//! i and j axes are turned by 20° about z, holding a smooth function of
//! world position `f` (a sum of sines, 12–30 mm wavelengths, amplitude
//! 1,000) rounded to integers. Before timing, each choice's volume is
//! compared with `f` at every grid voxel whose centre lies inside the
//! acquisition: `closest-axes` keeps the voxels but rotates the anatomy
//! by 20° about the centre, so its error is the misplacement's; `linear`
//! and `nearest` put each voxel where the header does, leaving only the
//! interpolation's error. Criterion then times `read_volume` (parse, read
//! and place) for each.

use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use std::hint::black_box;
use std::path::Path;
use voxflex_io::{ObliquePlacement, ReadOptions, read_volume};

const DIMS: [usize; 3] = [256, 256, 160];
const SPACING: [f64; 3] = [0.8, 0.8, 1.5];
const DEG: f64 = 20.0;
const ORIGIN: [f64; 3] = [-100.0, -90.0, -120.0];

/// The function every voxel samples (world mm, LPS).
fn f(p: DVec3) -> f64 {
    use std::f64::consts::TAU;
    1000.0
        * ((TAU * p.x / 30.0).sin() * (TAU * p.y / 24.0).cos()
            + 0.5 * (TAU * (p.x + p.z) / 12.0).sin())
}

/// Voxel axis `a`'s world step (mm).
fn directions() -> [DVec3; 3] {
    let (s, c) = DEG.to_radians().sin_cos();
    [
        DVec3::new(c, s, 0.0) * SPACING[0],
        DVec3::new(-s, c, 0.0) * SPACING[1],
        DVec3::Z * SPACING[2],
    ]
}

fn write_nrrd(path: &Path) {
    let d = directions();
    let o = DVec3::from_array(ORIGIN);
    let mut bytes = format!(
        "NRRD0004\ntype: short\ndimension: 3\nspace: left-posterior-superior\n\
         sizes: {} {} {}\nspace directions: ({},{},{}) ({},{},{}) ({},{},{})\n\
         space origin: ({},{},{})\nendian: little\nencoding: raw\n\n",
        DIMS[0],
        DIMS[1],
        DIMS[2],
        d[0].x,
        d[0].y,
        d[0].z,
        d[1].x,
        d[1].y,
        d[1].z,
        d[2].x,
        d[2].y,
        d[2].z,
        o.x,
        o.y,
        o.z
    )
    .into_bytes();
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                let p = o + d[0] * i as f64 + d[1] * j as f64 + d[2] * k as f64;
                bytes.extend_from_slice(&(f(p).round() as i16).to_le_bytes());
            }
        }
    }
    std::fs::write(path, bytes).expect("write the bench's NRRD");
}

fn opts(oblique: ObliquePlacement) -> ReadOptions {
    ReadOptions {
        oblique,
        ..Default::default()
    }
}

/// Mean and largest |volume − f| over grid voxels inside the acquisition
/// (one voxel in from its faces), and how many.
fn placement_error(path: &Path, oblique: ObliquePlacement) -> (f64, f64, usize) {
    let v = read_volume(path, &opts(oblique)).expect("read the bench's NRRD");
    let d = directions();
    let to_file = glam::DMat3::from_cols(d[0], d[1], d[2]).inverse();
    let values = v.data.as_slice().to_f32_vec();
    let (mut sum, mut max, mut n) = (0.0, 0.0f64, 0usize);
    for (l, value) in values.into_iter().enumerate() {
        let p = v
            .grid
            .index_to_world(DVec3::from_array(v.grid.unlinear(l).map(|x| x as f64)));
        let idx = to_file * (p - DVec3::from_array(ORIGIN));
        if (0..3).all(|a| idx[a] >= 1.0 && idx[a] <= (DIMS[a] - 2) as f64) {
            let e = (value as f64 - f(p)).abs();
            sum += e;
            max = max.max(e);
            n += 1;
        }
    }
    (sum / n.max(1) as f64, max, n)
}

const CHOICES: [ObliquePlacement; 3] = [
    ObliquePlacement::ClosestAxes,
    ObliquePlacement::Linear,
    ObliquePlacement::Nearest,
];

fn bench(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = dir.path().join("oblique.nrrd");
    write_nrrd(&path);
    for oblique in CHOICES {
        let v = read_volume(&path, &opts(oblique)).expect("read");
        let (mean, max, n) = placement_error(&path, oblique);
        eprintln!(
            "oblique {oblique:<12}: grid {:?}, |value − f| over {n} voxels inside: mean {mean:.2}, \
             max {max:.1} (f spans ±1,500)",
            v.grid.dims
        );
    }
    let mut g = c.benchmark_group("oblique_read_256x256x160_i16");
    g.sample_size(10);
    for oblique in CHOICES {
        g.bench_function(oblique.name(), |b| {
            b.iter(|| black_box(read_volume(&path, &opts(oblique)).expect("read")))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
