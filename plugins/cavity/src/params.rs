//! The cavity's parameters: the TOML of the scene's `[actuator.params]`
//! table, parsed with `deny_unknown_fields` (a misspelt key is refused,
//! naming it) and validated in full here, in `create`, so `voxflex
//! validate` reports every bad value and nothing turns into NaN later.

use serde::Deserialize;
use voxflex_core::actuator::ActuatorCommand;
use voxflex_core::deformation::FrameInfo;
use voxflex_core::error::ModelError;
use voxflex_core::glam::DVec3;
use voxflex_core::keyframes::Keyframes;
use voxflex_fluid::{FluidError, FluidWeightParams};

/// Density of water, kg/m³ (the default of `fluid = "water"`).
pub const WATER_KG_M3: f64 = 1000.0;

/// What fills the cavity.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Fluid {
    /// Pneumatic: the fluid's weight is neglected, so the cavity carries
    /// no loads — only the pressure's push.
    #[default]
    Air,
    /// Hydraulic: incompressible, ρ = 1000 kg/m³ unless `density_kg_m3`
    /// says otherwise; its weight loads the cavity's floor (ICRA 2017).
    Water,
}

/// Parameters of a cavity actuator (`[actuator.params]`).
///
/// ```toml
/// [actuator.params]
/// fluid = "water"                         # or "air" (default)
/// pressure_pa = [[0, 0], [50, 20000]]     # or volume_mm3 = [[frame, mm³]], or neither
/// max_pressure_pa = 50000
/// volume_growth_mm3 = [-100, 2000]
/// ```
#[derive(Clone, Debug, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CavityParams {
    /// What fills the cavity: `"air"` (pneumatic, weightless; default) or
    /// `"water"` (hydraulic, incompressible, its weight loads the walls).
    #[serde(default)]
    pub fluid: Fluid,
    /// Density of the fluid, kg/m³ (> 0; `fluid = "water"` only; default
    /// 1000).
    #[serde(default)]
    #[schemars(extend("unit" = "kg/m³", "default" = 1000.0))]
    pub density_kg_m3: Option<f64>,
    /// Columns along each side of the fluid-weight grid (1 … 4096;
    /// `fluid = "water"` only; default 200, the paper's real-time choice).
    #[serde(default)]
    #[schemars(range(min = 1, max = 4096), extend("default" = 200))]
    pub columns_per_side: Option<usize>,
    /// Parallel leveraging α ≥ 0 of the fluid-weight pass (workers per
    /// triangle = max(1, ⌊α·c⌋); `fluid = "water"` only; default 0.25,
    /// the paper's).
    #[serde(default)]
    #[schemars(range(min = 0), extend("default" = 0.25))]
    pub leverage_alpha: Option<f64>,
    /// Scripted pressure, `[[frame, Pa], …]` (linear between keyframes,
    /// held outside): the effort is given. Values in `[0,
    /// max_pressure_pa]`. Not with `volume_mm3`.
    #[serde(default)]
    #[schemars(extend("unit" = "Pa"))]
    pub pressure_pa: Option<Keyframes>,
    /// Scripted volume growth from rest, `[[frame, mm³], …]`: the pressure
    /// is found to reach it. Values within `volume_growth_mm3`. Not with
    /// `pressure_pa`. Neither key: the inverse solve chooses the pressure.
    #[serde(default)]
    #[schemars(extend("unit" = "mm³"))]
    pub volume_mm3: Option<Keyframes>,
    /// Largest pressure, Pa (> 0; leave it out: unbounded). The effort
    /// bounds are `[0, max_pressure_pa]`: a fluid only pushes.
    #[serde(default)]
    #[schemars(extend("unit" = "Pa"))]
    pub max_pressure_pa: Option<f64>,
    /// `[min, max]` volume growth from rest, mm³ (leave it out: unbounded;
    /// for one open side give a far value, e.g. `[-1e9, 500]`): the
    /// measure bounds of the inverse solve.
    #[serde(default)]
    #[schemars(extend("unit" = "mm³"))]
    pub volume_growth_mm3: Option<[f64; 2]>,
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

