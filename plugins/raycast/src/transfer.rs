//! 1-D transfer functions (data value → colour and opacity), their built-in
//! presets and the lookup table both render paths read.
//!
//! A transfer function is a list of control points `[value, r, g, b, a]`,
//! piecewise linear in between and constant beyond the first and last
//! point. Colours are **sRGB** in [0, 1] (interpolated in sRGB, like 3D
//! Slicer and ParaView, then linearised in the table; see [`crate::color`]).
//! Alpha `a` in [0, 1] is the **opacity of a slab `opacity_unit_distance`
//! thick** (1 mm by default), from which the table derives the extinction
//! coefficient `κ = −ln(1 − a) / opacity_unit_distance` (per mm; `a` is
//! capped at `1 − 10⁻⁶`, so `a = 1` means κ ≈ 13.8 / unit). A sample over
//! a ray segment of length Δt then has opacity `1 − exp(−κ Δt)`, which is
//! the classic correction `1 − (1 − a)^(Δt / unit)`.
//!
//! Values are in the volume's own units (Hounsfield units for CT), or — for
//! [`ValueUnits::Normalized`] functions such as the `mri-t1` preset — in
//! fractions of the volume's value range `[min, max]` (0 = min, 1 = max).

/// Entries of the lookup table ([`Lut`]), evenly spaced over the transfer
/// function's domain (first to last control point).
pub const LUT_SIZE: usize = 4096;

/// Opacities are capped at this value before conversion to κ.
pub const ALPHA_MAX: f32 = 1.0 - 1e-6;

/// Names of the built-in presets, for error messages and docs.
pub const PRESETS: [&str; 4] = ["ct-bone", "ct-soft-tissue", "ct-lung", "mri-t1"];

/// What a control point's value is measured in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueUnits {
    /// The volume's own units (e.g. Hounsfield units).
    Data,
    /// Fractions of the volume's value range: 0 = smallest, 1 = largest value.
    Normalized,
}

/// One control point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlPoint {
    /// Data value (see [`ValueUnits`]).
    pub value: f32,
    /// sRGB colour in [0, 1] and alpha (opacity per `opacity_unit_distance`) in [0, 1].
    pub rgba: [f32; 4],
}

/// A piecewise-linear 1-D transfer function.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferFunction {
    /// Control points, values non-decreasing (two equal values make a step).
    pub points: Vec<ControlPoint>,
    /// Units of the values.
    pub units: ValueUnits,
    /// The automatic Gaussian transfer function of the opacity-map paper:
    /// when set, every opacity `t(x)` becomes `t(x) · (a + b · g(x))`, `g`
    /// a Gaussian at the ROI seed's mean and σ (data units).
    pub gaussian: Option<voxflex_opacity::GaussianTf>,
}

const fn cp(value: f32, r: f32, g: f32, b: f32, a: f32) -> ControlPoint {
    ControlPoint {
        value,
        rgba: [r, g, b, a],
    }
}

/// `ct-bone`: bone only (HU). Soft tissue (< 150 HU) is transparent;
/// cancellous to cortical bone ramps from ivory to white.
const CT_BONE: [ControlPoint; 6] = [
    cp(-1000.0, 0.0, 0.0, 0.0, 0.0),
    cp(150.0, 0.55, 0.25, 0.15, 0.0),
    cp(300.0, 0.85, 0.65, 0.45, 0.3),
    cp(700.0, 0.95, 0.88, 0.75, 0.6),
    cp(1500.0, 1.0, 1.0, 0.95, 0.85),
    cp(3071.0, 1.0, 1.0, 1.0, 0.9),
];

/// `ct-soft-tissue` (HU): fat faint, skin and muscle pink and
/// semi-transparent, bone opaque white.
const CT_SOFT_TISSUE: [ControlPoint; 7] = [
    cp(-1000.0, 0.0, 0.0, 0.0, 0.0),
    cp(-300.0, 0.6, 0.3, 0.2, 0.0),
    cp(-100.0, 0.85, 0.6, 0.45, 0.01),
    cp(40.0, 0.9, 0.55, 0.45, 0.08),
    cp(100.0, 0.95, 0.7, 0.6, 0.12),
    cp(400.0, 1.0, 0.95, 0.85, 0.5),
    cp(3071.0, 1.0, 1.0, 1.0, 0.8),
];

