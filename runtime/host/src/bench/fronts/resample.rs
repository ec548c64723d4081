//! The `resample` front: both resampler interpolation modes under the
//! affine map, twist and bend of [`voxflex_resample::accuracy`] at
//! several head-phantom sizes, against its f64 reference (trilinear
//! sampling, in f64, of the source at each output voxel's exact preimage),
//! timed like `voxflex bench --accuracy` (median of full CPU resamples).

use super::{Front, Point};
use crate::bench::accuracy::time_mode;
use crate::bench::{BenchError, err};
use voxflex_phantom::phantom;
use voxflex_resample::accuracy::{bench_fields, errors};
use voxflex_resample::{Interpolation, ResampleParams};

/// The resampling front.
pub(super) fn front(quick: bool) -> Result<Front, BenchError> {
    let sizes: &[usize] = if quick { &[16, 24] } else { &[48, 96, 160] };
    let repeat = if quick { 1 } else { 3 };
    let largest = *sizes.last().expect("sizes");
    let mut points = vec![];
    for &n in sizes {
        let volume = phantom("head", [n, n, n]).map_err(err)?;
        let background = volume.value_range().0;
        for f in bench_fields(&volume.grid) {
            let field = f.field(&volume.grid);
            for mode in Interpolation::ALL {
                let params = ResampleParams {
                    background,
                    interpolation: mode,
                    ..Default::default()
                };
                let (t, output) = time_mode(&volume, &field, params, repeat, None)?;
                let e = errors(&volume, &output, &f.inverse);
                if e.non_finite > 0 || e.compared == 0 {
                    return Err(err(format!(
                        "resample front: {} {mode} at {n}³: {} voxels compared, {} not finite",
                        f.name, e.compared, e.non_finite
                    )));
                }
                points.push(Point {
                    series: format!("{} {}", mode.name(), f.name),
                    config: format!("{n}³"),
                    time_ms: t,
                    error: e.mean_abs,
                    is_default: mode == Interpolation::default() && n == largest,
                    group: f.name.to_string(),
                    extra: vec![
                        ("size", n.to_string()),
                        ("max_abs_hu", format!("{:.4}", e.max_abs)),
                        ("voxels_compared", e.compared.to_string()),
                    ],
                    tuning: None,
                });
            }
        }
    }
    Ok(Front {
        key: "resample",
        title: "resampling: tetrahedral vs trilinear vs f64 reference".into(),
        error_label: "mean |error|, HU".into(),
        description: format!(
            "The head phantom (i16 HU) at {} voxels a side, CPU path; fields about the volume \
             centre: affine (10°, ×1.05, 3 mm), twist (40° about z), bend (40° Barr bend of z \
             towards x). Reference: the f64 trilinear sample of the source at each output \
             voxel's exact analytic preimage, over output voxels whose preimage lies ≥ 1 voxel \
             inside the source. Time: median of {repeat} full resamples after a warm-up. The \
             default (`interpolation = \"trilinear\"`) is ringed at the largest size.",
            sizes
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        points,
    })
}
