//! The CPU's one pass over the triangles: each is classified (side and
//! candidate columns, in the grid's index space) and, when it has
//! candidates, scanned row by row ([`TriangleRaster`]) while its corners
//! are at hand; its non-empty runs, with their barycentric coordinates, go
//! to its task's bucket for the band of rows they lie in ([`BandRuns`]),
//! so the section pass finds a band's runs in one bucket per task, with no
//! sort and no write shared between tasks.
//!
//! Coordinates: (u, v) in the grid's index space
//! ([`crate::index_space`]), heights in the [`crate::GravityFrame`], mm.

use crate::distribute::RunBarycentric;
use crate::hits::{Run, TriangleRaster};
use crate::projection::{CandidateSum, ProjectedSurface};
use crate::schedule::TaskSplit;
use rayon::prelude::*;
use std::ops::Range;

/// Cells (columns × rows) a band of rows holds at most, unless one row is
/// wider: about 8,192, so a band's crossings fit in the L2 cache.
pub const BAND_CELLS: usize = 8192;

/// The grid's rows cut into bands of `2^shift` rows (the last may have
/// fewer), the unit of the section pass's parallelism.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowBands {
    /// Rows per band, as a power of two.
    pub shift: u32,
    /// Number of bands (at least 1).
    pub bands: usize,
    /// Rows of the grid.
    pub rows: usize,
}

impl RowBands {
    /// `rows` of `columns` each in bands of about [`BAND_CELLS`] cells (so a
    /// band's crossings are matched in cache), and at least
    /// `bands_wanted` bands where the rows allow (the section pass's
    /// parallelism).
    pub fn new(rows: usize, columns: usize, bands_wanted: usize) -> Self {
        let fits = (BAND_CELLS / columns.max(1)).max(1);
        let per = (1usize << fits.ilog2())
            .min(rows.div_ceil(bands_wanted.max(1)).next_power_of_two())
            .max(1);
        Self {
            shift: per.trailing_zeros(),
            bands: rows.div_ceil(per).max(1),
            rows,
        }
    }

    /// The band of row `j`.
    #[inline]
    pub fn band(&self, j: usize) -> usize {
        j >> self.shift
    }

    /// The rows of band `b`.
    pub fn rows(&self, b: usize) -> Range<usize> {
        (b << self.shift).min(self.rows)..((b + 1) << self.shift).min(self.rows)
    }
}

/// One task's runs in one band of rows (capacity reused between calls):
/// top runs apart from bottom runs, so only a bottom run — the only kind
/// whose fluid is weighed — carries barycentric coordinates. Each vector's
/// first `filled` entries are the non-empty runs (the rest is kept from
/// earlier calls, so a weighing neither allocates nor clears).
#[derive(Debug, Default)]
pub struct BandRuns {
    tops: Vec<Run>,
    bottoms: Vec<Run>,
    barycentrics: Vec<RunBarycentric>,
    /// Non-empty top and bottom runs kept.
    filled: [usize; 2],
    /// Columns crossed by the kept top and bottom runs.
    crossings: [usize; 2],
}

impl BandRuns {
    /// Forgets every run (keeps the capacity).
    pub fn clear(&mut self) {
        self.filled = [0; 2];
        self.crossings = [0; 2];
    }

    /// Keeps `run` when it crosses any column (an empty run is written but
    /// not kept, so it costs no branch).
    #[inline(always)]
    pub fn keep(&mut self, (run, barycentric): (Run, RunBarycentric)) {
        let kept = usize::from(run.len > 0);
        let [tops, bottoms] = self.filled;
        if run.top() {
            if self.tops.len() == tops {
                self.tops.resize((2 * tops).max(1024), Run::default());
            }
            self.tops[tops] = run;
            self.filled[0] += kept;
            self.crossings[0] += run.len as usize;
        } else {
            if self.bottoms.len() == bottoms {
                let room = (2 * bottoms).max(1024);
                self.bottoms.resize(room, Run::default());
                self.barycentrics.resize(room, RunBarycentric::default());
            }
            self.bottoms[bottoms] = run;
            self.barycentrics[bottoms] = barycentric;
            self.filled[1] += kept;
            self.crossings[1] += run.len as usize;
        }
    }