impl CavityParams {
    /// Parses and validates `[actuator.params]`; every error names the
    /// key, its value and what is allowed.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let p: CavityParams = toml::from_str(text).map_err(|e| toml_error(text, &e))?;
        p.validate()?;
        Ok(p)
    }

    /// The effort bounds `[0, max_pressure_pa]`, Pa.
    pub fn effort_bounds(&self) -> [f64; 2] {
        [0.0, self.max_pressure_pa.unwrap_or(f64::INFINITY)]
    }

    /// The measure bounds (`volume_growth_mm3`), mm³.
    pub fn measure_bounds(&self) -> [f64; 2] {
        self.volume_growth_mm3
            .unwrap_or([f64::NEG_INFINITY, f64::INFINITY])
    }

    /// What the script asks for at `frame`.
    pub fn command(&self, frame: FrameInfo) -> ActuatorCommand {
        let at = frame.frame as f64;
        match (&self.pressure_pa, &self.volume_mm3) {
            (Some(p), _) => ActuatorCommand::Effort(p.at(at)),
            (None, Some(v)) => ActuatorCommand::Measure(v.at(at)),
            (None, None) => ActuatorCommand::Free,
        }
    }

    /// The fluid-weight parameters under `gravity_m_s2`, or `None` when the
    /// fluid has no weight (air, or zero gravity).
    pub fn weighing(&self, gravity_m_s2: DVec3) -> Option<FluidWeightParams> {
        let density_kg_m3 = match self.fluid {
            Fluid::Air => return None,
            Fluid::Water => self.density_kg_m3.unwrap_or(WATER_KG_M3),
        };
        if gravity_m_s2 == DVec3::ZERO {
            return None;
        }
        let d = FluidWeightParams::default();
        Some(FluidWeightParams {
            columns_per_side: self.columns_per_side.unwrap_or(d.columns_per_side),
            density_kg_m3,
            gravity_m_s2,
            leverage_alpha: self.leverage_alpha.unwrap_or(d.leverage_alpha),
        })
    }

    fn validate(&self) -> Result<(), ModelError> {
        self.validate_fluid()?;
        self.validate_bounds()?;
        self.validate_control()
    }

    fn validate_fluid(&self) -> Result<(), ModelError> {
        if self.fluid == Fluid::Air {
            let hydraulic_only = [
                ("density_kg_m3", self.density_kg_m3.is_some()),
                ("columns_per_side", self.columns_per_side.is_some()),
                ("leverage_alpha", self.leverage_alpha.is_some()),
            ];
            if let Some((key, _)) = hydraulic_only.iter().find(|k| k.1) {
                return bad(
                    key,
                    "given",
                    "weighs the fluid, which fluid = \"air\" neglects; set fluid = \"water\" \
                     or remove the key",
                );
            }
            return Ok(());
        }
        if let Some(d) = self.density_kg_m3
            && !(d.is_finite() && d > 0.0)
        {
            return bad(
                "density_kg_m3",
                d,
                "must be a finite density > 0 kg/m³ (water: 1000)",
            );
        }
        // The grid keys checked under a stand-in gravity (the scene's
        // comes with `init`; zero gravity weighs nothing).
        match self.weighing(DVec3::new(0.0, 0.0, -9.81)) {
            Some(params) => params.check().map_err(|e| fluid_key_error(&e)),
            None => Ok(()),
        }
    }

    fn validate_bounds(&self) -> Result<(), ModelError> {
        if let Some(m) = self.max_pressure_pa
            && (m.is_nan() || m <= 0.0)
        {
            return bad(
                "max_pressure_pa",
                m,
                "must be > 0 Pa (leave the key out: unbounded)",
            );
        }
        if let Some([lo, hi]) = self.volume_growth_mm3
            && (lo.is_nan()
                || hi.is_nan()
                || lo > hi
                || lo == f64::INFINITY
                || hi == f64::NEG_INFINITY)
        {
            return bad(
                "volume_growth_mm3",
                [lo, hi],
                "must be [min, max] mm³ with min ≤ max (leave the key out: unbounded)",
            );
        }
        Ok(())
    }

    fn validate_control(&self) -> Result<(), ModelError> {
        match (&self.pressure_pa, &self.volume_mm3) {
            (Some(_), Some(_)) => bad(
                "pressure_pa and volume_mm3",
                "both given",
                "script either the pressure or the volume, not both (neither: the inverse \
                 solve chooses the pressure)",
            ),
            (Some(p), None) => within("pressure_pa", p, self.effort_bounds(), "Pa"),
            (None, Some(v)) => within("volume_mm3", v, self.measure_bounds(), "mm³"),
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
                 (see max_pressure_pa / volume_growth_mm3; a pressure only pushes: ≥ 0)"
            ),
        );
    }
    Ok(())
}

