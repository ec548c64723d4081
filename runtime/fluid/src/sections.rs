//! Per column: the crossings sorted by height and matched bottom → top
//! into sections of fluid.

use crate::hits::Hit;
use rayon::prelude::*;

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

/// Groups the batches of crossings by column into `out` (counting sort,
/// stable), so each column's crossings are one contiguous run. `start` and
/// `out` are scratch whose capacity is reused.
pub fn bucket_by_column(
    batches: &[Vec<Hit>],
    columns: usize,
    start: &mut Vec<u32>,
    out: &mut Vec<Hit>,
) {
    start.clear();
    start.resize(columns + 1, 0);
    for h in batches.iter().flatten() {
        start[h.column as usize + 1] += 1;
    }
    for c in 0..columns {
        start[c + 1] += start[c];
    }
    let total = start[columns] as usize;
    out.clear();
    out.resize(
        total,
        Hit {
            column: 0,
            triangle_and_side: 0,
            height: 0.0,
        },
    );
    for h in batches.iter().flatten() {
        let slot = &mut start[h.column as usize];
        out[*slot as usize] = *h;
        *slot += 1;
    }
}

/// Sorts each column's run by height and turns each bottom crossing's
/// height into the height of fluid above it, every top crossing's into 0
/// (see [`Hit::height`]). `hits` must be grouped by column
/// ([`bucket_by_column`]).
pub fn match_sections(hits: &mut [Hit]) -> SectionCount {
    hits.par_chunk_by_mut(|a, b| a.column == b.column)
        .map(match_column)
        .reduce(SectionCount::default, |a, b| SectionCount {
            sections: a.sections + b.sections,
            columns_with_fluid: a.columns_with_fluid + b.columns_with_fluid,
            irregular_columns: a.irregular_columns + b.irregular_columns,
        })
}

/// One column: bottom, top, bottom, top… from below, else irregular.
fn match_column(run: &mut [Hit]) -> SectionCount {
    // At equal heights a bottom sorts first: a zero-height section.
    run.sort_unstable_by(|a, b| a.height.total_cmp(&b.height).then(a.top().cmp(&b.top())));
    let alternates = run.len().is_multiple_of(2)
        && run
            .chunks_exact(2)
            .all(|pair| !pair[0].top() && pair[1].top());
    if !alternates {
        run.iter_mut().for_each(|h| h.height = 0.0);
        return SectionCount {
            irregular_columns: 1,
            ..Default::default()
        };
    }
    for pair in run.chunks_exact_mut(2) {
        pair[0].height = pair[1].height - pair[0].height;
        pair[1].height = 0.0;
    }
    SectionCount {
        sections: run.len() / 2,
        columns_with_fluid: usize::from(!run.is_empty()),
        irregular_columns: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bucket(batches: Vec<Vec<Hit>>, columns: usize) -> Vec<Hit> {
        let (mut start, mut out) = (Vec::new(), Vec::new());
        bucket_by_column(&batches, columns, &mut start, &mut out);
        out
    }

    fn hit(column: u32, top: bool, height: f64) -> Hit {
        Hit {
            column,
            triangle_and_side: if top { crate::hits::TOP } else { 0 },
            height,
        }
    }

    #[test]
    fn a_column_through_a_u_shape_holds_two_sections() {
        // from below: bottom 0, top 1, bottom 3, top 7 (given out of order)
        let mut hits = bucket(
            vec![
                vec![hit(1, true, 7.0), hit(1, false, 0.0), hit(0, false, 2.0)],
                vec![hit(1, false, 3.0), hit(1, true, 1.0), hit(0, true, 2.5)],
            ],
            2,
        );
        let n = match_sections(&mut hits);
        assert_eq!(
            n,
            SectionCount {
                sections: 3,
                columns_with_fluid: 2,
                irregular_columns: 0
            }
        );
        let total: f64 = hits.iter().map(|h| h.height).sum();
        assert_eq!(total, 0.5 + 1.0 + 4.0);
    }

    #[test]
    fn an_unmatched_crossing_makes_the_column_irregular_and_empty() {
        let mut hits = bucket(
            vec![vec![
                hit(0, false, 0.0),
                hit(0, false, 1.0),
                hit(0, true, 2.0),
            ]],
            1,
        );
        let n = match_sections(&mut hits);
        assert_eq!(n.irregular_columns, 1);
        assert!(hits.iter().all(|h| h.height == 0.0));
    }
}
