//! The renderer's parameters: the TOML of the scene's `[render]` params
//! table, also accepted (partially) by `Renderer::configure`.
//!
//! Every key is optional; defaults in brackets:
//!
//! ```toml
//! mode = "composite"              # "composite" (emission–absorption) | "mip"
//! sample_distance = 0.5           # ray step, in voxels of the smallest spacing
//! opacity_unit_distance = 1.0     # mm: TF alpha is the opacity of a slab this thick
//! early_termination = true        # stop a ray once its opacity reaches the threshold
//! termination_threshold = 0.998   # 1 − 0.5/255: the rest cannot change an 8-bit pixel
//! empty_space_skipping = true     # skip macro-cells the TF makes transparent
//! macro_cell = 8                  # macro-cell edge, voxels (2..=64)
//! opacity_map_interpolation = "trilinear"   # | "nearest"
//! sampling = "trilinear"          # | "tricubic" (cubic B-spline, 8 trilinear fetches)
//! gradient = "sobel"              # 3×3×3 Sobel | "central" — the shading normal
//! jitter = false                  # per-pixel ray-start offset in [0, step), fixed per pixel
//! background = [0, 0, 0, 1]       # sRGB (+ alpha) composited behind; absent = keep alpha
//! transfer_function = { preset = "ct-bone", shift = 0.0 }
//! # or: transfer_function = { points = [[value, r, g, b, a], …], shift = 0.0, normalized = false }
//! shading = { enabled = true, ambient = 0.1, diffuse = 0.9, specular = 0.2, shininess = 10.0 }
//! clip_planes = [{ point = [0, 0, 0], normal = [1, 0, 0] }]   # ≤ 6; keeps the side the normal points to
//! crop_box = { min = [-50, -50, -50], max = [50, 50, 50] }    # world mm; "none" = no crop box
//! ```
//!
//! `Renderer::configure` replaces only the keys its text gives and keeps
//! the others: `clip_planes = []` removes every clip plane and
//! `crop_box = "none"` the crop box (leaving the key out keeps them).

use crate::transfer::{ControlPoint, PRESETS, TransferFunction, ValueUnits};
use serde::Deserialize;
use voxflex_core::error::ModelError;

/// Most clip planes at once.
pub const MAX_CLIP_PLANES: usize = 6;

/// How the samples along a ray become a pixel.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum RenderMode {
    /// Emission–absorption, front to back (the default).
    #[default]
    Composite,
    /// Maximum intensity projection, then the transfer function.
    Mip,
}

/// How opacity maps are read between voxel centres.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum MapInterpolation {
    /// Trilinear interpolation of the voxel opacities (the default).
    #[default]
    Trilinear,
    /// The nearest voxel's opacity.
    Nearest,
}

/// How the volume is read between voxel centres (values, also for MIP).
#[derive(
    Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Sampling {
    /// Trilinear interpolation (the default).
    #[default]
    Trilinear,
    /// The cubic B-spline of the voxels (Sigg & Hadwiger's 8 trilinear
    /// fetches, [`crate::filters::tricubic`]): smooth, never overshoots,
    /// reproduces linear data; it approximates (slightly blurs) rather than
    /// interpolates.
    Tricubic,
}

/// How the shading normal (the gradient) is estimated.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum GradientFilter {
    /// Central differences of the trilinear field, ±1 voxel.
    Central,
    /// 3×3×3 Sobel ([`crate::filters::sobel`]): central difference along
    /// the axis, `[1, 2, 1] / 4` across it, trilinear between voxels (the
    /// default: the knee of the `render` front, docs/BENCHMARKS.md).
    #[default]
    Sobel,
}

/// Blinn–Phong shading with a headlight, on the gradient of the volume.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Shading {
    /// Shade composite samples (MIP is never shaded).
    pub enabled: bool,
    /// Ambient coefficient.
    pub ambient: f64,
    /// Diffuse coefficient.
    pub diffuse: f64,
    /// Specular coefficient (white highlight).
    pub specular: f64,
    /// Specular exponent.
    pub shininess: f64,
}

impl Default for Shading {
    fn default() -> Self {
        Self {
            enabled: true,
            ambient: 0.1,
            diffuse: 0.9,
            specular: 0.2,
            shininess: 10.0,
        }
    }
}