/// A fluid-weight parameter error under this table's key names.
fn fluid_key_error(e: &FluidError) -> ModelError {
    match e {
        FluidError::Param {
            key,
            value,
            message,
        } => {
            let key = match *key {
                "columns" => "columns_per_side",
                "density" => "density_kg_m3",
                other => other,
            };
            ModelError(format!("[actuator.params] {key} = {value}: {message}"))
        }
        other => ModelError(format!("[actuator.params]: {other}")),
    }
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
    fn defaults_are_air_free_and_unbounded() {
        let p = CavityParams::from_toml("").unwrap();
        assert_eq!(p.fluid, Fluid::Air);
        assert_eq!(p.command(frame(3)), ActuatorCommand::Free);
        assert_eq!(p.effort_bounds(), [0.0, f64::INFINITY]);
        assert_eq!(p.measure_bounds(), [f64::NEG_INFINITY, f64::INFINITY]);
        assert_eq!(p.weighing(DVec3::new(0.0, 0.0, -9.81)), None);
    }

    #[test]
    fn water_weighs_with_the_given_grid_density_and_gravity() {
        let p = CavityParams::from_toml(
            "fluid = \"water\"\ndensity_kg_m3 = 1100\ncolumns_per_side = 64\nleverage_alpha = 0",
        )
        .unwrap();
        let g = DVec3::new(0.0, -9.81, 0.0);
        let w = p.weighing(g).unwrap();
        assert_eq!(
            (
                w.columns_per_side,
                w.density_kg_m3,
                w.gravity_m_s2,
                w.leverage_alpha
            ),
            (64, 1100.0, g, 0.0)
        );
        let w = CavityParams::from_toml("fluid = \"water\"")
            .unwrap()
            .weighing(g)
            .unwrap();
        assert_eq!(
            (w.columns_per_side, w.density_kg_m3, w.leverage_alpha),
            (200, 1000.0, 0.25)
        );
        assert_eq!(p.weighing(DVec3::ZERO), None, "no gravity, no weight");
    }

    #[test]
    fn schedules_give_the_command_of_each_frame() {
        let p = CavityParams::from_toml("pressure_pa = [[10, 0], [20, 1000]]").unwrap();
        assert_eq!(p.command(frame(0)), ActuatorCommand::Effort(0.0));
        assert_eq!(p.command(frame(15)), ActuatorCommand::Effort(500.0));
        assert_eq!(p.command(frame(40)), ActuatorCommand::Effort(1000.0));
        let p = CavityParams::from_toml("volume_mm3 = [[0, 0], [4, -40]]").unwrap();
        assert_eq!(p.command(frame(1)), ActuatorCommand::Measure(-10.0));
        assert_eq!(p.command(frame(9)), ActuatorCommand::Measure(-40.0));
    }

    #[test]
    fn bounds_come_from_their_keys() {
        let p = CavityParams::from_toml("max_pressure_pa = 3e4\nvolume_growth_mm3 = [-5, inf]")
            .unwrap();
        assert_eq!(p.effort_bounds(), [0.0, 3e4]);
        assert_eq!(p.measure_bounds(), [-5.0, f64::INFINITY]);
    }

    #[test]
    fn each_bad_key_is_refused_naming_it() {
        for (text, key) in [
            ("fluid = \"oil\"", "fluid"),
            ("presure_pa = [[0, 1]]", "presure_pa"),
            ("density_kg_m3 = 1000", "density_kg_m3"),
            ("columns_per_side = 30", "columns_per_side"),
            ("leverage_alpha = 0.5", "leverage_alpha"),
            ("fluid = \"water\"\ndensity_kg_m3 = 0", "density_kg_m3"),
            ("fluid = \"water\"\ndensity_kg_m3 = nan", "density_kg_m3"),
            ("fluid = \"water\"\ndensity_kg_m3 = inf", "density_kg_m3"),
            (
                "fluid = \"water\"\ncolumns_per_side = 0",
                "columns_per_side",
            ),
            (
                "fluid = \"water\"\ncolumns_per_side = 5000",
                "columns_per_side",
            ),
            ("fluid = \"water\"\nleverage_alpha = -1", "leverage_alpha"),
            (
                "pressure_pa = [[0, 1]]\nvolume_mm3 = [[0, 1]]",
                "pressure_pa and volume_mm3",
            ),
            ("pressure_pa = [[0, -1]]", "pressure_pa"),
            (
                "pressure_pa = [[0, 10], [5, 200]]\nmax_pressure_pa = 100",
                "pressure_pa",
            ),
            ("pressure_pa = [[3, 1], [2, 1]]", "pressure_pa"),
            (
                "volume_mm3 = [[0, 50]]\nvolume_growth_mm3 = [0, 10]",
                "volume_mm3",
            ),
            ("max_pressure_pa = 0", "max_pressure_pa"),
            ("max_pressure_pa = nan", "max_pressure_pa"),
            ("volume_growth_mm3 = [5, 1]", "volume_growth_mm3"),
            ("volume_growth_mm3 = [nan, 1]", "volume_growth_mm3"),
            ("volume_growth_mm3 = [inf, inf]", "volume_growth_mm3"),
        ] {
            let e = CavityParams::from_toml(text).unwrap_err().0;
            assert!(e.contains(key), "{text}: {e}");
        }
    }
}
