//! The volume's value histogram drawn behind the transfer-function editor,
//! log-scaled (`ln(1 + count)`) so the few voxels of bone show beside the
//! many of air. The counts come from `Session::histogram` (the source
//! volume, computed once when the volume is opened).

use crate::tf_points::TfAxes;
use egui::{Color32, Painter, Pos2, Rect};
use voxflex_runtime::session::Histogram;

/// Bins asked of the session (a few screen points each in the editor).
pub const BINS: usize = 128;

/// Each bin's height as a fraction of the tallest, on a log scale:
/// `ln(1 + c) / ln(1 + max)` (all 0 for an empty histogram).
pub fn log_heights(counts: &[u64]) -> Vec<f32> {
    let top = counts.iter().copied().max().unwrap_or(0);
    if top == 0 {
        return vec![0.0; counts.len()];
    }
    let scale = (top as f64).ln_1p();
    counts
        .iter()
        .map(|&c| ((c as f64).ln_1p() / scale) as f32)
        .collect()
}

/// Paints `h` as grey bars over the editor's `axes` (the bins placed at
/// their values, so the bars line up with the control points).
pub fn paint(painter: &Painter, axes: &TfAxes, h: &Histogram) {
    let n = h.counts.len();
    if n == 0 {
        return;
    }
    let width = (f64::from(h.max) - f64::from(h.min)) / n as f64;
    let fill = Color32::from_gray(70);
    for (b, f) in log_heights(&h.counts).into_iter().enumerate() {
        if f <= 0.0 {
            continue;
        }
        let v0 = f64::from(h.min) + b as f64 * width;
        let (x0, x1) = (axes.value_to_x(v0), axes.value_to_x(v0 + width));
        let (x0, x1) = (x0.max(axes.left), x1.min(axes.right).max(x0 + 1.0));
        let top = axes.bottom - f * (axes.bottom - axes.top);
        painter.rect_filled(
            Rect::from_min_max(Pos2::new(x0, top), Pos2::new(x1, axes.bottom)),
            0.0,
            fill,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heights_are_log_scaled_to_the_tallest_bin() {
        let h = log_heights(&[0, 1, 1_000_000, 999]);
        assert_eq!(h[0], 0.0);
        assert_eq!(h[2], 1.0);
        // Linear would give 0.001; the log scale shows it at half height.
        assert!((h[3] - 0.5).abs() < 0.01, "{h:?}");
        assert!(h[1] > 0.0 && h[1] < h[3]);
        assert_eq!(log_heights(&[0, 0]), [0.0, 0.0]);
        assert!(log_heights(&[]).is_empty());
    }
}
