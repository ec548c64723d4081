//! The scene tables of soft-robot actuation: `[[actuator]]` (a plugin and
//! what it acts on) and `[[effector]]` (a point of the body and where it
//! should go: inverse control).
//!
//! ```toml
//! [[actuator]]
//! plugin = "cavity"              # or "cable"
//! name = "left"                  # for metrics.json (default: plugin#index)
//! cavity = { label = 2 }         # cavity surface: a label of the source volume,
//! # cavity = { file = "cavity.off" }   # or a closed triangle mesh (mm)
//! # points = [[x, y, z], …]      # a cable's points on the body (mm), in order
//! gravity_m_s2 = [0, 0, -9.81]   # the fluid's gravity (default)
//! [actuator.params]              # the plugin's own keys
//! fluid = "water"
//!
//! [actuation]                    # how each frame settles (optional)
//! settle_tolerance = 1e-4        # the follower forces' relative change that counts as settled
//! settle_iterations = 30         # repeated steps per frame at most; 0: lagged by a frame
//! response_refresh_frames = 1    # inverse control: recompute the compliance responses every N frames
//!
//! [[effector]]
//! point = [60, 10, 10]           # rest position on the body, mm
//! target = [60, 10, 30]          # where it should go, mm
//! # path = [[0, 60, 10, 10], [30, 60, 10, 30]]   # or [frame, x, y, z] keyframes
//! ```

use serde::Deserialize;
use std::path::PathBuf;
use voxflex_core::glam::DVec3;
use voxflex_core::keyframes::Keyframes;

/// `[[actuator]]`: one actuator plugin instance and its geometry.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ActuatorSettings {
    /// Plugin name (`cavity`, `cable`).
    pub plugin: String,
    /// Name in metrics and messages (default `plugin#index`).
    #[serde(default)]
    pub name: Option<String>,
    /// A cavity's closed surface (surface actuators).
    #[serde(default)]
    pub cavity: Option<CavitySource>,
    /// A cable's points on the body, world mm, in order from the pull
    /// point's end.
    #[serde(default)]
    pub points: Vec<[f64; 3]>,
    /// Gravity the actuator's fluid feels, m/s², world axes.
    #[serde(default = "earth")]
    pub gravity_m_s2: [f64; 3],
    /// The plugin's own table, passed to it as TOML text.
    #[serde(default)]
    pub params: toml::Table,
}

fn earth() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}

/// Where a cavity's surface comes from: exactly one of the two.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CavitySource {
    /// A closed triangle mesh file (`.off`, `.obj` or `.stl`), world mm,
    /// normals out of the fluid; relative to the scene file.
    #[serde(default)]
    pub file: Option<PathBuf>,
    /// A label of the source volume: the boundary of its voxels.
    #[serde(default)]
    pub label: Option<i64>,
}

/// `[actuation]`: how each frame settles the actuators' follower forces
/// (a pressure or a cable pushes along the wall it moves).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ActuationSettings {
    /// The forces count as settled when a repeated step changes them by
    /// less than this fraction of their size (default 1e-4).
    #[serde(default = "default_settle_tolerance")]
    pub settle_tolerance: f64,
    /// Repeated steps per frame at most (default 30). 0 applies each
    /// frame's forces as they were at its start and moves on — the
    /// interactive setting: the body then lags its follower forces by a
    /// frame, `force_change` in metrics.json says by how much, and the run
    /// warns when the last frame's change is above 1 %.
    #[serde(default = "default_settle_iterations")]
    pub settle_iterations: u32,
    /// Inverse control: the actuators' responses (one compliance solve per
    /// actuator, two for a hydraulic cavity) are recomputed every this
    /// many frames (default 1: every frame), and sooner whenever the last
    /// inverse step disappointed (the effectors got less than a quarter of
    /// the improvement it predicted). In between, the responses of the
    /// last solve, corrected by the secant update from what the effectors
    /// did, steer the efforts; the physics of every frame is still the
    /// model's full solve.
    #[serde(default = "default_response_refresh_frames")]
    pub response_refresh_frames: u32,
}

fn default_settle_tolerance() -> f64 {
    1e-4
}
fn default_settle_iterations() -> u32 {
    30
}
fn default_response_refresh_frames() -> u32 {
    1
}

