//! The CPU's one pass over the triangles: each is classified (side and
//! candidate columns, in the grid's index space) and, when it has
//! candidates, scanned row by row ([`TriangleRaster`]) while its corners
//! are at hand; its non-empty runs, with their barycentric coordinates, go
//! to its task's bucket for the band of rows they lie in, so the section
//! pass finds a band's runs in one bucket per task, with no sort and no
//! write shared between tasks.
//!
//! Coordinates: (u, v) in the grid's index space
//! ([`crate::index_space`]), heights in the [`crate::GravityFrame`], mm.

use crate::distribute::RunBarycentric;
use crate::hits::{Run, TriangleRaster};
use crate::index_space::IndexSpace;
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

/// One row-scan task's runs (capacity reused between calls).
#[derive(Debug, Default)]
pub struct TaskRuns {
    /// Per row band, room for runs and their barycentric coordinates: the
    /// first `filled[b]` are the non-empty runs this task's triangles cross
    /// (the rest is kept from earlier calls, so a weighing neither
    /// allocates nor clears).
    bands: Vec<(Vec<Run>, Vec<RunBarycentric>)>,
    filled: Vec<usize>,
    sum: CandidateSum,
}

impl TaskRuns {
    /// This task's runs of band `b`, and their barycentric coordinates.
    pub fn band(&self, b: usize) -> (&[Run], &[RunBarycentric]) {
        let (runs, bary) = &self.bands[b];
        (&runs[..self.filled[b]], &bary[..self.filled[b]])
    }

    /// Keeps `run` in band `b` when it crosses any column — written either
    /// way, so an empty run costs no branch.
    #[inline(always)]
    fn keep(&mut self, b: usize, (run, bary): (Run, RunBarycentric)) {
        let ((runs, barys), at) = (&mut self.bands[b], &mut self.filled[b]);
        if runs.len() == *at {
            let room = (2 * *at).max(1024);
            runs.resize(room, Run::default());
            barys.resize(room, RunBarycentric::default());
        }
        runs[*at] = run;
        barys[*at] = bary;
        *at += usize::from(run.len > 0);
    }
}

/// Classifies every triangle of `p` in the grid's index space
/// ([`TriangleRaster::of`]) and scans those with candidates into `tasks`
/// (one per task of `split`, which cuts `order`: each triangle's index and
/// corner ids in visiting order, [`crate::triangle_order`]); returns the mean candidates per non-vertical
/// triangle (the paper's `c`). The classifications are not kept: the CPU
/// path needs nothing of them after the scan.
pub fn scan_triangles(
    p: &ProjectedSurface<'_>,
    split: TaskSplit,
    bands: RowBands,
    tasks: &mut Vec<TaskRuns>,
    order: &[(u32, [u32; 3])],
) -> f64 {
    let space = IndexSpace::of(&p.grid);
    let uvh = &p.uvh;
    tasks.resize_with(split.tasks, Default::default);
    tasks.truncate(split.tasks);
    tasks.par_iter_mut().enumerate().for_each(|(b, task)| {
        task.bands.resize_with(bands.bands, Default::default);
        task.filled.clear();
        task.filled.resize(bands.bands, 0);
        let mut sum = CandidateSum::default();
        for &(t, ids) in &order[split.task(b)] {
            let t = t as usize;
            let corners = ids.map(|v| uvh[v as usize]);
            let (pt, raster) = TriangleRaster::of(t, ids, corners, &space);
            sum.add(&pt);
            let Some(mut raster) = raster else {
                continue;
            };
            for j in pt.rows[0] as usize..pt.rows[1] as usize {
                task.keep(bands.band(j), raster.run(j));
            }
        }
        task.sum = sum;
    });
    tasks
        .iter()
        .fold(CandidateSum::default(), |a, t| a.merge(t.sum))
        .mean()
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
