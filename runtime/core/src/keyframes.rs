//! A scalar scripted over frames: `[[frame, value], …]` keyframes,
//! linear between them and held before the first and after the last —
//! how scenes script an actuator's pressure, volume or cable tension.

use serde::Deserialize;

/// Keyframes `(frame, value)`, frames strictly increasing.
#[derive(Clone, Debug, PartialEq, Deserialize, schemars::JsonSchema, serde::Serialize)]
#[serde(try_from = "Vec<[f64; 2]>", into = "Vec<[f64; 2]>")]
pub struct Keyframes {
    points: Vec<(f64, f64)>,
}

impl TryFrom<Vec<[f64; 2]>> for Keyframes {
    type Error = String;

    fn try_from(raw: Vec<[f64; 2]>) -> Result<Self, String> {
        if raw.is_empty() {
            return Err("keyframes need at least one [frame, value] pair".into());
        }
        if let Some(p) = raw.iter().find(|p| !p[0].is_finite() || !p[1].is_finite()) {
            return Err(format!(
                "keyframe [{}, {}] is not finite; give numbers",
                p[0], p[1]
            ));
        }
        if let Some(w) = raw.windows(2).find(|w| w[1][0] <= w[0][0]) {
            return Err(format!(
                "keyframe frames must increase (frame {} follows frame {})",
                w[1][0], w[0][0]
            ));
        }
        if raw[0][0] < 0.0 {
            return Err(format!("keyframe frame {} is negative", raw[0][0]));
        }
        Ok(Self {
            points: raw.into_iter().map(|p| (p[0], p[1])).collect(),
        })
    }
}

impl From<Keyframes> for Vec<[f64; 2]> {
    fn from(k: Keyframes) -> Self {
        k.points.into_iter().map(|(f, v)| [f, v]).collect()
    }
}

impl Keyframes {
    /// One value for every frame.
    pub fn constant(value: f64) -> Self {
        Self {
            points: vec![(0.0, value)],
        }
    }

    /// The value at `frame` (linear between keyframes, held outside).
    pub fn at(&self, frame: f64) -> f64 {
        let p = &self.points;
        let after = p.partition_point(|k| k.0 <= frame);
        if after == 0 {
            return p[0].1;
        }
        if after == p.len() {
            return p[p.len() - 1].1;
        }
        let (f0, v0) = p[after - 1];
        let (f1, v1) = p[after];
        v0 + (v1 - v0) * (frame - f0) / (f1 - f0)
    }

    /// The largest and smallest value scripted.
    pub fn range(&self) -> (f64, f64) {
        self.points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.1), hi.max(p.1))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Keyframes, String> {
        #[derive(Deserialize)]
        struct T {
            k: Keyframes,
        }
        toml::from_str::<T>(text)
            .map(|t| t.k)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn values_are_linear_between_keyframes_and_held_outside() {
        let k = parse("k = [[10, 0], [20, 100], [30, 50]]").unwrap();
        assert_eq!(k.at(0.0), 0.0);
        assert_eq!(k.at(15.0), 50.0);
        assert_eq!(k.at(25.0), 75.0);
        assert_eq!(k.at(99.0), 50.0);
        assert_eq!(k.range(), (0.0, 100.0));
        assert_eq!(Keyframes::constant(3.0).at(7.0), 3.0);
    }

    #[test]
    fn bad_keyframes_are_refused_with_the_reason() {
        for (text, why) in [
            ("k = []", "at least one"),
            ("k = [[0, 1], [0, 2]]", "must increase"),
            ("k = [[-1, 1]]", "negative"),
            ("k = [[0, nan]]", "not finite"),
        ] {
            let e = parse(text).unwrap_err();
            assert!(e.contains(why), "{text}: {e}");
        }
    }
}
