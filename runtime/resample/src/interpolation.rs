//! Which interpolant pass 2 evaluates once pass 1 has found each output
//! voxel's owner tetrahedron.
//!
//! - [`Interpolation::Tetrahedral`] (the paper's scheme): the source values
//!   at the owner's four vertices, weighted by the voxel centre's
//!   barycentric coordinates. Piecewise linear on the 5-tetrahedra split, so
//!   it differs from trilinear interpolation inside every cell (by up to
//!   half the jump across a sharp edge).
//! - [`Interpolation::Trilinear`]: the same barycentric coordinates give the
//!   voxel centre's **rest position** (the owner's undeformed vertices,
//!   source voxel index units, interpolated — the piecewise-linear inverse
//!   of the deformation), and the source is sampled trilinearly there,
//!   clamped at the grid faces. This is what ITK-style resamplers compute
//!   with an exact backward map; the only difference left is the rest
//!   position's error (the inverse map is linear per tetrahedron).
//!
//! Both reproduce the source value bit for bit at a voxel centre that sits
//! on an (unmoved) mesh vertex: a barycentric weight of exactly 1 selects
//! that vertex (tetrahedral: its value; trilinear: its integer rest position,
//! where the trilinear sample is the voxel's value, every zero-weight
//! neighbour ignored even when it is NaN).
//!
//! The rest position is formed relative to the owner's cell (corner offsets
//! 0 or 1 per axis), not in absolute indices, so its fraction keeps full
//! f32 precision however large the grid.

use std::fmt;
use std::str::FromStr;

/// The interpolant of pass 2 (see the module docs). Shared by the CPU and
/// GPU paths; scene key `[resample] interpolation`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    /// Barycentric interpolation of the owner tetrahedron's vertex values
    /// (the paper's scheme).
    Tetrahedral,
    /// Trilinear sampling of the source at the owner's barycentric rest
    /// position (the default; see docs/BENCHMARKS.md, "Resampling accuracy", for its cost).
    #[default]
    Trilinear,
}

impl Interpolation {
    /// Both modes, in the order the benchmark reports them.
    pub const ALL: [Interpolation; 2] = [Interpolation::Tetrahedral, Interpolation::Trilinear];

    /// The scene-file name (`"tetrahedral"`, `"trilinear"`).
    pub fn name(self) -> &'static str {
        match self {
            Interpolation::Tetrahedral => "tetrahedral",
            Interpolation::Trilinear => "trilinear",
        }
    }

    /// The value the WGSL kernels read (`Params.chi.w`).
    pub(crate) fn code(self) -> i32 {
        match self {
            Interpolation::Tetrahedral => 0,
            Interpolation::Trilinear => 1,
        }
    }
}

impl fmt::Display for Interpolation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An interpolation name that is neither `tetrahedral` nor `trilinear`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown interpolation `{0}`; use \"tetrahedral\" or \"trilinear\"")]
pub struct UnknownInterpolation(pub String);

impl FromStr for Interpolation {
    type Err = UnknownInterpolation;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Interpolation::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| UnknownInterpolation(s.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_refused() {
        for m in Interpolation::ALL {
            assert_eq!(m.name().parse::<Interpolation>(), Ok(m));
            assert_eq!(m.to_string(), m.name());
        }
        let e = "cubic".parse::<Interpolation>().unwrap_err().to_string();
        assert!(e.contains("cubic") && e.contains("trilinear"), "{e}");
        #[derive(serde::Deserialize)]
        struct T {
            m: Interpolation,
        }
        let t: T = toml::from_str("m = \"tetrahedral\"").unwrap();
        assert_eq!(t.m, Interpolation::Tetrahedral);
        assert!(toml::from_str::<T>("m = \"linear\"").is_err());
    }
}
