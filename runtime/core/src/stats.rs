//! [`VolumeStats`]: geometry and value statistics of a volume, computed in
//! parallel, with a compact human-readable [`Display`](std::fmt::Display)
//! (what `voxflex info` prints).
//!
//! Non-finite values (NaN, ±∞ in f32 volumes) are counted apart and left
//! out of every value statistic. Percentiles use the nearest-rank definition;
//! they are exact for u8, i16 and u16 volumes (one counting bin per
//! representable value) and, for f32, accurate to one of 65 536 equal bins
//! over `[min, max]` (linearly interpolated within the bin).

use crate::grid::Grid;
use crate::ordered_reduce::ordered_reduce;
use crate::volume::{Sample, ScalarType, VolumeView, VoxelSlice};
use glam::DVec3;
use rayon::prelude::*;

/// Number of bins of [`VolumeStats::histogram`].
pub const HISTOGRAM_BINS: usize = 64;

/// Bins used for f32 percentiles.
const FINE_BINS_F32: usize = 1 << 16;

/// Values per parallel work item.
const CHUNK: usize = 1 << 16;

/// An equal-width histogram over `[min, max]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Histogram {
    /// Lower edge of the first bin (the smallest finite value).
    pub min: f32,
    /// Upper edge of the last bin (the largest finite value, included).
    pub max: f32,
    /// Voxel count per bin; bin `b` covers
    /// `[min + b·w, min + (b+1)·w)` with `w = (max − min) / counts.len()`.
    pub counts: Vec<u64>,
}

/// Geometry and value statistics of a volume.
#[derive(Clone, Debug, PartialEq)]
pub struct VolumeStats {
    /// Voxels along x, y, z.
    pub dims: [usize; 3],
    /// Voxel spacing (mm).
    pub spacing: DVec3,
    /// World position (mm) of the centre of voxel 0.
    pub origin: DVec3,
    /// Scalar type of the voxels.
    pub scalar_type: ScalarType,
    /// Total number of voxels.
    pub voxels: usize,
    /// Voxels holding NaN or ±∞ (f32 only), excluded from the statistics.
    pub non_finite: usize,
    /// Smallest finite value (0 when there is none).
    pub min: f32,
    /// Largest finite value (0 when there is none).
    pub max: f32,
    /// Mean of the finite values.
    pub mean: f64,
    /// Population standard deviation of the finite values.
    pub std: f64,
    /// 1st percentile (nearest rank).
    pub p1: f32,
    /// Median (nearest rank).
    pub p50: f32,
    /// 99th percentile (nearest rank).
    pub p99: f32,
    /// [`HISTOGRAM_BINS`]-bin histogram of the finite values over `[min, max]`.
    pub histogram: Histogram,
}

/// Count, mean and sum of squared deviations of a chunk (Chan et al. merge).
#[derive(Clone, Copy, Debug)]
struct Moments {
    n: u64,
    mean: f64,
    m2: f64,
    min: f32,
    max: f32,
    non_finite: u64,
}

impl Moments {
    const EMPTY: Moments = Moments {
        n: 0,
        mean: 0.0,
        m2: 0.0,
        min: f32::INFINITY,
        max: f32::NEG_INFINITY,
        non_finite: 0,
    };

    fn of<T: Sample>(s: &[T]) -> Moments {
        // Two-pass within the chunk: exact enough and vectorisable.
        let mut n = 0u64;
        let mut sum = 0.0f64;
        let mut min = f32::INFINITY;
        let mut max = f32::NEG_INFINITY;
        let mut non_finite = 0u64;
        for v in s {
            let v = v.to_f32();
            if v.is_finite() {
                n += 1;
                sum += f64::from(v);
                min = min.min(v);
                max = max.max(v);
            } else {
                non_finite += 1;
            }
        }
        let mean = if n > 0 { sum / n as f64 } else { 0.0 };
        let m2 = s
            .iter()
            .map(|v| v.to_f32())
            .filter(|v| v.is_finite())
            .map(|v| {
                let d = f64::from(v) - mean;
                d * d
            })
            .sum();
        Moments {
            n,
            mean,
            m2,
            min,
            max,
            non_finite,
        }
    }

    fn merge(a: Moments, b: Moments) -> Moments {
        let n = a.n + b.n;
        let (mean, m2) = if n == 0 {
            (0.0, 0.0)
        } else {
            let d = b.mean - a.mean;
            let mean = a.mean + d * b.n as f64 / n as f64;
            let m2 = a.m2 + b.m2 + d * d * (a.n as f64) * (b.n as f64) / n as f64;
            (mean, m2)
        };
        Moments {
            n,
            mean,
            m2,
            min: a.min.min(b.min),
            max: a.max.max(b.max),
            non_finite: a.non_finite + b.non_finite,
        }
    }
}