/// `ct-lung` (HU): air transparent, lung parenchyma (−900…−500 HU) a faint
/// blue haze, soft tissue transparent, bone white.
const CT_LUNG: [ControlPoint; 8] = [
    cp(-1000.0, 0.0, 0.0, 0.0, 0.0),
    cp(-950.0, 0.3, 0.45, 0.8, 0.0),
    cp(-750.0, 0.55, 0.7, 0.95, 0.04),
    cp(-500.0, 0.8, 0.8, 0.95, 0.02),
    cp(-300.0, 0.8, 0.6, 0.5, 0.0),
    cp(200.0, 0.9, 0.8, 0.7, 0.0),
    cp(500.0, 1.0, 1.0, 0.95, 0.5),
    cp(3071.0, 1.0, 1.0, 1.0, 0.8),
];

/// `mri-t1` (normalised 0–1 of the volume's value range): background and
/// CSF transparent, grey/white matter and fat increasingly bright and opaque.
const MRI_T1: [ControlPoint; 5] = [
    cp(0.0, 0.0, 0.0, 0.0, 0.0),
    cp(0.1, 0.3, 0.2, 0.15, 0.0),
    cp(0.35, 0.75, 0.6, 0.5, 0.05),
    cp(0.7, 0.95, 0.85, 0.75, 0.2),
    cp(1.0, 1.0, 1.0, 1.0, 0.4),
];

impl TransferFunction {
    /// A built-in preset by name (see [`PRESETS`]), or `None`.
    ///
    /// CT presets are in Hounsfield units; `mri-t1` in normalised units.
    pub fn preset(name: &str) -> Option<Self> {
        let (points, units): (&[ControlPoint], _) = match name {
            "ct-bone" => (&CT_BONE, ValueUnits::Data),
            "ct-soft-tissue" => (&CT_SOFT_TISSUE, ValueUnits::Data),
            "ct-lung" => (&CT_LUNG, ValueUnits::Data),
            "mri-t1" => (&MRI_T1, ValueUnits::Normalized),
            _ => return None,
        };
        Some(Self {
            points: points.to_vec(),
            units,
            gaussian: None,
        })
    }

    /// The same function moved along the value axis by `shift` (in the
    /// function's own units), like 3D Slicer's preset shift slider.
    pub fn shifted(mut self, shift: f32) -> Self {
        for p in &mut self.points {
            p.value += shift;
        }
        self
    }

    /// sRGB colour and alpha at value `v` (function units), piecewise linear,
    /// constant beyond the ends; at a step (equal values) the later point wins.
    pub fn evaluate(&self, v: f32) -> [f32; 4] {
        let pts = &self.points;
        let Some(first) = pts.first() else {
            return [0.0; 4];
        };
        // NaN (which no comparison holds for) takes the first point's.
        if v.is_nan() || first.value.is_nan() || v < first.value {
            return first.rgba;
        }
        // First point with value > v.
        let n = pts.partition_point(|p| p.value <= v);
        if n >= pts.len() {
            return pts[pts.len() - 1].rgba;
        }
        let (a, b) = (pts[n - 1], pts[n]);
        let w = (v - a.value) / (b.value - a.value);
        std::array::from_fn(|c| a.rgba[c] + w * (b.rgba[c] - a.rgba[c]))
    }

