//! GPU-versus-CPU checks of the resampler, written against [`GpuService`] so
//! that any crate owning a real device (the integration tests, through the
//! host's GPU context) can run them, plus the test volumes they use (the
//! analytic displacement fields live in [`crate::fields`]).
//!
//! Every `check_*` runs in both [`Interpolation`] modes and returns
//! `Err(description)` (naming the mode) on the first disagreement.
//! Identity must match bit for bit; other fields within `1e-5` of the data
//! range per voxel (GPUs may fuse multiply-adds, so boundary decisions and
//! the last bits can differ; at most [`MAX_COVERAGE_MISMATCH`] of the voxels
//! may differ in being covered at all).

use super::gpu::GpuSource;
use super::{Interpolation, ResampleError, ResampleOutput, ResampleParams, Resampler, TetMask};
use crate::deformation::DirtyRegion;
use crate::grid::Grid;
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use voxflex_core::gpu::LimitedDevice;
use voxflex_core::gpu::{BufferId, GpuService, GpuServiceExt};

/// Fraction of voxels allowed to be covered on one backend and background on
/// the other (fused multiply-adds on the mesh boundary).
pub const MAX_COVERAGE_MISMATCH: f64 = 1e-4;

pub use crate::fields::{Field, affine, bend_zx, bump, twist_z};
pub use crate::parity_slabs::{check_512_cubed_source, check_source_slabs};

/// A linear ramp `v = a·X` (X world mm) as an f32 volume.
pub fn ramp(grid: &Grid, a: DVec3) -> Volume {
    let v = (0..grid.len())
        .map(|l| {
            let [i, j, k] = grid.unlinear(l);
            a.dot(grid.index_to_world(DVec3::new(i as f64, j as f64, k as f64))) as f32
        })
        .collect();
    Volume::new(*grid, VoxelData::F32(v)).expect("sizes match")
}

/// A CT-like i16 head phantom: air (−1000) around a skull shell (1500) and
/// brain (≈ 40) with a small textured pattern.
pub fn head_i16(grid: &Grid) -> Volume {
    let dims = grid.dims.map(|d| d as f64);
    let v = (0..grid.len())
        .map(|l| {
            let [i, j, k] = grid.unlinear(l);
            let p = DVec3::new(
                2.0 * i as f64 / (dims[0] - 1.0).max(1.0) - 1.0,
                2.0 * j as f64 / (dims[1] - 1.0).max(1.0) - 1.0,
                2.0 * k as f64 / (dims[2] - 1.0).max(1.0) - 1.0,
            );
            let r = (p / DVec3::new(0.85, 0.95, 0.8)).length();
            if r > 1.0 {
                -1000
            } else if r > 0.88 {
                1500
            } else {
                40 + ((i * 7 + j * 13 + k * 3) % 17) as i16
            }
        })
        .collect();
    Volume::new(*grid, VoxelData::I16(v)).expect("sizes match")
}

fn e(err: ResampleError) -> String {
    err.to_string()
}

/// Uploaded inputs of one GPU run, freed on drop of the guard by `finish`.
struct GpuInputs {
    source: GpuSource,
    disp: [BufferId; 3],
}

impl GpuInputs {
    fn new(gpu: &dyn GpuService, vol: &Volume, f: &Field) -> Result<Self, String> {
        let source = GpuSource::upload(gpu, vol.view()).map_err(e)?;
        let up = |v: &[f32], l| gpu.upload(v, l).map_err(|x| x.to_string());
        Ok(Self {
            source,
            disp: [
                up(&f.x, "parity.dx")?,
                up(&f.y, "parity.dy")?,
                up(&f.z, "parity.dz")?,
            ],
        })
    }
    fn set_field(&self, gpu: &dyn GpuService, f: &Field) -> Result<(), String> {
        for (id, v) in self.disp.iter().zip([&f.x, &f.y, &f.z]) {
            gpu.write_buffer(*id, 0, bytemuck::cast_slice(v))
                .map_err(|x| x.to_string())?;
        }
        Ok(())
    }
    fn free(self, gpu: &dyn GpuService) {
        self.source.release(gpu);
        for d in self.disp {
            gpu.destroy_buffer(d);
        }
    }
}

pub(crate) fn cpu_run(
    vol: &Volume,
    f: &Field,
    mask: Option<&TetMask>,
    params: ResampleParams,
) -> Result<ResampleOutput, String> {
    let mut r = Resampler::new(params);
    r.resample_cpu(vol.view(), f.as_ref(), mask, DirtyRegion::All)
        .map_err(e)?;
    r.cpu_output().ok_or_else(|| "no CPU output".to_string())
}

