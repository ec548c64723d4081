//! What the *Rendering* panel sets on the renderer — the transfer
//! function (a preset or control points), composite or MIP, shading on or
//! off, one clip plane per axis and a crop box — read from and written
//! back to the renderer's `[render.params]` TOML table (the keys of the
//! `raycast` plugin: `mode`, `shading.enabled`, `transfer_function`,
//! `clip_planes`, `crop_box`). Every other key of the opened scene's table
//! (background, sampling, …) is kept as it was.
//!
//! The plugin's `configure` keeps a key its text leaves out, so no clip
//! plane and no crop box are written out as such (`clip_planes = []`,
//! `crop_box = "none"`): left out, the last ones sent would stay.

use crate::tf_points::{TfPoint, TfPoints};
use voxflex_core::glam::DVec3;

/// Where the transfer function comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum TfSource {
    /// A preset of the renderer plugin, by name.
    Preset(String),
    /// The editor's own control points (volume units).
    Points(TfPoints),
}

/// A clip plane perpendicular to one world axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisClip {
    /// Clip along this axis.
    pub enabled: bool,
    /// Keep the side towards −axis (default: the +axis side).
    pub keep_below: bool,
    /// Where the plane crosses the axis, world mm.
    pub at_mm: f64,
}

/// The crop box, world mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crop {
    /// Crop at all.
    pub enabled: bool,
    /// Lower corner, world mm.
    pub min: [f64; 3],
    /// Upper corner, world mm.
    pub max: [f64; 3],
}

/// The renderer settings the panel edits.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Maximum intensity projection instead of composite.
    pub mip: bool,
    /// Gradient shading (composite only).
    pub shading: bool,
    /// The transfer function.
    pub tf: TfSource,
    /// One plane per world axis (x, y, z).
    pub clips: [AxisClip; 3],
    /// The crop box.
    pub crop: Crop,
}

/// The preset the raycast plugin uses when the table names none.
const DEFAULT_PRESET: &str = "ct-bone";

/// The raycast plugin's `crop_box` value for "no crop box".
const NO_CROP_BOX: &str = "none";

fn mm3(v: Option<&toml::Value>) -> Option<[f64; 3]> {
    let a = v?.as_array()?;
    let f = |i: usize| {
        a.get(i)
            .and_then(|x| x.as_float().or(x.as_integer().map(|n| n as f64)))
    };
    Some([f(0)?, f(1)?, f(2)?])
}

fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or(v.as_integer().map(|n| n as f64))
}

impl RenderOptions {
    /// The options `params` (a `[render.params]` table) sets, for a volume
    /// spanning `bounds` (world mm, lower and upper corner) with values in
    /// `range`. Points given as fractions (`normalized = true`) become
    /// values of `range`, and `shift` is folded into the values. Clip
    /// planes that are not perpendicular to an axis are not shown (and
    /// dropped on the next change).
    pub fn from_params(params: &toml::Table, bounds: (DVec3, DVec3), range: (f64, f64)) -> Self {
        let (lo, hi) = bounds;
        let centre = (lo + hi) * 0.5;
        let mut clips = [0, 1, 2].map(|a| AxisClip {
            enabled: false,
            keep_below: false,
            at_mm: centre[a],
        });
        for plane in params
            .get("clip_planes")
            .and_then(|v| v.as_array())
            .into_iter()
            .flatten()
            .filter_map(|v| v.as_table())
        {
            let (Some(p), Some(n)) = (mm3(plane.get("point")), mm3(plane.get("normal"))) else {
                continue;
            };
            let nonzero: Vec<usize> = (0..3).filter(|&a| n[a] != 0.0).collect();
            if let [a] = nonzero[..] {
                clips[a] = AxisClip {
                    enabled: true,
                    keep_below: n[a] < 0.0,
                    at_mm: p[a],
                };
            }
        }
        let crop_table = params.get("crop_box").and_then(|v| v.as_table());
        let crop = Crop {
            enabled: crop_table.is_some(),
            min: crop_table
                .and_then(|t| mm3(t.get("min")))
                .unwrap_or(lo.to_array()),
            max: crop_table
                .and_then(|t| mm3(t.get("max")))
                .unwrap_or(hi.to_array()),
        };
        Self {
            mip: params.get("mode").and_then(|v| v.as_str()) == Some("mip"),
            shading: params
                .get("shading")
                .and_then(|v| v.get("enabled"))
                .and_then(|v| v.as_bool())
                .unwrap_or(true),
            tf: tf_source(params.get("transfer_function"), range),
            clips,
            crop,
        }
    }