/// A half-space kept by clipping: points `x` with `normal · (x − point) ≥ 0`.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClipPlane {
    /// A point on the plane, world mm.
    pub point: [f64; 3],
    /// Normal pointing into the kept side (any non-zero length).
    pub normal: [f64; 3],
}

/// An axis-aligned box in world mm; only what is inside is drawn.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CropBox {
    /// Lower corner, world mm.
    pub min: [f64; 3],
    /// Upper corner, world mm.
    pub max: [f64; 3],
}

/// The `transfer_function` table as written: a preset or points.
#[derive(Clone, Debug, Default, Deserialize, serde::Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TransferFunctionSpec {
    /// A built-in preset name (`ct-bone`, `ct-soft-tissue`, `ct-lung`, `mri-t1`).
    pub preset: Option<String>,
    /// Control points `[value, r, g, b, a]` (sRGB colour, alpha per
    /// `opacity_unit_distance`), values non-decreasing.
    pub points: Option<Vec<Vec<f64>>>,
    /// Offset added to every point's value, in the points' units.
    #[serde(default)]
    pub shift: f64,
    /// `points` values are fractions of the volume's value range (0 = min,
    /// 1 = max) instead of data units. Presets carry their own units.
    pub normalized: Option<bool>,
    /// The automatic Gaussian transfer function of the opacity-map paper
    /// (`f(x) = t(x)·(a + b·g(x))`); the host fills it from a `[[roi]]` with
    /// `gaussian_tf = true`.
    pub gaussian: Option<GaussianSpec>,
}

/// `transfer_function.gaussian`: `g` is a Gaussian at `mean` with `sigma`
/// (data units); `a` (default 0.01) and `b` (default 0.99) as in the paper.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GaussianSpec {
    /// Centre of the Gaussian (the seed's mean `d_s`), data units.
    pub mean: f64,
    /// Its standard deviation (the seed's σ_s), data units, > 0.
    pub sigma: f64,
    /// Floor of the weight.
    #[serde(default = "gaussian_a")]
    pub a: f64,
    /// Gain of the Gaussian.
    #[serde(default = "gaussian_b")]
    pub b: f64,
}

fn gaussian_a() -> f64 {
    0.01
}
fn gaussian_b() -> f64 {
    0.99
}

/// Parameters of the `raycast` renderer (see the module docs for the TOML).
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RaycastParams {
    /// Composite or MIP.
    pub mode: RenderMode,
    /// Ray step in voxels of the smallest spacing (> 0).
    #[schemars(extend("unit" = "voxels"), range(min = 0))]
    pub sample_distance: f64,
    /// Thickness (mm) of the slab whose opacity the TF alpha gives (> 0).
    #[schemars(extend("unit" = "mm"), range(min = 0))]
    pub opacity_unit_distance: f64,
    /// Stop rays whose accumulated opacity reaches `termination_threshold`.
    pub early_termination: bool,
    /// Opacity at which a ray stops, in (0, 1].
    #[schemars(range(min = 0, max = 1))]
    pub termination_threshold: f64,
    /// Skip macro-cells whose value range the TF maps to zero opacity.
    pub empty_space_skipping: bool,
    /// Edge of a macro-cell, voxels (2..=64).
    #[schemars(extend("unit" = "voxels"), range(min = 2, max = 64))]
    pub macro_cell: u32,
    /// Opacity-map interpolation.
    pub opacity_map_interpolation: MapInterpolation,
    /// Volume sampling between voxel centres.
    pub sampling: Sampling,
    /// Gradient (shading normal) estimate.
    pub gradient: GradientFilter,
    /// Offset each pixel's first sample by a fraction in `[0, 1)` of a step
    /// ([`crate::filters::jitter`]; fixed per pixel, so frames do not
    /// flicker): turns the rings of step aliasing into fine noise.
    pub jitter: bool,
    /// Background sRGB colour (3 values, alpha 1) or sRGB + alpha (4 values)
    /// composited behind the volume; `None` keeps the image's alpha.
    pub background: Option<Vec<f64>>,
    /// Transfer function (default: the `ct-bone` preset).
    pub transfer_function: TransferFunctionSpec,
    /// Gradient shading.
    pub shading: Shading,
    /// Clip planes (≤ [`MAX_CLIP_PLANES`]); `[]`, the default, for none.
    pub clip_planes: Vec<ClipPlane>,
    /// Crop box, world mm, or `"none"` for no crop box (the default).
    /// `configure` keeps a key its text leaves out, so `"none"` is how it
    /// removes a crop box.
    #[serde(deserialize_with = "crop_box_or_none")]
    #[schemars(schema_with = "crop_box_schema")]
    pub crop_box: Option<CropBox>,
}