pub(crate) fn gpu_run(
    gpu: &dyn GpuService,
    vol: &Volume,
    f: &Field,
    mask: Option<&TetMask>,
    params: ResampleParams,
) -> Result<ResampleOutput, String> {
    let inputs = GpuInputs::new(gpu, vol, f)?;
    let mut r = Resampler::new(params);
    let out = r
        .resample_gpu(gpu, &inputs.source, inputs.disp, mask, DirtyRegion::All)
        .and_then(|_| r.read_gpu_output(gpu))
        .map_err(e);
    r.release_gpu(gpu);
    inputs.free(gpu);
    out
}

/// Compares two outputs: same grid, bit-identical when `tol` is `None`,
/// else within `tol × data range` per voxel covered on both (see the module
/// docs for coverage).
pub fn compare(
    what: &str,
    want: &ResampleOutput,
    got: &ResampleOutput,
    background: f32,
    tol: Option<f32>,
) -> Result<(), String> {
    if want.grid != got.grid {
        return Err(format!(
            "{what}: output grid {:?} != {:?}",
            got.grid, want.grid
        ));
    }
    let (lo, hi) = want
        .values
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let range = (hi - lo).max(1e-30);
    let mut coverage = 0usize;
    let mut worst = (0.0f32, 0usize);
    for (n, (&w, &g)) in want.values.iter().zip(&got.values).enumerate() {
        match tol {
            None => {
                if w.to_bits() != g.to_bits() {
                    let q = want.grid.unlinear(n);
                    return Err(format!(
                        "{what}: voxel {q:?}: {g} (bits {:#x}) != {w} (bits {:#x})",
                        g.to_bits(),
                        w.to_bits()
                    ));
                }
            }
            Some(t) => {
                if (w == background) != (g == background) {
                    coverage += 1;
                    continue;
                }
                let d = (w - g).abs() / range;
                if d > worst.0 || d.is_nan() {
                    worst = (d, n);
                }
                if d.is_nan() || d > t {
                    let q = want.grid.unlinear(n);
                    return Err(format!(
                        "{what}: voxel {q:?}: {g} vs {w} (relative error {d:e} > {t:e})"
                    ));
                }
            }
        }
    }
    if coverage as f64 > MAX_COVERAGE_MISMATCH * want.values.len() as f64 + 1.0 {
        return Err(format!(
            "{what}: {coverage} of {} voxels covered on one backend only",
            want.values.len()
        ));
    }
    Ok(())
}

pub(crate) fn test_grid() -> Grid {
    Grid::new(
        [23, 19, 17],
        DVec3::new(0.9, 1.1, 1.3),
        DVec3::new(-12.0, 4.0, 30.0),
    )
}

pub(crate) fn twisted(grid: &Grid) -> Field {
    let (tw, _) = twist_z(grid.centre(), 0.6 / (grid.dims[2] as f64 * grid.spacing.z));
    let (af, _) = affine(
        grid.centre(),
        DVec3::new(0.3, 1.0, 0.2),
        10.0,
        1.15,
        DVec3::new(2.3, -1.7, 0.9),
    );
    Field::from_map(grid, move |p| af(tw(p)))
}

/// Identity field: the GPU output equals the source bit for bit, on the
/// source grid (i16 head phantom and an f32 ramp).
pub fn check_identity_bitwise(gpu: &dyn GpuService) -> Result<(), String> {
    for mode in Interpolation::ALL {
        identity_bitwise(gpu, mode).map_err(|m| format!("{mode}: {m}"))?;
    }
    Ok(())
}

fn identity_bitwise(gpu: &dyn GpuService, interpolation: Interpolation) -> Result<(), String> {
    let grid = test_grid();
    let params = ResampleParams {
        background: -1234.5,
        interpolation,
        ..Default::default()
    };
    for vol in [head_i16(&grid), ramp(&grid, DVec3::new(1.0, -2.0, 0.5))] {
        let f = Field::zero(&grid);
        let got = gpu_run(gpu, &vol, &f, None, params)?;
        let want = ResampleOutput {
            grid,
            values: vol.data.as_slice().to_f32_vec(),
        };
        compare(
            &format!("identity ({})", vol.scalar_type().name()),
            &want,
            &got,
            params.background,
            None,
        )?;
    }
    Ok(())
}

/// Twist + rotation + scale + translation (output growth): GPU within
/// tolerance of CPU.
pub fn check_deformed_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    for mode in Interpolation::ALL {
        deformed_matches_cpu(gpu, mode).map_err(|m| format!("{mode}: {m}"))?;
    }
    Ok(())
}

