//! Header orientation: a file's voxel axes as its header places them in
//! the world, applied by reordering voxels (no resampling).
//!
//! voxflex grids are axis-aligned ([`Grid`]: voxel `(i, j, k)` at
//! `origin + (i, j, k) * spacing`, spacing positive) in one world frame:
//! **LPS millimetres** (x grows towards the patient's left, y posterior,
//! z superior — DICOM's and ITK's frame, and the built-in phantoms'). A
//! header may store the voxels along other axes: a coronal or sagittal
//! acquisition permutes them, storage order may reverse any of them, and
//! RAS formats (NIfTI, NRRD with `space: right-anterior-superior`) count x
//! and y the other way. `place` turns every such header into that grid
//! exactly by permuting and reversing the voxel axes — like nibabel's
//! `as_closest_canonical`, towards LPS — so slices, renders and scene
//! coordinates are anatomical whatever the file's storage order.
//!
//! A header whose axes are rotated by other than multiples of 90°
//! (oblique) cannot be represented exactly on an axis-aligned grid. By
//! default ([`ObliquePlacement::ClosestAxes`]) it is placed along the
//! closest axes, anchored at its centre, and a warning gives the angle and
//! how far its corners move; `oblique = "linear"` or `"nearest"` resamples
//! it where the header puts it instead (`crate::oblique_resample`).

use super::header_err;
use crate::ReadOptions;
use crate::error::IoError;
use crate::grid::Grid;
use crate::oblique_resample::{ObliqueHeader, resample_oblique};
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use rayon::prelude::*;
use std::path::Path;
use voxflex_core::oblique::ObliquePlacement;

/// The world frame a header's directions and origin are written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum HeaderFrame {
    /// Left-posterior-superior (DICOM, ITK's MetaImage; NRRD
    /// `left-posterior-superior`): voxflex's own frame.
    Lps,
    /// Right-anterior-superior (NIfTI; NRRD `right-anterior-superior`): x
    /// and y are negated into LPS.
    Ras,
    /// Left-anterior-superior (NRRD `left-anterior-superior`): y is
    /// negated.
    Las,
}

impl HeaderFrame {
    /// The signs that take this frame's coordinates to LPS.
    fn to_lps(self) -> DVec3 {
        match self {
            Self::Lps => DVec3::ONE,
            Self::Ras => DVec3::new(-1.0, -1.0, 1.0),
            Self::Las => DVec3::new(1.0, -1.0, 1.0),
        }
    }
}

/// A header's geometry as read, before [`place`]: voxel axis `a` steps
/// `directions[a]` (mm, in `frame`) and voxel `(0, 0, 0)` sits at `origin`
/// (mm, in `frame`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct HeaderGeometry {
    /// Per voxel axis: the world step (mm) from one voxel to the next; its
    /// length is the spacing.
    pub directions: [DVec3; 3],
    /// World position (mm) of voxel `(0, 0, 0)`.
    pub origin: DVec3,
    /// The frame of `directions` and `origin`.
    pub frame: HeaderFrame,
    /// The header fields the directions came from, for messages.
    pub field: &'static str,
}

impl HeaderGeometry {
    /// Axis-aligned steps of `spacing` (mm) from `origin` (mm).
    pub fn aligned(spacing: DVec3, origin: DVec3, frame: HeaderFrame, field: &'static str) -> Self {
        Self {
            directions: [
                DVec3::X * spacing.x,
                DVec3::Y * spacing.y,
                DVec3::Z * spacing.z,
            ],
            origin,
            frame,
            field,
        }
    }
}

/// The closest axis-aligned orientation of three voxel axis directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisOrientation {
    /// `world[a]`: the world axis (0 x, 1 y, 2 z) voxel axis `a` runs along.
    pub world: [usize; 3],
    /// `reversed[a]`: voxel axis `a` runs towards the negative world axis.
    pub reversed: [bool; 3],
    /// Largest angle (degrees) between a voxel axis and the world axis it
    /// was given: 0 for any permutation and reversal of the world axes.
    pub residual_deg: f64,
}

