//! The `roi` front: spatial opacity maps (`[[roi]]`) on the labelled
//! abdomen phantom, seeds in the liver, the spleen and the right kidney
//! (`voxflex_phantom::abdomen::SEEDS`), grown to convergence on the
//! CPU at every λ of the automatic rule's candidates and at the paper's
//! λ = 30, and with `lambda = "auto"` (the default); error 1 − Dice of the map ≥ 0.5
//! against the seed's organ label. (The Dice-against-λ figure is the
//! `roi_dice` example's; this front adds the time.)

use super::{Front, Point};
use crate::bench::{BenchError, err};
use std::time::Instant;
use voxflex_opacity::auto_lambda::CANDIDATES;
use voxflex_opacity::{GrowthLimits, GrowthParams, LambdaChoice, RoiRequest, Seed, grow_roi};
use voxflex_phantom::abdomen::{SEEDS, map_dice};
use voxflex_phantom::abdomen_labelled;

/// The paper's λ (the scene default until this front showed it off the
/// front for every seed; the default is now `"auto"`).
const PAPER_LAMBDA: f32 = 30.0;

/// The ROI front.
pub(super) fn front(quick: bool) -> Result<Front, BenchError> {
    let dims = if quick { [48, 38, 32] } else { [120, 94, 80] };
    let ph = abdomen_labelled(dims);
    let vol = ph.volume.view();
    let mut lambdas: Vec<LambdaChoice> =
        CANDIDATES.iter().map(|&l| LambdaChoice::Fixed(l)).collect();
    if quick {
        lambdas = [1.0, 4.0, 16.0].map(LambdaChoice::Fixed).to_vec();
    }
    lambdas.push(LambdaChoice::Fixed(PAPER_LAMBDA));
    lambdas.push(LambdaChoice::Auto);
    let mut points = vec![];
    for (name, lab, p) in SEEDS {
        for &lambda in &lambdas {
            let req = RoiRequest {
                seed: Seed::World(p),
                params: GrowthParams::default(),
                lambda,
                limits: GrowthLimits::default(),
                steps: None,
            };
            let t = Instant::now();
            let o = grow_roi(vol, &req, None).map_err(err)?;
            let time_ms = t.elapsed().as_secs_f64() * 1e3;
            let d = map_dice(&o.grown.map, dims, &ph.labels, lab);
            let (series, config) = match lambda {
                LambdaChoice::Fixed(l) => (format!("{name} fixed λ"), format!("λ = {l}")),
                LambdaChoice::Auto => {
                    ("λ = auto".to_string(), format!("{name} (λ = {})", o.lambda))
                }
            };
            points.push(Point {
                series,
                config,
                time_ms,
                error: 1.0 - d,
                is_default: lambda == LambdaChoice::Auto,
                group: name.to_string(),
                extra: vec![
                    ("seed", name.to_string()),
                    ("lambda", o.lambda.to_string()),
                    ("dice", format!("{d:.4}")),
                    ("voxels", o.voxels.to_string()),
                    ("label_voxels", ph.count(lab).to_string()),
                    ("steps", o.grown.report.steps.to_string()),
                ],
                tuning: None,
            });
        }
    }
    Ok(Front {
        key: "roi",
        title: "ROI map: 1 − Dice vs time, per λ".into(),
        error_label: "1 − Dice".into(),
        description: format!(
            "`phantom:abdomen` at {dims:?} voxels with its labels; one seed each in the liver, \
             the spleen and the right kidney; grown to convergence on the CPU, no intensity or \
             distance bounds. Error: 1 − Dice of the map ≥ 0.5 against the seed's organ. One \
             series per seed over fixed λ (the automatic rule's candidates, √2 apart, and 30), \
             and the three `lambda = \"auto\"` runs (its time is the scan and the map written from \
             it, with no growth; the scene \
             default, ringed). The paper's λ = {PAPER_LAMBDA} is the fixed series' last point."
        ),
        points,
    })
}
