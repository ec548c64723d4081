//! [`GrowthParams`]: the constants of the opacity region growing.

use super::OpacityError;
use crate::opacity_map::to_fixed;

/// Largest [`GrowthParams::seed_radius`]: a 17³ neighbourhood (4,913
/// voxels) already spans more than most organs at CT resolution.
pub const MAX_SEED_RADIUS: u32 = 8;

/// Constants of the region growing (CEIG 2016): the opacity range, the
/// extinction scale λ, the seed neighbourhood its statistics come from and
/// the floor under the seed's standard deviation.
///
/// All opacities are dimensionless, in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrowthParams {
    /// Opacity of every voxel the growth does not raise (the map's
    /// [`crate::opacity_map::OpacityMap::outside`]), in [0, 1). Default 0.03.
    pub o_min: f32,
    /// Opacity of the seed and the ceiling of every voxel, in (o_min, 1].
    /// Default 1.
    pub o_max: f32,
    /// Extinction scale λ > 0: a voxel whose value differs from the seed's
    /// mean `d_s` by `|d_s − d_v|` extinguishes `E_v = (|d_s − d_v| − σ_s) /
    /// (λ σ_s)` of opacity per step, so a larger λ lets the region flow
    /// further across intensity differences. Default 30 (the paper's).
    pub lambda: f32,
    /// Floor under the seed's standard deviation, as a fraction of the
    /// volume's value range: `σ_s ← max(σ_s, sigma_floor · (max − min))`
    /// (`sigma_floor · max(|d_s|, 1)` for a constant volume). Keeps `E_v`
    /// finite when the seed sits in a homogeneous region (σ_s = 0). Default
    /// 1e-3.
    pub sigma_floor: f32,
    /// Half-width, in voxels, of the cube around the seed voxel whose mean
    /// and standard deviation are `d_s` and σ_s: `(2 r + 1)³` voxels,
    /// clipped to the volume. 1 is the paper's 1-ring (27 voxels); the
    /// default, 2 (125 voxels, ITK's `ConfidenceConnected` default), because
    /// 27 voxels of spatially correlated CT noise misjudge σ_s by up to 2×
    /// (8.2–15 HU on 15 HU noise), which decides how far the growth runs
    /// (docs/BENCHMARKS.md, "ROI maps"). 1 ..= [`MAX_SEED_RADIUS`].
    pub seed_radius: u32,
    /// Which neighbours pass opacity on: 6 (faces only; the default) or 26
    /// (faces, edges and corners: the paper's). With 26, opacity crosses a
    /// contact where two organs touch only at a voxel's edge or corner —
    /// on 3 mm CT that is how a liver map reached the spleen (Dice 0.897
    /// against 0.971 with 6); over three organs at three grids the
    /// automatic λ's mean Dice is 0.933 with 6 against 0.906 with 26, and
    /// no case is worse (docs/BENCHMARKS.md, "ROI maps").
    pub connectivity: u32,
}

impl Default for GrowthParams {
    fn default() -> Self {
        Self {
            o_min: 0.03,
            o_max: 1.0,
            lambda: 30.0,
            sigma_floor: 1e-3,
            seed_radius: 2,
            connectivity: 6,
        }
    }
}

impl GrowthParams {
    /// Checks every field; the error names the value at fault.
    pub fn validate(&self) -> Result<(), OpacityError> {
        if !(self.lambda.is_finite() && self.lambda > 0.0) {
            return Err(OpacityError::BadLambda {
                lambda: self.lambda,
            });
        }
        let unit = |o: f32| o.is_finite() && (0.0..=1.0).contains(&o);
        if !unit(self.o_min) || !unit(self.o_max) || to_fixed(self.o_min) >= to_fixed(self.o_max) {
            return Err(OpacityError::BadOpacityRange {
                o_min: self.o_min,
                o_max: self.o_max,
            });
        }
        if !(self.sigma_floor.is_finite() && self.sigma_floor > 0.0) {
            return Err(OpacityError::BadSigmaFloor {
                sigma_floor: self.sigma_floor,
            });
        }
        if !matches!(self.connectivity, 6 | 26) {
            return Err(OpacityError::BadConnectivity {
                connectivity: self.connectivity,
            });
        }
        if !(1..=MAX_SEED_RADIUS).contains(&self.seed_radius) {
            return Err(OpacityError::BadSeedRadius {
                seed_radius: self.seed_radius,
            });
        }
        Ok(())
    }
}