    /// The lookup table for a volume whose values span `data_range` (used to
    /// place [`ValueUnits::Normalized`] points), with alpha given per
    /// `unit_distance_mm` (> 0).
    pub fn lut(&self, data_range: (f32, f32), unit_distance_mm: f32) -> Lut {
        let (dlo, dhi) = data_range;
        let span = if dhi > dlo { dhi - dlo } else { 1.0 };
        let to_data = |v: f32| match self.units {
            ValueUnits::Data => v,
            ValueUnits::Normalized => dlo + v * span,
        };
        let (lo, mut hi) = match (self.points.first(), self.points.last()) {
            (Some(a), Some(b)) => (to_data(a.value), to_data(b.value)),
            _ => (0.0, 1.0),
        };
        if hi - lo <= f32::EPSILON * lo.abs().max(1.0) {
            hi = lo + lo.abs().max(1.0) * 1e-3;
        }
        let scale = (LUT_SIZE - 1) as f32 / (hi - lo);
        let inv_unit = 1.0 / unit_distance_mm;
        let entries: Vec<[f32; 4]> = (0..LUT_SIZE)
            .map(|e| {
                let v = lo + (hi - lo) * (e as f32 / (LUT_SIZE - 1) as f32);
                let fv = match self.units {
                    ValueUnits::Data => v,
                    ValueUnits::Normalized => (v - dlo) / span,
                };
                let [r, g, b, a] = self.evaluate(fv);
                let a = match &self.gaussian {
                    Some(gauss) => gauss.opacity(v, a),
                    None => a,
                };
                let a = a.clamp(0.0, ALPHA_MAX);
                let kappa = -(1.0 - a).ln() * inv_unit;
                [
                    crate::color::srgb_to_linear(r),
                    crate::color::srgb_to_linear(g),
                    crate::color::srgb_to_linear(b),
                    kappa.max(0.0),
                ]
            })
            .collect();
        let mut nonzero_prefix = Vec::with_capacity(LUT_SIZE + 1);
        let mut count = 0u32;
        nonzero_prefix.push(0);
        for e in &entries {
            count += (e[3] > 0.0) as u32;
            nonzero_prefix.push(count);
        }
        let visible = (
            entries
                .iter()
                .position(|e| e[3] > 0.0)
                .unwrap_or(LUT_SIZE + 1),
            entries.iter().rposition(|e| e[3] > 0.0).unwrap_or(0),
        );
        Lut {
            entries,
            lo,
            scale,
            nonzero_prefix,
            visible,
        }
    }
}

/// A key that orders the non-NaN f32 values as numbers (−∞ lowest, −0
/// just below +0), as unsigned integers.
fn order_key(v: f32) -> u32 {
    let b = v.to_bits();
    if b >> 31 == 1 { !b } else { b | 0x8000_0000 }
}

/// The value of an [`order_key`].
fn from_order_key(k: u32) -> f32 {
    f32::from_bits(if k >> 31 == 1 { k & 0x7fff_ffff } else { !k })
}

/// The smallest non-NaN value (−∞ to +∞) where `pass`, non-decreasing
/// (false, then true), holds; `None` when it holds nowhere. 32 steps.
fn first_passing(pass: impl Fn(f32) -> bool) -> Option<f32> {
    let (mut lo, mut hi) = (order_key(f32::NEG_INFINITY), order_key(f32::INFINITY));
    if !pass(from_order_key(hi)) {
        return None;
    }
    // Invariant: `pass` holds at `hi`; it fails below `lo` (or `lo` is −∞).
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if pass(from_order_key(mid)) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    Some(from_order_key(hi))
}

/// Where a data value falls in a [`LUT_SIZE`]-entry table: between entry
/// `entry` (≤ `LUT_SIZE − 2`) and the next, `frac` ∈ [0, 1] of the way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TablePlace {
    /// The entry below the value.
    pub entry: usize,
    /// The fraction of the way to the next entry.
    pub frac: f32,
}

/// The precomputed transfer function both paths sample identically:
/// [`LUT_SIZE`] entries of **linear** RGB and extinction κ (per mm), linearly
/// interpolated, clamped at the ends.
#[derive(Clone, Debug, PartialEq)]
pub struct Lut {
    /// `[r, g, b, κ]`: linear colour and extinction per mm.
    pub entries: Vec<[f32; 4]>,
    /// Data value of entry 0.
    pub lo: f32,
    /// Entries per data unit: entry position `x = (v − lo) · scale`.
    pub scale: f32,
    /// `nonzero_prefix[e]` = number of entries before `e` with κ > 0
    /// ([`LUT_SIZE`] + 1 values): the opacity range table of empty-space skipping.
    pub nonzero_prefix: Vec<u32>,
    /// The first and the last entry with κ > 0 (first > last when none):
    /// a value whose two entries both lie outside has κ = 0 exactly
    /// ([`Lut::lookup_visible`]).
    pub visible: (usize, usize),
}

impl Lut {
    /// Interpolated `[r, g, b, κ]` at data value `v`.
    #[inline(always)]
    pub fn lookup(&self, v: f32) -> [f32; 4] {
        let (e0, f) = self.position(v);
        self.at(e0, f)
    }

    /// [`Lut::lookup`], or `None` when both table entries around `v` lie
    /// outside the visible range (then κ is 0 exactly, and the renderer
    /// skips the sample without reading the table: three in four samples
    /// of the `ct-bone` head lie in soft tissue next to bone).
    #[inline(always)]
    pub fn lookup_visible(&self, v: f32) -> Option<[f32; 4]> {
        self.lookup_visible_placed(v).map(|(x, _)| x)
    }

