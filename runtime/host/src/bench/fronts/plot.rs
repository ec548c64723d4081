//! The SVG plot of a front: run time (ms, or a ratio) on x, error on y, both on log
//! scales, one coloured series per model/configuration family (points
//! joined in order of time), the default configuration ringed in black.
//! Drawn with `plotters`' SVG backend (text as SVG `<text>`, no fonts).

use super::{ERROR_FLOOR, Front};
use plotters::prelude::*;

const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Log-axis range covering `v` with a margin (at least one decade).
fn range(v: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = v.fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
    if !lo.is_finite() {
        return 1e-3..1.0;
    }
    let lo = 10f64.powf(lo.log10().floor());
    let hi = 10f64.powf(hi.log10().ceil()).max(lo * 10.0);
    lo..hi
}

/// The front as an SVG document, its time axis labelled `time_label`.
pub(super) fn svg(front: &Front, time_label: &str) -> Result<String, Box<dyn std::error::Error>> {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, (760, 480)).into_drawing_area();
        root.fill(&WHITE)?;
        let y = |e: f64| e.max(ERROR_FLOOR);
        let xr = range(front.points.iter().map(|p| p.time_ms.max(1e-6)));
        let yr = range(front.points.iter().map(|p| y(p.error)));
        let mut chart = ChartBuilder::on(&root)
            .caption(&front.title, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(xr.log_scale(), yr.log_scale())?;
        chart
            .configure_mesh()
            .x_desc(time_label)
            .y_desc(front.error_label.as_str())
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()?;
        let mut series: Vec<&str> = vec![];
        for p in &front.points {
            if !series.contains(&p.series.as_str()) {
                series.push(&p.series);
            }
        }
        for (s, name) in series.iter().enumerate() {
            let colour = PALETTE[s % PALETTE.len()];
            let mut pts: Vec<(f64, f64)> = front
                .points
                .iter()
                .filter(|p| p.series == *name)
                .map(|p| (p.time_ms.max(1e-6), y(p.error)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))?
                .label(*name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2))
                });
            chart.draw_series(
                pts.iter()
                    .map(|&(x, y)| Circle::new((x, y), 3, colour.filled())),
            )?;
        }
        chart
            .draw_series(
                front.points.iter().filter(|p| p.is_default).map(|p| {
                    Circle::new((p.time_ms.max(1e-6), y(p.error)), 8, BLACK.stroke_width(2))
                }),
            )?
            .label("default")
            .legend(|(x, y)| Circle::new((x + 8, y), 5, BLACK.stroke_width(2)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()?;
    }
    Ok(text)
}
