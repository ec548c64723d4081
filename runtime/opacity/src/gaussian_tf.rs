//! The automatic Gaussian transfer function of the paper:
//! `f(x) = t(x) · (a + b · g(x))`, `g` a Gaussian centred on the seed's mean
//! `d_s` with standard deviation σ_s, so voxels of the seed's intensity keep
//! their base opacity `t(x)` and others fade to `a · t(x)`.

use super::seed::SeedStats;

/// `f(x) = t(x) · (a + b · exp(−(x − mean)² / (2 σ²)))`; `x` in the volume's
/// value units, `t(x)` the base transfer function's opacity in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussianTf {
    /// Centre of the Gaussian, `d_s` (value units).
    pub mean: f32,
    /// Standard deviation of the Gaussian, σ_s (value units). Zero, negative
    /// or non-finite makes `g` an indicator of `x == mean`.
    pub sigma: f32,
    /// Floor `a` of the weight (default 0.01).
    pub a: f32,
    /// Gaussian gain `b` (default 0.99; `a + b = 1` keeps `t` at the mean).
    pub b: f32,
}

impl GaussianTf {
    /// The paper's defaults `a = 0.01`, `b = 0.99` around `mean`, `sigma`.
    pub fn new(mean: f32, sigma: f32) -> Self {
        Self {
            mean,
            sigma,
            a: 0.01,
            b: 0.99,
        }
    }

    /// The defaults around a seed's `d_s` and σ_s (the floored σ the growth
    /// used).
    pub fn from_stats(stats: &SeedStats) -> Self {
        Self::new(stats.mean, stats.sigma)
    }

    /// The Gaussian `g(x)` in [0, 1].
    #[inline]
    pub fn gaussian(&self, x: f32) -> f32 {
        let d = x - self.mean;
        if self.sigma.is_finite() && self.sigma > 0.0 {
            (-(d * d) / (2.0 * self.sigma * self.sigma)).exp()
        } else if d == 0.0 {
            1.0
        } else {
            0.0
        }
    }

    /// The weight `a + b · g(x)`.
    #[inline]
    pub fn weight(&self, x: f32) -> f32 {
        self.a + self.b * self.gaussian(x)
    }

    /// `f(x) = t · (a + b · g(x))` for value `x` and base opacity `t`.
    #[inline]
    pub fn opacity(&self, x: f32, t: f32) -> f32 {
        t * self.weight(x)
    }
}

/// The transfer function `(value, base opacity t(x)) ↦ t(x) · (a + b · g(x))`
/// with `g` the Gaussian of mean `d_s` and standard deviation `sigma_s`
/// (value units).
pub fn gaussian_tf(
    d_s: f32,
    sigma_s: f32,
    a: f32,
    b: f32,
) -> impl Fn(f32, f32) -> f32 + Copy + Send + Sync {
    let tf = GaussianTf {
        mean: d_s,
        sigma: sigma_s,
        a,
        b,
    };
    move |x, t| tf.opacity(x, t)
}
