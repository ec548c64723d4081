//! Per column: the crossings sorted by height and matched bottom → top
//! into sections of fluid — one band of rows per task, so a band's
//! crossings are grouped by column in a counting sort over the band's
//! columns (counts from the runs' ends, then the fill) instead of a sort of
//! every crossing of the grid. Each section's height goes to a slot of its
//! bottom run; then each bottom run's slots are summed and its fluid
//! weighed onto its triangle's corners ([`crate::distribute`]).
//!
//! Heights in the gravity frame, mm.

use crate::distribute::{RunBarycentric, Weighted, run_weights};
use crate::hits::{Run, TOP};
use crate::row_scan::{BandRuns, RowBands, TaskRuns};
use rayon::prelude::*;
use std::ops::Range;

/// What the section pass found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SectionCount {
    /// Sections of fluid (bottom–top pairs) over all columns.
    pub sections: usize,
    /// Columns holding at least one section.
    pub columns_with_fluid: usize,
    /// Columns whose crossings do not alternate bottom, top, bottom, top…
    /// from below (a surface that is not closed, or folds through itself);
    /// their fluid is left out and the caller reports them.
    pub irregular_columns: usize,
}

/// [`SectionCount`] with the crossings and the fluid's height summed.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SectionTally {
    /// Sections and columns.
    pub count: SectionCount,
    /// Column–surface crossings.
    pub crossings: usize,
    /// Sum of every section's height, mm (times the column area: the volume).
    pub fluid_height: f64,
}

impl SectionTally {
    fn add(&mut self, o: &Self) {
        self.count.sections += o.count.sections;
        self.count.columns_with_fluid += o.count.columns_with_fluid;
        self.count.irregular_columns += o.count.irregular_columns;
        self.crossings += o.crossings;
        self.fluid_height += o.fluid_height;
    }
}

/// What a bottom run holds: `[Σ h, Σ h·m]` over its columns `first + m`
/// where it is the bottom of a section of height `h` (mm, mm·columns).
pub type RunResult = [f64; 2];

/// One crossing while its band is matched: height (mm), and the slot of
/// its section's height (a bottom run's column), with [`TOP`] set for a
/// top run's crossing.
#[derive(Clone, Copy, Debug, Default)]
struct Entry {
    height: f64,
    slot: u32,
}

impl Entry {
    #[inline]
    fn top(&self) -> bool {
        self.slot & TOP != 0
    }

    /// Below `o`: lower, or as low and a bottom (a zero-height section).
    #[inline]
    fn before(&self, o: &Self) -> std::cmp::Ordering {
        self.height
            .total_cmp(&o.height)
            .then(self.top().cmp(&o.top()))
    }
}

/// Working memory of one band of rows (capacity reused between calls),
/// and what the band found.
#[derive(Debug, Default)]
pub struct BandScratch {
    /// Per cell (row-major in the band), first the change in its count of
    /// crossings, then where its crossings start, then where they end.
    ends: Vec<u32>,
    entries: Vec<Entry>,
    /// Per bottom crossing, in the order of the runs, the height of its
    /// section (0 when none), mm.
    fluid: Vec<f64>,
    /// `task_fluid[t]..task_fluid[t + 1]`: task `t`'s bottom crossings in
    /// `fluid`.
    task_fluid: Vec<usize>,
    /// The band's bottom runs with fluid, weighed.
    pub weighted: Vec<Weighted>,
    /// The band's sections.
    pub tally: SectionTally,
}

/// Matches every band of rows (`tasks`' runs, bands in parallel; `n_u`
/// columns per row) and weighs each bottom run's fluid onto its triangle's
/// corners ([`run_weights`], `scale = ρ·|g|·A` in µN per mm of fluid
/// height) into `scratch[band].weighted`; returns the tally, summed in band
/// order (so the volume does not depend on the schedule).
pub fn match_bands(
    n_u: usize,
    bands: RowBands,
    tasks: &[TaskRuns],
    scale: f64,
    scratch: &mut Vec<BandScratch>,
) -> SectionTally {
    scratch.resize_with(bands.bands, Default::default);
    scratch.truncate(bands.bands);
    scratch.par_iter_mut().enumerate().for_each(|(b, s)| {
        let band = || tasks.iter().map(|t| t.band(b));
        s.tally = s.match_band(band(), bands.rows(b), n_u);
        s.weighted.clear();
        for (t, runs) in band().enumerate() {
            let fluid = &s.fluid[s.task_fluid[t]..s.task_fluid[t + 1]];
            let weighted = &mut s.weighted;
            s.tally.fluid_height += each_bottom(fluid, runs, |bary, result| {
                weighted.push(run_weights(bary, result, scale));
            });
        }
    });
    let mut tally = SectionTally::default();
    for s in scratch.iter() {
        tally.add(&s.tally);
    }
    tally
}

