//! The cable's parameters: the TOML of the scene's `[actuator.params]`
//! table, parsed with `deny_unknown_fields` (a misspelt key is refused,
//! naming it) and validated in full here, in `create`, so `voxflex
//! validate` reports every bad value.

use serde::Deserialize;
use voxflex_core::actuator::ActuatorCommand;
use voxflex_core::deformation::FrameInfo;
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::keyframes::Keyframes;

/// Parameters of a cable actuator (`[actuator.params]`).
///
/// ```toml
/// [actuator.params]
/// pull_point_mm = [0, 0, -5]                 # fixed in space (e.g. the finger's base)
/// tension_uN = [[0, 0], [50, 2e5]]           # or shortening_mm = [[frame, mm]], or neither
/// max_tension_uN = 5e5
/// max_shortening_mm = 12
/// ```
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CableParams {
    /// The fixed point in space the cable is pulled through (world mm; e.g.
    /// the finger's base). The body does not move it.
    #[schemars(extend("unit" = "mm"))]
    pub pull_point_mm: [f64; 3],
    /// Scripted tension, `[[frame, µN], …]` (linear between keyframes,
    /// held outside): the effort is given. Values in `[0,
    /// max_tension_uN]`. Not with `shortening_mm`.
    #[serde(default, rename = "tension_uN")]
    #[schemars(extend("unit" = "µN"))]
    pub tension_un: Option<Keyframes>,
    /// Scripted shortening from rest, `[[frame, mm], …]`: the tension is
    /// found to reach it. Values ≤ `max_shortening_mm`. Not with
    /// `tension_uN`. Neither key: the inverse solve chooses the tension.
    #[serde(default)]
    #[schemars(extend("unit" = "mm"))]
    pub shortening_mm: Option<Keyframes>,
    /// Largest tension, µN (> 0; leave it out: unbounded). The effort
    /// bounds are `[0, max_tension_uN]`: a cable only pulls.
    #[serde(default, rename = "max_tension_uN")]
    #[schemars(extend("unit" = "µN"))]
    pub max_tension_un: Option<f64>,
    /// Largest shortening (the stroke), mm (> 0; leave it out:
    /// unbounded). The measure bounds are `[−∞, max_shortening_mm]`.
    #[serde(default)]
    #[schemars(extend("unit" = "mm"))]
    pub max_shortening_mm: Option<f64>,
}

fn bad<T>(key: &str, value: impl std::fmt::Debug, why: &str) -> Result<T, ModelError> {
    Err(ModelError(format!(
        "[actuator.params] {key} = {value:?}: {why}"
    )))
}

/// A toml parse error as one line naming the offending line of the text.
fn toml_error(text: &str, e: &toml::de::Error) -> ModelError {
    voxflex_core::error::toml_table_error("[actuator.params]", text, e)
}

impl CableParams {
    /// Parses and validates `[actuator.params]`; every error names the
    /// key, its value and what is allowed.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let p: CableParams = toml::from_str(text).map_err(|e| toml_error(text, &e))?;
        p.validate()?;
        Ok(p)
    }

    /// The pull point, world mm.
    pub fn pull_point(&self) -> DVec3 {
        DVec3::from_array(self.pull_point_mm)
    }

    /// The effort bounds `[0, max_tension_uN]`, µN.
    pub fn effort_bounds(&self) -> [f64; 2] {
        [0.0, self.max_tension_un.unwrap_or(f64::INFINITY)]
    }

    /// The measure bounds `[−∞, max_shortening_mm]`, mm.
    pub fn measure_bounds(&self) -> [f64; 2] {
        [
            f64::NEG_INFINITY,
            self.max_shortening_mm.unwrap_or(f64::INFINITY),
        ]
    }

    /// What the script asks for at `frame`.
    pub fn command(&self, frame: FrameInfo) -> ActuatorCommand {
        let at = frame.frame as f64;
        match (&self.tension_un, &self.shortening_mm) {
            (Some(t), _) => ActuatorCommand::Effort(t.at(at)),
            (None, Some(s)) => ActuatorCommand::Measure(s.at(at)),
            (None, None) => ActuatorCommand::Free,
        }
    }

    fn validate(&self) -> Result<(), ModelError> {
        if !self.pull_point().is_finite() {
            return bad(
                "pull_point_mm",
                self.pull_point_mm,
                "must be three finite coordinates, mm",
            );
        }
        for (key, max) in [
            ("max_tension_uN", self.max_tension_un),
            ("max_shortening_mm", self.max_shortening_mm),
        ] {
            if let Some(m) = max
                && (m.is_nan() || m <= 0.0)
            {
                return bad(key, m, "must be > 0 (leave the key out: unbounded)");
            }
        }
        self.validate_control()
    }

    fn validate_control(&self) -> Result<(), ModelError> {
        match (&self.tension_un, &self.shortening_mm) {
            (Some(_), Some(_)) => bad(
                "tension_uN and shortening_mm",
                "both given",
                "script either the tension or the shortening, not both (neither: the inverse \
                 solve chooses the tension)",
            ),
            (Some(t), None) => within("tension_uN", t, self.effort_bounds(), "µN"),
            (None, Some(s)) => within("shortening_mm", s, self.measure_bounds(), "mm"),
            (None, None) => Ok(()),
        }
    }
}

