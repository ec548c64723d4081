//! An oblique volume resampled onto an axis-aligned grid where its header
//! puts it (`[volume] oblique = "linear"` or `"nearest"`; see
//! [`voxflex_core::oblique`]).
//!
//! The output grid (LPS millimetres) is the smallest axis-aligned box of
//! voxel centres that holds the eight corner voxel centres of the file,
//! starting at their lowest corner, with the spacing of the file axis
//! closest to each world axis. Every output voxel centre is mapped back
//! through the header's affine (world mm → fractional file voxel index)
//! and sampled there, trilinearly or by the nearest voxel. Centres outside
//! the acquired box (beyond the outermost voxel centres, or half a voxel
//! around a single-voxel axis) take the **background**: the smallest
//! finite value of the file (air in CT, zero in most MRI), the value the
//! non-finite policy gives NaN. A NaN in an `f32` file spreads to the
//! output voxels whose interpolation touches it; the non-finite policy
//! then counts and replaces (or refuses) them as in any other volume.

use crate::error::IoError;
use crate::grid::Grid;
use crate::header_err;
use crate::volume::{Sample, Volume, VoxelData, finite_range};
use glam::{DMat3, DVec3};
use rayon::prelude::*;
use std::path::Path;
use voxflex_core::oblique::ObliquePlacement;

/// A header's placement in LPS: voxel axis `a` steps `directions[a]` (mm)
/// and file voxel `(0, 0, 0)` sits at `origin` (mm).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ObliqueHeader {
    /// Per file voxel axis, the world step (mm, LPS) to the next voxel.
    pub directions: [DVec3; 3],
    /// World position (mm, LPS) of file voxel `(0, 0, 0)`.
    pub origin: DVec3,
    /// Voxels per file axis.
    pub dims: [usize; 3],
}

/// Index-space tolerance for the acquired box: output centres that fall on
/// the outermost voxel centres up to rounding are inside.
const EDGE_TOLERANCE: f64 = 1e-6;

