//! Work counters of the CPU raster, for profiling (cargo feature
//! `counters`; off by default, and then every call here compiles to
//! nothing).
//!
//! They answer what a profile of the fused tile kernel cannot: how many
//! cells each output tile hands to the lanes (cells of blocks that straddle
//! tiles go through the lanes once per tile), how full the eight lanes of
//! the candidate loop are, and how many candidate voxel centres are tested,
//! skipped as decided, found inside a tetrahedron and claimed. With the
//! feature on, each count is one relaxed atomic add (both threads share the
//! counters), so the build is slower than the default one: time without
//! the feature, count with it.
//!
//! `voxflex resample … --log voxflex_resample=debug` prints them once per
//! resample (see `docs/BENCHMARKS.md`, *Where a full twist's time goes*).

/// What is counted, per resample call.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(not(feature = "counters"), allow(dead_code))]
pub(crate) enum Counter {
    /// Cells handed to the lanes (each tile counts its own; a cell of a
    /// block that straddles tiles counts once per tile).
    Cells,
    /// Lane groups (eight cells of one parity) with at least one non-empty
    /// candidate box inside the tile: the groups that build their planes.
    BusyGroups,
    /// Cells with a non-empty candidate box inside the tile.
    BusyCells,
    /// Candidates skipped before their test: a strong claim of a smaller id
    /// already holds the voxel.
    Decided,
    /// Iterations of the candidate loop (one eight-lane test each).
    Iterations,
    /// Lane-candidates tested (active lanes summed over the iterations).
    Tested,
    /// Lane-candidates found inside a tetrahedron of their cell.
    Found,
    /// Claims that beat the tile's key.
    Claims,
}

/// The work counts of the last CPU resample (see [`Counter`] for each).
/// Cells count once per output tile that runs them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterCounts {
    /// The sampling mesh's cells.
    pub mesh_cells: u64,
    /// Output voxels of the resampled region.
    pub output_voxels: u64,
    /// Cells handed to the lanes, once per tile.
    pub cells: u64,
    /// Lane groups that built their planes.
    pub busy_groups: u64,
    /// Cells with a non-empty candidate box in a tile.
    pub busy_cells: u64,
    /// Candidates skipped as already decided.
    pub decided: u64,
    /// Candidate-loop iterations (eight lanes each).
    pub iterations: u64,
    /// Lane-candidates tested.
    pub tested: u64,
    /// Lane-candidates found inside a tetrahedron of their cell.
    pub found: u64,
    /// Claims that beat the tile's key.
    pub claims: u64,
}

/// The counts of the last CPU resample that rasterised; `None` without the
/// `counters` feature or before one.
pub fn last_raster_counts() -> Option<RasterCounts> {
    #[cfg(feature = "counters")]
    return *on::LAST.lock().unwrap_or_else(|e| e.into_inner());
    #[cfg(not(feature = "counters"))]
    None
}

#[cfg(feature = "counters")]
mod on {
    use super::Counter;
    use std::sync::atomic::{AtomicU64, Ordering};

    pub(super) const N: usize = Counter::Claims as usize + 1;
    pub(super) static COUNTS: [AtomicU64; N] = [const { AtomicU64::new(0) }; N];

    pub(super) static LAST: std::sync::Mutex<Option<super::RasterCounts>> =
        std::sync::Mutex::new(None);

    pub(super) fn take() -> [u64; N] {
        std::array::from_fn(|i| COUNTS[i].swap(0, Ordering::Relaxed))
    }
}

/// Adds `n` to counter `c` (nothing without the feature).
#[inline(always)]
#[cfg_attr(not(feature = "counters"), allow(unused_variables))]
pub(crate) fn add(c: Counter, n: u32) {
    #[cfg(feature = "counters")]
    on::COUNTS[c as usize].fetch_add(u64::from(n), std::sync::atomic::Ordering::Relaxed);
}

/// Logs the counts of the resample that just ran (`debug` level), with the
/// mesh's cells and the region's output voxels to compare them with, keeps
/// them for [`last_raster_counts`] and starts again from zero (nothing
/// without the feature).
pub(crate) fn report(mesh_cells: usize, output_voxels: usize) {
    #[cfg(feature = "counters")]
    {
        let taken = on::take();
        let n = |c: Counter| taken[c as usize];
        let counts = super::RasterCounts {
            mesh_cells: mesh_cells as u64,
            output_voxels: output_voxels as u64,
            cells: n(Counter::Cells),
            busy_groups: n(Counter::BusyGroups),
            busy_cells: n(Counter::BusyCells),
            decided: n(Counter::Decided),
            iterations: n(Counter::Iterations),
            tested: n(Counter::Tested),
            found: n(Counter::Found),
            claims: n(Counter::Claims),
        };
        let lane_use = counts.tested as f64 / (8 * counts.iterations).max(1) as f64;
        tracing::debug!(?counts, lane_use, "resample: raster counters (cpu)");
        *on::LAST.lock().unwrap_or_else(|e| e.into_inner()) = Some(counts);
    }
    #[cfg(not(feature = "counters"))]
    let _ = (mesh_cells, output_voxels);
}