fn deformed_matches_cpu(gpu: &dyn GpuService, interpolation: Interpolation) -> Result<(), String> {
    let grid = test_grid();
    let params = ResampleParams {
        background: -3000.0,
        interpolation,
        ..Default::default()
    };
    let f = twisted(&grid);
    for vol in [head_i16(&grid), ramp(&grid, DVec3::new(1.0, -2.0, 0.5))] {
        let want = cpu_run(&vol, &f, None, params)?;
        let got = gpu_run(gpu, &vol, &f, None, params)?;
        compare("deformed", &want, &got, params.background, Some(1e-5))?;
    }
    Ok(())
}

/// Folds: a block of vertices pulled several cells through still
/// neighbours, towards lower and towards higher indices along each axis
/// (moved over still cells, inverted cells, still vertices covered by moved
/// tissue — every case of the owner-key rule, `sampling_mesh::WEAK_OWNER`):
/// the GPU's owners are the CPU's, so the outputs are bit-identical.
pub fn check_folds_match_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    for mode in Interpolation::ALL {
        folds_match_cpu(gpu, mode).map_err(|m| format!("{mode}: {m}"))?;
    }
    Ok(())
}

fn folds_match_cpu(gpu: &dyn GpuService, interpolation: Interpolation) -> Result<(), String> {
    let grid = test_grid();
    let params = ResampleParams {
        background: -3000.0,
        interpolation,
        ..Default::default()
    };
    let vol = head_i16(&grid);
    let d = grid.dims;
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let by = sign * 4.5 * grid.spacing[axis] as f32;
            let mut f = Field::zero(&grid);
            for k in d[2] / 3..d[2] / 2 {
                for j in d[1] / 3..d[1] / 2 {
                    for i in d[0] / 3..d[0] / 2 {
                        [&mut f.x, &mut f.y, &mut f.z][axis][grid.linear(i, j, k)] = by;
                    }
                }
            }
            let want = cpu_run(&vol, &f, None, params)?;
            let got = gpu_run(gpu, &vol, &f, None, params)?;
            compare(
                &format!("fold along axis {axis}, sign {sign}"),
                &want,
                &got,
                params.background,
                None,
            )?;
        }
    }
    Ok(())
}

/// As [`check_deformed_matches_cpu`] but with a storage binding limit so
/// small that the output is processed in many z-slabs; an exact integer
/// translation (output grown, slabbed) must still match bit for bit. (The
/// source then fits one binding; [`check_source_slabs`] splits it too.)
pub fn check_output_slabs(gpu: &dyn GpuService) -> Result<(), String> {
    for mode in Interpolation::ALL {
        output_slabs(gpu, mode).map_err(|m| format!("{mode}: {m}"))?;
    }
    Ok(())
}

fn output_slabs(gpu: &dyn GpuService, interpolation: Interpolation) -> Result<(), String> {
    let grid = test_grid();
    let limit = (grid.len() as u64 * 4).next_multiple_of(256) + 256;
    let small = LimitedDevice::binding(gpu, limit);
    let params = ResampleParams {
        interpolation,
        ..Default::default()
    };
    let vol = ramp(&grid, DVec3::new(0.3, 1.0, -0.7));
    let f = twisted(&grid);
    let want = cpu_run(&vol, &f, None, params)?;
    if want.values.len() as u64 * 4 <= limit {
        return Err("slab test is not slabbed: the output fits one binding".into());
    }
    let got = gpu_run(&small, &vol, &f, None, params)?;
    compare("slabbed output", &want, &got, params.background, Some(1e-5))?;

    // Exact translation by (3, −2, 5) voxels: powers-of-two spacing keep
    // every position an exact integer, so GPU = CPU = shifted source, bitwise.
    let g2 = Grid::new(
        [21, 18, 16],
        DVec3::new(1.0, 0.5, 2.0),
        DVec3::new(-3.0, 1.0, 7.0),
    );
    let shift = DVec3::new(3.0, -2.0, 5.0);
    let t = Field::from_map(&g2, move |p| p + shift * g2.spacing);
    let vol2 = head_i16(&g2);
    let small2 = LimitedDevice::binding(gpu, (g2.len() as u64 * 4).next_multiple_of(256) + 256);
    let want = cpu_run(&vol2, &t, None, params)?;
    let got = gpu_run(&small2, &vol2, &t, None, params)?;
    compare(
        "slabbed exact translation",
        &want,
        &got,
        params.background,
        None,
    )?;
    let src = vol2.data.as_slice();
    for l in 0..g2.len() {
        let [i, j, k] = g2.unlinear(l);
        let w = g2.index_to_world(DVec3::new(i as f64, j as f64, k as f64)) + shift * g2.spacing;
        let q = want.grid.world_to_index(w).round();
        let o = want.grid.linear(q.x as usize, q.y as usize, q.z as usize);
        if got.values[o].to_bits() != src.get_f32(l).to_bits() {
            return Err(format!(
                "translated voxel {:?}: {} != {}",
                [i, j, k],
                got.values[o],
                src.get_f32(l)
            ));
        }
    }

    Ok(())
}

