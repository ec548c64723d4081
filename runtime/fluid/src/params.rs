//! What a fluid-weight computation is asked for.

use crate::error::FluidError;
use glam::DVec3;

/// Largest column grid side accepted: 4096² columns (16.8 M) — far beyond
/// convergence (the icosphere is exact to 1e-5 at 500²) and still bounded
/// in memory.
pub const MAX_COLUMNS_PER_SIDE: usize = 4096;

/// The paper's leveraging factor α (workers per triangle = ⌊α · mean
/// candidates⌋, at least one).
pub const PAPER_ALPHA: f64 = 0.25;

/// Parameters of [`crate::fluid_weights`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FluidWeightParams {
    /// Columns along each side of the grid (the paper's 30² … 500² are
    /// 30 … 500). The grid spans the cavity's bounding box projected on
    /// the plane perpendicular to gravity, so columns need not be square.
    pub columns_per_side: usize,
    /// Fluid density, kg/m³ (water 1000; air ≈ 1.2, whose weight is
    /// usually negligible).
    pub density_kg_m3: f64,
    /// Gravity, m/s², world frame (e.g. `[0, 0, −9.81]`). Its direction
    /// sets what is up; its length scales the weights.
    pub gravity_m_s2: DVec3,
    /// Leveraging factor α ≥ 0: workers per triangle = max(1, ⌊α·c⌋),
    /// `c` the mean candidate columns per triangle. 0 is one worker per
    /// triangle; [`PAPER_ALPHA`] the paper's choice.
    pub leverage_alpha: f64,
}

impl Default for FluidWeightParams {
    fn default() -> Self {
        Self {
            columns_per_side: 200,
            density_kg_m3: 1000.0,
            gravity_m_s2: DVec3::new(0.0, 0.0, -9.81),
            leverage_alpha: PAPER_ALPHA,
        }
    }
}

impl FluidWeightParams {
    /// Refuses values no computation can use, naming the key and the fix.
    pub fn check(&self) -> Result<(), FluidError> {
        let param = |key, value: String, message: &str| {
            Err(FluidError::Param {
                key,
                value,
                message: message.into(),
            })
        };
        if !(1..=MAX_COLUMNS_PER_SIDE).contains(&self.columns_per_side) {
            return param(
                "columns",
                self.columns_per_side.to_string(),
                "give 1 … 4096 columns per side (200 is the paper's real-time choice)",
            );
        }
        if !(self.density_kg_m3.is_finite() && self.density_kg_m3 >= 0.0) {
            return param(
                "density",
                self.density_kg_m3.to_string(),
                "give a finite density ≥ 0 kg/m³ (water: 1000)",
            );
        }
        let g = self.gravity_m_s2;
        if !(g.is_finite() && g.length() > 0.0) {
            return param(
                "gravity",
                format!("{:?}", g.to_array()),
                "give a finite, non-zero gravity vector in m/s² (e.g. [0, 0, -9.81])",
            );
        }
        if !(self.leverage_alpha.is_finite() && self.leverage_alpha >= 0.0) {
            return param(
                "leverage_alpha",
                self.leverage_alpha.to_string(),
                "give α ≥ 0 (0: one worker per triangle; the paper uses 0.25)",
            );
        }
        Ok(())
    }
}