/// The six permutations of three axes.
const PERMUTATIONS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

impl AxisOrientation {
    /// The assignment of voxel axes to world axes that keeps each axis
    /// closest to its direction (the permutation with the largest sum of
    /// |cosines|). `None` when a direction is zero or not finite, or the
    /// directions are (nearly) linearly dependent.
    pub fn closest(directions: [DVec3; 3]) -> Option<Self> {
        let unit: Vec<DVec3> = directions
            .iter()
            .map(|d| {
                let len = d.length();
                (len.is_finite() && len > 0.0).then(|| *d / len)
            })
            .collect::<Option<_>>()?;
        let volume = unit[0].cross(unit[1]).dot(unit[2]).abs();
        if volume < 1e-6 {
            return None;
        }
        let score = |p: &[usize; 3]| (0..3).map(|a| unit[a][p[a]].abs()).sum::<f64>();
        let world = *PERMUTATIONS
            .iter()
            .max_by(|p, q| score(p).total_cmp(&score(q)))
            .expect("six permutations");
        let cosine = |a: usize| unit[a][world[a]];
        Some(Self {
            world,
            reversed: [0, 1, 2].map(|a| cosine(a) < 0.0),
            residual_deg: (0..3)
                .map(|a| cosine(a).abs().min(1.0).acos().to_degrees())
                .fold(0.0, f64::max),
        })
    }

    /// True when the voxel axes are the world axes, in order, forwards.
    pub fn is_identity(&self) -> bool {
        self.world == [0, 1, 2] && self.reversed == [false; 3]
    }
}

/// Oblique angles (degrees) below this are rounding in the header, placed
/// without a warning.
const OBLIQUE_DEG: f64 = 1e-3;