impl ObliqueHeader {
    /// The axis-aligned grid (LPS mm) that encloses every voxel centre of
    /// the file, with `spacing` (mm) per world axis.
    pub fn enclosing_grid(&self, spacing: DVec3) -> Grid {
        let last = self.dims.map(|n| (n.max(1) - 1) as f64);
        let (mut lo, mut hi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
        for corner in 0..8 {
            let p = self.world(DVec3::from_array(
                [0, 1, 2].map(|a| if corner >> a & 1 == 1 { last[a] } else { 0.0 }),
            ));
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let steps = ((hi - lo) / spacing - EDGE_TOLERANCE)
            .ceil()
            .max(DVec3::ZERO);
        Grid::new(steps.to_array().map(|s| s as usize + 1), spacing, lo)
    }

    /// World position (mm, LPS) of a fractional file voxel index.
    fn world(&self, idx: DVec3) -> DVec3 {
        self.origin + self.matrix() * idx
    }

    /// The header's directions as the columns of a matrix (index → mm).
    fn matrix(&self) -> DMat3 {
        DMat3::from_cols(self.directions[0], self.directions[1], self.directions[2])
    }

    /// The acquired box along file axis `a` (fractional index): the
    /// outermost voxel centres up to rounding, or half a voxel around a
    /// single voxel.
    fn bounds(&self, a: usize) -> (f64, f64) {
        match self.dims[a] {
            0 | 1 => (-0.5, 0.5),
            n => (-EDGE_TOLERANCE, (n - 1) as f64 + EDGE_TOLERANCE),
        }
    }

    /// Whether fractional file index `idx` lies in the acquired box.
    #[cfg(test)]
    fn inside(&self, idx: DVec3) -> bool {
        (0..3).all(|a| {
            let (lo, hi) = self.bounds(a);
            idx[a] >= lo && idx[a] <= hi
        })
    }
}

/// `data` (x fastest, in the file's voxel order) resampled by `mode` onto
/// the grid that encloses it (see the module docs), refusing a grid of
/// more than `max_voxels` voxels. `path` and `field` name the file and
/// header field in errors.
pub(crate) fn resample_oblique(
    path: &Path,
    field: &str,
    header: ObliqueHeader,
    data: VoxelData,
    spacing: DVec3,
    mode: ObliquePlacement,
    max_voxels: usize,
) -> Result<Volume, IoError> {
    let grid = header.enclosing_grid(spacing);
    let dims = grid.dims;
    let fits = dims[0]
        .checked_mul(dims[1])
        .and_then(|v| v.checked_mul(dims[2]))
        .is_some_and(|n| n <= max_voxels);
    if !fits {
        return Err(header_err(
            path,
            field,
            format!(
                "resampling the oblique volume (`oblique = \"{mode}\"`) needs a grid of \
                 {} × {} × {} voxels, above the limit of {max_voxels} (`max_voxels`); raise the \
                 limit or use `oblique = \"closest-axes\"`",
                dims[0], dims[1], dims[2]
            ),
        ));
    }
    let sampler = Sampler::new(header, grid);
    // The smallest finite value (exact in every voxel type); 0 when there
    // is none: the non-finite policy refuses such a volume afterwards.
    let background = finite_range(data.as_slice()).map_or(0.0, |(lo, _)| lo);
    let data = match data {
        VoxelData::U8(v) => VoxelData::U8(sampler.fill(&v, background, mode)),
        VoxelData::I16(v) => VoxelData::I16(sampler.fill(&v, background, mode)),
        VoxelData::U16(v) => VoxelData::U16(sampler.fill(&v, background, mode)),
        VoxelData::F32(v) => VoxelData::F32(sampler.fill(&v, background, mode)),
    };
    Volume::new(grid, data).map_err(|e| header_err(path, field, e.to_string()))
}

/// Maps output voxel indices to fractional file indices.
struct Sampler {
    grid: Grid,
    /// File index of output voxel `(0, 0, 0)`.
    start: DVec3,
    /// File index step per output voxel along x, y, z.
    step: [DVec3; 3],
    /// Per file axis: its bounds and strides.
    axes: [FileAxis; 3],
}

/// One file axis as the sampler walks it.
#[derive(Clone, Copy, Debug)]
struct FileAxis {
    /// The acquired box along the axis (fractional index): the outermost
    /// voxel centres, or half a voxel around a single voxel.
    lo: f64,
    hi: f64,
    /// The last voxel's index.
    last: f64,
    /// The last cell's lower voxel (`n − 2`; 0 for a single voxel).
    top: usize,
    /// Linear offset of one step along the axis.
    stride: usize,
    /// Linear offset to a cell's upper voxel (0 for a single voxel: the
    /// value is constant along it).
    next: usize,
}

impl Sampler {
    fn new(header: ObliqueHeader, grid: Grid) -> Self {
        // `place` has checked that the directions are independent.
        let inverse = header.matrix().inverse();
        let d = header.dims;
        let strides = [1, d[0], d[0] * d[1]];
        let axes = [0, 1, 2].map(|a| {
            let n = d[a];
            let (lo, hi) = header.bounds(a);
            FileAxis {
                lo,
                hi,
                last: (n.max(1) - 1) as f64,
                top: n.saturating_sub(2),
                stride: strides[a],
                next: if n > 1 { strides[a] } else { 0 },
            }
        });
        Self {
            grid,
            start: inverse * (grid.origin - header.origin),
            step: [0, 1, 2].map(|a| inverse.col(a) * grid.spacing[a]),
            axes,
        }
    }

    /// The output voxels `x` of a row starting at file index `base` whose
    /// centres lie in the acquired box (a row meets a box in one span).
    fn inside_span(&self, base: DVec3, nx: usize) -> std::ops::Range<usize> {
        let (mut from, mut to) = (0.0f64, (nx - 1) as f64);
        for (a, axis) in self.axes.iter().enumerate() {
            let (b, s) = (base[a], self.step[0][a]);
            if s == 0.0 {
                if b < axis.lo || b > axis.hi {
                    return 0..0;
                }
                continue;
            }
            let (p, q) = ((axis.lo - b) / s, (axis.hi - b) / s);
            from = from.max(p.min(q));
            to = to.min(p.max(q));
        }
        if from > to {
            return 0..0;
        }
        from.ceil() as usize..(to.floor() as usize + 1).min(nx)
    }

    /// Every output voxel's value, x fastest; `background` (volume units)
    /// outside the acquired box.
    fn fill<T: Sample>(&self, src: &[T], background: f32, mode: ObliquePlacement) -> Vec<T> {
        let [nx, ny, nz] = self.grid.dims;
        let mut out = vec![T::from_f32(background); nx * ny * nz];
        out.par_chunks_mut(nx).enumerate().for_each(|(row, line)| {
            let (y, z) = ((row % ny) as f64, (row / ny) as f64);
            let base = self.start + self.step[1] * y + self.step[2] * z;
            let span = self.inside_span(base, nx);
            // Stepped in 32.32 fixed point: integer adds, and the cell and
            // its fraction are a shift and a mask (2⁻³² voxels, finer than
            // the f32 weights; a row of 1,000 drifts < 1e-6 voxels).
            let mut idx = (base + self.step[0] * span.start as f64)
                .to_array()
                .map(to_fixed);
            let step = self.step[0].to_array().map(to_fixed);
            let line = &mut line[span];
            let mut next = || {
                let at = idx;
                for a in 0..3 {
                    idx[a] += step[a];
                }
                at
            };
            match mode {
                ObliquePlacement::Nearest => {
                    line.iter_mut().for_each(|v| *v = self.nearest(src, next()))
                }
                _ => line.iter_mut().for_each(|v| *v = self.linear(src, next())),
            }
        });
        out
    }

    /// The file voxel closest to `idx` (32.32 fixed point, inside the box).
    #[inline]
    fn nearest<T: Sample>(&self, src: &[T], idx: [i64; 3]) -> T {
        let mut at = 0;
        for (a, axis) in self.axes.iter().enumerate() {
            // Rounded half up, then clamped: a centre on the box's edge.
            let i = ((idx[a] + (1 << 31)) >> 32).clamp(0, axis.last as i64);
            at += i as usize * axis.stride;
        }
        src[at]
    }

    /// The trilinear interpolation of the file's voxels at `idx` (32.32
    /// fixed point, inside the box; an axis of one voxel is constant along
    /// it).
    #[inline]
    fn linear<T: Sample>(&self, src: &[T], idx: [i64; 3]) -> T {
        let mut at = 0;
        let mut t = [0f32; 3];
        for (a, axis) in self.axes.iter().enumerate() {
            // The cell clamped into the volume, the fraction into [0, 1]:
            // a centre up to the box's tolerance outside takes the face.
            let i = (idx[a] >> 32).clamp(0, axis.top as i64);
            at += i as usize * axis.stride;
            let f = (idx[a] - (i << 32)).clamp(0, 1 << 32);
            t[a] = f as f32 * (1.0 / 4_294_967_296.0);
        }
        let [sx, sy, sz] = self.axes.map(|axis| axis.next);
        // Written out: as closures or `array::map` the compiler left the
        // loads a call (a third of the time).
        let c = &src[at..=at + sx + sy + sz];
        let (z0, z1) = (&c[..=sy + sx], &c[sz..]);
        let y0 = lerp(
            lerp(z0[0].to_f32(), z0[sx].to_f32(), t[0]),
            lerp(z0[sy].to_f32(), z0[sy + sx].to_f32(), t[0]),
            t[1],
        );
        let y1 = lerp(
            lerp(z1[0].to_f32(), z1[sx].to_f32(), t[0]),
            lerp(z1[sy].to_f32(), z1[sy + sx].to_f32(), t[0]),
            t[1],
        );
        T::from_f32(lerp(y0, y1, t[2]))
    }
}

/// A fractional voxel index in 32.32 fixed point.
fn to_fixed(x: f64) -> i64 {
    (x * 4_294_967_296.0).round() as i64
}

/// `a + (b − a) t`: exact where `a = b`, so flat regions stay flat.
#[inline(always)]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ReadOptions;
    use crate::orientation::{HeaderFrame, HeaderGeometry, place};

    /// Voxel axes rotated by `deg` about world axis `about` (LPS), spacing
    /// `spacing` per file axis, optionally reversed, in `frame`.
    fn rotated(deg: f64, about: usize, spacing: [f64; 3], frame: HeaderFrame) -> HeaderGeometry {
        let (s, c) = deg.to_radians().sin_cos();
        let (u, v) = ((about + 1) % 3, (about + 2) % 3);
        let mut d = [DVec3::ZERO; 3];
        d[about][about] = 1.0;
        d[u][u] = c;
        d[u][v] = s;
        d[v][u] = -s;
        d[v][v] = c;
        HeaderGeometry {
            directions: [0, 1, 2].map(|a| d[a] * spacing[a]),
            origin: DVec3::new(-12.0, 7.5, 30.0),
            frame,
            field: "space directions",
        }
    }

    /// The header's own map: file index → world (LPS mm).
    fn header_world(g: &HeaderGeometry, idx: DVec3) -> DVec3 {
        let lps = match g.frame {
            HeaderFrame::Lps => DVec3::ONE,
            HeaderFrame::Ras => DVec3::new(-1.0, -1.0, 1.0),
            HeaderFrame::Las => DVec3::new(1.0, -1.0, 1.0),
        };
        (g.origin + (0..3).map(|a| g.directions[a] * idx[a]).sum::<DVec3>()) * lps
    }

    fn opts(oblique: ObliquePlacement) -> ReadOptions {
        ReadOptions {
            oblique,
            ..Default::default()
        }
    }

    /// Every file voxel holds a linear function of its world position,
    /// which trilinear interpolation reproduces exactly: every output voxel
    /// whose centre the header's box holds must carry the function's value
    /// there, every other one the background, and the grid must hold every
    /// file voxel centre. Rotations both ways about every axis, in LPS and
    /// RAS, with one axis reversed.
    #[test]
    fn a_linear_function_of_world_position_is_resampled_where_the_header_puts_it() {
        let dims = [9, 7, 5];
        let f = |p: DVec3| 2.0 * p.x - 0.5 * p.y + 1.25 * p.z + 100.0;
        for deg in [17.0, -17.0, 45.0, 95.0] {
            for about in 0..3 {
                for frame in [HeaderFrame::Lps, HeaderFrame::Ras] {
                    let mut g = rotated(deg, about, [1.0, 1.5, 2.0], frame);
                    if about == 1 {
                        g.directions[2] = -g.directions[2];
                    }
                    let n = dims.iter().product::<usize>();
                    let values: Vec<f32> = (0..n)
                        .map(|l| {
                            let i = [l % 9, l / 9 % 7, l / 63].map(|x| x as f64);
                            f(header_world(&g, DVec3::from_array(i))) as f32
                        })
                        .collect();
                    let background = values.iter().copied().fold(f32::INFINITY, f32::min);
                    let v = place(
                        Path::new("t.nrrd"),
                        dims,
                        VoxelData::F32(values),
                        g,
                        &opts(ObliquePlacement::Linear),
                    )
                    .unwrap();
                    check_linear(&v, &g, dims, f, background, (deg, about, frame));
                }
            }
        }
    }

    fn check_linear(
        v: &Volume,
        g: &HeaderGeometry,
        dims: [usize; 3],
        f: impl Fn(DVec3) -> f64,
        background: f32,
        case: (f64, usize, HeaderFrame),
    ) {
        let VoxelData::F32(out) = &v.data else {
            panic!("type kept")
        };
        let to_file = DMat3::from_cols(
            header_world(g, DVec3::X) - header_world(g, DVec3::ZERO),
            header_world(g, DVec3::Y) - header_world(g, DVec3::ZERO),
            header_world(g, DVec3::Z) - header_world(g, DVec3::ZERO),
        )
        .inverse();
        let mut inside = 0;
        for (l, &value) in out.iter().enumerate() {
            let p = v
                .grid
                .index_to_world(DVec3::from_array(v.grid.unlinear(l).map(|x| x as f64)));
            let idx = to_file * (p - header_world(g, DVec3::ZERO));
            let held = (0..3).all(|a| idx[a] > -1e-9 && idx[a] < (dims[a] - 1) as f64 + 1e-9);
            let clear = (0..3).any(|a| idx[a] < -1e-3 || idx[a] > (dims[a] - 1) as f64 + 1e-3);
            if held {
                inside += 1;
                let want = f(p) as f32;
                assert!(
                    (value - want).abs() < 2e-3,
                    "{case:?} {p}: {value} vs {want}"
                );
            } else if clear {
                assert_eq!(
                    value, background,
                    "{case:?} {p} lies outside the acquisition"
                );
            }
        }
        assert!(inside > 100, "{case:?}: only {inside} voxels inside");
        for corner in 0..8 {
            let i = [0, 1, 2].map(|a| if corner >> a & 1 == 1 { dims[a] - 1 } else { 0 });
            let p = header_world(g, DVec3::from_array(i.map(|x| x as f64)));
            let gi = v.grid.world_to_index(p);
            assert!(
                (0..3).all(|a| gi[a] > -1e-6 && gi[a] < v.grid.dims[a] as f64 - 1.0 + 1e-6),
                "{case:?}: corner {i:?} at {p} outside the grid {:?}",
                v.grid
            );
        }
    }

    /// Nearest-voxel resampling only copies file values (labels stay
    /// labels), and each one is the file voxel nearest to the output centre.
    #[test]
    fn nearest_copies_the_file_voxel_nearest_to_each_centre() {
        let dims = [6, 5, 4];
        let g = rotated(30.0, 2, [1.0, 1.0, 2.0], HeaderFrame::Ras);
        let labels: Vec<u8> = (0..120).map(|l| (l * 37 % 11 + 1) as u8).collect();
        let v = place(
            Path::new("labels.nii"),
            dims,
            VoxelData::U8(labels.clone()),
            g,
            &opts(ObliquePlacement::Nearest),
        )
        .unwrap();
        let VoxelData::U8(out) = &v.data else {
            panic!("type kept")
        };
        let header = ObliqueHeader {
            directions: g.directions.map(|d| d * DVec3::new(-1.0, -1.0, 1.0)),
            origin: g.origin * DVec3::new(-1.0, -1.0, 1.0),
            dims,
        };
        let sampler = Sampler::new(header, v.grid);
        let mut copied = 0;
        for (l, &value) in out.iter().enumerate() {
            let [x, y, z] = v.grid.unlinear(l).map(|c| c as f64);
            let idx =
                sampler.start + sampler.step[0] * x + sampler.step[1] * y + sampler.step[2] * z;
            // (A centre halfway between two voxels may take either.)
            let tie = (0..3).any(|a| (idx[a].fract().abs() - 0.5).abs() < 1e-6);
            if header.inside(idx) {
                let i = [0, 1, 2].map(|a| idx[a].round() as usize);
                assert!(
                    tie || value == labels[i[0] + 6 * (i[1] + 5 * i[2])],
                    "{idx}"
                );
                copied += 1;
            } else {
                assert_eq!(value, 1, "the smallest label is the background");
            }
        }
        assert!(copied > 50);
    }

    /// A row's span of inside voxels is exactly the voxels whose centres
    /// the box holds (away from rounding at its faces), for turns both ways
    /// about every axis, and a single-voxel axis keeps half a voxel.
    #[test]
    fn a_rows_inside_span_is_the_voxels_the_box_holds() {
        for (deg, about, dims) in [
            (17.0, 0, [7, 6, 5]),
            (-17.0, 1, [7, 6, 5]),
            (33.0, 2, [9, 4, 3]),
            (-61.0, 2, [9, 4, 1]),
        ] {
            let g = rotated(deg, about, [1.0, 1.25, 0.75], HeaderFrame::Lps);
            let header = ObliqueHeader {
                directions: g.directions,
                origin: g.origin,
                dims,
            };
            let grid = header.enclosing_grid(DVec3::new(0.5, 0.6, 0.7));
            let s = Sampler::new(header, grid);
            let [nx, ny, nz] = grid.dims;
            let mut held = 0;
            for z in 0..nz {
                for y in 0..ny {
                    let base = s.start + s.step[1] * y as f64 + s.step[2] * z as f64;
                    let span = s.inside_span(base, nx);
                    for x in 0..nx {
                        let idx = base + s.step[0] * x as f64;
                        let near_face = (0..3).any(|a| {
                            let (lo, hi) = header.bounds(a);
                            (idx[a] - lo).abs() < 1e-9 || (idx[a] - hi).abs() < 1e-9
                        });
                        if !near_face {
                            assert_eq!(span.contains(&x), header.inside(idx), "{deg}° {idx}");
                        }
                        held += usize::from(span.contains(&x));
                    }
                }
            }
            assert!(held > 20, "{deg}°: {held} voxels held");
        }
    }

    /// Integer volumes are rounded, and a grid above `max_voxels` is
    /// refused naming the option and the way out.
    #[test]
    fn integers_round_and_a_grid_above_the_limit_is_refused() {
        let dims = [4, 4, 4];
        let g = rotated(10.0, 2, [1.0, 1.0, 1.0], HeaderFrame::Lps);
        let data = VoxelData::I16((0..64).map(|l| (l % 4 * 3) as i16).collect());
        let v = place(
            Path::new("ct.mhd"),
            dims,
            data.clone(),
            g,
            &opts(ObliquePlacement::Linear),
        )
        .unwrap();
        let VoxelData::I16(out) = &v.data else {
            panic!("type kept")
        };
        assert!(out.iter().all(|&x| (0..=9).contains(&x)));
        assert!(
            out.iter().any(|&x| x % 3 != 0),
            "interpolated values appear"
        );
        let small = ReadOptions {
            max_voxels: 64,
            oblique: ObliquePlacement::Linear,
        };
        let e = place(Path::new("ct.mhd"), dims, data, g, &small)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("ct.mhd") && e.contains("max_voxels") && e.contains("closest-axes"),
            "{e}"
        );
    }

