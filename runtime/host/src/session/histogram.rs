//! [`Session::histogram`]: the source volume's value histogram, for a
//! front end's transfer-function editor (drawn behind its control points).

use super::Session;
use crate::pipeline::RunError;
use rayon::prelude::*;
use voxflex_core::stats::Histogram;
use voxflex_core::volume::VoxelSlice;

/// Voxels per parallel work item.
const CHUNK: usize = 1 << 16;

/// Most bins [`Session::histogram`] gives (a screen is narrower).
pub const MAX_HISTOGRAM_BINS: usize = 1 << 16;

impl Session {
    /// A `bins`-bin equal-width histogram of the **source** volume's finite
    /// values over its finite value range `[min, max]` (volume value units;
    /// the last bin includes `max`). A volume with one value puts every
    /// voxel in bin 0; one with no finite value gives `min = max = 0` and
    /// zero counts. Errors when `bins` is 0 or above
    /// [`MAX_HISTOGRAM_BINS`].
    pub fn histogram(&self, bins: usize) -> Result<Histogram, RunError> {
        if bins == 0 || bins > MAX_HISTOGRAM_BINS {
            return Err(RunError::Other(format!(
                "{}: histogram: {bins} bins; use 1 to {MAX_HISTOGRAM_BINS}",
                self.context
            )));
        }
        let data = self.source.view().data;
        let (min, max) = voxflex_core::volume::finite_range(data).unwrap_or((0.0, 0.0));
        let counts = count(data, bins, min, max);
        Ok(Histogram { min, max, counts })
    }
}

/// Counts of `data`'s finite values in `bins` equal bins over `[min, max]`.
fn count(data: VoxelSlice<'_>, bins: usize, min: f32, max: f32) -> Vec<u64> {
    let width = f64::from(max) - f64::from(min);
    let n = data.len();
    (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut counts = vec![0u64; bins];
            for l in c * CHUNK..((c + 1) * CHUNK).min(n) {
                let v = data.get_f32(l);
                if !v.is_finite() {
                    continue;
                }
                let b = if width > 0.0 {
                    ((f64::from(v) - f64::from(min)) / width * bins as f64) as usize
                } else {
                    0
                };
                counts[b.min(bins - 1)] += 1;
            }
            counts
        })
        .reduce(
            || vec![0u64; bins],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        )
}
