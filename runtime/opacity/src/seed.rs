//! Seeds ([`Seed`]) and the seed statistics `d_s`, `σ_s` ([`SeedStats`]).
//!
//! A seed is given as a voxel index, a world point (mm) or a click on a 2-D
//! slice image. Slice pixels follow the orientation of `voxflex_io::png`,
//! which shows z (superior) up; a pixel is `[column, row]`, column counted
//! left → right and row top → bottom, from 0:
//!
//! | axis | slice `index` fixes | column | row | voxel `(i, j, k)` |
//! |---|---|---|---|---|
//! | [`SliceAxis::Axial`] | `k` (z) | `i` (x) | `j` (y) | `(col, row, index)` |
//! | [`SliceAxis::Coronal`] | `j` (y) | `i` (x) | `nz − 1 − k` | `(col, index, nz − 1 − row)` |
//! | [`SliceAxis::Sagittal`] | `i` (x) | `j` (y) | `nz − 1 − k` | `(index, col, nz − 1 − row)` |

use super::OpacityError;
use super::params::GrowthParams;
use crate::grid::Grid;
use crate::volume::VolumeView;
use glam::DVec3;
use voxflex_core::slice_axis::SliceAxis;

/// Where a region growing starts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Seed {
    /// A voxel, by **voxel index** `(i, j, k)`.
    Voxel([usize; 3]),
    /// A world point, **millimetres**; the seed is the voxel whose centre is
    /// nearest (the voxel containing the point). Accepted when the point lies
    /// inside the volume's voxels, i.e. within half a voxel of the centres'
    /// box.
    World(DVec3),
    /// A click on a slice image as `voxflex_io::png` draws it (see the
    /// module table): `index` is the **voxel index** of the slice along the
    /// fixed axis, `pixel` is `[column, row]` in image pixels (one pixel per
    /// voxel, row 0 at the top).
    Slice {
        /// The axis the slice is taken across.
        axis: SliceAxis,
        /// Voxel index of the slice along that axis.
        index: usize,
        /// `[column, row]`, pixels from the top-left corner.
        pixel: [usize; 2],
    },
}

impl std::fmt::Display for Seed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Seed::Voxel(v) => write!(f, "voxel {v:?}"),
            Seed::World(p) => write!(f, "world point ({}, {}, {}) mm", p.x, p.y, p.z),
            Seed::Slice { axis, index, pixel } => write!(
                f,
                "{axis} slice {index} pixel (column {}, row {})",
                pixel[0], pixel[1]
            ),
        }
    }
}

impl Seed {
    /// The seed's voxel index in `grid`, or an error naming the coordinate
    /// that is NaN or out of range.
    pub fn resolve(&self, grid: &Grid) -> Result<[usize; 3], OpacityError> {
        let outside = |detail: String| OpacityError::SeedOutside {
            seed: self.to_string(),
            detail,
        };
        let dims = grid.dims;
        if dims.contains(&0) {
            return Err(OpacityError::EmptyVolume { dims });
        }
        match *self {
            Seed::Voxel(v) => {
                for a in 0..3 {
                    if v[a] >= dims[a] {
                        return Err(outside(format!(
                            "index {} along {} is not below the {} voxels of dims {dims:?}",
                            v[a],
                            ["x", "y", "z"][a],
                            dims[a]
                        )));
                    }
                }
                Ok(v)
            }
            Seed::World(p) => {
                if !p.is_finite() {
                    return Err(OpacityError::SeedNotFinite {
                        seed: self.to_string(),
                    });
                }
                let idx = grid.world_to_index(p);
                let mut v = [0usize; 3];
                for a in 0..3 {
                    let r = idx[a].round();
                    if !(r >= 0.0 && r < dims[a] as f64) {
                        let (lo, hi) = grid.world_bounds();
                        return Err(outside(format!(
                            "{} = {} mm is {} voxels from the first centre; the volume's centres \
                             span {} to {} mm (± half a voxel) along {}",
                            ["x", "y", "z"][a],
                            p[a],
                            idx[a],
                            lo[a],
                            hi[a],
                            ["x", "y", "z"][a]
                        )));
                    }
                    v[a] = r as usize;
                }
                Ok(v)
            }
            Seed::Slice { axis, index, pixel } => {
                let fixed = axis.fixed_axis();
                if index >= dims[fixed] {
                    return Err(outside(format!(
                        "slice index {index} is not below the {} {axis} slices",
                        dims[fixed]
                    )));
                }
                let (w, h) = axis.image_size(grid);
                if pixel[0] >= w || pixel[1] >= h {
                    return Err(outside(format!(
                        "pixel (column {}, row {}) is outside the {w} × {h} {axis} image",
                        pixel[0], pixel[1]
                    )));
                }
                let [col, row] = pixel;
                let nz = dims[2];
                Ok(match axis {
                    SliceAxis::Axial => [col, row, index],
                    SliceAxis::Coronal => [col, index, nz - 1 - row],
                    SliceAxis::Sagittal => [index, col, nz - 1 - row],
                })
            }
        }
    }

