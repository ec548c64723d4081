//! The scripted interactions every deformation model understands (the
//! scene's `[[interaction]]` tables, `frame` removed by the host), and the
//! motion of a grabbed point.
//!
//! Units: points, offsets and boxes in world millimetres; tractions in
//! pascals; forces in newtons. A model that cannot apply a kind (ChainMail
//! has no forces, the analytic fields no topology) refuses it by name.

use crate::cut_polygon::CutPolygon;
use crate::deformation::ModelNotes;
use crate::error::ModelError;
use glam::DVec3;
use serde::Deserialize;

/// One scripted interaction.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum InteractionSpec {
    /// Grab the element or node nearest `point` (mm) and move it by `by`
    /// (mm), to `to` (mm), or along the waypoints `path` (mm, visited in
    /// order at constant speed), over `frames` frames; it stays held
    /// afterwards.
    Grab {
        /// World point, mm.
        point: [f64; 3],
        /// Offset, mm (one of `by` / `to` / `path`).
        #[serde(default)]
        by: Option<[f64; 3]>,
        /// Target, mm (one of `by` / `to` / `path`).
        #[serde(default)]
        to: Option<[f64; 3]>,
        /// Waypoints, mm (one of `by` / `to` / `path`).
        #[serde(default)]
        path: Option<Vec<[f64; 3]>>,
        /// Frames over which the grab moves (default 1).
        #[serde(default = "one_frame")]
        frames: u64,
    },
    /// Fix elements or nodes — those inside a world box (mm), those of a
    /// named material, or those of the material inside the box: they never
    /// move again.
    Fix {
        /// Lower corner, mm (with `max`).
        #[serde(default)]
        min: Option<[f64; 3]>,
        /// Upper corner, mm (with `min`).
        #[serde(default)]
        max: Option<[f64; 3]>,
        /// A material's `name`.
        #[serde(default)]
        material: Option<String>,
    },
    /// Let go of every grabbed element or node.
    Release,
    /// Cut along a planar polygon (mm, ≥ 3 corners, fanned into triangles
    /// from the first).
    Cut {
        /// Polygon corners, world mm.
        polygon: Vec<[f64; 3]>,
    },
    /// Remove what lies inside a ball (`centre`, `radius`, mm) or a box
    /// (`min`, `max`, mm).
    Carve {
        /// Ball centre, mm.
        #[serde(default)]
        centre: Option<[f64; 3]>,
        /// Ball radius, mm.
        #[serde(default)]
        radius: Option<f64>,
        /// Box lower corner, mm.
        #[serde(default)]
        min: Option<[f64; 3]>,
        /// Box upper corner, mm.
        #[serde(default)]
        max: Option<[f64; 3]>,
    },
    /// A load on the part of the model inside a box (`min`, `max`, mm):
    /// `traction` (Pa, world axes) on its boundary surface, or `force` (N,
    /// world axes) in total, shared equally by its nodes. Ramped in over
    /// `frames` frames; it stays on afterwards.
    Load {
        /// Lower corner, mm.
        min: [f64; 3],
        /// Upper corner, mm.
        max: [f64; 3],
        /// Surface traction, Pa (one of `traction` / `force`).
        #[serde(default)]
        traction: Option<[f64; 3]>,
        /// Total force, N (one of `traction` / `force`).
        #[serde(default)]
        force: Option<[f64; 3]>,
        /// Frames over which the load ramps in (default 1).
        #[serde(default = "one_frame")]
        frames: u64,
    },
}

fn one_frame() -> u64 {
    1
}

/// The kinds, for messages.
const KINDS: &str = "grab, fix, release, cut, carve, load";

/// Finite as the f32 every model's displacements are narrowed to (a
/// finite f64 beyond ±3.4e38 becomes ±∞ there, then NaN).
fn finite(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite() && (*x as f32).is_finite())
}

/// The region a `carve` removes, world mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CarveRegion {
    /// A ball: centre and radius, mm.
    Ball {
        /// Centre, mm.
        centre: DVec3,
        /// Radius, mm.
        radius: f64,
    },
    /// An axis-aligned box, corners in mm.
    Box {
        /// Lower corner, mm.
        min: DVec3,
        /// Upper corner, mm.
        max: DVec3,
    },
}

impl CarveRegion {
    /// The region of a `carve` interaction; `None` for any other kind (or
    /// a carve that [`InteractionSpec::from_toml`] would have refused).
    pub fn of(spec: &InteractionSpec) -> Option<Self> {
        match spec {
            InteractionSpec::Carve {
                centre: Some(c),
                radius: Some(r),
                ..
            } => Some(Self::Ball {
                centre: DVec3::from_array(*c),
                radius: *r,
            }),
            InteractionSpec::Carve {
                min: Some(a),
                max: Some(b),
                ..
            } => Some(Self::Box {
                min: DVec3::from_array(*a),
                max: DVec3::from_array(*b),
            }),
            _ => None,
        }
    }

