//! STEP 2: the plugin's parameters — the TOML of the scene's
//! `[model.params]` table (or `[model.params.<name>]`).
//!
//! Parse with serde and `deny_unknown_fields`, so a misspelt key is refused
//! naming it; then validate every value, so a bad one is refused here, in
//! `create`, where `voxflex validate` sees it, and never panics or turns
//! into NaN later. Replace the fields with your model's; keep the shape.

use serde::Deserialize;
use voxflex_core::error::ModelError;

/// Parameters of the bulge field (`[model.params]`).
///
/// ```toml
/// [model.params]
/// centre = [0, 0, 0]     # world mm (default: the volume centre)
/// radius_mm = 30         # the ball the field lives in, mm (> 0)
/// amplitude_mm = 10      # strength, mm (the largest displacement is 0.286 × this)
/// ramp_frames = 5        # frames over which the field grows in (≥ 1, default 1)
/// ```
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TemplateParams {
    /// Centre of the ball, world mm (LPS); `None` = the volume's centre.
    #[serde(default)]
    #[schemars(extend("unit" = "mm"))]
    pub centre: Option<[f64; 3]>,
    /// Radius of the ball, mm. Nothing outside it moves.
    #[schemars(extend("unit" = "mm"), range(min = 0))]
    pub radius_mm: f64,
    /// Strength of the bulge, mm: points move by
    /// `amplitude_mm · t (1 − t²)²` along the radius, `t = r / radius_mm`
    /// (negative: a dent). The largest move, `0.286 · amplitude_mm`, is at
    /// `t = 1/√5`.
    #[schemars(extend("unit" = "mm"))]
    pub amplitude_mm: f64,
    /// Frames over which the field ramps in linearly (default 1: full at
    /// the first frame); after that it is still and nothing re-runs.
    #[serde(default = "one_frame")]
    #[schemars(extend("unit" = "frames"), range(min = 1))]
    pub ramp_frames: u64,
}

fn one_frame() -> u64 {
    1
}

impl TemplateParams {
    /// Parses and validates `[model.params]`; every error names the key,
    /// its value and what is allowed.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let p: TemplateParams = toml::from_str(text)
            .map_err(|e| ModelError(format!("[model.params]: {}", e.message().trim())))?;
        p.validate()?;
        Ok(p)
    }

    fn validate(&self) -> Result<(), ModelError> {
        let bad = |key: &str, value: &dyn std::fmt::Debug, why: &str| {
            Err(ModelError(format!(
                "[model.params] {key} = {value:?}: {why}"
            )))
        };
        // Both paths compute in f32: a finite f64 beyond ±3.4e38 would
        // become ±∞ there, so "finite" means finite as an f32.
        let finite32 = |v: f64| v.is_finite() && (v as f32).is_finite();
        if let Some(c) = self.centre
            && !c.iter().all(|&v| finite32(v))
        {
            return bad("centre", &c, "must be three finite coordinates, mm");
        }
        if !(finite32(self.radius_mm) && self.radius_mm > 0.0) {
            return bad(
                "radius_mm",
                &self.radius_mm,
                "must be a finite length > 0, mm",
            );
        }
        if !finite32(self.amplitude_mm) {
            return bad(
                "amplitude_mm",
                &self.amplitude_mm,
                "must be a finite length, mm",
            );
        }
        if self.ramp_frames == 0 {
            return bad("ramp_frames", &self.ramp_frames, "must be at least 1");
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_defaults_and_every_key() {
        let p = TemplateParams::from_toml("radius_mm = 20\namplitude_mm = 4").unwrap();
        assert_eq!((p.centre, p.ramp_frames), (None, 1));
        let p = TemplateParams::from_toml(
            "centre = [1, -2, 3.5]\nradius_mm = 20\namplitude_mm = -4\nramp_frames = 7",
        )
        .unwrap();
        assert_eq!(p.centre, Some([1.0, -2.0, 3.5]));
        assert_eq!(
            (p.radius_mm, p.amplitude_mm, p.ramp_frames),
            (20.0, -4.0, 7)
        );
    }

    #[test]
    fn bad_values_are_refused_naming_the_key() {
        for (text, key) in [
            ("radius_mm = 0\namplitude_mm = 1", "radius_mm"),
            ("radius_mm = -3\namplitude_mm = 1", "radius_mm"),
            ("radius_mm = nan\namplitude_mm = 1", "radius_mm"),
            ("radius_mm = 5\namplitude_mm = 1e39", "amplitude_mm"),
            ("radius_mm = 5\namplitude_mm = inf", "amplitude_mm"),
            (
                "radius_mm = 5\namplitude_mm = 1\nramp_frames = 0",
                "ramp_frames",
            ),
            (
                "radius_mm = 5\namplitude_mm = 1\ncentre = [0, 0, 1e40]",
                "centre",
            ),
            ("radius_mm = 5\namplitude_mm = 1\nradius = 3", "radius"),
            ("amplitude_mm = 1", "radius_mm"),
        ] {
            let e = TemplateParams::from_toml(text).unwrap_err().0;
            assert!(e.contains(key), "{text}: {e}");
        }
    }
}
