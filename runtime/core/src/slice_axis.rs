//! [`SliceAxis`]: which voxel axis a slice image holds fixed, and the
//! image's size and pixel size on a grid. Vocabulary shared by the PNG
//! snapshots (`voxflex_io::png`, which also gives the image orientation)
//! and the opacity seeds placed by a click on a slice, so neither needs
//! the other.

use crate::grid::Grid;

/// The axis a slice is taken across.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SliceAxis {
    /// Fixed z (voxel index `k`): the x–y plane.
    Axial,
    /// Fixed y (voxel index `j`): the x–z plane.
    Coronal,
    /// Fixed x (voxel index `i`): the y–z plane.
    Sagittal,
}

impl SliceAxis {
    /// The grid axis (0 = x, 1 = y, 2 = z) held fixed.
    pub fn fixed_axis(self) -> usize {
        match self {
            SliceAxis::Axial => 2,
            SliceAxis::Coronal => 1,
            SliceAxis::Sagittal => 0,
        }
    }

    /// Lower-case name (`axial`, `coronal`, `sagittal`).
    pub fn name(self) -> &'static str {
        match self {
            SliceAxis::Axial => "axial",
            SliceAxis::Coronal => "coronal",
            SliceAxis::Sagittal => "sagittal",
        }
    }

    /// Name of the fixed grid axis (`x`, `y` or `z`).
    pub fn letter(self) -> &'static str {
        ["x", "y", "z"][self.fixed_axis()]
    }

    /// A voxel's `(width, height)` in a slice of `grid` across this axis,
    /// mm.
    pub fn pixel_mm(self, grid: &Grid) -> (f64, f64) {
        let s = grid.spacing;
        match self {
            SliceAxis::Axial => (s.x, s.y),
            SliceAxis::Coronal => (s.x, s.z),
            SliceAxis::Sagittal => (s.y, s.z),
        }
    }

    /// Image `(width, height)` in pixels of a slice of `grid` across this axis.
    pub fn image_size(self, grid: &Grid) -> (usize, usize) {
        let [nx, ny, nz] = grid.dims;
        match self {
            SliceAxis::Axial => (nx, ny),
            SliceAxis::Coronal => (nx, nz),
            SliceAxis::Sagittal => (ny, nz),
        }
    }
}

impl std::fmt::Display for SliceAxis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SliceAxis {
    type Err = String;

    /// Parses `axial`/`z`, `coronal`/`y`, `sagittal`/`x` (any case).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "axial" | "z" => Ok(SliceAxis::Axial),
            "coronal" | "y" => Ok(SliceAxis::Coronal),
            "sagittal" | "x" => Ok(SliceAxis::Sagittal),
            _ => Err(format!(
                "unknown slice axis `{s}`; use axial (z), coronal (y) or sagittal (x)"
            )),
        }
    }
}