    /// True when `p` (mm) lies in the region (its boundary included).
    pub fn contains(&self, p: DVec3) -> bool {
        match *self {
            Self::Ball { centre, radius } => (p - centre).length() <= radius,
            Self::Box { min, max } => p.cmpge(min).all() && p.cmple(max).all(),
        }
    }

    /// The region's bounding box `(min, max)`, mm.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        match *self {
            Self::Ball { centre, radius } => {
                (centre - DVec3::splat(radius), centre + DVec3::splat(radius))
            }
            Self::Box { min, max } => (min, max),
        }
    }
}

impl InteractionSpec {
    /// Parses and validates one interaction table; errors name the kind and
    /// the key.
    pub fn from_toml(text: &str) -> Result<Self, ModelError> {
        let spec: InteractionSpec = toml::from_str(text).map_err(|e| {
            ModelError(format!("[[interaction]]: {} (kinds: {KINDS})", e.message()))
        })?;
        spec.validate()?;
        Ok(spec)
    }

    /// The kind's name, as written in the scene.
    pub fn kind(&self) -> &'static str {
        match self {
            InteractionSpec::Grab { .. } => "grab",
            InteractionSpec::Fix { .. } => "fix",
            InteractionSpec::Release => "release",
            InteractionSpec::Cut { .. } => "cut",
            InteractionSpec::Carve { .. } => "carve",
            InteractionSpec::Load { .. } => "load",
        }
    }

    fn validate(&self) -> Result<(), ModelError> {
        let fail = |msg: &str| {
            Err(ModelError(format!(
                "[[interaction]] {}: {msg}",
                self.kind()
            )))
        };
        match self {
            InteractionSpec::Grab {
                point,
                by,
                to,
                path,
                frames,
            } => {
                if !finite(point) {
                    return fail("`point` must be finite");
                }
                let given = [by.is_some(), to.is_some(), path.is_some()];
                match given.iter().filter(|&&g| g).count() {
                    0 => {
                        return fail(
                            "needs `by = [dx, dy, dz]`, `to = [x, y, z]` or `path = [[x, y, z], …]` (mm)",
                        );
                    }
                    1 => {}
                    _ => return fail("give one of `by`, `to` and `path`"),
                }
                let targets = by.iter().chain(to).chain(path.iter().flatten());
                if targets.clone().any(|v| !finite(v)) {
                    return fail("`by`/`to`/`path` must be finite");
                }
                if path.as_ref().is_some_and(|p| p.is_empty()) {
                    return fail("`path` needs at least one waypoint");
                }
                if *frames == 0 {
                    return fail("`frames` must be ≥ 1");
                }
            }
            InteractionSpec::Fix { min, max, material } => match (min, max) {
                (Some(a), Some(b)) if a.iter().chain(b).any(|v| v.is_nan()) => {
                    return fail("`min`/`max` must not be NaN");
                }
                (Some(_), None) | (None, Some(_)) => {
                    return fail("give both `min` and `max` (mm), or neither");
                }
                (None, None) if material.is_none() => {
                    return fail("needs a box (`min`, `max`, mm) and/or `material = \"<name>\"`");
                }
                _ => {}
            },
            InteractionSpec::Release => {}
            InteractionSpec::Cut { polygon } => {
                if polygon.len() < 3 || polygon.iter().any(|v| !finite(v)) {
                    return fail("`polygon` needs at least 3 finite corners [x, y, z] (mm)");
                }
                if !CutPolygon::spans_area(polygon) {
                    return fail(
                        "`polygon` spans no area (its corners are collinear or repeated), so it \
                         would cut nothing; give at least 3 corners (mm) that span the cut's plane",
                    );
                }
            }
            InteractionSpec::Carve {
                centre,
                radius,
                min,
                max,
            } => {
                let ball = centre.is_some() && radius.is_some_and(|r| r > 0.0 && r.is_finite());
                let boxed = min.is_some() && max.is_some();
                if ball == boxed
                    || centre.is_some() != radius.is_some()
                    || min.is_some() != max.is_some()
                {
                    return fail(
                        "give a ball (`centre`, `radius` > 0, mm) or a box (`min`, `max`, mm)",
                    );
                }
            }
            InteractionSpec::Load {
                min,
                max,
                traction,
                force,
                frames,
            } => {
                if !finite(min) || !finite(max) || (0..3).any(|a| min[a] > max[a]) {
                    return fail("`min`/`max` must be finite with min ≤ max on every axis (mm)");
                }
                match (traction, force) {
                    (Some(v), None) | (None, Some(v)) if finite(v) => {}
                    (Some(_), Some(_)) => {
                        return fail("give `traction` (Pa) or `force` (N), not both");
                    }
                    (None, None) => {
                        return fail(
                            "needs `traction = [x, y, z]` (Pa) or `force = [x, y, z]` (N)",
                        );
                    }
                    _ => return fail("`traction`/`force` must be finite"),
                }
                if *frames == 0 {
                    return fail("`frames` must be ≥ 1");
                }
            }
        }
        Ok(())
    }
}