/// The word `crop_box` takes for "no crop box".
pub const NO_CROP_BOX: &str = "none";

/// `crop_box`: a table `{ min, max }`, or [`NO_CROP_BOX`] for none; any
/// other value is refused, naming both forms.
fn crop_box_or_none<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<CropBox>, D::Error> {
    struct CropBoxOrNone;
    impl<'de> serde::de::Visitor<'de> for CropBoxOrNone {
        type Value = Option<CropBox>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            write!(
                f,
                "a crop box {{ min = [x, y, z], max = [x, y, z] }} (world mm), \
                 or \"{NO_CROP_BOX}\" for no crop box"
            )
        }
        fn visit_str<E: serde::de::Error>(self, s: &str) -> Result<Self::Value, E> {
            if s == NO_CROP_BOX {
                Ok(None)
            } else {
                Err(E::invalid_value(serde::de::Unexpected::Str(s), &self))
            }
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
            CropBox::deserialize(serde::de::value::MapAccessDeserializer::new(map)).map(Some)
        }
    }
    d.deserialize_any(CropBoxOrNone)
}

/// The schema of `crop_box`: the [`CropBox`] table or the string
/// [`NO_CROP_BOX`] (absent: none).
fn crop_box_schema(g: &mut schemars::SchemaGenerator) -> schemars::Schema {
    let table = g.subschema_for::<CropBox>();
    schemars::json_schema!({
        "anyOf": [table, { "type": "string", "const": NO_CROP_BOX }, { "type": "null" }]
    })
}

impl Default for RaycastParams {
    fn default() -> Self {
        Self {
            mode: RenderMode::Composite,
            sample_distance: 0.5,
            opacity_unit_distance: 1.0,
            early_termination: true,
            termination_threshold: 0.998,
            empty_space_skipping: true,
            macro_cell: 8,
            opacity_map_interpolation: MapInterpolation::Trilinear,
            sampling: Sampling::Trilinear,
            gradient: GradientFilter::Sobel,
            jitter: false,
            background: None,
            transfer_function: TransferFunctionSpec::default(),
            shading: Shading::default(),
            clip_planes: Vec::new(),
            crop_box: None,
        }
    }
}

fn bad<T>(key: &str, why: impl std::fmt::Display) -> Result<T, ModelError> {
    Err(ModelError(format!("[render] {key}: {why}")))
}

/// A toml parse error as one line naming the offending line of the text.
fn toml_error(text: &str, e: &toml::de::Error) -> ModelError {
    voxflex_core::error::toml_table_error("[render]", text, e)
}

/// `v` is finite **as the f32 the renderer computes with**: a finite f64
/// beyond ±3.4e38 becomes ±∞ when narrowed, and NaN after arithmetic.
fn finite(key: &str, v: f64) -> Result<(), ModelError> {
    if v.is_finite() && (v as f32).is_finite() {
        Ok(())
    } else {
        bad(
            key,
            format!(
                "must be a finite number within ±{:e} (the renderer computes in f32; got {v})",
                f32::MAX
            ),
        )
    }
}