/// The volume of `data` (x fastest, `dims` voxels, in the file's order)
/// that `geometry` places, as an axis-aligned grid in LPS millimetres:
/// voxel axes permuted and reversed onto the closest world axes, the
/// spacing along each the length of its direction, and every voxel where
/// the header puts it. An oblique header is placed as `opts.oblique` says:
/// along the closest axes anchored at the volume's centre (with a warning),
/// or resampled where the header puts it (within `opts.max_voxels`).
/// `path` names the file in errors and warnings.
pub(crate) fn place(
    path: &Path,
    dims: [usize; 3],
    data: VoxelData,
    geometry: HeaderGeometry,
    opts: &ReadOptions,
) -> Result<Volume, IoError> {
    let to_lps = geometry.frame.to_lps();
    let mut directions = geometry.directions.map(|d| d * to_lps);
    let origin = geometry.origin * to_lps;
    if AxisOrientation::closest(directions).is_none() {
        // A single-voxel axis (a 2-D image's third) may carry no direction:
        // it gets the normal of the other two.
        for a in 0..3 {
            if dims[a] <= 1 {
                let normal = directions[(a + 1) % 3]
                    .cross(directions[(a + 2) % 3])
                    .normalize_or_zero();
                let len = directions[a].length();
                directions[a] = normal
                    * if len.is_finite() && len > 0.0 {
                        len
                    } else {
                        1.0
                    };
            }
        }
    }
    let Some(o) = AxisOrientation::closest(directions) else {
        return Err(header_err(
            path,
            geometry.field,
            format!(
                "the voxel axes' directions {:?} are zero, not finite or linearly dependent, so \
                 they place no volume; fix the header",
                geometry.directions.map(|d| d.to_array())
            ),
        ));
    };
    // The header's world position of a file voxel index, and the grid
    // index it gets.
    let last = dims.map(|n| (n.max(1) - 1) as f64);
    let header_at = |idx: [f64; 3]| origin + (0..3).map(|a| directions[a] * idx[a]).sum::<DVec3>();
    let grid_index = |idx: [f64; 3]| {
        let mut out = DVec3::ZERO;
        for a in 0..3 {
            out[o.world[a]] = if o.reversed[a] {
                last[a] - idx[a]
            } else {
                idx[a]
            };
        }
        out
    };
    let mut out_dims = [0usize; 3];
    let mut spacing = DVec3::ZERO;
    for a in 0..3 {
        out_dims[o.world[a]] = dims[a];
        spacing[o.world[a]] = directions[a].length();
    }
    let grid = if o.residual_deg <= OBLIQUE_DEG {
        // Exact: grid voxel 0 is the file voxel at the low end of every
        // axis, where the header puts it.
        let first = [0, 1, 2].map(|a| if o.reversed[a] { last[a] } else { 0.0 });
        Grid::new(out_dims, spacing, header_at(first))
    } else if opts.oblique != ObliquePlacement::ClosestAxes {
        let header = ObliqueHeader {
            directions,
            origin,
            dims,
        };
        let v = resample_oblique(
            path,
            geometry.field,
            header,
            data,
            spacing,
            opts.oblique,
            opts.max_voxels,
        )?;
        tracing::info!(
            file = %path.display(),
            "header field `{}` is oblique by {:.2}°: resampled ({}) where the header puts it, \
             onto an axis-aligned grid of {:?} voxels; voxels outside the acquisition take the \
             smallest value",
            geometry.field,
            o.residual_deg,
            opts.oblique,
            v.grid.dims
        );
        return Ok(v);
    } else {
        let extent = DVec3::from_array(out_dims.map(|n| (n.max(1) - 1) as f64)) * spacing;
        let grid = Grid::new(
            out_dims,
            spacing,
            header_at(last.map(|l| 0.5 * l)) - 0.5 * extent,
        );
        // Largest distance between where the header puts a corner voxel
        // and where the grid does.
        let worst = (0..8)
            .map(|corner| {
                let idx = [0, 1, 2].map(|a| if corner >> a & 1 == 1 { last[a] } else { 0.0 });
                (grid.index_to_world(grid_index(idx)) - header_at(idx)).length()
            })
            .fold(0.0, f64::max);
        tracing::warn!(
            file = %path.display(),
            "header field `{}` is oblique by {:.2}°; voxflex grids are axis-aligned, so the \
             volume is placed along the closest axes, anchored at its centre: its corners move \
             by up to {worst:.2} mm (set `[volume] oblique = \"linear\"`, or `--oblique linear`, \
             to resample it where the header puts it)",
            geometry.field,
            o.residual_deg
        );
        grid
    };
    let data = if o.is_identity() {
        data
    } else {
        let axis = |a: usize| {
            let sign = if o.reversed[a] { '−' } else { '+' };
            format!(
                "{}→{sign}{}",
                ['i', 'j', 'k'][a],
                ['x', 'y', 'z'][o.world[a]]
            )
        };
        tracing::info!(
            file = %path.display(),
            "voxels reordered into LPS: {}, {}, {} (grid dims {out_dims:?})",
            axis(0),
            axis(1),
            axis(2)
        );
        reorder(data, dims, &o)
    };
    Volume::new(grid, data).map_err(|e| header_err(path, "dim", e.to_string()))
}

/// `data` (x fastest, `dims` in the file's voxel order) reordered so that
/// voxel axis `a` becomes grid axis `o.world[a]`, reversed where
/// `o.reversed[a]`.
fn reorder(data: VoxelData, dims: [usize; 3], o: &AxisOrientation) -> VoxelData {
    match data {
        VoxelData::U8(v) => VoxelData::U8(reorder_values(&v, dims, o)),
        VoxelData::I16(v) => VoxelData::I16(reorder_values(&v, dims, o)),
        VoxelData::U16(v) => VoxelData::U16(reorder_values(&v, dims, o)),
        VoxelData::F32(v) => VoxelData::F32(reorder_values(&v, dims, o)),
    }
}