/// How fine-histogram bins map back to values.
#[derive(Clone, Copy, Debug)]
enum FineMap {
    /// Bin `b` holds exactly the value `b + offset` (integer types).
    Exact { offset: f64 },
    /// Bin `b` covers `[lo + b·w, lo + (b+1)·w)` (f32).
    Range { lo: f64, width: f64 },
}

fn fine_histogram<T: Sample>(
    s: &[T],
    bins: usize,
    index: impl Fn(f32) -> Option<usize> + Sync,
) -> Vec<u64> {
    s.par_chunks(CHUNK)
        .fold(
            || vec![0u64; bins],
            |mut acc, c| {
                for v in c {
                    if let Some(b) = index(v.to_f32()) {
                        acc[b] += 1;
                    }
                }
                acc
            },
        )
        .reduce(
            || vec![0u64; bins],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
                a
            },
        )
}

impl VolumeStats {
    /// Computes the statistics of a volume (parallel; two passes over the
    /// values).
    pub fn compute(view: VolumeView<'_>) -> Self {
        let grid = view.grid;
        let data = view.data;
        // Merged in chunk order, not along rayon's reduction tree (which
        // follows work stealing): the mean and σ are the same to the last
        // bit whatever the threads did.
        let m = crate::with_voxels!(data, |s| ordered_reduce(
            s.len(),
            CHUNK,
            true,
            |r| Moments::of(&s[r]),
            Moments::EMPTY,
            Moments::merge
        ));
        let (min, max) = if m.n > 0 { (m.min, m.max) } else { (0.0, 0.0) };

        // Fine counts for percentiles and the display histogram.
        let (fine, map) = match data {
            VoxelSlice::U8(s) => (
                fine_histogram(s, 256, |v| Some(v as usize)),
                FineMap::Exact { offset: 0.0 },
            ),
            VoxelSlice::I16(s) => (
                fine_histogram(s, 65536, |v| Some((v as i32 + 32768) as usize)),
                FineMap::Exact { offset: -32768.0 },
            ),
            VoxelSlice::U16(s) => (
                fine_histogram(s, 65536, |v| Some(v as usize)),
                FineMap::Exact { offset: 0.0 },
            ),
            VoxelSlice::F32(s) => {
                let lo = f64::from(min);
                let span = f64::from(max) - lo;
                let width = if span > 0.0 {
                    span / FINE_BINS_F32 as f64
                } else {
                    1.0
                };
                let bins = FINE_BINS_F32;
                (
                    fine_histogram(s, bins, |v| {
                        v.is_finite()
                            .then(|| (((f64::from(v) - lo) / width) as usize).min(bins - 1))
                    }),
                    FineMap::Range { lo, width },
                )
            }
        };
        let percentile = |q: f64| -> f32 {
            if m.n == 0 {
                return 0.0;
            }
            let rank = ((q * m.n as f64).ceil() as u64).clamp(1, m.n);
            let mut seen = 0u64;
            for (b, &c) in fine.iter().enumerate() {
                if c == 0 {
                    continue;
                }
                if seen + c >= rank {
                    let v = match map {
                        FineMap::Exact { offset } => b as f64 + offset,
                        FineMap::Range { lo, width } => {
                            let within = (rank - seen) as f64 - 0.5;
                            lo + (b as f64 + within / c as f64) * width
                        }
                    };
                    return (v as f32).clamp(min, max);
                }
                seen += c;
            }
            max
        };
        let (p1, p50, p99) = (percentile(0.01), percentile(0.50), percentile(0.99));

        // Display histogram over [min, max].
        let mut counts = vec![0u64; HISTOGRAM_BINS];
        let span = f64::from(max) - f64::from(min);
        for (b, &c) in fine.iter().enumerate() {
            if c == 0 {
                continue;
            }
            let v = match map {
                FineMap::Exact { offset } => b as f64 + offset,
                FineMap::Range { lo, width } => lo + (b as f64 + 0.5) * width,
            };
            let bin = if span > 0.0 {
                (((v - f64::from(min)) / span * HISTOGRAM_BINS as f64) as usize)
                    .min(HISTOGRAM_BINS - 1)
            } else {
                0
            };
            counts[bin] += c;
        }

        VolumeStats {
            dims: grid.dims,
            spacing: grid.spacing,
            origin: grid.origin,
            scalar_type: data.scalar_type(),
            voxels: data.len(),
            non_finite: m.non_finite as usize,
            min,
            max,
            mean: m.mean,
            std: if m.n > 0 {
                (m.m2 / m.n as f64).sqrt()
            } else {
                0.0
            },
            p1,
            p50,
            p99,
            histogram: Histogram { min, max, counts },
        }
    }