    /// `base` (the opened `[render.params]` table) with this panel's keys
    /// set, as TOML text for `Renderer::configure` and the saved scene.
    /// A transfer function's other keys (`gaussian`) are kept.
    pub fn params_table(&self, base: &toml::Table) -> toml::Table {
        let mut t = base.clone();
        t.insert(
            "mode".into(),
            if self.mip { "mip" } else { "composite" }.into(),
        );
        let mut shading = base
            .get("shading")
            .and_then(|v| v.as_table())
            .cloned()
            .unwrap_or_default();
        shading.insert("enabled".into(), self.shading.into());
        t.insert("shading".into(), shading.into());
        let mut tf = base
            .get("transfer_function")
            .and_then(|v| v.as_table())
            .cloned()
            .unwrap_or_default();
        for key in ["preset", "points", "normalized"] {
            tf.remove(key);
        }
        match &self.tf {
            // A preset keeps the opened table's `shift`.
            TfSource::Preset(name) => {
                tf.insert("preset".into(), name.clone().into());
            }
            TfSource::Points(p) => {
                // Folded into the points' values by `from_params`.
                tf.remove("shift");
                let rows: Vec<toml::Value> = p
                    .points()
                    .iter()
                    .map(|q| toml::Value::from(q.row().to_vec()))
                    .collect();
                tf.insert("points".into(), rows.into());
            }
        }
        t.insert("transfer_function".into(), tf.into());
        // Written even when off: a reconfigure without the keys would keep
        // the planes and box last sent.
        let planes: Vec<toml::Value> = (0..3)
            .filter(|&a| self.clips[a].enabled)
            .map(|a| plane_table(a, &self.clips[a]).into())
            .collect();
        t.insert("clip_planes".into(), planes.into());
        let crop_box = if self.crop.enabled {
            let mut b = toml::Table::new();
            let (min, max) = self.crop_corners();
            b.insert("min".into(), vec3(min));
            b.insert("max".into(), vec3(max));
            b.into()
        } else {
            NO_CROP_BOX.into()
        };
        t.insert("crop_box".into(), crop_box);
        t
    }

    /// [`Self::params_table`] as TOML text.
    pub fn params_toml(&self, base: &toml::Table) -> String {
        toml::to_string(&self.params_table(base)).unwrap_or_default()
    }

    /// The crop box's corners with each axis ordered (min ≤ max), as the
    /// plugin requires.
    pub fn crop_corners(&self) -> ([f64; 3], [f64; 3]) {
        let (a, b) = (self.crop.min, self.crop.max);
        (
            [0, 1, 2].map(|i| a[i].min(b[i])),
            [0, 1, 2].map(|i| a[i].max(b[i])),
        )
    }
}

fn vec3(v: [f64; 3]) -> toml::Value {
    v.iter()
        .map(|&x| toml::Value::from(x))
        .collect::<Vec<_>>()
        .into()
}

/// The `clip_planes` entry of the plane across axis `a`.
fn plane_table(a: usize, c: &AxisClip) -> toml::Table {
    let mut point = [0.0; 3];
    point[a] = c.at_mm;
    let mut normal = [0.0; 3];
    normal[a] = if c.keep_below { -1.0 } else { 1.0 };
    let mut t = toml::Table::new();
    t.insert("point".into(), vec3(point));
    t.insert("normal".into(), vec3(normal));
    t
}