/// Grabs whose `point` lay far from the body: every model takes the
/// element or node nearest the point, wherever it is, so a point in the
/// wrong units or frame silently grabs the wrong tissue. Each such grab
/// warns with the distance, and the model reports them in its notes
/// ([`FarGrabs::add_notes`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FarGrabs {
    /// Grabs farther than their element's reach from what they took.
    pub count: u32,
    /// The largest such distance, mm.
    pub max_mm: f64,
}

impl FarGrabs {
    /// Records a grab at `point` that took the element or node at `taken`
    /// (both world mm). Farther than `reach_mm` (the size of one element
    /// there, mm) it warns, naming `model`, the distance and the key, and
    /// returns the distance.
    pub fn check(&mut self, model: &str, point: DVec3, taken: DVec3, reach_mm: f64) -> Option<f64> {
        let d = (point - taken).length();
        // NaN (a NaN point is refused on parsing) counts as near.
        if d.is_nan() || d <= reach_mm {
            return None;
        }
        self.count += 1;
        self.max_mm = self.max_mm.max(d);
        tracing::warn!(
            "{model} grab: `point` = [{}, {}, {}] mm lies {d:.1} mm from the body, beyond one \
             element ({reach_mm:.1} mm); it takes the nearest one, at [{:.1}, {:.1}, {:.1}] mm. \
             Check the [[interaction]]'s `point` (world mm, LPS)",
            point.x,
            point.y,
            point.z,
            taken.x,
            taken.y,
            taken.z
        );
        Some(d)
    }

    /// Adds `grabs_far_from_body` (count) and `grab_far_max_mm` to `notes`
    /// when there was one.
    pub fn add_notes(&self, notes: &mut ModelNotes) {
        if self.count > 0 {
            notes.insert("grabs_far_from_body".into(), self.count as f64);
            notes.insert("grab_far_max_mm".into(), self.max_mm);
        }
    }
}

/// Where a grabbed point goes: from its position when grabbed (mm) through
/// waypoints at constant speed, one step per frame over `frames` frames.
#[derive(Clone, Debug, PartialEq)]
pub struct GrabMotion {
    /// Start, then waypoints (world mm).
    points: Vec<DVec3>,
    /// Arc length at each of `points`, mm (from 0).
    arc: Vec<f64>,
    frames: u64,
    done: u64,
}

impl GrabMotion {
    /// The motion of a grab spec (validated) for a point now at `current`
    /// (world mm). Returns `None` for any other kind.
    pub fn new(spec: &InteractionSpec, current: DVec3) -> Option<Self> {
        let InteractionSpec::Grab {
            by,
            to,
            path,
            frames,
            ..
        } = spec
        else {
            return None;
        };
        let mut points = vec![current];
        match (by, to, path) {
            (Some(b), _, _) => points.push(current + DVec3::from_array(*b)),
            (_, Some(t), _) => points.push(DVec3::from_array(*t)),
            (_, _, Some(p)) => points.extend(p.iter().map(|&v| DVec3::from_array(v))),
            _ => points.push(current),
        }
        let mut arc = vec![0.0];
        for w in points.windows(2) {
            arc.push(arc.last().copied().unwrap_or(0.0) + (w[1] - w[0]).length());
        }
        Some(Self {
            points,
            arc,
            frames: *frames,
            done: 0,
        })
    }

    /// True once every frame's step was taken.
    pub fn finished(&self) -> bool {
        self.done >= self.frames
    }

    /// The next frame's target (world mm), or `None` when finished.
    pub fn advance(&mut self) -> Option<DVec3> {
        if self.finished() {
            return None;
        }
        self.done += 1;
        Some(self.at(self.done as f64 / self.frames as f64))
    }