    /// [`Lut::lookup_visible`], with where `v` fell in the table (for
    /// tables indexed like this one: [`crate::step_opacity::StepOpacity`]).
    #[inline(always)]
    pub fn lookup_visible_placed(&self, v: f32) -> Option<([f32; 4], TablePlace)> {
        let (e0, f) = self.position(v);
        let (first, last) = self.visible;
        (e0 + 1 >= first && e0 <= last).then(|| (self.at(e0, f), TablePlace { entry: e0, frac: f }))
    }

    /// The table entry below `v` (the one [`Lut::lookup`] interpolates
    /// from); non-decreasing in `v`, entry 0 for NaN.
    #[inline(always)]
    pub fn entry(&self, v: f32) -> usize {
        self.position(v).0
    }

    /// False only when no value whose entry ([`Lut::entry`]) is *within one
    /// entry* of `[e_lo, e_hi]` is shown: then every value interpolated from
    /// values with entries in `[e_lo, e_hi]` — even one rounded a step past
    /// them — has κ = 0, and [`Lut::lookup_visible`] answers `None`.
    #[inline]
    pub fn entries_may_show(&self, e_lo: usize, e_hi: usize) -> bool {
        let (first, last) = self.visible;
        e_hi + 2 >= first && e_lo <= last + 1
    }

    /// [`Lut::entries_may_show`] in data values: `(t_lo, t_hi)` with
    /// `entry(v) + 2 ≥ first ⟺ v ≥ t_lo` and `entry(v) ≤ last + 1 ⟺
    /// v ≤ t_hi` for every non-NaN `v` (−∞ / +∞ when every value passes,
    /// NaN when none does, so the comparison is false). Values whose
    /// entries span `[e_lo, e_hi]` may show exactly when the largest is
    /// ≥ `t_lo` and the smallest ≤ `t_hi` — two comparisons per value
    /// instead of a table position ([`crate::visible_cells`]).
    ///
    /// Found by bisection over the ordered f32 values with [`Lut::entry`]
    /// itself as the oracle (it is non-decreasing), so the thresholds
    /// agree with it on every value; 64 evaluations of it.
    pub fn show_window(&self) -> (f32, f32) {
        let (first, last) = self.visible;
        let least = first.saturating_sub(2);
        let t_lo = first_passing(|v| self.entry(v) >= least).unwrap_or(f32::NAN);
        let t_hi = match first_passing(|v| self.entry(v) > last + 1) {
            // The value just below the first one past the window.
            Some(v) if v == f32::NEG_INFINITY => f32::NAN,
            Some(v) => from_order_key(order_key(v) - 1),
            None => f32::INFINITY,
        };
        (t_lo, t_hi)
    }

    /// The entry below `v` and the fraction past it.
    #[inline(always)]
    fn position(&self, v: f32) -> (usize, f32) {
        // `max` then `min`, not `clamp`: NaN becomes entry 0 instead of
        // passing through.
        let x = ((v - self.lo) * self.scale)
            .max(0.0)
            .min((LUT_SIZE - 1) as f32);
        let e0 = (x as usize).min(LUT_SIZE - 2);
        (e0, x - e0 as f32)
    }

    /// Entries `e0` and `e0 + 1` interpolated at fraction `f`.
    #[inline(always)]
    fn at(&self, e0: usize, f: f32) -> [f32; 4] {
        let (a, b) = (self.entries[e0], self.entries[e0 + 1]);
        [
            a[0] + f * (b[0] - a[0]),
            a[1] + f * (b[1] - a[1]),
            a[2] + f * (b[2] - a[2]),
            a[3] + f * (b[3] - a[3]),
        ]
    }

