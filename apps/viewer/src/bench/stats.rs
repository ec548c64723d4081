//! Summary statistics of a set of timings: count, mean, median, 99th
//! percentile and worst.

use serde_json::{Value, json};
use std::time::Duration;

/// A set of timings summarised, in milliseconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stats {
    /// Samples.
    pub count: usize,
    /// Mean, ms.
    pub mean_ms: f64,
    /// Median (nearest rank), ms.
    pub p50_ms: f64,
    /// 99th percentile (nearest rank), ms.
    pub p99_ms: f64,
    /// Largest, ms.
    pub worst_ms: f64,
}

/// The `p`-quantile (0 < p ≤ 1) of ascending `sorted` by nearest rank:
/// the smallest sample with at least a fraction `p` of the samples at or
/// below it.
fn nearest_rank(sorted: &[f64], p: f64) -> f64 {
    let rank = (p * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

impl Stats {
    /// The statistics of `samples`; `None` when there are none.
    pub fn of(samples: &[Duration]) -> Option<Self> {
        let mut ms: Vec<f64> = samples.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        if ms.is_empty() {
            return None;
        }
        ms.sort_by(f64::total_cmp);
        Some(Self {
            count: ms.len(),
            mean_ms: ms.iter().sum::<f64>() / ms.len() as f64,
            p50_ms: nearest_rank(&ms, 0.5),
            p99_ms: nearest_rank(&ms, 0.99),
            worst_ms: ms[ms.len() - 1],
        })
    }

    /// As JSON: `{count, mean_ms, p50_ms, p99_ms, worst_ms}`.
    pub fn json(&self) -> Value {
        json!({
            "count": self.count,
            "mean_ms": self.mean_ms,
            "p50_ms": self.p50_ms,
            "p99_ms": self.p99_ms,
            "worst_ms": self.worst_ms,
        })
    }

    /// One line: `N frames: mean a, p50 b, p99 c, worst d ms`.
    pub fn line(&self) -> String {
        format!(
            "{} samples: mean {:.2}, p50 {:.2}, p99 {:.2}, worst {:.2} ms",
            self.count, self.mean_ms, self.p50_ms, self.p99_ms, self.worst_ms
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank_samples() {
        let d: Vec<Duration> = (1..=200).map(Duration::from_millis).collect();
        let s = Stats::of(&d).unwrap();
        assert_eq!(s.count, 200);
        assert!((s.mean_ms - 100.5).abs() < 1e-9);
        assert!((s.p50_ms - 100.0).abs() < 1e-9);
        assert!((s.p99_ms - 198.0).abs() < 1e-9);
        assert!((s.worst_ms - 200.0).abs() < 1e-9);
        let one = Stats::of(&[Duration::from_millis(7)]).unwrap();
        assert_eq!((one.p50_ms, one.p99_ms, one.worst_ms), (7.0, 7.0, 7.0));
        assert!(Stats::of(&[]).is_none());
    }
}