impl BandScratch {
    /// Groups the crossings of every task's runs in the band (`rows`,
    /// `n_u` columns per row) by cell, sorts each cell's by height, and
    /// matches them bottom, top, bottom, top… from below — else the cell's
    /// column is irregular and holds nothing. Each section's height goes to
    /// its bottom crossing's slot (`fluid`: the tasks' bottom runs'
    /// crossings in order). The tally's `fluid_height` is left 0 (see
    /// [`each_bottom`]).
    fn match_band<'r>(
        &mut self,
        tasks: impl Iterator<Item = &'r BandRuns> + Clone,
        rows: Range<usize>,
        n_u: usize,
    ) -> SectionTally {
        let mut tally = SectionTally::default();
        let (mut total, mut bottoms) = (0, 0);
        self.task_fluid.clear();
        self.task_fluid.push(0);
        for task in tasks.clone() {
            let [top, bottom] = task.crossings();
            total += top + bottom;
            bottoms += bottom;
            self.task_fluid.push(bottoms);
        }
        self.fluid.clear();
        self.fluid.resize(bottoms, 0.0);
        if total == 0 {
            return tally;
        }
        // the band's cells, row-major (a few thousand: see `RowBands`)
        let span = rows.len() * n_u;
        let cell = |r: &Run| (r.row as usize - rows.start) * n_u + r.first as usize;
        let runs = tasks
            .clone()
            .flat_map(|t| t.tops().iter().chain(t.bottoms()));
        let ends = &mut self.ends;
        ends.clear();
        ends.resize(span + 1, 0);
        for r in runs {
            let x = cell(r);
            ends[x] = ends[x].wrapping_add(1);
            ends[x + r.len as usize] = ends[x + r.len as usize].wrapping_sub(1);
        }
        let (mut count, mut at) = (0u32, 0u32);
        for e in &mut ends[..span] {
            count = count.wrapping_add(*e);
            *e = at;
            at += count;
        }
        self.entries.resize(total, Entry::default());
        let mut fill = |r: &Run, slot: u32, step: u32| {
            let x = cell(r);
            for (m, end) in ends[x..x + r.len as usize].iter_mut().enumerate() {
                self.entries[*end as usize] = Entry {
                    height: r.height_at(m as u32),
                    slot: slot + m as u32 * step,
                };
                *end += 1;
            }
        };
        let mut slot = 0u32;
        for task in tasks {
            for r in task.tops() {
                fill(r, TOP, 0);
            }
            for r in task.bottoms() {
                fill(r, slot, 1);
                slot += r.len;
            }
        }
        let mut start = 0;
        for &end in &ends[..span] {
            let column = &mut self.entries[start as usize..end as usize];
            start = end;
            if column.is_empty() {
                continue;
            }
            tally.crossings += column.len();
            if column.len() == 2 {
                if column[0].before(&column[1]).is_gt() {
                    column.swap(0, 1);
                }
            } else {
                column.sort_unstable_by(Entry::before);
            }
            let alternates = column.len().is_multiple_of(2)
                && column
                    .chunks_exact(2)
                    .all(|pair| !pair[0].top() && pair[1].top());
            if !alternates {
                tally.count.irregular_columns += 1;
                continue;
            }
            tally.count.columns_with_fluid += 1;
            tally.count.sections += column.len() / 2;
            for pair in column.chunks_exact(2) {
                self.fluid[pair[0].slot as usize] = pair[1].height - pair[0].height;
            }
        }
        tally
    }

    /// Task `t`'s bottom crossings in this band, in the order of its bottom
    /// runs: the heights of their sections (0 when none), mm.
    pub fn task_fluid(&self, t: usize) -> &[f64] {
        &self.fluid[self.task_fluid[t]..self.task_fluid[t + 1]]
    }
}

