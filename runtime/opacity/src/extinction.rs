//! [`Extinction`]: the per-voxel extinction `E_v` and the update rule, in the
//! exact arithmetic both paths share.
//!
//! The paper's update is `o_v ← max(o_v, max_n o_n − E_v)` clamped to
//! `[o_min, o_max]`, with `E_v = (|d_s − d_v| − σ_s) / (λ σ_s)`. Opacities
//! are held as u16 fixed point (`q = round(o · 65535)`, see
//! [`crate::opacity_map`]), so the update becomes
//!
//! ```text
//! e_v = round_ties_even(((min(|d_s − d_v|, cap) − σ_s) · K).clamp(−131072, 131072))   (f32, then i32)
//! q_v ← max(q_v, clamp(max_n q_n − e_v, q_min, q_max))                                 (integers)
//! ```
//!
//! with `K = 65535 / (λ σ_s)` and `cap = (λ + 2) σ_s` computed once in f64
//! and rounded to f32. `e_v` is `E_v` in fixed-point units; capping
//! `|d_s − d_v|` at `(λ + 2) σ_s` changes nothing (`E_v` is then already
//! above `1 + 1/λ`, a full extinction) but keeps every intermediate finite.
//! The f32 part is a subtraction, an `abs`, a `min`, a subtraction and one
//! multiplication — no multiply-add a GPU compiler could fuse, no division
//! — so the WGSL twin (`shaders/opacity/common.wgsl`) computes the same
//! bits; the rest is integer arithmetic. CPU and GPU maps are therefore
//! identical, not just close. Against the real-valued rule the result is
//! off by at most half a fixed-point step (7.6e-6) per step of a path.

use super::OpacityError;
use super::params::GrowthParams;
use super::seed::SeedStats;
use crate::opacity_map::to_fixed;

/// Largest magnitude a voxel value is read with; NaN reads as `+SANE_MAX`.
pub const SANE_MAX: f32 = 1e30;

/// Bound on `|e_v|` before rounding: twice the full fixed-point range, so a
/// clamped value still extinguishes (or lifts) fully.
pub(crate) const E_BOUND: f32 = 131_072.0;

/// `x.round_ties_even()` for `|x| ≤ 2²²`, without a libm call: adding
/// `1.5 · 2²³` leaves no fraction bits, so the addition itself rounds to
/// the nearest integer, ties to even (IEEE default rounding), and the
/// subtraction is exact. (WGSL's `round` is ties-to-even too.)
#[inline]
pub fn round_ties_even_small(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0;
    (x + MAGIC) - MAGIC
}

/// A voxel value as the growth reads it: NaN → `+1e30`, everything else
/// clamped to `[−1e30, 1e30]`, so differences never overflow. Integer
/// volumes pass unchanged. The GPU path uploads values through this too.
#[inline]
pub fn sanitize(v: f32) -> f32 {
    if v.is_nan() {
        SANE_MAX
    } else {
        v.clamp(-SANE_MAX, SANE_MAX)
    }
}

/// The extinction of one region growing: the seed's statistics turned into
/// the constants of the fixed-point update rule (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extinction {
    /// Seed mean `d_s` (value units).
    pub mean: f32,
    /// Seed standard deviation σ_s as used, after the floor (value units).
    pub sigma: f32,
    /// `K = 65535 / (λ σ_s)`: fixed-point opacity per value unit.
    pub scale: f32,
    /// `(λ + 2) σ_s`: cap on `|d_s − d_v|` (value units).
    pub cap: f32,
    /// `o_min` in fixed point.
    pub q_min: u16,
    /// `o_max` in fixed point.
    pub q_max: u16,
}