/// Refuses a script whose values leave `[lo, hi]`.
fn within(key: &str, k: &Keyframes, [lo, hi]: [f64; 2], unit: &str) -> Result<(), ModelError> {
    let (min, max) = k.range();
    if min < lo || max > hi {
        return bad(
            key,
            Vec::<[f64; 2]>::from(k.clone()),
            &format!(
                "scripts values from {min} to {max} {unit}, outside the allowed [{lo}, {hi}] \
                 (see max_tension_uN / max_shortening_mm; a cable only pulls: tension ≥ 0)"
            ),
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(n: u64) -> FrameInfo {
        FrameInfo {
            frame: n,
            frames: 100,
            dt_s: 0.01,
        }
    }

    #[test]
    fn defaults_are_free_and_unbounded() {
        let p = CableParams::from_toml("pull_point_mm = [1, 2, 3]").unwrap();
        assert_eq!(p.pull_point(), DVec3::new(1.0, 2.0, 3.0));
        assert_eq!(p.command(frame(7)), ActuatorCommand::Free);
        assert_eq!(p.effort_bounds(), [0.0, f64::INFINITY]);
        assert_eq!(p.measure_bounds(), [f64::NEG_INFINITY, f64::INFINITY]);
    }

    #[test]
    fn schedules_and_bounds_come_from_their_keys() {
        let p = CableParams::from_toml(
            "pull_point_mm = [0, 0, 0]\ntension_uN = [[0, 0], [10, 100]]\nmax_tension_uN = 200",
        )
        .unwrap();
        assert_eq!(p.command(frame(4)), ActuatorCommand::Effort(40.0));
        assert_eq!(p.command(frame(30)), ActuatorCommand::Effort(100.0));
        assert_eq!(p.effort_bounds(), [0.0, 200.0]);
        let p = CableParams::from_toml(
            "pull_point_mm = [0, 0, 0]\nshortening_mm = [[2, 0], [4, 3]]\nmax_shortening_mm = 5",
        )
        .unwrap();
        assert_eq!(p.command(frame(0)), ActuatorCommand::Measure(0.0));
        assert_eq!(p.command(frame(3)), ActuatorCommand::Measure(1.5));
        assert_eq!(p.measure_bounds(), [f64::NEG_INFINITY, 5.0]);
    }

    #[test]
    fn each_bad_key_is_refused_naming_it() {
        let pull = "pull_point_mm = [0, 0, 0]\n";
        for (text, key) in [
            ("", "pull_point_mm"),
            ("pull_point_mm = [0, 0]", "pull_point_mm"),
            ("pull_point_mm = [0, nan, 0]", "pull_point_mm"),
            (
                "pull_point_mm = [0, 0, 0]\ntension_un = [[0, 1]]",
                "tension_un",
            ),
            (
                "pull_point_mm = [0, 0, 0]\nmax_tension_uN = 0",
                "max_tension_uN",
            ),
            (
                "pull_point_mm = [0, 0, 0]\nmax_tension_uN = nan",
                "max_tension_uN",
            ),
            (
                "pull_point_mm = [0, 0, 0]\nmax_shortening_mm = -1",
                "max_shortening_mm",
            ),
            (
                "pull_point_mm = [0, 0, 0]\ntension_uN = [[0, 1]]\nshortening_mm = [[0, 1]]",
                "tension_uN and shortening_mm",
            ),
            (
                "pull_point_mm = [0, 0, 0]\ntension_uN = [[0, -5]]",
                "tension_uN",
            ),
            (
                "pull_point_mm = [0, 0, 0]\ntension_uN = [[0, 50]]\nmax_tension_uN = 10",
                "tension_uN",
            ),
            (
                "pull_point_mm = [0, 0, 0]\nshortening_mm = [[0, 6]]\nmax_shortening_mm = 5",
                "shortening_mm",
            ),
            (
                "pull_point_mm = [0, 0, 0]\nshortening_mm = [[1, 0], [1, 2]]",
                "shortening_mm",
            ),
        ] {
            let e = CableParams::from_toml(text).unwrap_err().0;
            assert!(e.contains(key), "{text}: {e}");
        }
        assert!(CableParams::from_toml(&format!("{pull}shortening_mm = [[0, -2]]")).is_ok());
    }
}
