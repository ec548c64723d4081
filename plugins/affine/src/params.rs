//! The plugin's parameters: the TOML of the scene's `[model.params]` table.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use voxflex_core::error::ModelError;

/// Which analytic field.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, JsonSchema, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum FieldKind {
    /// `x' = c + M (x − c) + t` with `matrix` (3 rows of 4: M | t, t in mm).
    Affine,
    /// Rotation about `axis` through `centre`, by an angle growing linearly
    /// along the axis: `angle_deg` over the volume's extent on that axis.
    Twist,
    /// Bend of the volume's `axis` towards `towards` (Barr 1984): the axis
    /// becomes a circular arc subtending `angle_deg` over the volume's extent.
    Bend,
}

/// A world axis.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, JsonSchema, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// x.
    X = 0,
    /// y.
    Y = 1,
    /// z.
    Z = 2,
}

/// Confines the field to a ball with a smooth (C²) fall-off:
/// `u(x) = w(|x − centre| / radius) · u_full(x)`, `w(r) = (1 − r²)³` for r < 1.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// Ball centre, world mm.
    #[schemars(extend("unit" = "mm"))]
    pub centre: [f64; 3],
    /// Ball radius, mm (> 0).
    #[schemars(extend("unit" = "mm"), range(min = 0))]
    pub radius: f64,
}

/// Parameters of the `affine` plugin (`[model.params]`).
#[derive(Clone, Debug, Deserialize, JsonSchema, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct AffineParams {
    /// The field.
    pub field: FieldKind,
    /// Axis of a twist or bend (default z).
    #[serde(default = "default_axis")]
    pub axis: Axis,
    /// Direction a bend bends towards (default x; must differ from `axis`).
    #[serde(default = "default_towards")]
    pub towards: Axis,
    /// Total twist or bend angle over the volume's extent, degrees.
    #[serde(default)]
    #[schemars(extend("unit" = "degrees"))]
    pub angle_deg: f64,
    /// Affine matrix rows `[m00, m01, m02, t0]`, … (t in mm), about `centre`.
    #[serde(default = "identity_rows")]
    pub matrix: [[f64; 4]; 3],
    /// Fixed point of the field, world mm (default: the volume centre).
    #[serde(default)]
    #[schemars(extend("unit" = "mm"))]
    pub centre: Option<[f64; 3]>,
    /// Frames over which the field ramps linearly from identity to full
    /// (default 1: full at the first frame). After that the field is still.
    #[serde(default = "default_ramp")]
    #[schemars(extend("unit" = "frames"), range(min = 1))]
    pub ramp_frames: u64,
    /// Optional ball the field is confined to.
    #[serde(default)]
    pub region: Option<Region>,
}

fn default_axis() -> Axis {
    Axis::Z
}
fn default_towards() -> Axis {
    Axis::X
}
fn default_ramp() -> u64 {
    1
}
fn identity_rows() -> [[f64; 4]; 3] {
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ]
}

impl AffineParams {
    /// Parses and validates `[model.params]`; errors name the key.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let p: AffineParams = toml::from_str(text)
            .map_err(|e| ModelError(format!("[model.params]: {}", e.message().trim())))?;
        p.validate()?;
        Ok(p)
    }

    fn validate(&self) -> Result<(), ModelError> {
        let bad = |key: &str, why: &str| Err(ModelError(format!("[model.params] {key}: {why}")));
        // The field is evaluated in f32 (both paths): a finite f64 beyond
        // ±3.4e38 would become ±∞ there, and NaN displacements after.
        let f32_finite = |v: &f64| v.is_finite() && (*v as f32).is_finite();
        let region = self.region.map(|r| r.centre.into_iter().chain([r.radius]));
        if let Some(key) = [
            ("angle_deg", vec![self.angle_deg]),
            ("matrix", self.matrix.iter().flatten().copied().collect()),
            ("centre", self.centre.map(Vec::from).unwrap_or_default()),
            ("region", region.map(Iterator::collect).unwrap_or_default()),
        ]
        .into_iter()
        .find(|(_, vs)| vs.iter().any(|v| v.is_finite() && !f32_finite(v)))
        .map(|(k, _)| k)
        {
            return bad(
                key,
                &format!(
                    "every value must lie within ±{:e} (the field is computed in f32)",
                    f32::MAX
                ),
            );
        }
        if !self.angle_deg.is_finite() {
            return bad("angle_deg", "must be a finite number of degrees");
        }
        if self.matrix.iter().flatten().any(|v| !v.is_finite()) {
            return bad("matrix", "every entry must be finite");
        }
        if self
            .centre
            .is_some_and(|c| c.iter().any(|v| !v.is_finite()))
        {
            return bad("centre", "must be three finite millimetre coordinates");
        }
        if self.ramp_frames == 0 {
            return bad("ramp_frames", "must be at least 1");
        }
        if let Some(r) = self.region
            && (r.radius.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
                || !r.radius.is_finite()
                || r.centre.iter().any(|v| !v.is_finite()))
        {
            return bad("region", "needs finite `centre` (mm) and `radius` > 0 (mm)");
        }
        if self.field == FieldKind::Bend && self.axis == self.towards {
            return bad(
                "towards",
                "a bend must bend towards an axis other than `axis`",
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_twist_with_defaults() {
        let p = AffineParams::from_toml("field = \"twist\"\nangle_deg = 30").unwrap();
        assert_eq!(p.field, FieldKind::Twist);
        assert_eq!(p.axis, Axis::Z);
        assert_eq!(p.ramp_frames, 1);
    }

    #[test]
    fn rejects_unknown_key_naming_it() {
        let e = AffineParams::from_toml("field = \"twist\"\nangel_deg = 30").unwrap_err();
        assert!(e.0.contains("angel_deg"), "{e}");
    }

    #[test]
    fn rejects_values_beyond_f32_naming_the_key() {
        for (text, key) in [
            ("field = \"twist\"\nangle_deg = 1e39", "angle_deg"),
            (
                "field = \"affine\"\nmatrix = [[1, 0, 0, 1e39], [0, 1, 0, 0], [0, 0, 1, 0]]",
                "matrix",
            ),
            ("field = \"twist\"\ncentre = [0, -1e39, 0]", "centre"),
            (
                "field = \"twist\"\nregion = { centre = [0, 0, 0], radius = 1e300 }",
                "region",
            ),
        ] {
            let e = AffineParams::from_toml(text).unwrap_err().0;
            assert!(e.contains(key) && e.contains("f32"), "{text}: {e}");
        }
    }

    #[test]
    fn rejects_nan_and_bad_region() {
        assert!(AffineParams::from_toml("field = \"twist\"\nangle_deg = nan").is_err());
        let e = AffineParams::from_toml(
            "field = \"twist\"\nregion = { centre = [0,0,0], radius = -1 }",
        )
        .unwrap_err();
        assert!(e.0.contains("region"), "{e}");
    }
}