    /// A NaN in an oblique f32 file spreads to the output voxels that
    /// interpolate it and is then counted by the non-finite policy like any
    /// other: refused under `refuse` (naming the file), replaced under the
    /// default, so nothing downstream sees one.
    #[test]
    fn a_nan_in_an_oblique_file_meets_the_non_finite_policy() {
        use crate::non_finite::NonFinitePolicy;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("nan.nrrd");
        let (s, c) = 25f64.to_radians().sin_cos();
        let mut bytes = format!(
            "NRRD0004\ntype: float\ndimension: 3\nspace: left-posterior-superior\n\
             sizes: 5 5 3\nspace directions: ({c},{s},0) ({},{c},0) (0,0,1)\n\
             space origin: (0,0,0)\nendian: little\nencoding: raw\n\n",
            -s
        )
        .into_bytes();
        for l in 0..75 {
            let v = if l == 37 { f32::NAN } else { l as f32 };
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        std::fs::write(&path, bytes).unwrap();
        let opts = opts(ObliquePlacement::Linear);
        let e = crate::read_volume_with(&path, &opts, NonFinitePolicy::Refuse, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("nan.nrrd") && e.contains("NaN"), "{e}");
        let v = crate::read_volume_with(&path, &opts, NonFinitePolicy::Replace, None).unwrap();
        let VoxelData::F32(out) = &v.data else {
            panic!("type kept")
        };
        assert!(out.iter().all(|x| x.is_finite()));
        assert_eq!(v.grid.dims[2], 3);
    }

    /// A header that is axis-aligned up to rounding is placed exactly,
    /// whatever the option: no resampling, the voxels unchanged.
    #[test]
    fn an_aligned_header_is_never_resampled() {
        let g = rotated(90.0, 2, [1.0, 2.0, 3.0], HeaderFrame::Lps);
        let data = VoxelData::U16((0..24).collect());
        for mode in [ObliquePlacement::Linear, ObliquePlacement::Nearest] {
            let v = place(Path::new("t.nrrd"), [2, 3, 4], data.clone(), g, &opts(mode)).unwrap();
            assert_eq!(v.grid.dims, [3, 2, 4]);
            let VoxelData::U16(out) = &v.data else {
                panic!("type kept")
            };
            let mut sorted = out.clone();
            sorted.sort();
            assert_eq!(sorted, (0..24).collect::<Vec<u16>>());
        }
    }
}
