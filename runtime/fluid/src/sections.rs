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

/// A cell of one top and one bottom crossing, in [`BandScratch::cells`]
/// (a count: one top, one bottom — never a position in `entries`, which
/// holds far fewer than 2³² crossings).
const SIMPLE: u64 = 1 | 1 << 32;

/// Working memory of one band of rows (capacity reused between calls),
/// and what the band found.
#[derive(Debug, Default)]
pub struct BandScratch {
    /// Per cell (row-major in the band), first the change in its count of
    /// top (low half) and bottom (high half) crossings, then [`SIMPLE`] or
    /// where its next crossing goes in `entries`.
    cells: Vec<u64>,
    /// Per cell holding one top and one bottom crossing, the top's height
    /// (mm; other cells' entries are stale).
    top_heights: Vec<f64>,
    /// The crossings of the other cells, grouped by cell.
    entries: Vec<Entry>,
    /// Each other cell's range in `entries`.
    mixed: Vec<(u32, u32)>,
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
        let mut weighted = std::mem::take(&mut s.weighted);
        weighted.clear();
        for (t, runs) in band().enumerate() {
            s.tally.fluid_height += each_bottom(s.task_fluid(t), runs, |bary, result| {
                push_merged(&mut weighted, run_weights(bary, result, scale));
            });
        }
        s.weighted = weighted;
    });
    let mut tally = SectionTally::default();
    for s in scratch.iter() {
        tally.add(&s.tally);
    }
    tally
}

impl BandScratch {
    /// Groups the crossings of every task's runs in the band (`rows`,
    /// `n_u` columns per row) by cell and matches each cell's, sorted by
    /// height, bottom, top, bottom, top… from below — else the cell's
    /// column is irregular and holds nothing. Each section's height goes to
    /// its bottom crossing's slot (`fluid`: the tasks' bottom runs'
    /// crossings in order). The tally's `fluid_height` is left 0 (see
    /// [`each_bottom`]).
    ///
    /// Most cells hold one bottom and one top crossing (every cell of a
    /// convex cavity): counted first, such a cell keeps its top's height
    /// and its bottom takes the difference directly. Only the other cells'
    /// crossings are gathered (a counting sort) and sorted.
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
        self.count_cells(tasks.clone(), span, cell);
        self.top_heights.resize(span, 0.0);
        let (cells, entries) = (&mut self.cells, &mut self.entries);
        let top_heights = &mut self.top_heights;
        for task in tasks.clone() {
            for r in task.tops() {
                let x = cell(r);
                for (m, c) in cells[x..x + r.len as usize].iter_mut().enumerate() {
                    let height = r.height_at(m as u32);
                    if *c == SIMPLE {
                        top_heights[x + m] = height;
                    } else {
                        entries[*c as usize] = Entry { height, slot: TOP };
                        *c += 1;
                    }
                }
            }
        }
        let mut slot = 0u32;
        for task in tasks {
            for r in task.bottoms() {
                let x = cell(r);
                for (m, c) in cells[x..x + r.len as usize].iter_mut().enumerate() {
                    let height = r.height_at(m as u32);
                    if *c == SIMPLE {
                        let top = top_heights[x + m];
                        // as the sort would order them: a bottom at its
                        // top's height makes a zero-height section
                        if height.total_cmp(&top).is_le() {
                            self.fluid[slot as usize] = top - height;
                            tally.count.sections += 1;
                            tally.count.columns_with_fluid += 1;
                        } else {
                            tally.count.irregular_columns += 1;
                        }
                        tally.crossings += 2;
                    } else {
                        entries[*c as usize] = Entry { height, slot };
                        *c += 1;
                    }
                    slot += 1;
                }
            }
        }
        for &(start, end) in &self.mixed {
            let column = &mut self.entries[start as usize..end as usize];
            tally.crossings += column.len();
            column.sort_unstable_by(Entry::before);
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

    /// Counts every cell's top and bottom crossings (a difference array
    /// over the runs, then its running sum) and leaves in `cells`, per
    /// cell, [`SIMPLE`] for one of each, else where its crossings start in
    /// `entries` (sized for them); `mixed` lists those cells' ranges.
    fn count_cells<'r>(
        &mut self,
        tasks: impl Iterator<Item = &'r BandRuns>,
        span: usize,
        cell: impl Fn(&Run) -> usize,
    ) {
        const BOTTOM: u64 = 1 << 32;
        let changes = &mut self.cells;
        changes.clear();
        changes.resize(span + 1, 0);
        let mut add = |r: &Run, one: u64| {
            let x = cell(r);
            changes[x] = changes[x].wrapping_add(one);
            changes[x + r.len as usize] = changes[x + r.len as usize].wrapping_sub(one);
        };
        for task in tasks {
            task.tops().iter().for_each(|r| add(r, 1));
            task.bottoms().iter().for_each(|r| add(r, BOTTOM));
        }
        self.mixed.clear();
        let (mut count, mut at) = (0u64, 0u64);
        for c in &mut changes[..span] {
            count = count.wrapping_add(*c);
            // u32 halves: a cell with 2³² crossings of a kind is beyond
            // any memory this could run in
            let crossings = (count & 0xffff_ffff) + (count >> 32);
            if count == SIMPLE || crossings == 0 {
                *c = SIMPLE;
                continue;
            }
            *c = at;
            self.mixed.push((at as u32, (at + crossings) as u32));
            at += crossings;
        }
        self.entries.resize(at as usize, Entry::default());
    }

    /// Task `t`'s bottom crossings in this band, in the order of its bottom
    /// runs: the heights of their sections (0 when none), mm.
    pub fn task_fluid(&self, t: usize) -> &[f64] {
        &self.fluid[self.task_fluid[t]..self.task_fluid[t + 1]]
    }
}

/// Appends `w` to `weighted`, or adds it to the last entry when that is
/// the same triangle's: a triangle's runs in a band come one after another
/// (its rows are scanned in turn), so the serial pass that adds the
/// weights onto the vertices ([`crate::distribute::add_weights`]) gets one
/// entry per triangle and band instead of one per row.
#[inline]
fn push_merged(weighted: &mut Vec<Weighted>, w: Weighted) {
    match weighted.last_mut() {
        Some(last) if last.corners == w.corners => {
            for (a, b) in last.weights.iter_mut().zip(w.weights) {
                *a += b;
            }
        }
        _ => weighted.push(w),
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
    fn one_top_below_its_bottom_or_two_of_a_kind_make_a_column_irregular() {
        // row 6: column 5 has its top under its bottom (the simple path),
        // column 6 two tops, column 7 two bottoms (the sorted path); column
        // 8 is a proper section beside them
        let (t, held) = matched(&[
            run(6, 5, 1, false, 2.0, 0.0, 0),
            run(6, 5, 1, true, 1.0, 0.0, 1),
            run(6, 6, 1, true, 1.0, 0.0, 2),
            run(6, 6, 1, true, 3.0, 0.0, 3),
            run(6, 7, 1, false, 1.0, 0.0, 4),
            run(6, 7, 1, false, 3.0, 0.0, 5),
            run(6, 8, 1, false, 1.0, 0.0, 6),
            run(6, 8, 1, true, 4.0, 0.0, 7),
        ]);
        assert_eq!(
            t.count,
            SectionCount {
                sections: 1,
                columns_with_fluid: 1,
                irregular_columns: 3
            }
        );
        assert_eq!(t.crossings, 8);
        assert_eq!(held, vec![(6, [3.0, 0.0])]);
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
