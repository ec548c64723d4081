//! [`GrowthReport`]: how much work a growth did and how much of it was
//! useful.

/// Work done by a run of steps of a region growing.
///
/// A **visit** is one update of a voxel by the step (its new value
/// `max(q_v, max_n rise(q_n, e_v))` computed); a **useful** visit is one
/// that changed the voxel's value. The paper's dense kernel visits every
/// voxel of the volume each step (0.7–12 % useful in the thesis). The sparse
/// step visits only voxels that a neighbour changed in the previous step
/// lifts — which is exact, so there **every visit is useful by
/// construction** and [`GrowthReport::useful_fraction`] is 1. Its remaining
/// overhead is the neighbour scan: the 26 neighbours of each changed voxel
/// are checked (two state bits each, read three at a time) and those not at
/// their ceiling tested (a value read, the extinction, a compare) — work
/// proportional to the changes. [`GrowthReport::dense_useful_fraction`]
/// gives the fraction a dense sweep would have had, for comparison with the
/// thesis.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GrowthReport {
    /// Steps run (Jacobi steps: every update reads the previous step's
    /// values).
    pub steps: u64,
    /// Voxel visits (updates computed).
    pub visits: u64,
    /// Visits that changed a value.
    pub useful: u64,
    /// True when the growth has converged (no voxel changed in the last
    /// step, or nothing is left to visit).
    pub converged: bool,
    /// Times the working box had to grow (and its field be copied).
    pub regrows: u64,
}

impl GrowthReport {
    /// `useful / visits`, 1 when nothing was visited.
    pub fn useful_fraction(&self) -> f64 {
        if self.visits == 0 {
            1.0
        } else {
            self.useful as f64 / self.visits as f64
        }
    }

    /// `useful / (steps · voxels)`: the useful fraction a dense sweep of a
    /// volume of `voxels` voxels would have had over the same steps.
    pub fn dense_useful_fraction(&self, voxels: usize) -> f64 {
        let dense = self.steps as f64 * voxels as f64;
        if dense == 0.0 {
            1.0
        } else {
            self.useful as f64 / dense
        }
    }

    /// Adds a later run's counts (its `converged` wins).
    pub fn merge(&mut self, later: &GrowthReport) {
        self.steps += later.steps;
        self.visits += later.visits;
        self.useful += later.useful;
        self.regrows += later.regrows;
        self.converged = later.converged;
    }
}
