//! Oblique volumes: what loading does with a header whose voxel axes are
//! rotated against the world axes by other than multiples of 90°.
//!
//! voxflex grids are axis-aligned in LPS millimetres ([`crate::grid::Grid`]),
//! so such a volume cannot keep both its voxel values and its placement.
//! [`ObliquePlacement`] says which one gives way (`[volume] oblique` in a
//! scene, `--oblique` on the CLI); the resampling itself lives in
//! `voxflex_io` (`oblique_resample`).

use serde::Deserialize;
use std::fmt;
use std::str::FromStr;

/// How an oblique header is put on an axis-aligned grid.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum ObliquePlacement {
    /// Keep every voxel value: reorder the voxels onto the closest world
    /// axes, anchored at the volume's centre, and warn with the angle and
    /// how far the corners move (up to several millimetres: the anatomy is
    /// rotated by the oblique angle against the world frame).
    #[default]
    ClosestAxes,
    /// Keep the placement: resample the volume onto an axis-aligned grid
    /// that encloses it, where the header puts every voxel, by trilinear
    /// interpolation (intensity images; integer types are rounded to the
    /// nearest value).
    Linear,
    /// Keep the placement, resampling by the nearest voxel (label maps:
    /// no value is made up).
    Nearest,
}

impl ObliquePlacement {
    /// The accepted spellings, for messages.
    pub const NAMES: &'static str = "\"closest-axes\", \"linear\" or \"nearest\"";

    /// The spelling a scene or the CLI uses.
    pub fn name(self) -> &'static str {
        match self {
            Self::ClosestAxes => "closest-axes",
            Self::Linear => "linear",
            Self::Nearest => "nearest",
        }
    }
}

impl fmt::Display for ObliquePlacement {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(self.name())
    }
}

impl FromStr for ObliquePlacement {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [Self::ClosestAxes, Self::Linear, Self::Nearest]
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("unknown oblique placement `{s}`; use {}", Self::NAMES))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_ones_list_the_choices() {
        for p in [
            ObliquePlacement::ClosestAxes,
            ObliquePlacement::Linear,
            ObliquePlacement::Nearest,
        ] {
            assert_eq!(p.name().parse::<ObliquePlacement>(), Ok(p));
        }
        let e = "cubic".parse::<ObliquePlacement>().unwrap_err();
        assert!(e.contains("cubic") && e.contains("closest-axes"), "{e}");
        assert_eq!(ObliquePlacement::default(), ObliquePlacement::ClosestAxes);
    }
}
