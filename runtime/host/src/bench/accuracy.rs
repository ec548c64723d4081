//! `voxflex bench --accuracy`: time and error of both resampler
//! interpolation modes ([`Interpolation`]) under an affine map, a twist and a
//! bend of the head phantom, against the f64 reference of
//! [`voxflex_resample::accuracy`] (trilinear sampling, in f64, of the
//! source at the exact analytic preimage of each output voxel).
//!
//! The displacement fields come straight from the analytic maps (f64, stored
//! as the f32 the resampler reads), so reference and input describe the
//! same deformation; the time is the median over `--repeat` full resamples
//! (`DirtyRegion::All`, output already allocated), on the chosen backend.

use super::{BenchError, BenchOptions, err, median, ms};
use crate::backend;
use std::fmt::Write as _;
use std::time::Instant;
use voxflex_core::deformation::DirtyRegion;
use voxflex_core::gpu::{GpuService, GpuServiceExt};
use voxflex_core::volume::Volume;
use voxflex_phantom::phantom;
use voxflex_resample::accuracy::{ErrorStats, bench_fields, errors};
use voxflex_resample::fields::Field;
use voxflex_resample::gpu::GpuSource;
use voxflex_resample::{Interpolation, ResampleOutput, ResampleParams, Resampler};

/// One resample of `field` in `params`' mode, `repeat` times after a warm-up:
/// the median time (ms) and the output.
pub(super) fn time_mode(
    volume: &Volume,
    field: &Field,
    params: ResampleParams,
    repeat: usize,
    gpu: Option<&dyn GpuService>,
) -> Result<(f64, ResampleOutput), BenchError> {
    let mut r = Resampler::new(params);
    let mut times = vec![];
    let out = match gpu {
        None => {
            for i in 0..=repeat {
                let t = Instant::now();
                r.resample_cpu(volume.view(), field.as_ref(), None, DirtyRegion::All)
                    .map_err(err)?;
                if i > 0 {
                    times.push(t.elapsed());
                }
            }
            r.cpu_output().ok_or_else(|| err("no CPU output"))?
        }
        Some(g) => {
            let source = GpuSource::upload(g, volume.view()).map_err(err)?;
            let up = |v: &[f32], l| g.upload(v, l).map_err(err);
            let disp = [
                up(&field.x, "bench.dx")?,
                up(&field.y, "bench.dy")?,
                up(&field.z, "bench.dz")?,
            ];
            let run = (|| {
                for i in 0..=repeat {
                    let t = Instant::now();
                    r.resample_gpu(g, &source, disp, None, DirtyRegion::All)
                        .map_err(err)?;
                    // Wait for the GPU so the time is real.
                    let mut probe = [0f32; 1];
                    if let Some(b) = r.gpu_output_buffer() {
                        g.read_buffer(b, 0, bytemuck::cast_slice_mut(&mut probe))
                            .map_err(err)?;
                    }
                    if i > 0 {
                        times.push(t.elapsed());
                    }
                }
                r.read_gpu_output(g).map_err(err)
            })();
            r.release_gpu(g);
            disp.iter().for_each(|&b| g.destroy_buffer(b));
            source.release(g);
            run?
        }
    };
    Ok((ms(median(times)), out))
}

/// Runs the accuracy benchmark and returns a human-readable report.
pub(super) fn run(args: &BenchOptions) -> Result<String, BenchError> {
    let repeat = args.repeat.max(1);
    let resolved = backend::resolve(args.backend).map_err(err)?;
    let gpu = resolved.gpu_service();
    let n = args.size;
    let volume = phantom("head", [n, n, n]).map_err(err)?;
    let background = volume.value_range().0;
    let mut out = String::new();
    let mut json = serde_json::Map::new();
    let _ = writeln!(
        out,
        "voxflex bench --accuracy: {n}³ head phantom ({} voxels), {}",
        volume.grid.len(),
        resolved.reason
    );
    let _ = writeln!(
        out,
        "error = |resampled − f64 trilinear sample of the source at the exact preimage| (HU), \
         over output voxels whose preimage is ≥ 1 voxel inside the source"
    );
    let _ = writeln!(
        out,
        "{:<7} {:<12} {:>12} {:>14} {:>13} {:>11}",
        "field", "mode", "resample ms", "mean |err| HU", "max |err| HU", "voxels"
    );
    for f in bench_fields(&volume.grid) {
        let field = f.field(&volume.grid);
        let mut rows: Vec<(Interpolation, f64, ErrorStats)> = vec![];
        for mode in Interpolation::ALL {
            let params = ResampleParams {
                background,
                interpolation: mode,
                ..Default::default()
            };
            let (t, output) = time_mode(&volume, &field, params, repeat, gpu.as_deref())?;
            let e = errors(&volume, &output, &f.inverse);
            if e.non_finite > 0 {
                return Err(err(format!(
                    "{} {mode}: {} compared voxels are not finite",
                    f.name, e.non_finite
                )));
            }
            let _ = writeln!(
                out,
                "{:<7} {:<12} {t:>12.1} {:>14.4} {:>13.3} {:>11}",
                f.name,
                mode.name(),
                e.mean_abs,
                e.max_abs,
                e.compared
            );
            let key = format!("{}_{}", f.name, mode.name());
            json.insert(format!("{key}_ms"), t.into());
            json.insert(format!("{key}_mean_abs_hu"), e.mean_abs.into());
            json.insert(format!("{key}_max_abs_hu"), e.max_abs.into());
            json.insert(format!("{key}_voxels"), e.compared.into());
            rows.push((mode, t, e));
        }
        let (tet, tri) = (&rows[0], &rows[1]);
        let _ = writeln!(
            out,
            "{:<7} trilinear vs tetrahedral: time ×{:.2}, mean error ÷{:.0}, max error ÷{:.0}   ({})",
            f.name,
            tri.1 / tet.1.max(1e-9),
            tet.2.mean_abs / tri.2.mean_abs.max(1e-12),
            tet.2.max_abs / tri.2.max_abs.max(1e-12),
            f.description
        );
    }
    let _ = writeln!(
        out,
        "default interpolation: {}",
        Interpolation::default().name()
    );
    if let Some(p) = &args.json {
        let text = serde_json::to_string_pretty(&json).map_err(err)?;
        voxflex_io::write_atomically(p, |w| w.write_all(text.as_bytes())).map_err(err)?;
    }
    Ok(out)
}