/// The transfer function a `transfer_function` table gives (absent: the
/// plugin's default preset).
fn tf_source(tf: Option<&toml::Value>, range: (f64, f64)) -> TfSource {
    let Some(t) = tf.and_then(|v| v.as_table()) else {
        return TfSource::Preset(DEFAULT_PRESET.into());
    };
    let shift = t.get("shift").and_then(number).unwrap_or(0.0);
    if let Some(rows) = t.get("points").and_then(|v| v.as_array()) {
        let normalized = t.get("normalized").and_then(|v| v.as_bool()) == Some(true);
        let points: Option<Vec<TfPoint>> = rows
            .iter()
            .map(|r| {
                let row: Vec<f64> = r.as_array()?.iter().filter_map(number).collect();
                let mut p = TfPoint::from_row(&row)?;
                let v = p.value + shift;
                p.value = if normalized {
                    range.0 + v * (range.1 - range.0)
                } else {
                    v
                };
                Some(p)
            })
            .collect();
        if let Some(p) = points.filter(|p| !p.is_empty()) {
            return TfSource::Points(TfPoints::new(p));
        }
    }
    let name = t
        .get("preset")
        .and_then(|v| v.as_str())
        .unwrap_or(DEFAULT_PRESET);
    TfSource::Preset(name.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bounds() -> (DVec3, DVec3) {
        (DVec3::splat(-100.0), DVec3::splat(100.0))
    }

    fn table(text: &str) -> toml::Table {
        text.parse().unwrap()
    }

    #[test]
    fn a_scenes_table_is_read_and_written_back_with_its_other_keys() {
        let base = table(
            r#"
            background = [0, 0, 0]
            mode = "mip"
            transfer_function = { preset = "ct-soft-tissue", gaussian = { mean = 40, sigma = 10 } }
            shading = { enabled = false, ambient = 0.3 }
            clip_planes = [{ point = [5, 0, 0], normal = [-2, 0, 0] }, { point = [0, 0, 0], normal = [1, 1, 0] }]
            crop_box = { min = [-50, -40, -30], max = [50, 40, 30] }
            "#,
        );
        let o = RenderOptions::from_params(&base, bounds(), (-1000.0, 2000.0));
        assert!(o.mip && !o.shading);
        assert_eq!(o.tf, TfSource::Preset("ct-soft-tissue".into()));
        assert_eq!(
            o.clips[0],
            AxisClip {
                enabled: true,
                keep_below: true,
                at_mm: 5.0
            }
        );
        assert!(!o.clips[1].enabled, "an oblique plane is not shown");
        assert!(o.crop.enabled && o.crop.min == [-50.0, -40.0, -30.0]);
        let out = table(&o.params_toml(&base));
        assert_eq!(out["background"], base["background"]);
        assert_eq!(out["mode"].as_str(), Some("mip"));
        assert_eq!(out["shading"]["ambient"].as_float(), Some(0.3));
        assert_eq!(
            out["transfer_function"]["gaussian"],
            base["transfer_function"]["gaussian"]
        );
        assert_eq!(out["clip_planes"].as_array().unwrap().len(), 1);
        // What it writes reads back as the same options.
        assert_eq!(
            RenderOptions::from_params(&out, bounds(), (-1000.0, 2000.0)),
            o
        );
    }

    #[test]
    fn points_shift_and_normalized_values_become_volume_values() {
        let base = table(
            "transfer_function = { points = [[0, 0, 0, 0, 0], [0.5, 1, 1, 1, 0.5]], normalized = true, shift = 0.25 }",
        );
        let o = RenderOptions::from_params(&base, bounds(), (-1000.0, 1000.0));
        let TfSource::Points(p) = &o.tf else {
            panic!("{:?}", o.tf)
        };
        let values: Vec<f64> = p.points().iter().map(|q| q.value).collect();
        assert_eq!(values, [-500.0, 500.0]);
        let out = table(&o.params_toml(&base));
        let tf = out["transfer_function"].as_table().unwrap();
        assert!(!tf.contains_key("normalized") && !tf.contains_key("shift"));
        assert_eq!(tf["points"][1][0].as_float(), Some(500.0));
        assert_eq!(tf["points"][1][4].as_float(), Some(0.5));
    }

    #[test]
    fn the_panels_changes_reach_the_table() {
        let base = table("");
        let mut o = RenderOptions::from_params(&base, bounds(), (0.0, 1.0));
        assert_eq!(
            o.tf,
            TfSource::Preset("ct-bone".into()),
            "the plugin's default"
        );
        assert!(!o.mip && o.shading && !o.crop.enabled);
        let t = o.params_table(&base);
        assert_eq!(t["clip_planes"].as_array().map(Vec::len), Some(0));
        assert_eq!(t["crop_box"].as_str(), Some(NO_CROP_BOX));
        o.mip = true;
        o.shading = false;
        o.clips[2] = AxisClip {
            enabled: true,
            keep_below: false,
            at_mm: 12.5,
        };
        o.crop = Crop {
            enabled: true,
            min: [10.0, -100.0, -100.0],
            max: [-10.0, 100.0, 100.0],
        };
        let t = o.params_table(&base);
        assert_eq!(t["mode"].as_str(), Some("mip"));
        assert_eq!(t["shading"]["enabled"].as_bool(), Some(false));
        let plane = &t["clip_planes"][0];
        assert_eq!(mm3(plane.get("point")), Some([0.0, 0.0, 12.5]));
        assert_eq!(mm3(plane.get("normal")), Some([0.0, 0.0, 1.0]));
        assert_eq!(
            mm3(t["crop_box"].get("min")),
            Some([-10.0, -100.0, -100.0]),
            "each axis ordered"
        );
    }

    #[test]
    fn unticked_clip_planes_and_crop_box_are_written_as_off() {
        // A scene that clips and crops, both then turned off in the panel.
        let base = table(
            r#"
            clip_planes = [{ point = [0, 0, 7], normal = [0, 0, 1] }]
            crop_box = { min = [-50, -40, -30], max = [50, 40, 30] }
            "#,
        );
        let mut o = RenderOptions::from_params(&base, bounds(), (0.0, 1.0));
        assert!(o.clips[2].enabled && o.crop.enabled);
        o.clips[2].enabled = false;
        o.crop.enabled = false;
        let out = table(&o.params_toml(&base));
        // Left out, the plugin would keep the ones it was given last.
        assert_eq!(out["clip_planes"], toml::Value::Array(vec![]));
        assert_eq!(out["crop_box"].as_str(), Some(NO_CROP_BOX));
        // And it reads back as off, the sliders where the volume ends.
        let back = RenderOptions::from_params(&out, bounds(), (0.0, 1.0));
        assert!(!back.clips.iter().any(|c| c.enabled) && !back.crop.enabled);
        assert_eq!((back.crop.min, back.crop.max), ([-100.0; 3], [100.0; 3]));
    }
}