    /// The grid these statistics describe.
    pub fn grid(&self) -> Grid {
        Grid::new(self.dims, self.spacing, self.origin)
    }
}

/// A number with at most 4 decimals, trailing zeros removed.
fn num(x: f64) -> String {
    if !x.is_finite() {
        return x.to_string();
    }
    let s = format!("{x:.4}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

/// One character per bin, height on a log scale.
fn sparkline(counts: &[u64]) -> String {
    const BARS: [char; 9] = [' ', '▁', '▂', '▃', '▄', '▅', '▆', '▇', '█'];
    let top = counts.iter().copied().max().unwrap_or(0);
    if top == 0 {
        return String::new();
    }
    let lmax = (top as f64).ln_1p();
    counts
        .iter()
        .map(|&c| {
            if c == 0 {
                BARS[0]
            } else {
                let h = ((c as f64).ln_1p() / lmax * 8.0).ceil() as usize;
                BARS[h.clamp(1, 8)]
            }
        })
        .collect()
}

impl std::fmt::Display for VolumeStats {
    /// Compact summary, for example:
    ///
    /// ```text
    /// dims      181 × 217 × 181 voxels (7109137 u8)
    /// spacing   1 × 1 × 1 mm (field of view 181 × 217 × 181 mm)
    /// origin    (-90, -125, -71) mm (centre of voxel 0)
    /// values    min 0  max 255  mean 52.3  std 40.1
    /// pct       p1 0  p50 43  p99 180
    /// histogram ▇▃▂▂▃▄▄▃▂▁ … [0 … 255] (64 bins, log scale)
    /// ```
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [nx, ny, nz] = self.dims;
        let s = self.spacing;
        let fov = s * DVec3::new(nx as f64, ny as f64, nz as f64);
        writeln!(
            f,
            "dims      {nx} × {ny} × {nz} voxels ({} {})",
            self.voxels,
            self.scalar_type.name()
        )?;
        writeln!(
            f,
            "spacing   {} × {} × {} mm (field of view {} × {} × {} mm)",
            num(s.x),
            num(s.y),
            num(s.z),
            num(fov.x),
            num(fov.y),
            num(fov.z)
        )?;
        writeln!(
            f,
            "origin    ({}, {}, {}) mm (centre of voxel 0)",
            num(self.origin.x),
            num(self.origin.y),
            num(self.origin.z)
        )?;
        if self.voxels == self.non_finite {
            write!(f, "values    no finite values")?;
            if self.non_finite > 0 {
                write!(f, " ({} NaN/inf)", self.non_finite)?;
            }
            return Ok(());
        }
        write!(
            f,
            "values    min {}  max {}  mean {}  std {}",
            num(f64::from(self.min)),
            num(f64::from(self.max)),
            num(self.mean),
            num(self.std)
        )?;
        if self.non_finite > 0 {
            write!(f, "  ({} NaN/inf ignored)", self.non_finite)?;
        }
        writeln!(f)?;
        writeln!(
            f,
            "pct       p1 {}  p50 {}  p99 {}",
            num(f64::from(self.p1)),
            num(f64::from(self.p50)),
            num(f64::from(self.p99))
        )?;
        write!(
            f,
            "histogram {} [{} … {}] ({} bins, log scale)",
            sparkline(&self.histogram.counts),
            num(f64::from(self.histogram.min)),
            num(f64::from(self.histogram.max)),
            self.histogram.counts.len()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::{Volume, VoxelData};

    fn vol(data: VoxelData, dims: [usize; 3]) -> Volume {
        Volume::new(
            Grid::new(dims, DVec3::new(0.5, 1.0, 2.0), DVec3::ZERO),
            data,
        )
        .unwrap()
    }

    #[test]
    fn integer_stats_are_exact() {
        // 0..=99 as i16 minus 50: mean -0.5, p50 = -1 (rank 50), p1 = -50, p99 = 48.
        let v = vol(
            VoxelData::I16((0..100).map(|i| i - 50).collect()),
            [10, 10, 1],
        );
        let s = VolumeStats::compute(v.view());
        assert_eq!((s.min, s.max), (-50.0, 49.0));
        assert!((s.mean + 0.5).abs() < 1e-12);
        let want_std = ((0..100).map(|i| (i as f64 - 49.5).powi(2)).sum::<f64>() / 100.0).sqrt();
        assert!((s.std - want_std).abs() < 1e-9);
        assert_eq!((s.p1, s.p50, s.p99), (-50.0, -1.0, 48.0));
        assert_eq!(s.histogram.counts.len(), HISTOGRAM_BINS);
        assert_eq!(s.histogram.counts.iter().sum::<u64>(), 100);
        assert_eq!(s.scalar_type, ScalarType::I16);
        let text = s.to_string();
        assert!(text.contains("10 × 10 × 1 voxels (100 i16)"), "{text}");
        assert!(text.contains("0.5 × 1 × 2 mm"), "{text}");
        assert!(text.contains("min -50  max 49  mean -0.5"), "{text}");
        assert!(text.contains("p1 -50  p50 -1  p99 48"), "{text}");
    }

    /// The mean and σ of a volume of many chunks are the same bits on 1,
    /// 2, 3 and 8 threads, and those of the chunks merged in order.
    #[test]
    fn mean_and_std_round_alike_on_any_thread_count() {
        let n = 9 * CHUNK + 12_345;
        let vals: Vec<f32> = (0..n)
            .map(|i| ((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as f32 * 1e-3 - 7.0e3)
            .collect();
        let want = vals
            .chunks(CHUNK)
            .map(Moments::of)
            .fold(Moments::EMPTY, Moments::merge);
        let v = vol(VoxelData::F32(vals), [n, 1, 1]);
        for threads in [1, 2, 3, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let s = pool.install(|| VolumeStats::compute(v.view()));
            assert_eq!(s.mean.to_bits(), want.mean.to_bits(), "{threads} threads");
            let std = (want.m2 / want.n as f64).sqrt();
            assert_eq!(s.std.to_bits(), std.to_bits(), "{threads} threads");
        }
    }

    #[test]
    fn float_stats_skip_non_finite_and_match_sorting() {
        let n = 200_000;
        let mut vals: Vec<f32> = (0..n)
            .map(|i| ((i as u64 * 2654435761) % 100_000) as f32 / 1000.0 - 20.0)
            .collect();
        vals[7] = f32::NAN;
        vals[9] = f32::INFINITY;
        let v = vol(VoxelData::F32(vals.clone()), [n, 1, 1]);
        let s = VolumeStats::compute(v.view());
        assert_eq!(s.non_finite, 2);
        let mut finite: Vec<f32> = vals.into_iter().filter(|v| v.is_finite()).collect();
        finite.sort_by(f32::total_cmp);
        let m = finite.len();
        let exact = |q: f64| finite[((q * m as f64).ceil() as usize).clamp(1, m) - 1];
        let tol = (s.max - s.min) / 65536.0 * 1.01;
        for (got, q) in [(s.p1, 0.01), (s.p50, 0.5), (s.p99, 0.99)] {
            assert!(
                (got - exact(q)).abs() <= tol,
                "q {q}: {got} vs {}",
                exact(q)
            );
        }
        assert_eq!(s.min, finite[0]);
        assert_eq!(s.max, finite[m - 1]);
        let mean = finite.iter().map(|&v| f64::from(v)).sum::<f64>() / m as f64;
        assert!((s.mean - mean).abs() < 1e-9);
        assert!(s.to_string().contains("2 NaN/inf ignored"));
    }

    #[test]
    fn degenerate_volumes() {
        let s = VolumeStats::compute(vol(VoxelData::U8(vec![7; 8]), [2, 2, 2]).view());
        assert_eq!((s.min, s.max, s.p1, s.p99), (7.0, 7.0, 7.0, 7.0));
        assert_eq!(s.std, 0.0);
        assert_eq!(s.histogram.counts[0], 8);
        let s = VolumeStats::compute(vol(VoxelData::F32(vec![f32::NAN; 3]), [3, 1, 1]).view());
        assert_eq!((s.min, s.max, s.non_finite), (0.0, 0.0, 3));
        assert!(s.to_string().contains("no finite values"));
        let s = VolumeStats::compute(vol(VoxelData::U16(vec![]), [0, 1, 1]).view());
        assert_eq!(s.voxels, 0);
        assert_eq!(num(1.23456), "1.2346");
        assert_eq!(num(-0.00001), "0");
    }
}