    /// The [`Seed::Slice`] click that selects `voxel` on a slice across
    /// `axis` (the inverse of [`Seed::resolve`] for slices; `voxel` must lie
    /// in `grid`).
    pub fn slice_click(grid: &Grid, voxel: [usize; 3], axis: SliceAxis) -> Seed {
        let [i, j, k] = voxel;
        let row_z = grid.dims[2].saturating_sub(1).saturating_sub(k);
        let (index, pixel) = match axis {
            SliceAxis::Axial => (k, [i, j]),
            SliceAxis::Coronal => (j, [i, row_z]),
            SliceAxis::Sagittal => (i, [j, row_z]),
        };
        Seed::Slice { axis, index, pixel }
    }
}

/// The seed's intensity statistics over its neighbourhood: the cube of
/// half-width [`GrowthParams::seed_radius`] voxels around the seed voxel
/// (the paper's 1-ring at radius 1), clipped to the volume, in the
/// volume's value units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeedStats {
    /// The seed voxel, **voxel index**.
    pub voxel: [usize; 3],
    /// Voxels in the neighbourhood (`(2 r + 1)³` inside the volume, fewer at
    /// its border).
    pub ring_voxels: usize,
    /// Mean `d_s` of the neighbourhood (value units).
    pub mean: f32,
    /// Population standard deviation of the neighbourhood (value units), as
    /// measured.
    pub std: f32,
    /// The σ_s the growth uses: `max(std, floor)` (see
    /// [`GrowthParams::sigma_floor`]), > 0.
    pub sigma: f32,
}

/// Mean and standard deviation of the seed voxel's neighbourhood (half-width
/// `params.seed_radius` voxels), with the σ floor of `params` applied. A
/// neighbourhood holding a NaN or infinite value, or values
/// beyond ±1e29, is an error.
pub fn seed_stats(
    volume: VolumeView<'_>,
    voxel: [usize; 3],
    params: &GrowthParams,
) -> Result<SeedStats, OpacityError> {
    params.validate()?;
    let g = volume.grid;
    let d = g.dims;
    if d.contains(&0) {
        return Err(OpacityError::EmptyVolume { dims: d });
    }
    let mut n = 0usize;
    let (mut s, mut s2) = (0f64, 0f64);
    let r = params.seed_radius as usize;
    let lo = voxel.map(|c| c.saturating_sub(r));
    let hi = [0, 1, 2].map(|a| (voxel[a] + r).min(d[a] - 1));
    let mut values = Vec::with_capacity((2 * r + 1).pow(3));
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            for i in lo[0]..=hi[0] {
                let v = volume.data.get_f32(g.linear(i, j, k)) as f64;
                values.push(v);
                s += v;
                n += 1;
            }
        }
    }
    let mean = s / n as f64;
    for v in &values {
        s2 += (v - mean) * (v - mean);
    }
    let std = (s2 / n as f64).sqrt();
    if !mean.is_finite() || !std.is_finite() || mean.abs() > 1e29 {
        return Err(OpacityError::SeedStatsNotFinite { voxel, mean, std });
    }
    let (vmin, vmax) = volume.value_range();
    let range = (vmax as f64 - vmin as f64).max(0.0);
    let floor = if range > 0.0 && range.is_finite() {
        params.sigma_floor as f64 * range
    } else {
        params.sigma_floor as f64 * mean.abs().max(1.0)
    };
    Ok(SeedStats {
        voxel,
        ring_voxels: n,
        mean: mean as f32,
        std: std as f32,
        sigma: std.max(floor) as f32,
    })
}