/// Calls `f(barycentric, [Σ h, Σ h·m])` for each bottom run of `runs`
/// holding fluid (`fluid`: its crossings' section heights, in order, as
/// [`BandScratch::task_fluid`] gives them); returns the sum of every
/// section's height (mm).
pub fn each_bottom<'r>(
    fluid: &[f64],
    runs: &'r BandRuns,
    mut f: impl FnMut(&'r RunBarycentric, RunResult),
) -> f64 {
    let (mut slot, mut total) = (0, 0.0);
    for (r, bary) in runs.bottoms().iter().zip(runs.barycentrics()) {
        let held = &fluid[slot..slot + r.len as usize];
        slot += r.len as usize;
        let (h, hm) = held
            .iter()
            .enumerate()
            .fold((0.0, 0.0), |(h, hm), (m, &x)| (h + x, hm + m as f64 * x));
        if h > 0.0 {
            total += h;
            f(bary, [h, hm]);
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(row: u32, first: u32, len: u32, top: bool, height: f64, step: f64, t: u32) -> Run {
        Run {
            tag: t | if top { TOP } else { 0 },
            first,
            len,
            row,
            height,
            step,
        }
    }

    /// Matches `runs` as one band of rows 4..8, 10 columns each.
    /// (The runs' tags come back as their barycentrics' first corner.)
    fn matched(runs: &[Run]) -> (SectionTally, Vec<(u32, RunResult)>) {
        let mut band = BandRuns::default();
        for r in runs {
            let corners = [r.tag, 0, 0];
            band.keep((
                *r,
                RunBarycentric {
                    corners,
                    ..Default::default()
                },
            ));
        }
        let mut s = BandScratch::default();
        let mut t = s.match_band(std::iter::once(&band), 4..8, 10);
        let mut held = Vec::new();
        t.fluid_height = each_bottom(s.task_fluid(0), &band, |b, x| held.push((b.corners[0], x)));
        (t, held)
    }

    #[test]
    fn a_column_through_a_u_shape_holds_two_sections() {
        // row 5, column 1 from below: bottom 0, top 1, bottom 3, top 7 (given
        // out of order); column 0: bottom 2, top 2.5
        let (t, held) = matched(&[
            run(5, 1, 1, true, 7.0, 0.0, 0),
            run(5, 0, 2, false, 2.0, -2.0, 1), // 2 at column 0, 0 at column 1
            run(5, 1, 1, false, 3.0, 0.0, 2),
            run(5, 1, 1, true, 1.0, 0.0, 3),
            run(5, 0, 1, true, 2.5, 0.0, 4),
        ]);
        assert_eq!(
            t.count,
            SectionCount {
                sections: 3,
                columns_with_fluid: 2,
                irregular_columns: 0
            }
        );
        assert_eq!(t.crossings, 6);
        assert_eq!(t.fluid_height, 0.5 + 1.0 + 4.0);
        // run 1 holds 0.5 at its column 0 (m = 0) and 1 at column 1 (m = 1)
        assert_eq!(held, vec![(1, [1.5, 1.0]), (2, [4.0, 0.0])]);
    }

    #[test]
    fn rows_of_a_band_are_matched_apart() {
        // the same column in rows 4 and 7: one section each
        let (t, held) = matched(&[
            run(7, 3, 1, true, 5.0, 0.0, 0),
            run(4, 3, 1, false, 1.0, 0.0, 1),
            run(7, 3, 1, false, 2.0, 0.0, 2),
            run(4, 3, 1, true, 1.5, 0.0, 3),
        ]);
        assert_eq!(t.count.sections, 2);
        assert_eq!(t.count.columns_with_fluid, 2);
        assert_eq!(held, vec![(1, [0.5, 0.0]), (2, [3.0, 0.0])]);
    }

    #[test]
    fn an_unmatched_crossing_makes_the_column_irregular_and_empty() {
        let (t, held) = matched(&[
            run(6, 5, 1, false, 0.0, 0.0, 0),
            run(6, 5, 1, false, 1.0, 0.0, 1),
            run(6, 5, 1, true, 2.0, 0.0, 2),
        ]);
        assert_eq!(t.count.irregular_columns, 1);
        assert_eq!(t.count.sections, 0);
        assert!(held.is_empty());
    }

    #[test]
    fn a_bottom_and_a_top_at_one_height_make_a_zero_height_section() {
        let (t, held) = matched(&[
            run(4, 0, 1, true, 1.0, 0.0, 0),
            run(4, 0, 1, false, 1.0, 0.0, 1),
        ]);
        assert_eq!(t.count.sections, 1);
        assert_eq!(t.count.irregular_columns, 0);
        assert!(held.is_empty(), "no fluid, nothing to weigh");
    }
}