impl Extinction {
    /// The constants for a seed and parameters; fails when `λ σ_s` is so
    /// small that `K` overflows.
    pub fn new(stats: &SeedStats, params: &GrowthParams) -> Result<Self, OpacityError> {
        params.validate()?;
        let sigma = stats.sigma;
        let lambda = params.lambda;
        let scale = 65535.0 / (lambda as f64 * sigma as f64);
        let cap = (lambda as f64 + 2.0) * sigma as f64;
        let ok = |x: f64| x.is_finite() && x > 0.0 && x < f32::MAX as f64 / 4.0;
        if sigma.is_nan() || sigma <= 0.0 || !ok(scale) || !ok(cap) || !ok(scale * cap) {
            return Err(OpacityError::ExtinctionOverflow { lambda, sigma });
        }
        Ok(Self {
            mean: stats.mean,
            sigma,
            scale: scale as f32,
            cap: cap as f32,
            q_min: to_fixed(params.o_min),
            q_max: to_fixed(params.o_max),
        })
    }

    /// `e_v`: the extinction of a voxel of value `value` (value units), in
    /// fixed-point opacity units (65535 = an opacity of 1). Negative inside
    /// one σ_s of the seed mean.
    #[inline]
    pub fn fixed(&self, value: f32) -> i32 {
        let e = (self.excess(value) * self.scale).clamp(-E_BOUND, E_BOUND);
        round_ties_even_small(e) as i32
    }

    /// `min(|d_s − d_v|, cap) − σ_s` (value units): how far a voxel of
    /// value `value` lies beyond one σ_s of the seed mean, capped — `E_v`
    /// before the scale `1 / (λ σ_s)`. [`Extinction::fixed`] scales and
    /// rounds it; the automatic λ's path-cost scan adds it up along paths
    /// ([`crate::path_cost`]).
    #[inline]
    pub fn excess(&self, value: f32) -> f32 {
        (self.mean - sanitize(value)).abs().min(self.cap) - self.sigma
    }

    /// `E_v` as a real opacity difference (for display and tests).
    pub fn real(&self, value: f32) -> f32 {
        let a = (self.mean - sanitize(value)).abs();
        (a - self.sigma) / (self.scale.recip() * 65535.0)
    }

    /// The candidate value `clamp(neighbour_max − e, q_min, q_max)` of a
    /// voxel with extinction `e` whose highest neighbour holds
    /// `neighbour_max` (fixed point).
    #[inline]
    pub fn rise(&self, neighbour_max: u16, e: i32) -> u16 {
        (neighbour_max as i32 - e).clamp(self.q_min as i32, self.q_max as i32) as u16
    }

    /// The highest value a voxel with extinction `e` can ever reach
    /// (`rise(q_max, e)`): a voxel already holding it is inert.
    #[inline]
    pub fn ceiling(&self, e: i32) -> u16 {
        self.rise(self.q_max, e)
    }

    /// Whether a voxel just lifted to `new` with extinction `e` may be the
    /// lifting half of a pumping pair (`e < 0`, `new < q_max`); only then
    /// are its neighbours checked with [`Extinction::pumps`].
    #[inline]
    pub fn may_pump(&self, new: u16, e: i32) -> bool {
        e < 0 && new < self.q_max
    }

    /// The pump shortcut. Two neighbours `v`, `n` with `e_v + e_n < 0` lift
    /// each other without bound once both are reached: `q_n ≥ q_v − e_n`
    /// then `q_v ≥ q_n − e_v > q_v`, so the plain iteration ratchets both up
    /// by `|e_v + e_n|` every two steps until `q_max` — tens of thousands
    /// of steps when the sum is a few fixed-point units. At the fixed point
    /// the one with `e < 0` (both when both are negative) holds `q_max`.
    /// So a voxel `v` lifted to `new` (`e_v < 0`) in a step whose neighbour
    /// `n` (extinction `e_n`, value `q_n` after the step's lift) satisfies
    /// `e_v + e_n < 0` and is or becomes reached (`q_n > q_min` or
    /// `rise(new, e_n) > q_min`) jumps to `q_max` at the end of that step. The jump only sets a value the growth would reach
    /// anyway, so the converged map is unchanged (the least fixed point of
    /// the update); only the number of steps drops. Every adjacent cycle of
    /// negative total extinction contains such a pair, so no pump is missed.
    #[inline]
    pub fn pumps(&self, new: u16, e: i32, e_n: i32, q_n: u16) -> bool {
        e + e_n < 0 && (q_n > self.q_min || self.rise(new, e_n) > self.q_min)
    }
}