    /// True when every value in `[min, max]` has κ = 0 (conservative by one
    /// table entry on each side, so float rounding never skips a visible
    /// sample). Same formula as `cell_is_empty` in `raycast.wgsl`.
    #[inline]
    pub fn range_is_empty(&self, min: f32, max: f32) -> bool {
        let top = (LUT_SIZE - 1) as f32;
        // NaN-safe like `lookup`: NaN bounds become entry 0.
        let a = ((min - self.lo) * self.scale).floor().max(0.0).min(top) as usize;
        let b = ((max - self.lo) * self.scale).floor().max(0.0).min(top) as usize;
        let lo = a.saturating_sub(1);
        let hi = (b + 2).min(LUT_SIZE - 1);
        self.nonzero_prefix[hi + 1] == self.nonzero_prefix[lo]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every preset and a function with nothing visible.
    fn presets_and_an_invisible_function() -> Vec<TransferFunction> {
        let mut fns: Vec<TransferFunction> = PRESETS
            .iter()
            .map(|p| TransferFunction::preset(p).unwrap())
            .collect();
        fns.push(tf(&[
            [0.0, 1.0, 1.0, 1.0, 0.0],
            [100.0, 1.0, 1.0, 1.0, 0.0],
        ]));
        fns
    }

    /// `lookup_visible` is `lookup` wherever it answers, and answers `None`
    /// only where `lookup`'s κ is 0: every preset (`ct-lung` has two
    /// visible ranges), a function with nothing visible, values below,
    /// inside, between and above the table's entries, and NaN.
    #[test]
    fn lookup_visible_skips_only_invisible_values() {
        for f in &presets_and_an_invisible_function() {
            let lut = f.lut((-1024.0, 3071.0), 1.0);
            let mut skipped = 0;
            for i in -4200..=4200 {
                let v = i as f32;
                for v in [v, v + 0.37, f32::NAN] {
                    match lut.lookup_visible(v) {
                        Some(x) => assert_eq!(x, lut.lookup(v), "{v}"),
                        None => {
                            assert_eq!(lut.lookup(v)[3], 0.0, "{v}");
                            skipped += 1;
                        }
                    }
                }
            }
            assert!(skipped > 0, "{f:?}");
        }
    }

    /// The show window's two comparisons answer what the entries answer,
    /// on every preset, a function with nothing visible and one visible
    /// everywhere, over the data range (integers, fractions), at each
    /// threshold and the floats either side of it, at ±0 and ±∞.
    #[test]
    fn show_window_agrees_with_the_entries_on_every_value() {
        let mut fns = presets_and_an_invisible_function();
        fns.push(tf(&[
            [0.0, 1.0, 1.0, 1.0, 0.5],
            [100.0, 1.0, 1.0, 1.0, 0.5],
        ]));
        let (mut hidden, mut only_one) = (0, 0);
        for f in &fns {
            let lut = f.lut((-1024.0, 3071.0), 1.0);
            let (first, last) = lut.visible;
            let (t_lo, t_hi) = lut.show_window();
            let near = |t: f32| {
                let k = order_key(t);
                (k.saturating_sub(3)..=k.saturating_add(3)).map(from_order_key)
            };
            let mut values: Vec<f32> = (-4200..=4200)
                .flat_map(|i| [i as f32, i as f32 + 0.37])
                .collect();
            values.extend([
                0.0,
                -0.0,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::MAX,
                f32::MIN,
            ]);
            values.extend(near(t_lo).chain(near(t_hi)).filter(|v| !v.is_nan()));
            for v in values {
                let e = lut.entry(v);
                assert_eq!(v >= t_lo, e + 2 >= first, "{f:?}: {v} ≥ {t_lo}");
                assert_eq!(v <= t_hi, e <= last + 1, "{f:?}: {v} ≤ {t_hi}");
                hidden += !(v >= t_lo && v <= t_hi) as u32;
                only_one += ((v >= t_lo) != (v <= t_hi)) as u32;
            }
        }
        assert!(only_one > 0, "the thresholds cut somewhere");
        assert!(hidden > 0, "some values are hidden");
    }

    fn tf(points: &[[f32; 5]]) -> TransferFunction {
        TransferFunction {
            points: points
                .iter()
                .map(|p| cp(p[0], p[1], p[2], p[3], p[4]))
                .collect(),
            units: ValueUnits::Data,
            gaussian: None,
        }
    }

    #[test]
    fn gaussian_tf_weights_opacity_around_the_seed_mean() {
        let mut t = tf(&[[0.0, 1.0, 1.0, 1.0, 0.5], [100.0, 1.0, 1.0, 1.0, 0.5]]);
        let plain = t.lut((0.0, 0.0), 1.0);
        t.gaussian = Some(voxflex_opacity::GaussianTf::new(50.0, 5.0));
        let weighted = t.lut((0.0, 0.0), 1.0);
        // At the mean the weight is a + b = 1; four σ away it is ≈ a = 0.01.
        assert!(
            (weighted.lookup(50.0)[3] - plain.lookup(50.0)[3]).abs() < 1e-3 * plain.lookup(50.0)[3]
        );
        let far = -(1.0 - 0.5 * 0.01f32 - 0.5 * 0.99 * (-8.0f32).exp()).ln();
        assert!(
            (weighted.lookup(70.0)[3] - far).abs() < 1e-3,
            "{}",
            weighted.lookup(70.0)[3]
        );
    }

    #[test]
    fn evaluates_piecewise_linear_and_clamps() {
        let t = tf(&[[0.0, 0.0, 0.0, 0.0, 0.0], [10.0, 1.0, 0.5, 0.0, 1.0]]);
        assert_eq!(t.evaluate(-5.0), [0.0; 4]);
        assert_eq!(t.evaluate(5.0), [0.5, 0.25, 0.0, 0.5]);
        assert_eq!(t.evaluate(50.0), [1.0, 0.5, 0.0, 1.0]);
    }

    #[test]
    fn steps_take_the_later_point() {
        let t = tf(&[
            [0.0, 0.0, 0.0, 0.0, 0.0],
            [5.0, 0.0, 0.0, 0.0, 0.0],
            [5.0, 1.0, 1.0, 1.0, 1.0],
            [9.0, 1.0, 1.0, 1.0, 1.0],
        ]);
        assert_eq!(t.evaluate(4.999)[3], 0.0);
        assert_eq!(t.evaluate(5.0)[3], 1.0);
    }

    #[test]
    fn lut_converts_alpha_to_extinction() {
        let t = tf(&[[0.0, 1.0, 1.0, 1.0, 0.5], [100.0, 1.0, 1.0, 1.0, 0.5]]);
        let lut = t.lut((0.0, 100.0), 2.0);
        let k = lut.lookup(37.0)[3];
        // 1 − exp(−κ · 2 mm) = 0.5.
        assert!((1.0 - (-k * 2.0).exp() - 0.5).abs() < 1e-6, "{k}");
        assert!((lut.lookup(37.0)[0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn normalized_points_follow_the_data_range() {
        let t = TransferFunction::preset("mri-t1").unwrap();
        let a = t.lut((0.0, 1000.0), 1.0);
        let b = t.lut((0.0, 2000.0), 1.0);
        assert!((a.lookup(700.0)[3] - b.lookup(1400.0)[3]).abs() < 1e-5);
        assert_eq!(a.lookup(50.0)[3], 0.0);
    }

    #[test]
    fn empty_ranges_follow_the_opacity() {
        let lut = TransferFunction::preset("ct-bone")
            .unwrap()
            .lut((0.0, 0.0), 1.0);
        assert!(lut.range_is_empty(-1000.0, 40.0));
        assert!(!lut.range_is_empty(-1000.0, 1200.0));
        assert!(!lut.range_is_empty(200.0, 210.0));
        // Beyond the last point the function stays opaque.
        assert!(!lut.range_is_empty(5000.0, 6000.0));
        // Shifting moves the empty range.
        let shifted = TransferFunction::preset("ct-bone")
            .unwrap()
            .shifted(-200.0)
            .lut((0.0, 0.0), 1.0);
        assert!(!shifted.range_is_empty(-1000.0, 40.0));
    }

    /// A NaN value (from a NaN voxel, or a NaN shift) takes the first
    /// point's colour and table entry 0; it used to index point −1.
    #[test]
    fn nan_values_are_looked_up_safely() {
        let t = TransferFunction::preset("ct-bone").unwrap();
        assert_eq!(t.evaluate(f32::NAN), t.points[0].rgba);
        let lut = t.lut((0.0, 0.0), 1.0);
        assert_eq!(lut.lookup(f32::NAN), lut.entries[0]);
        let _ = lut.range_is_empty(f32::NAN, f32::NAN); // no panic
        let nan_shifted = t.shifted(f32::NAN);
        assert_eq!(nan_shifted.evaluate(100.0), nan_shifted.points[0].rgba);
        let lut = nan_shifted.lut((0.0, 0.0), 1.0);
        let _ = lut.lookup(100.0);
    }

    #[test]
    fn every_preset_exists() {
        for name in PRESETS {
            let t = TransferFunction::preset(name).unwrap();
            assert!(t.points.windows(2).all(|w| w[0].value <= w[1].value));
        }
        assert!(TransferFunction::preset("ct-nope").is_none());
    }
}
