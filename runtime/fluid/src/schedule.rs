//! Parallel leveraging: how many workers each triangle gets, which of its
//! candidate rows each worker scans, and how the CPU cuts the workers into
//! rayon tasks.

use std::ops::Range;

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

/// The CPU's cut of the triangles into contiguous runs of equal length,
/// one rayon task each. The row scan's work per triangle is its candidate
/// rows, and a task holds hundreds of triangles, so equal runs balance
/// (rayon steals between the few tasks); leveraging's finer cut — a
/// triangle's rows shared by `k` workers — is what a GPU needs to keep its
/// invocations busy, and changes nothing a CPU task does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TaskSplit {
    /// All triangles.
    pub triangles: usize,
    /// Triangles per task (the last may have fewer).
    pub per_task: usize,
    /// Number of tasks (at least 1).
    pub tasks: usize,
}

impl TaskSplit {
    /// `triangles` cut into about `tasks_wanted` tasks, each at least
    /// `min_triangles` long (so a small surface is not dominated by task
    /// overhead).
    pub fn new(triangles: usize, tasks_wanted: usize, min_triangles: usize) -> Self {
        let most = triangles.div_ceil(min_triangles.max(1)).max(1);
        let per_task = triangles.div_ceil(tasks_wanted.clamp(1, most)).max(1);
        Self {
            triangles,
            per_task,
            tasks: triangles.div_ceil(per_task).max(1),
        }
    }

    /// The triangles of task `b`.
    pub fn task(&self, b: usize) -> Range<usize> {
        (b * self.per_task).min(self.triangles)..((b + 1) * self.per_task).min(self.triangles)
    }
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

    #[test]
    fn the_tasks_cover_every_triangle_once() {
        for (n, want, min) in [
            (0, 8, 1),
            (1, 8, 1),
            (5120, 8, 512),
            (100, 8, 64),
            (75408, 8, 64),
        ] {
            let s = TaskSplit::new(n, want, min);
            let covered: Vec<usize> = (0..s.tasks).flat_map(|b| s.task(b)).collect();
            assert_eq!(covered, (0..n).collect::<Vec<_>>(), "{n}");
            assert!(s.tasks <= want.max(1));
        }
        assert_eq!(TaskSplit::new(100, 8, 64).tasks, 2);
    }
}