    /// The position at fraction `f` (0 … 1) of the path's length.
    pub fn at(&self, f: f64) -> DVec3 {
        let total = *self.arc.last().unwrap_or(&0.0);
        if total <= 0.0 || f >= 1.0 {
            return *self.points.last().unwrap_or(&DVec3::ZERO);
        }
        let s = f.max(0.0) * total;
        let seg = self
            .arc
            .partition_point(|&a| a <= s)
            .clamp(1, self.points.len() - 1);
        let (a0, a1) = (self.arc[seg - 1], self.arc[seg]);
        let t = if a1 > a0 { (s - a0) / (a1 - a0) } else { 1.0 };
        self.points[seg - 1].lerp(self.points[seg], t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_kind_and_key() {
        let e = InteractionSpec::from_toml("kind = \"grab\"\npoint = [0, 0, 0]")
            .unwrap_err()
            .0;
        assert!(e.contains("grab") && e.contains("`by = "), "{e}");
        let e = InteractionSpec::from_toml("kind = \"poke\"").unwrap_err().0;
        assert!(e.contains("poke") && e.contains("load"), "{e}");
        let e = InteractionSpec::from_toml(
            "kind = \"grab\"\npoint = [0, 0, 0]\nby = [1, 0, 0]\nto = [1, 0, 0]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("one of"), "{e}");
        let e = InteractionSpec::from_toml(
            "kind = \"load\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]\ntraction = [0, nan, 0]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("finite"), "{e}");
        let e = InteractionSpec::from_toml(
            "kind = \"load\"\nmin = [0, 0, 0]\nmax = [1, -1, 1]\nforce = [0, 0, 1]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("min ≤ max"), "{e}");
        let e = InteractionSpec::from_toml("kind = \"fix\"\nmin = [0, 0, 0]\nmaks = [1, 1, 1]")
            .unwrap_err()
            .0;
        assert!(e.contains("maks"), "{e}");
    }

    #[test]
    fn a_cut_polygon_without_area_is_refused() {
        let e = InteractionSpec::from_toml(
            "kind = \"cut\"\npolygon = [[0, 0, 0], [1, 1, 1], [2, 2, 2]]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("cut") && e.contains("spans no area"), "{e}");
        let e = InteractionSpec::from_toml(
            "kind = \"cut\"\npolygon = [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]",
        )
        .unwrap_err()
        .0;
        assert!(e.contains("spans no area"), "{e}");
        assert!(
            InteractionSpec::from_toml(
                "kind = \"cut\"\npolygon = [[0, 0, 0], [0, 1, 0], [0, 1, 1]]"
            )
            .is_ok()
        );
    }

    #[test]
    fn coordinates_beyond_f32_are_refused() {
        for text in [
            "kind = \"grab\"\npoint = [0, 0, 0]\nby = [1e39, 0, 0]",
            "kind = \"grab\"\npoint = [0, -1e300, 0]\nto = [0, 0, 0]",
            "kind = \"cut\"\npolygon = [[0, 0, 0], [0, 1, 0], [0, 1, 1e39]]",
            "kind = \"load\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]\nforce = [0, 0, 1e39]",
        ] {
            let e = InteractionSpec::from_toml(text).unwrap_err().0;
            assert!(e.contains("finite"), "{text}: {e}");
        }
    }

    #[test]
    fn far_grabs_are_counted_beyond_the_reach_only() {
        let mut far = FarGrabs::default();
        assert_eq!(
            far.check("m", DVec3::ZERO, DVec3::new(0.9, 0.0, 0.0), 1.0),
            None
        );
        assert_eq!(
            far.check("m", DVec3::ZERO, DVec3::new(0.0, 30.0, 40.0), 1.0),
            Some(50.0)
        );
        far.check("m", DVec3::ZERO, DVec3::new(0.0, 3.0, 4.0), 1.0);
        assert_eq!(
            far,
            FarGrabs {
                count: 2,
                max_mm: 50.0
            }
        );
        let mut notes = ModelNotes::new();
        FarGrabs::default().add_notes(&mut notes);
        assert!(notes.is_empty());
        far.add_notes(&mut notes);
        assert_eq!(notes["grabs_far_from_body"], 2.0);
        assert_eq!(notes["grab_far_max_mm"], 50.0);
    }

    #[test]
    fn a_path_is_walked_at_constant_speed() {
        let spec = InteractionSpec::from_toml(
            "kind = \"grab\"\npoint = [0, 0, 0]\npath = [[2, 0, 0], [2, 2, 0]]\nframes = 4",
        )
        .unwrap();
        let mut g = GrabMotion::new(&spec, DVec3::ZERO).unwrap();
        let steps: Vec<DVec3> = std::iter::from_fn(|| g.advance()).collect();
        let expect = [
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(2.0, 1.0, 0.0),
            DVec3::new(2.0, 2.0, 0.0),
        ];
        assert_eq!(steps.len(), 4);
        for (s, e) in steps.iter().zip(expect) {
            assert!((*s - e).length() < 1e-12, "{s} vs {e}");
        }
        assert!(g.finished());
        // `by` is relative to where the point is when grabbed.
        let by = InteractionSpec::from_toml("kind = \"grab\"\npoint = [0, 0, 0]\nby = [0, 0, 3]")
            .unwrap();
        let mut g = GrabMotion::new(&by, DVec3::new(1.0, 1.0, 1.0)).unwrap();
        assert_eq!(g.advance(), Some(DVec3::new(1.0, 1.0, 4.0)));
        assert_eq!(g.advance(), None);
    }
}