fn reorder_values<T: Copy + Default + Send + Sync>(
    src: &[T],
    dims: [usize; 3],
    o: &AxisOrientation,
) -> Vec<T> {
    let stride = [1, dims[0], dims[0] * dims[1]];
    // Per grid axis: the file axis it comes from.
    let mut from = [0usize; 3];
    for a in 0..3 {
        from[o.world[a]] = a;
    }
    let out_dims = from.map(|a| dims[a]);
    // Per grid axis: the file index of grid index 0 and the step per grid
    // index, as signed linear offsets.
    let start: isize = (0..3)
        .map(|a| {
            if o.reversed[a] {
                ((dims[a] - 1) * stride[a]) as isize
            } else {
                0
            }
        })
        .sum();
    let step = from.map(|a| {
        if o.reversed[a] {
            -(stride[a] as isize)
        } else {
            stride[a] as isize
        }
    });
    let mut out = vec![T::default(); src.len()];
    out.par_chunks_mut(out_dims[0].max(1))
        .enumerate()
        .for_each(|(row, line)| {
            let (y, z) = (row % out_dims[1], row / out_dims[1]);
            let mut s = start + y as isize * step[1] + z as isize * step[2];
            for v in line {
                *v = src[s as usize];
                s += step[0];
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn voxel_world(dims: [usize; 3], g: &HeaderGeometry, i: [usize; 3]) -> DVec3 {
        let _ = dims;
        (g.origin + (0..3).map(|a| g.directions[a] * i[a] as f64).sum::<DVec3>()) * g.frame.to_lps()
    }

    /// Every voxel's value is its file index; after placing, each grid
    /// voxel holds the value of the file voxel the header puts at the same
    /// world position.
    fn check_exact(dims: [usize; 3], g: HeaderGeometry) {
        let n = dims.iter().product::<usize>();
        let data = VoxelData::F32((0..n).map(|i| i as f32).collect());
        let v = place(Path::new("t.nii"), dims, data, g, &ReadOptions::default()).unwrap();
        assert!(v.grid.spacing.min_element() > 0.0);
        let VoxelData::F32(values) = &v.data else {
            panic!("type kept")
        };
        for (l, &value) in values.iter().enumerate() {
            let idx = v.grid.unlinear(l);
            let file = value as usize;
            let fi = [
                file % dims[0],
                file / dims[0] % dims[1],
                file / (dims[0] * dims[1]),
            ];
            let want = voxel_world(dims, &g, fi);
            let got = v
                .grid
                .index_to_world(DVec3::from_array(idx.map(|x| x as f64)));
            assert!((got - want).length() < 1e-9, "{idx:?}: {got} vs {want}");
        }
    }

    #[test]
    fn a_coronal_radiological_header_is_placed_exactly() {
        // Voxel i runs towards RAS −x (2 mm), j towards +z (2 mm), k
        // towards RAS +y (3 mm): the header of `mri_t1_small.nii.gz`. In
        // LPS, i runs along +x and k along −y.
        let g = HeaderGeometry {
            directions: [DVec3::X * -2.0, DVec3::Z * 2.0, DVec3::Y * 3.0],
            origin: DVec3::new(0.0, -254.0, 0.0),
            frame: HeaderFrame::Ras,
            field: "sform",
        };
        let o = AxisOrientation::closest(g.directions.map(|d| d * g.frame.to_lps())).unwrap();
        assert_eq!(o.world, [0, 2, 1]);
        assert_eq!(o.reversed, [false, false, true]);
        assert_eq!(o.residual_deg, 0.0);
        check_exact([4, 3, 2], g);
    }

    #[test]
    fn ras_headers_are_turned_into_lps() {
        let g = HeaderGeometry::aligned(
            DVec3::new(0.5, 1.0, 2.0),
            DVec3::new(10.0, 20.0, 30.0),
            HeaderFrame::Ras,
            "srow_x/srow_y/srow_z",
        );
        let v = place(
            Path::new("t.nrrd"),
            [2, 2, 2],
            VoxelData::U8((0..8).collect()),
            g,
            &ReadOptions::default(),
        )
        .unwrap();
        // x and y reversed: the file's last voxel along them comes first.
        assert_eq!(v.grid.origin, DVec3::new(-10.5, -21.0, 30.0));
        assert_eq!(v.data, VoxelData::U8(vec![3, 2, 1, 0, 7, 6, 5, 4]));
        check_exact([3, 4, 2], g);
    }

    #[test]
    fn a_single_slice_without_a_third_direction_is_placed() {
        let g = HeaderGeometry {
            directions: [DVec3::Y * 2.0, DVec3::X * -1.0, DVec3::ZERO],
            origin: DVec3::ZERO,
            frame: HeaderFrame::Ras,
            field: "space directions",
        };
        let v = place(
            Path::new("t.nrrd"),
            [3, 2, 1],
            VoxelData::U8(vec![0; 6]),
            g,
            &ReadOptions::default(),
        )
        .unwrap();
        assert_eq!(v.grid.dims, [2, 3, 1]);
        assert_eq!(v.grid.spacing, DVec3::new(1.0, 2.0, 1.0));
    }

    #[test]
    fn degenerate_directions_are_refused_naming_the_field() {
        let g = HeaderGeometry {
            directions: [DVec3::X, DVec3::X * 2.0, DVec3::Z],
            origin: DVec3::ZERO,
            frame: HeaderFrame::Ras,
            field: "srow_x/srow_y/srow_z",
        };
        let e = place(
            Path::new("bad.nii"),
            [2, 2, 2],
            VoxelData::U8(vec![0; 8]),
            g,
            &ReadOptions::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("bad.nii") && e.contains("srow_x") && e.contains("linearly dependent"),
            "{e}"
        );
    }

    #[test]
    fn an_oblique_header_keeps_its_centre_and_reports_the_angle() {
        let (s, c) = 10f64.to_radians().sin_cos();
        let directions = [DVec3::new(c, s, 0.0), DVec3::new(-s, c, 0.0), DVec3::Z];
        let o = AxisOrientation::closest(directions).unwrap();
        assert!(o.is_identity());
        assert!((o.residual_deg - 10.0).abs() < 1e-9);
        let g = HeaderGeometry {
            directions,
            origin: DVec3::new(5.0, 6.0, 7.0),
            frame: HeaderFrame::Ras,
            field: "srow",
        };
        let v = place(
            Path::new("t.nii"),
            [5, 5, 5],
            VoxelData::U8(vec![0; 125]),
            g,
            &ReadOptions::default(),
        )
        .unwrap();
        let header_centre = voxel_world([5, 5, 5], &g, [2, 2, 2]);
        assert!((v.grid.centre() - header_centre).length() < 1e-12);
    }

    proptest! {
        /// Any permutation and reversal of the axes, any spacing, origin
        /// and frame: every voxel lands where the header puts it.
        #[test]
        fn axis_permutations_and_flips_are_exact(
            p in 0usize..6,
            flips in 0u8..8,
            dims in prop::array::uniform3(1usize..5),
            spacing in prop::array::uniform3(0.1f64..4.0),
            origin in prop::array::uniform3(-100.0f64..100.0),
            frame in 0usize..3,
        ) {
            let perm = PERMUTATIONS[p];
            let directions = [0, 1, 2].map(|a| {
                let mut d = DVec3::ZERO;
                d[perm[a]] = if flips >> a & 1 == 1 { -spacing[a] } else { spacing[a] };
                d
            });
            let g = HeaderGeometry {
                directions,
                origin: DVec3::from_array(origin),
                frame: [HeaderFrame::Ras, HeaderFrame::Lps, HeaderFrame::Las][frame],
                field: "test",
            };
            check_exact(dims, g);
        }
    }
}