    /// The kept top runs.
    pub fn tops(&self) -> &[Run] {
        &self.tops[..self.filled[0]]
    }

    /// The kept bottom runs.
    pub fn bottoms(&self) -> &[Run] {
        &self.bottoms[..self.filled[1]]
    }

    /// The kept bottom runs' barycentric coordinates, in their order.
    pub fn barycentrics(&self) -> &[RunBarycentric] {
        &self.barycentrics[..self.filled[1]]
    }

    /// Columns crossed by the kept top and the kept bottom runs.
    pub fn crossings(&self) -> [usize; 2] {
        self.crossings
    }
}

/// One row-scan task's runs, per band of rows.
#[derive(Debug, Default)]
pub struct TaskRuns {
    bands: Vec<BandRuns>,
    sum: CandidateSum,
}

impl TaskRuns {
    /// This task's runs of band `b`.
    pub fn band(&self, b: usize) -> &BandRuns {
        &self.bands[b]
    }
}

/// Classifies every triangle of `p` in the grid's index space
/// ([`TriangleRaster::of`]) and scans those with candidates into `tasks`
/// (one per task of `split`, which cuts `order`: each triangle's index and
/// corner ids in visiting order, [`crate::triangle_order`]); returns the
/// mean candidates per non-vertical triangle (the paper's `c`). The classifications are not kept: the CPU
/// path needs nothing of them after the scan.
pub fn scan_triangles(
    p: &ProjectedSurface<'_>,
    split: TaskSplit,
    bands: RowBands,
    tasks: &mut Vec<TaskRuns>,
    order: &[(u32, [u32; 3])],
) -> f64 {
    let n = p.grid.n;
    let uvh = &p.uvh;
    tasks.resize_with(split.tasks, Default::default);
    tasks.truncate(split.tasks);
    tasks.par_iter_mut().enumerate().for_each(|(b, task)| {
        task.bands.resize_with(bands.bands, Default::default);
        task.bands.iter_mut().for_each(BandRuns::clear);
        let mut sum = CandidateSum::default();
        for &(t, ids) in &order[split.task(b)] {
            let t = t as usize;
            let corners = ids.map(|v| uvh[v as usize]);
            let (pt, raster) = TriangleRaster::of(t, ids, corners, n);
            sum.add(&pt);
            let Some(mut raster) = raster else {
                continue;
            };
            if raster.wants_row_test(pt.rows) {
                scan_with_row_test(&raster, pt.rows, bands, &mut task.bands);
                continue;
            }
            for j in pt.rows[0] as usize..pt.rows[1] as usize {
                task.bands[bands.band(j)].keep(raster.run(j));
            }
        }
        task.sum = sum;
    });
    tasks
        .iter()
        .fold(CandidateSum::default(), |a, t| a.merge(t.sum))
        .mean()
}

/// Scans `rows` of `raster` with its [`crate::fill_rule::RowTest`] into `out` — apart from
/// the plain scan and not inlined into it, so the bunny's many small
/// triangles run code that does not carry the row test's set-up.
#[inline(never)]
fn scan_with_row_test(
    raster: &TriangleRaster,
    rows: [u32; 2],
    bands: RowBands,
    out: &mut [BandRuns],
) {
    let test = raster.row_test();
    for j in rows[0] as usize..rows[1] as usize {
        out[bands.band(j)].keep(raster.run_with(&test, j));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bands_cover_every_row_once() {
        for (rows, want) in [(1, 16), (30, 16), (200, 16), (1500, 16), (4096, 3)] {
            let b = RowBands::new(rows, rows, want);
            let covered: Vec<usize> = (0..b.bands).flat_map(|i| b.rows(i)).collect();
            assert_eq!(covered, (0..rows).collect::<Vec<_>>(), "{rows}");
            assert!((0..rows).all(|j| b.rows(b.band(j)).contains(&j)));
        }
        assert_eq!(RowBands::new(200, 200, 16).bands, 13);
        assert_eq!(RowBands::new(30, 30, 16).bands, 15);
        assert_eq!(RowBands::new(1500, 1500, 16).bands, 375);
    }
}
