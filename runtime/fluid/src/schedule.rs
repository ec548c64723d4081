//! Parallel leveraging: how many workers each triangle gets, and which of
//! its candidate columns each worker tests.

/// `k` workers per triangle for a surface whose triangles have `c`
/// candidate columns on average: `max(1, ⌊α·c⌋)` (the paper's rule; α = 0
/// gives one worker per triangle).
pub fn workers_per_triangle(alpha: f64, mean_candidates: f64) -> usize {
    ((alpha * mean_candidates).floor() as usize).max(1)
}

/// The candidates worker `lane` of `k` tests among a triangle's `count`:
/// `lane, lane + k, lane + 2k, …`.
pub fn lane_candidates(lane: usize, k: usize, count: usize) -> impl Iterator<Item = usize> {
    (lane..count).step_by(k.max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lanes_of_a_triangle_cover_each_candidate_once() {
        for (count, k) in [(0, 1), (1, 4), (17, 4), (100, 1), (5, 9)] {
            let mut seen: Vec<usize> = (0..k).flat_map(|l| lane_candidates(l, k, count)).collect();
            seen.sort_unstable();
            assert_eq!(seen, (0..count).collect::<Vec<_>>(), "count {count}, k {k}");
        }
    }

    #[test]
    fn workers_follow_the_papers_rule() {
        assert_eq!(workers_per_triangle(0.25, 40.0), 10);
        assert_eq!(workers_per_triangle(0.25, 3.0), 1);
        assert_eq!(workers_per_triangle(0.0, 1e6), 1);
    }
}
