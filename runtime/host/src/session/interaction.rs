//! [`Interaction`]: what a front end does to the model between steps —
//! the scene file's `[[interaction]]` vocabulary (grab, release, fix, cut,
//! carve, load), typed, or as the TOML text the plugins accept.
//!
//! Units: points, targets, boxes and polygons in world millimetres;
//! tractions in pascals, forces in newtons.

/// One interaction, applied by [`super::Session::interact`] before the next
/// [`super::Session::step`].
#[derive(Clone, Debug, PartialEq)]
pub enum Interaction {
    /// Grab the tissue at `point` (mm) and move it to `to` (mm) over
    /// `frames` steps; it stays held afterwards. Every model takes the
    /// element (ChainMail) or node (corotational-fem, mass-spring) whose
    /// *rest* position is nearest `point`. A drag is this same grab sent
    /// again with the point first pressed and a new `to` each call: it
    /// takes the same element or node each time, however far it has moved,
    /// and re-targets it.
    Grab {
        /// World point, mm.
        point: [f64; 3],
        /// Target, mm.
        to: [f64; 3],
        /// Steps over which the grabbed point moves to `to` (≥ 1).
        frames: u64,
    },
    /// Let go of everything grabbed.
    Release,
    /// Fix the tissue inside the box `min`..`max` (mm): it never moves again.
    Fix {
        /// Lower corner, mm.
        min: [f64; 3],
        /// Upper corner, mm.
        max: [f64; 3],
    },
    /// Fix every element of the material named `material`.
    FixMaterial {
        /// A material's `name` in the model's parameters.
        material: String,
    },
    /// Cut along a planar polygon (world mm, ≥ 3 corners).
    Cut {
        /// Polygon corners, mm.
        polygon: Vec<[f64; 3]>,
    },
    /// Remove the tissue inside a ball (centre and radius, mm).
    CarveBall {
        /// Centre, mm.
        centre: [f64; 3],
        /// Radius, mm.
        radius: f64,
    },
    /// Remove the tissue inside a box (mm).
    CarveBox {
        /// Lower corner, mm.
        min: [f64; 3],
        /// Upper corner, mm.
        max: [f64; 3],
    },
    /// A total force (N, world axes) on the tissue inside a box (mm),
    /// ramped in over `frames` steps.
    Load {
        /// Lower corner, mm.
        min: [f64; 3],
        /// Upper corner, mm.
        max: [f64; 3],
        /// Total force, N.
        force: [f64; 3],
        /// Steps over which the load ramps in (≥ 1).
        frames: u64,
    },
    /// Any interaction in the TOML text of a scene's `[[interaction]]`
    /// table without `frame` (e.g. `kind = "grab"` with a `path`).
    Toml(String),
}

fn point(v: [f64; 3]) -> toml::Value {
    toml::Value::Array(v.iter().map(|&x| toml::Value::Float(x)).collect())
}

impl Interaction {
    /// The TOML text the plugins accept (the scene vocabulary).
    pub fn to_toml(&self) -> String {
        let mut t = toml::Table::new();
        let mut put = |k: &str, v: toml::Value| {
            t.insert(k.to_owned(), v);
        };
        let frames = |f: u64| toml::Value::Integer(f.clamp(1, i64::MAX as u64) as i64);
        match self {
            Interaction::Toml(text) => return text.clone(),
            Interaction::Grab {
                point: p,
                to,
                frames: f,
            } => {
                put("kind", "grab".into());
                put("point", point(*p));
                put("to", point(*to));
                put("frames", frames(*f));
            }
            Interaction::Release => put("kind", "release".into()),
            Interaction::Fix { min, max } => {
                put("kind", "fix".into());
                put("min", point(*min));
                put("max", point(*max));
            }
            Interaction::FixMaterial { material } => {
                put("kind", "fix".into());
                put("material", material.clone().into());
            }
            Interaction::Cut { polygon } => {
                put("kind", "cut".into());
                put(
                    "polygon",
                    toml::Value::Array(polygon.iter().map(|&c| point(c)).collect()),
                );
            }
            Interaction::CarveBall { centre, radius } => {
                put("kind", "carve".into());
                put("centre", point(*centre));
                put("radius", toml::Value::Float(*radius));
            }
            Interaction::CarveBox { min, max } => {
                put("kind", "carve".into());
                put("min", point(*min));
                put("max", point(*max));
            }
            Interaction::Load {
                min,
                max,
                force,
                frames: f,
            } => {
                put("kind", "load".into());
                put("min", point(*min));
                put("max", point(*max));
                put("force", point(*force));
                put("frames", frames(*f));
            }
        }
        toml::to_string(&t).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use voxflex_core::interaction::InteractionSpec;

    /// Every typed interaction is the scene vocabulary the plugins parse.
    #[test]
    fn typed_interactions_are_the_scene_vocabulary() {
        let cases = [
            (
                Interaction::Grab {
                    point: [1.0, 2.0, 3.0],
                    to: [4.0, 5.0, 6.5],
                    frames: 2,
                },
                InteractionSpec::Grab {
                    point: [1.0, 2.0, 3.0],
                    by: None,
                    to: Some([4.0, 5.0, 6.5]),
                    path: None,
                    frames: 2,
                },
            ),
            (Interaction::Release, InteractionSpec::Release),
            (
                Interaction::Fix {
                    min: [0.0; 3],
                    max: [1.0; 3],
                },
                InteractionSpec::Fix {
                    min: Some([0.0; 3]),
                    max: Some([1.0; 3]),
                    material: None,
                },
            ),
            (
                Interaction::FixMaterial {
                    material: "bone".into(),
                },
                InteractionSpec::Fix {
                    min: None,
                    max: None,
                    material: Some("bone".into()),
                },
            ),
            (
                Interaction::Cut {
                    polygon: vec![[0.0, -1.0, -1.0], [0.0, 1.0, -1.0], [0.0, 1.0, 1.0]],
                },
                InteractionSpec::Cut {
                    polygon: vec![[0.0, -1.0, -1.0], [0.0, 1.0, -1.0], [0.0, 1.0, 1.0]],
                },
            ),
            (
                Interaction::CarveBall {
                    centre: [1.0, 1.0, 1.0],
                    radius: 2.0,
                },
                InteractionSpec::Carve {
                    centre: Some([1.0, 1.0, 1.0]),
                    radius: Some(2.0),
                    min: None,
                    max: None,
                },
            ),
            (
                Interaction::CarveBox {
                    min: [0.0; 3],
                    max: [2.0; 3],
                },
                InteractionSpec::Carve {
                    centre: None,
                    radius: None,
                    min: Some([0.0; 3]),
                    max: Some([2.0; 3]),
                },
            ),
            (
                Interaction::Load {
                    min: [0.0; 3],
                    max: [2.0; 3],
                    force: [0.0, 0.0, -1.5],
                    frames: 3,
                },
                InteractionSpec::Load {
                    min: [0.0; 3],
                    max: [2.0; 3],
                    traction: None,
                    force: Some([0.0, 0.0, -1.5]),
                    frames: 3,
                },
            ),
        ];
        for (typed, spec) in cases {
            let text = typed.to_toml();
            assert_eq!(InteractionSpec::from_toml(&text).unwrap(), spec, "{text}");
        }
        let raw = "kind = \"release\"\n";
        assert_eq!(Interaction::Toml(raw.into()).to_toml(), raw);
    }
}
