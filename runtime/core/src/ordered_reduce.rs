//! [`ordered_reduce`]: a parallel reduction that rounds the same way on
//! any number of threads.
//!
//! Rayon's `sum` and `reduce` combine partial results along the tree its
//! work stealing happened to split, so a float sum's last bits — and
//! whatever a solver decides from them, such as when a conjugate-gradient
//! solve stops — changed between runs of the same input. Here the parts
//! are fixed chunks of the index range, computed in parallel, and their
//! results are combined one after another in chunk order: the same
//! operations in the same order whatever the threads did.

use rayon::prelude::*;
use std::ops::Range;

/// `part(r₀) ⊕ part(r₁) ⊕ …` folded from `identity` in order, where
/// `r₀, r₁, …` are the consecutive ranges of `chunk` indices (the last
/// shorter) covering `0 .. len`, and `⊕` is `combine`. The parts run on
/// the rayon pool when `parallel`, else on the calling thread; the result
/// is the same bit for bit either way.
pub fn ordered_reduce<R: Send>(
    len: usize,
    chunk: usize,
    parallel: bool,
    part: impl Fn(Range<usize>) -> R + Sync,
    identity: R,
    combine: impl FnMut(R, R) -> R,
) -> R {
    let chunk = chunk.max(1);
    let range = |c: usize| c * chunk..((c + 1) * chunk).min(len);
    let count = len.div_ceil(chunk);
    if parallel {
        let parts: Vec<R> = (0..count).into_par_iter().map(|c| part(range(c))).collect();
        parts.into_iter().fold(identity, combine)
    } else {
        (0..count).map(|c| part(range(c))).fold(identity, combine)
    }
}

#[cfg(test)]
mod tests {
    use super::ordered_reduce;

    /// A float sum over values of six decades: the same bits serially and
    /// on pools of 1, 2, 3 and 8 threads, equal to the chunks' sums added
    /// in order; empty and one-chunk ranges included.
    #[test]
    fn sums_round_alike_on_any_thread_count() {
        let values: Vec<f64> = (0..100_003u64)
            .map(|i| {
                let h = i.wrapping_mul(0x9E37_79B9_7F4A_7C15);
                ((h >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10f64.powi((h % 6) as i32)
            })
            .collect();
        for (len, chunk) in [(0, 7), (5, 1000), (100_003, 1000), (100_003, 1)] {
            let v = &values[..len];
            let want = v
                .chunks(chunk)
                .map(|c| c.iter().sum::<f64>())
                .fold(0.0, |a, b| a + b);
            let sum = |parallel| {
                ordered_reduce(
                    len,
                    chunk,
                    parallel,
                    |r| v[r].iter().sum::<f64>(),
                    0.0,
                    |a, b| a + b,
                )
            };
            assert_eq!(
                sum(false).to_bits(),
                want.to_bits(),
                "serial, {len}/{chunk}"
            );
            for threads in [1, 2, 3, 8] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let got = pool.install(|| sum(true));
                assert_eq!(
                    got.to_bits(),
                    want.to_bits(),
                    "{threads} threads, {len}/{chunk}"
                );
            }
        }
    }
}