impl RaycastParams {
    /// Parses and validates the TOML text; errors name the key.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let p: RaycastParams = toml::from_str(text).map_err(|e| toml_error(text, &e))?;
        p.validate()?;
        Ok(p)
    }

    /// `self` with the top-level keys present in `text` replaced (nested
    /// tables such as `shading` are replaced whole). Validates the result.
    pub fn merged(&self, text: &str) -> Result<Self, ModelError> {
        // The partial text alone must be valid (every key has a default), which
        // also gives errors that point at its lines.
        Self::from_toml(text)?;
        let update: toml::Table = toml::from_str(text).map_err(|e| toml_error(text, &e))?;
        let mut base = toml::Table::try_from(self.clone())
            .map_err(|e| ModelError(format!("[render]: cannot re-encode settings: {e}")))?;
        for (k, v) in update {
            base.insert(k, v);
        }
        let p: RaycastParams = toml::Value::Table(base)
            .try_into()
            .map_err(|e: toml::de::Error| ModelError(format!("[render]: {}", e.message())))?;
        p.validate()?;
        Ok(p)
    }

    /// Checks ranges, finiteness and the transfer function.
    pub fn validate(&self) -> Result<(), ModelError> {
        finite("sample_distance", self.sample_distance)?;
        if self.sample_distance <= 0.0 {
            return bad("sample_distance", "must be > 0 (voxels)");
        }
        finite("opacity_unit_distance", self.opacity_unit_distance)?;
        if self.opacity_unit_distance <= 0.0 {
            return bad("opacity_unit_distance", "must be > 0 (mm)");
        }
        finite("termination_threshold", self.termination_threshold)?;
        if !(self.termination_threshold > 0.0 && self.termination_threshold <= 1.0) {
            return bad("termination_threshold", "must be in (0, 1]");
        }
        if !(2..=64).contains(&self.macro_cell) {
            return bad("macro_cell", "must be 2..=64 voxels");
        }
        if let Some(bg) = &self.background {
            if bg.len() != 3 && bg.len() != 4 {
                return bad("background", "give [r, g, b] or [r, g, b, a] (sRGB, 0–1)");
            }
            for (c, v) in bg.iter().enumerate() {
                finite(&format!("background[{c}]"), *v)?;
                if !(0.0..=1.0).contains(v) {
                    return bad(&format!("background[{c}]"), "must be in [0, 1]");
                }
            }
        }
        let s = &self.shading;
        for (key, v) in [
            ("shading.ambient", s.ambient),
            ("shading.diffuse", s.diffuse),
            ("shading.specular", s.specular),
            ("shading.shininess", s.shininess),
        ] {
            finite(key, v)?;
            if v < 0.0 {
                return bad(key, "must be ≥ 0");
            }
        }
        if self.clip_planes.len() > MAX_CLIP_PLANES {
            return bad(
                "clip_planes",
                format!(
                    "at most {MAX_CLIP_PLANES} planes (got {})",
                    self.clip_planes.len()
                ),
            );
        }
        for (n, p) in self.clip_planes.iter().enumerate() {
            for (c, v) in p.point.iter().chain(&p.normal).enumerate() {
                let field = if c < 3 { "point" } else { "normal" };
                finite(&format!("clip_planes[{n}].{field}"), *v)?;
            }
            let len2: f64 = p.normal.iter().map(|v| v * v).sum();
            if len2 <= 1e-24 {
                return bad(&format!("clip_planes[{n}].normal"), "must not be zero");
            }
        }
        if let Some(b) = &self.crop_box {
            for (c, v) in b.min.iter().chain(&b.max).enumerate() {
                let field = if c < 3 { "min" } else { "max" };
                finite(&format!("crop_box.{field}"), *v)?;
            }
            if (0..3).any(|a| b.min[a] > b.max[a]) {
                return bad("crop_box", "min must be ≤ max on every axis");
            }
        }
        self.transfer_function()?;
        Ok(())
    }

    /// The transfer function the parameters describe (preset or points,
    /// shifted), validated.
    pub fn transfer_function(&self) -> Result<TransferFunction, ModelError> {
        let spec = &self.transfer_function;
        finite("transfer_function.shift", spec.shift)?;
        let tf = match (&spec.preset, &spec.points) {
            (Some(_), Some(_)) => {
                return bad(
                    "transfer_function",
                    "give either `preset` or `points`, not both",
                );
            }
            (Some(name), None) => {
                if spec.normalized.is_some() {
                    return bad(
                        "transfer_function.normalized",
                        "applies to `points` only; presets carry their own units",
                    );
                }
                TransferFunction::preset(name).ok_or_else(|| {
                    ModelError(format!(
                        "[render] transfer_function.preset: unknown preset `{name}`; built-in presets: {}",
                        PRESETS.join(", ")
                    ))
                })?
            }
            (None, None) => TransferFunction::preset("ct-bone").expect("built-in preset"),
            (None, Some(points)) => {
                if points.is_empty() {
                    return bad("transfer_function.points", "needs at least one point");
                }
                let mut out = Vec::with_capacity(points.len());
                for (n, p) in points.iter().enumerate() {
                    let key = format!("transfer_function.points[{n}]");
                    if p.len() != 5 {
                        return bad(
                            &key,
                            format!("needs 5 numbers [value, r, g, b, a], got {}", p.len()),
                        );
                    }
                    for v in p {
                        finite(&key, *v)?;
                    }
                    if p[1..].iter().any(|v| !(0.0..=1.0).contains(v)) {
                        return bad(&key, "colour and alpha must be in [0, 1]");
                    }
                    if let Some(prev) = out.last().map(|c: &ControlPoint| c.value)
                        && (p[0] as f32) < prev
                    {
                        return bad(
                            &key,
                            format!("values must be non-decreasing, but {} follows {prev}", p[0]),
                        );
                    }
                    out.push(ControlPoint {
                        value: p[0] as f32,
                        rgba: [p[1] as f32, p[2] as f32, p[3] as f32, p[4] as f32],
                    });
                }
                TransferFunction {
                    points: out,
                    units: if spec.normalized.unwrap_or(false) {
                        ValueUnits::Normalized
                    } else {
                        ValueUnits::Data
                    },
                    gaussian: None,
                }
            }
        };
        let mut tf = tf.shifted(spec.shift as f32);
        // Validated after narrowing and shifting: the lookup table spans
        // the points' values in f32.
        if let (Some(a), Some(b)) = (tf.points.first(), tf.points.last())
            && !(a.value.is_finite() && b.value.is_finite() && (b.value - a.value).is_finite())
        {
            return bad(
                "transfer_function.shift",
                format!(
                    "moves the points to [{}, {}], beyond what f32 holds; use a smaller shift",
                    a.value, b.value
                ),
            );
        }
        if let Some(g) = spec.gaussian {
            for (key, v) in [("mean", g.mean), ("sigma", g.sigma), ("a", g.a), ("b", g.b)] {
                finite(&format!("transfer_function.gaussian.{key}"), v)?;
            }
            if g.sigma <= 0.0 || g.a < 0.0 || g.b < 0.0 {
                return bad("transfer_function.gaussian", "needs sigma > 0 and a, b ≥ 0");
            }
            tf.gaussian = Some(voxflex_opacity::GaussianTf {
                mean: g.mean as f32,
                sigma: g.sigma as f32,
                a: g.a as f32,
                b: g.b as f32,
            });
        }
        Ok(tf)
    }

    /// The background as linear premultiplied RGBA, if any.
    pub fn background_linear(&self) -> Option<[f32; 4]> {
        self.background.as_ref().map(|bg| {
            let a = bg.get(3).copied().unwrap_or(1.0) as f32;
            let c = |i: usize| crate::color::srgb_to_linear(bg[i] as f32) * a;
            [c(0), c(1), c(2), a]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        RaycastParams::from_toml(text).unwrap_err().0
    }

    #[test]
    fn defaults_parse() {
        let p = RaycastParams::from_toml("").unwrap();
        assert_eq!(p, RaycastParams::default());
        assert_eq!(
            p.transfer_function().unwrap(),
            TransferFunction::preset("ct-bone").unwrap()
        );
    }

    #[test]
    fn full_example_parses() {
        let p = RaycastParams::from_toml(
            r#"
            mode = "mip"
            sample_distance = 0.25
            background = [0.1, 0.2, 0.3]
            transfer_function = { points = [[0, 0, 0, 0, 0], [100, 1, 1, 1, 0.5]], shift = 10 }
            shading = { enabled = false }
            clip_planes = [{ point = [0, 0, 0], normal = [1, 0, 0] }]
            crop_box = { min = [-1, -2, -3], max = [1, 2, 3] }
            opacity_map_interpolation = "nearest"
            "#,
        )
        .unwrap();
        assert_eq!(p.mode, RenderMode::Mip);
        assert!(!p.shading.enabled);
        assert_eq!(p.shading.ambient, 0.1);
        assert_eq!(p.transfer_function().unwrap().points[1].value, 110.0);
        assert_eq!(p.background_linear().unwrap()[3], 1.0);
    }

    #[test]
    fn unknown_keys_are_named() {
        assert!(err("sample_distanse = 1").contains("sample_distanse"));
        assert!(err("shading = { ambiant = 0.1 }").contains("ambiant"));
        assert!(err("transfer_function = { preset = \"ct-bone\", shfit = 2 }").contains("shfit"));
    }

    #[test]
    fn nan_and_ranges_are_named() {
        assert!(err("sample_distance = nan").contains("sample_distance"));
        assert!(err("sample_distance = -1").contains("sample_distance"));
        assert!(err("termination_threshold = 1.5").contains("termination_threshold"));
        assert!(err("shading = { specular = nan }").contains("shading.specular"));
        assert!(err("crop_box = { min = [0, 0, nan], max = [1, 1, 1] }").contains("crop_box.min"));
        assert!(
            err("clip_planes = [{ point = [0, 0, 0], normal = [0, 0, 0] }]")
                .contains("clip_planes[0].normal")
        );
        assert!(err("transfer_function = { preset = \"ct-bone\", shift = inf }").contains("shift"));
        // Finite as f64, infinite as the f32 the renderer uses.
        for text in [
            "transfer_function = { preset = \"ct-bone\", shift = 1e39 }",
            "transfer_function = { preset = \"ct-bone\", shift = -1e39 }",
            "transfer_function = { points = [[-3e38, 0, 0, 0, 0], [3e38, 1, 1, 1, 1]] }",
        ] {
            assert!(err(text).contains("transfer_function"), "{text}");
        }
        for key in [
            "sample_distance = 1e39",
            "opacity_unit_distance = 1e300",
            "shading = { shininess = 1e39 }",
            "clip_planes = [{ point = [1e39, 0, 0], normal = [1, 0, 0] }]",
            "crop_box = { min = [-1e39, 0, 0], max = [0, 1, 1] }",
            "transfer_function = { preset = \"ct-bone\", gaussian = { mean = 1e39, sigma = 1, a = 0, b = 1 } }",
        ] {
            assert!(err(key).contains("f32"), "{key}: {}", err(key));
        }
        assert!(err("background = [1, 1]").contains("background"));
        assert!(err("macro_cell = 1").contains("macro_cell"));
        // A type error points at its line.
        assert!(err("mode = \"composite\"\nsample_distance = \"x\"").contains("sample_distance"));
    }

    #[test]
    fn transfer_function_errors_are_named() {
        let e = err(
            "transfer_function = { points = [[0, 0, 0, 0, 0], [10, 1, 1, 1, 1], [5, 1, 1, 1, 1]] }",
        );
        assert!(
            e.contains("transfer_function.points[2]") && e.contains("non-decreasing"),
            "{e}"
        );
        let e = err("transfer_function = { points = [[0, 0, 0, 0, nan]] }");
        assert!(e.contains("transfer_function.points[0]"), "{e}");
        let e = err("transfer_function = { points = [[0, 0, 0, 2, 0]] }");
        assert!(e.contains("[0, 1]"), "{e}");
        let e = err("transfer_function = { preset = \"ct-boen\" }");
        assert!(
            e.contains("transfer_function.preset") && e.contains("ct-boen"),
            "{e}"
        );
        let e = err("transfer_function = { preset = \"ct-bone\", points = [[0, 0, 0, 0, 0]] }");
        assert!(e.contains("either"), "{e}");
        let e = err("transfer_function = { points = [[0, 0, 0, 0]] }");
        assert!(e.contains("5 numbers"), "{e}");
    }

    #[test]
    fn filters_parse_and_bad_values_name_the_key() {
        let p = RaycastParams::from_toml(
            "sampling = \"tricubic\"\ngradient = \"sobel\"\njitter = true",
        )
        .unwrap();
        assert_eq!(
            (p.sampling, p.gradient, p.jitter),
            (Sampling::Tricubic, GradientFilter::Sobel, true)
        );
        let e = err("gradient = \"sobol\"");
        assert!(
            e.contains("gradient") && e.contains("sobel") && e.contains("central"),
            "{e}"
        );
        let e = err("sampling = \"cubic\"");
        assert!(e.contains("sampling") && e.contains("tricubic"), "{e}");
        let e = err("jitter = 1");
        assert!(e.contains("jitter"), "{e}");
    }

    #[test]
    fn merged_replaces_only_given_keys() {
        let p = RaycastParams::from_toml("sample_distance = 0.25\nmode = \"mip\"").unwrap();
        let q = p.merged("shading = { enabled = false }").unwrap();
        assert_eq!(q.sample_distance, 0.25);
        assert_eq!(q.mode, RenderMode::Mip);
        assert!(!q.shading.enabled);
        assert!(p.merged("sample_distance = 0").is_err());
    }

    #[test]
    fn merged_with_the_explicit_off_clears_a_crop_and_clip_planes() {
        let p = RaycastParams::from_toml(
            "crop_box = { min = [-1, -2, -3], max = [1, 2, 3] }\n\
             clip_planes = [{ point = [0, 0, 0], normal = [1, 0, 0] }]",
        )
        .unwrap();
        assert!(p.crop_box.is_some() && p.clip_planes.len() == 1);
        // Left out, both are kept (a partial `configure`)…
        let kept = p.merged("mode = \"mip\"").unwrap();
        assert_eq!(
            (kept.crop_box, &kept.clip_planes),
            (p.crop_box, &p.clip_planes)
        );
        // …and the explicit off removes them.
        let off = p.merged("crop_box = \"none\"\nclip_planes = []").unwrap();
        assert_eq!(off.crop_box, None);
        assert!(off.clip_planes.is_empty());
        assert_eq!(
            off,
            RaycastParams::default(),
            "as if never cropped nor clipped"
        );
        // Each on its own, the other kept.
        let q = p.merged("crop_box = \"none\"").unwrap();
        assert_eq!((q.crop_box, q.clip_planes.len()), (None, 1));
        let q = p.merged("clip_planes = []").unwrap();
        assert_eq!((q.crop_box, q.clip_planes.len()), (p.crop_box, 0));
        // A new box after "none" crops again.
        let again = off
            .merged("crop_box = { min = [0, 0, 0], max = [5, 5, 5] }")
            .unwrap();
        assert_eq!(again.crop_box.unwrap().max, [5.0, 5.0, 5.0]);
        // "none" in a whole table is the default.
        assert_eq!(
            RaycastParams::from_toml("crop_box = \"none\"").unwrap(),
            RaycastParams::default()
        );
    }

    #[test]
    fn a_crop_box_that_is_neither_a_table_nor_none_is_refused() {
        for text in [
            "crop_box = \"off\"",
            "crop_box = \"None\"",
            "crop_box = false",
            "crop_box = true",
            "crop_box = 0",
            "crop_box = []",
        ] {
            let e = err(text);
            assert!(
                e.contains("crop_box") && e.contains("\"none\"") && e.contains("min = [x, y, z]"),
                "{text}: {e}"
            );
        }
        let e = err("mode = \"mip\"\ncrop_box = \"off\"");
        assert!(e.contains("line 2") && e.contains("\"off\""), "{e}");
        // A table still names its own bad keys and values.
        assert!(err("crop_box = { min = [0, 0, 0] }").contains("max"));
        assert!(err("crop_box = { min = [0, 0, 0], max = [1, 1, 1], mid = 0 }").contains("mid"));
        assert!(err("crop_box = { min = [2, 0, 0], max = [1, 1, 1] }").contains("min must be"));
        // `configure`'s merge refuses it as well.
        let p =
            RaycastParams::from_toml("crop_box = { min = [0, 0, 0], max = [1, 1, 1] }").unwrap();
        assert!(p.merged("crop_box = false").is_err());
    }

    #[test]
    fn the_schema_the_host_reads_takes_a_table_or_none_for_the_crop_box() {
        use voxflex_runtime::param_schema::ParamSchema;
        let json = voxflex_abi::params_schema::json(&schemars::schema_for!(RaycastParams)).unwrap();
        let schema = ParamSchema::from_json(&json).unwrap();
        let spec = schema.get("crop_box").unwrap();
        assert!(!spec.required);
        assert_eq!(spec.kind.to_string(), "\"none\" | table", "{spec:?}");
        assert!(spec.doc.contains("\"none\""), "{}", spec.doc);
        let check = |text: &str| schema.check(&text.parse().unwrap());
        assert_eq!(
            check("crop_box = \"none\"\nclip_planes = []"),
            Vec::<String>::new()
        );
        assert_eq!(
            check("crop_box = { min = [0, 0, 0], max = [1, 1, 1] }"),
            Vec::<String>::new()
        );
        let issues = check("crop_box = \"off\"");
        assert!(
            issues.len() == 1 && issues[0].contains("crop_box") && issues[0].contains("\"none\""),
            "{issues:?}"
        );
        assert_eq!(check("crop_box = true").len(), 1);
    }
}
