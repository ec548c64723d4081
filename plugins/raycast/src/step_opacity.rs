//! [`StepOpacity`]: the opacity of one full ray step at every entry of the
//! transfer-function table, so that the CPU path's samples interpolate it
//! instead of computing `1 − exp(−κ Δt)` each.
//!
//! A sample over a full step of Δt mm has opacity `1 − exp(−κ Δt)`
//! ([`crate::transfer`]). Δt is the same for every full step of a frame, so
//! the table holds `α_e = 1 − exp(−κ_e Δt)` per entry `e` and a sample
//! interpolates `α` between its two entries with the fraction it already
//! has for the colours — one load and a lerp instead of the libm `exp`
//! call, which was 9 % of a steady shaded frame of the 512 × 512 × 133
//! head (docs/BENCHMARKS.md). The first and last partial steps of a ray
//! (jitter lead, remainder) keep the `exp`.
//!
//! **Error.** Between two entries κ is linear in the fraction and `α` is
//! concave in κ, so the interpolated `α` lies below the exact one by at
//! most `(Δt · Δκ)² / 8` (`Δκ` the two entries' difference; the second
//! derivative of `1 − exp(−x)` is at most 1 in magnitude) — about 1e-7
//! for the presets at the default step, below the rounding of an f32
//! `exp`, and bounded in [`StepOpacity::error_bound`], which the tests
//! check on every preset. At the entries themselves it is the exact
//! expression, bit for bit. The GPU path keeps computing the `exp` (cheap
//! there); the two paths agree within their parity tolerance.
//!
//! Units: Δt in mm (the frame's `RayUniforms::step[0]`), κ per mm.

use crate::transfer::{LUT_SIZE, Lut, TablePlace};

/// `1 − exp(−κ Δt)` at every entry of a [`Lut`], for one step length Δt.
#[derive(Clone, Debug, PartialEq)]
pub struct StepOpacity {
    /// Δt, mm.
    step_mm: f32,
    /// `α_e = 1 − exp(−κ_e Δt)`, [`LUT_SIZE`] values.
    alpha: Vec<f32>,
}

impl StepOpacity {
    /// The table of `lut`'s opacities over a step of `step_mm` mm.
    pub fn new(lut: &Lut, step_mm: f32) -> Self {
        Self {
            step_mm,
            alpha: lut
                .entries
                .iter()
                .map(|e| 1.0 - (-e[3] * step_mm).exp())
                .collect(),
        }
    }

    /// Δt, mm: the step the table was made for.
    #[inline(always)]
    pub fn step_mm(&self) -> f32 {
        self.step_mm
    }

    /// The opacity of a full step at table place `at` (`lut`'s place of
    /// the sample's value: [`Lut::lookup_visible_placed`]).
    #[inline(always)]
    pub fn at(&self, at: TablePlace) -> f32 {
        let (a0, a1) = (self.alpha[at.entry], self.alpha[at.entry + 1]);
        a0 + at.frac * (a1 - a0)
    }

    /// The most [`StepOpacity::at`] can differ from `1 − exp(−κ Δt)`, κ
    /// interpolated between entries `entry` and `entry + 1` of `lut`:
    /// `(Δt · Δκ)² / 8`.
    pub fn error_bound(&self, lut: &Lut, entry: usize) -> f32 {
        debug_assert!(entry + 1 < LUT_SIZE);
        let dk = (lut.entries[entry + 1][3] - lut.entries[entry][3]).abs();
        (self.step_mm * dk).powi(2) / 8.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transfer::{PRESETS, TransferFunction};

    /// Every preset's table over a CT's value range.
    fn preset_luts() -> impl Iterator<Item = (&'static str, Lut)> {
        PRESETS.into_iter().map(|name| {
            let tf = TransferFunction::preset(name).unwrap();
            (name, tf.lut((-1024.0, 3071.0), 1.0))
        })
    }

    /// Every preset, steps from 0.05 to 4 mm, every entry and fractions
    /// across it: the interpolated opacity is within the analytic bound
    /// (plus the f32 rounding of both sides) of `1 − exp(−κ Δt)` with κ
    /// interpolated as the colours are, and exact at the entries.
    #[test]
    fn interpolated_opacity_is_within_the_concavity_bound() {
        for (name, lut) in preset_luts() {
            for step in [0.05f32, 0.35, 1.0, 4.0] {
                let table = StepOpacity::new(&lut, step);
                assert_eq!(table.step_mm(), step);
                let mut worst_over_bound = 0f64;
                for entry in 0..LUT_SIZE - 1 {
                    let (k0, k1) = (lut.entries[entry][3], lut.entries[entry + 1][3]);
                    for frac in [0.0f32, 0.125, 0.5, 0.8, 0.999] {
                        let kappa = k0 + frac * (k1 - k0);
                        let exact = 1.0 - (-(kappa as f64) * step as f64).exp();
                        let got = table.at(TablePlace { entry, frac }) as f64;
                        if frac == 0.0 {
                            let at_entry = 1.0 - (-k0 * step).exp();
                            assert_eq!(got as f32, at_entry, "{name} Δt {step} entry {entry}");
                        }
                        let bound =
                            table.error_bound(&lut, entry) as f64 + 4.0 * f32::EPSILON as f64;
                        let err = (got - exact).abs();
                        assert!(
                            err <= bound,
                            "{name} Δt {step} entry {entry} frac {frac}: |{got} − {exact}| = {err:e} > {bound:e}"
                        );
                        worst_over_bound = worst_over_bound.max(err / bound);
                    }
                }
                assert!(worst_over_bound > 0.0, "{name}: the test compared nothing");
            }
        }
    }

    /// The bound is small at the renderer's default step on every preset:
    /// the table changes an image by less than an f32 `exp`'s rounding.
    #[test]
    fn the_bound_is_below_f32_rounding_at_the_default_step() {
        for (name, lut) in preset_luts() {
            // 0.5 voxel of a 0.7 mm CT.
            let table = StepOpacity::new(&lut, 0.35);
            let worst = (0..LUT_SIZE - 1)
                .map(|e| table.error_bound(&lut, e))
                .fold(0f32, f32::max);
            assert!(worst < 2.0 * f32::EPSILON, "{name}: {worst:e}");
        }
    }
}