/// Removed tetrahedra: GPU within tolerance of CPU.
pub fn check_mask_matches_cpu(gpu: &dyn GpuService) -> Result<(), String> {
    for mode in Interpolation::ALL {
        mask_matches_cpu(gpu, mode).map_err(|m| format!("{mode}: {m}"))?;
    }
    Ok(())
}

fn mask_matches_cpu(gpu: &dyn GpuService, interpolation: Interpolation) -> Result<(), String> {
    let grid = test_grid();
    let params = ResampleParams {
        background: -50.0,
        interpolation,
        ..Default::default()
    };
    let mut mask = TetMask::new(&grid).map_err(e)?;
    for (n, c) in [[3, 3, 3], [10, 8, 7], [11, 8, 7], [0, 0, 0], [21, 17, 15]]
        .into_iter()
        .enumerate()
    {
        for t in 0..5 {
            if t != n % 5 || c == [10, 8, 7] {
                mask.remove(c, t).map_err(e)?;
            }
        }
    }
    let vol = ramp(&grid, DVec3::new(1.0, 1.0, 1.0));
    let f = twisted(&grid);
    let want = cpu_run(&vol, &f, Some(&mask), params)?;
    let got = gpu_run(gpu, &vol, &f, Some(&mask), params)?;
    compare("masked", &want, &got, params.background, Some(1e-5))
}

/// A sequence of local changes resampled by dirty region on the GPU equals
/// a full GPU resample bit for bit, and the CPU within tolerance.
pub fn check_dirty_matches_full(gpu: &dyn GpuService) -> Result<(), String> {
    for mode in Interpolation::ALL {
        dirty_matches_full(gpu, mode).map_err(|m| format!("{mode}: {m}"))?;
    }
    Ok(())
}

pub(crate) fn dirty_matches_full(
    gpu: &dyn GpuService,
    interpolation: Interpolation,
) -> Result<(), String> {
    let grid = test_grid();
    let params = ResampleParams {
        interpolation,
        ..Default::default()
    };
    let vol = head_i16(&grid);
    let base = twisted(&grid);
    let inputs = GpuInputs::new(gpu, &vol, &base)?;
    let mut r = Resampler::new(params);
    let result = (|| {
        r.resample_gpu(gpu, &inputs.source, inputs.disp, None, DirtyRegion::All)
            .map_err(e)?;
        let c = grid.index_to_world(DVec3::new(6.0, 7.0, 5.0));
        let mut field = base.clone();
        for (step, amp) in [
            DVec3::new(1.5, -0.5, 0.7),
            DVec3::new(-1.0, 0.8, 0.0),
            DVec3::ZERO,
        ]
        .into_iter()
        .enumerate()
        {
            let radius = 4.0;
            let moved = Field::from_map(&grid, bump(c, radius, amp));
            for l in 0..grid.len() {
                field.x[l] = base.x[l] + moved.x[l];
                field.y[l] = base.y[l] + moved.y[l];
                field.z[l] = base.z[l] + moved.z[l];
            }
            inputs.set_field(gpu, &field)?;
            let dirty = DirtyRegion::Box {
                min: c - DVec3::splat(radius),
                max: c + DVec3::splat(radius),
            };
            let rep = r
                .resample_gpu(gpu, &inputs.source, inputs.disp, None, dirty)
                .map_err(e)?;
            if rep.full {
                return Err(format!(
                    "step {step}: expected a dirty-region resample, got a full one"
                ));
            }
            let got = r.read_gpu_output(gpu).map_err(e)?;
            let full = gpu_run(gpu, &vol, &field, None, params)?;
            compare(
                &format!("dirty step {step} vs full (GPU)"),
                &full,
                &got,
                params.background,
                None,
            )?;
            let cpu = cpu_run(&vol, &field, None, params)?;
            compare(
                &format!("dirty step {step} vs CPU"),
                &cpu,
                &got,
                params.background,
                Some(1e-5),
            )?;
        }
        Ok(())
    })();
    r.release_gpu(gpu);
    inputs.free(gpu);
    result
}

/// Every check above, in order.
pub fn check_all(gpu: &dyn GpuService) -> Result<(), String> {
    check_identity_bitwise(gpu)?;
    check_deformed_matches_cpu(gpu)?;
    check_folds_match_cpu(gpu)?;
    check_output_slabs(gpu)?;
    check_source_slabs(gpu)?;
    check_mask_matches_cpu(gpu)?;
    check_dirty_matches_full(gpu)
}