/// More frames between response refreshes than this is a typo.
pub const MAX_RESPONSE_REFRESH_FRAMES: u32 = 1000;

/// More repeated steps per frame than this is a typo, not a setting.
pub const MAX_SETTLE_ITERATIONS: u32 = 1000;

impl Default for ActuationSettings {
    fn default() -> Self {
        Self {
            settle_tolerance: default_settle_tolerance(),
            settle_iterations: default_settle_iterations(),
            response_refresh_frames: default_response_refresh_frames(),
        }
    }
}

impl ActuationSettings {
    /// The key and the message of the first bad value.
    pub fn check(&self) -> Result<(), (String, String)> {
        if !(self.settle_tolerance > 0.0 && self.settle_tolerance < 1.0) {
            return Err((
                "settle_tolerance".into(),
                format!(
                    "{} must lie in (0, 1): the follower forces' relative change per repeated \
                     step that counts as settled (default 1e-4)",
                    self.settle_tolerance
                ),
            ));
        }
        if self.settle_iterations > MAX_SETTLE_ITERATIONS {
            return Err((
                "settle_iterations".into(),
                format!(
                    "{} is more than {MAX_SETTLE_ITERATIONS} repeated steps a frame; use 0 \
                     (interactive: forces lag a frame) to 30 (the default)",
                    self.settle_iterations
                ),
            ));
        }
        if !(1..=MAX_RESPONSE_REFRESH_FRAMES).contains(&self.response_refresh_frames) {
            return Err((
                "response_refresh_frames".into(),
                format!(
                    "{} must lie in 1..={MAX_RESPONSE_REFRESH_FRAMES}: recompute the \
                     actuators' compliance responses every N frames (default 1: every frame)",
                    self.response_refresh_frames
                ),
            ));
        }
        Ok(())
    }
}

/// `[[effector]]`: a point of the body driven to a target by the inverse
/// solve.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EffectorSettings {
    /// Name in metrics (default `effector#index`).
    #[serde(default)]
    pub name: Option<String>,
    /// Rest position on the body, world mm.
    pub point: [f64; 3],
    /// A fixed target, world mm.
    #[serde(default)]
    pub target: Option<[f64; 3]>,
    /// Or a moving one: `[frame, x, y, z]` keyframes (mm), linear between.
    #[serde(default)]
    pub path: Vec<[f64; 4]>,
}

impl ActuatorSettings {
    /// The name in metrics: `name`, else `plugin#index`.
    pub fn display_name(&self, index: usize) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| format!("{}#{index}", self.plugin))
    }

    /// The plugin's table as TOML text.
    pub fn params_toml(&self) -> String {
        toml::to_string(&self.params).unwrap_or_default()
    }

    /// Checks what the host reads (the plugin checks its own table): one
    /// geometry, finite numbers. Errors name the key.
    pub fn check(&self) -> Result<(), (String, String)> {
        let err = |key: &str, m: String| Err((key.to_string(), m));
        match (&self.cavity, self.points.is_empty()) {
            (Some(_), false) => {
                return err(
                    "points",
                    "give a `cavity` (surface actuators) or `points` (a cable), not both".into(),
                );
            }
            (None, true) => {
                return err(
                    "cavity",
                    "every [[actuator]] needs `cavity = { label = N }`, `cavity = { file = \"….off\" }` \
                     or `points = [[x, y, z], …]`"
                        .into(),
                );
            }
            (Some(c), true) => match (&c.file, c.label) {
                (Some(_), Some(_)) | (None, None) => {
                    return err(
                        "cavity",
                        "give exactly one of `file` and `label` in `cavity = { … }`".into(),
                    );
                }
                _ => {}
            },
            (None, false) => {}
        }
        if self.points.iter().flatten().any(|v| !v.is_finite()) {
            return err(
                "points",
                "every coordinate must be a finite number (mm)".into(),
            );
        }
        if self.gravity_m_s2.iter().any(|v| !v.is_finite()) {
            return err("gravity_m_s2", "must be three finite numbers (m/s²)".into());
        }
        Ok(())
    }
}

impl EffectorSettings {
    /// The name in metrics: `name`, else `effector#index`.
    pub fn display_name(&self, index: usize) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| format!("effector#{index}"))
    }

    /// The target per axis as keyframes, checking that exactly one of
    /// `target` and `path` is given. Errors name the key.
    pub fn targets(&self) -> Result<[Keyframes; 3], (String, String)> {
        let err = |key: &str, m: String| Err((key.to_string(), m));
        if self.point.iter().any(|v| !v.is_finite()) {
            return err("point", "must be three finite numbers (mm)".into());
        }
        match (self.target, self.path.is_empty()) {
            (Some(t), true) => {
                if t.iter().any(|v| !v.is_finite()) {
                    return err("target", "must be three finite numbers (mm)".into());
                }
                Ok(t.map(Keyframes::constant))
            }
            (None, false) => {
                let axis = |a: usize| {
                    Keyframes::try_from(
                        self.path
                            .iter()
                            .map(|p| [p[0], p[a + 1]])
                            .collect::<Vec<_>>(),
                    )
                };
                match (axis(0), axis(1), axis(2)) {
                    (Ok(x), Ok(y), Ok(z)) => Ok([x, y, z]),
                    (Err(e), _, _) | (_, Err(e), _) | (_, _, Err(e)) => err("path", e),
                }
            }
            _ => err(
                "target",
                "every [[effector]] needs exactly one of `target = [x, y, z]` and \
                 `path = [[frame, x, y, z], …]`"
                    .into(),
            ),
        }
    }

    /// The rest point, mm.
    pub fn rest(&self) -> DVec3 {
        DVec3::from_array(self.point)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn actuator(text: &str) -> ActuatorSettings {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn an_actuator_needs_exactly_one_geometry() {
        actuator("plugin = \"cavity\"\ncavity = { label = 2 }")
            .check()
            .unwrap();
        actuator("plugin = \"cable\"\npoints = [[0, 0, 0]]")
            .check()
            .unwrap();
        for (text, key) in [
            ("plugin = \"cavity\"", "cavity"),
            ("plugin = \"cavity\"\ncavity = {}", "cavity"),
            (
                "plugin = \"cavity\"\ncavity = { label = 2, file = \"a.off\" }",
                "cavity",
            ),
            (
                "plugin = \"cavity\"\ncavity = { label = 2 }\npoints = [[0, 0, 0]]",
                "points",
            ),
            ("plugin = \"cable\"\npoints = [[0, nan, 0]]", "points"),
            (
                "plugin = \"cable\"\npoints = [[0, 0, 0]]\ngravity_m_s2 = [0, 0, inf]",
                "gravity_m_s2",
            ),
        ] {
            assert_eq!(actuator(text).check().unwrap_err().0, key, "{text}");
        }
        assert_eq!(
            actuator("plugin = \"cable\"\npoints = [[0, 0, 0]]").display_name(3),
            "cable#3"
        );
    }

    #[test]
    fn an_effector_has_a_target_or_a_path() {
        let e: EffectorSettings = toml::from_str("point = [1, 2, 3]\ntarget = [4, 5, 6]").unwrap();
        let t = e.targets().unwrap();
        assert_eq!([t[0].at(9.0), t[1].at(9.0), t[2].at(9.0)], [4.0, 5.0, 6.0]);
        let e: EffectorSettings =
            toml::from_str("point = [1, 2, 3]\npath = [[0, 0, 0, 0], [10, 10, 20, 30]]").unwrap();
        let t = e.targets().unwrap();
        assert_eq!(
            [t[0].at(5.0), t[1].at(5.0), t[2].at(5.0)],
            [5.0, 10.0, 15.0]
        );
        for text in [
            "point = [1, 2, 3]",
            "point = [1, 2, 3]\ntarget = [1, 1, 1]\npath = [[0, 1, 1, 1]]",
            "point = [1, 2, 3]\npath = [[5, 1, 1, 1], [2, 1, 1, 1]]",
            "point = [1, nan, 3]\ntarget = [1, 1, 1]",
        ] {
            let e: EffectorSettings = toml::from_str(text).unwrap();
            assert!(e.targets().is_err(), "{text}");
        }
    }
}
