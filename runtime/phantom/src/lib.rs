//! # voxflex-phantom
//!
//! Built-in volume sources. Its own crate, above voxflex-io (a scene's
//! source is a phantom *or* a file, [`VolumeSource`]), so that the plugins'
//! tests and benchmarks, the opacity tests (the labelled [`abdomen`] and its
//! Dice scores) and the host share one set of phantoms without any of them
//! pulling the phantoms into voxflex-core.
//!
//! Built-in phantoms: analytic volumes generated at any resolution, so demos,
//! tests and benchmarks never need a data file.
//!
//! Every phantom has a fixed **physical** size; the requested dims only set
//! the sampling: `spacing = size / dims` (mm) and the grid is centred on the
//! world origin ([`Grid::centred`]). Structures are defined in world
//! millimetres, so a phantom looks the same at 32³ and at 512³.
//!
//! | name | type | size (mm) | content |
//! |---|---|---|---|
//! | `head` | i16 (HU) | 200 × 240 × 220 | CT-like head of nested ellipsoids (see [`head`]) |
//! | `cube` | u8 | 100 × 100 × 100 | homogeneous cube 100 in air 0 (see [`cube`]) |
//! | `rings` | u8 | 100 × 100 × 100 | annulus, soft half 100 / hard half 200 (see [`rings`]) |
//! | `ramp` | f32 | 100 × 100 × 100 | linear field `a·x + b·y + c·z` (see [`ramp`]) |
//! | `abdomen` | i16 (HU) | 360 × 280 × 240 | labelled portal-venous contrast CT of the upper abdomen, with noise (see [`abdomen`]) |
//! | `finger` | u8 labels | 96 × 24 × 24 | soft finger: silicone bar with one off-centre cavity (see [`soft_robot`]) |
//! | `cylinder` | u8 labels | 48 × 48 × 68 | the hydraulics paper's cylinder specimen with one cavity (see [`soft_robot`]) |
//! | `pendulum` | u8 labels | 36 × 36 × 88 | column with four cavities (the paper's Fig. 6, see [`soft_robot`]) |
//!
//! Axes follow DICOM/LPS: +x toward the patient's left, +y posterior, +z
//! superior — what [`voxflex_io::png`] displays upright.
//!
//! [`parse_source`] turns a scene's `source` string into a
//! [`VolumeSource`]: `"phantom:head"` or a file path.

#![warn(missing_docs)]

// The voxflex-core modules this crate builds on, imported at the root so
// `crate::grid`, `crate::volume`, ... read as they did when the phantoms
// were a module of voxflex-core.
use voxflex_core::{error, grid, opacity_map, volume};

use crate::error::IoError;
use crate::grid::Grid;
use crate::volume::{Volume, VoxelData};
use glam::DVec3;
use rayon::prelude::*;
use std::path::PathBuf;
use voxflex_io::ReadOptions;

pub mod abdomen;
pub mod soft_robot;
pub use abdomen::{LabelledVolume, abdomen_labelled};

/// The built-in phantoms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PhantomKind {
    /// CT-like head, i16 Hounsfield units ([`head`]).
    Head,
    /// Homogeneous cube, u8 ([`cube`]).
    Cube,
    /// Two-material annulus, u8 ([`rings`]).
    Rings,
    /// Linear f32 field ([`ramp`]).
    Ramp,
    /// Labelled abdominal contrast CT, i16 Hounsfield units ([`abdomen`]).
    Abdomen,
    /// Soft finger with one cavity, u8 labels ([`soft_robot::finger`]).
    Finger,
    /// The paper's cylinder specimen with one cavity, u8 labels ([`soft_robot::cylinder`]).
    Cylinder,
    /// The four-cavity pendulum, u8 labels ([`soft_robot::pendulum`]).
    Pendulum,
}

impl PhantomKind {
    /// Every phantom, in documentation order.
    pub const ALL: [PhantomKind; 8] = [
        PhantomKind::Head,
        PhantomKind::Cube,
        PhantomKind::Rings,
        PhantomKind::Ramp,
        PhantomKind::Abdomen,
        PhantomKind::Finger,
        PhantomKind::Cylinder,
        PhantomKind::Pendulum,
    ];

    /// The name used in `phantom:<name>` sources.
    pub fn name(self) -> &'static str {
        match self {
            PhantomKind::Head => "head",
            PhantomKind::Cube => "cube",
            PhantomKind::Rings => "rings",
            PhantomKind::Ramp => "ramp",
            PhantomKind::Abdomen => "abdomen",
            PhantomKind::Finger => "finger",
            PhantomKind::Cylinder => "cylinder",
            PhantomKind::Pendulum => "pendulum",
        }
    }

    /// Physical size (mm) of the whole field of view along x, y, z.
    pub fn size_mm(self) -> DVec3 {
        match self {
            PhantomKind::Head => HEAD_SIZE_MM,
            PhantomKind::Abdomen => abdomen::ABDOMEN_SIZE_MM,
            PhantomKind::Finger => soft_robot::FINGER_SIZE_MM,
            PhantomKind::Cylinder => soft_robot::CYLINDER_SIZE_MM,
            PhantomKind::Pendulum => soft_robot::PENDULUM_SIZE_MM,
            PhantomKind::Cube | PhantomKind::Rings | PhantomKind::Ramp => DVec3::splat(100.0),
        }
    }

    /// The phantom's grid at `dims`: spacing `size / dims` (mm), centred on
    /// the world origin.
    pub fn grid(self, dims: [usize; 3]) -> Grid {
        let d = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64).max(DVec3::ONE);
        Grid::centred(dims, self.size_mm() / d)
    }

    /// Generates the phantom at `dims` voxels.
    pub fn generate(self, dims: [usize; 3]) -> Result<Volume, PhantomError> {
        check_dims(dims)?;
        Ok(match self {
            PhantomKind::Head => head(dims),
            PhantomKind::Cube => cube(dims),
            PhantomKind::Rings => rings(dims),
            PhantomKind::Ramp => ramp(dims),
            PhantomKind::Abdomen => abdomen::abdomen(dims),
            PhantomKind::Finger => soft_robot::finger(self.grid(dims)),
            PhantomKind::Cylinder => soft_robot::cylinder(self.grid(dims)),
            PhantomKind::Pendulum => soft_robot::pendulum(self.grid(dims)),
        })
    }
}

impl std::fmt::Display for PhantomKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for PhantomKind {
    type Err = PhantomError;

    /// Parses a phantom name (case-insensitive).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        PhantomKind::ALL
            .into_iter()
            .find(|k| k.name() == lower)
            .ok_or_else(|| PhantomError::UnknownName {
                name: s.to_string(),
            })
    }
}

/// A phantom could not be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PhantomError {
    /// No built-in phantom has this name.
    #[error(
        "unknown phantom `{name}`; built-in phantoms: head, cube, rings, ramp, abdomen, finger, cylinder, pendulum (e.g. `phantom:head`)"
    )]
    UnknownName {
        /// The name asked for.
        name: String,
    },
    /// Some dimension is zero.
    #[error("phantom dims {dims:?} must all be at least 1 voxel")]
    EmptyDims {
        /// The dims asked for.
        dims: [usize; 3],
    },
    /// The voxel count exceeds [`ReadOptions::DEFAULT_MAX_VOXELS`] (1024³).
    #[error("phantom dims {dims:?} exceed the limit of 1024³ voxels; ask for a lower resolution")]
    TooLarge {
        /// The dims asked for.
        dims: [usize; 3],
    },
}

fn check_dims(dims: [usize; 3]) -> Result<(), PhantomError> {
    if dims.contains(&0) {
        return Err(PhantomError::EmptyDims { dims });
    }
    match dims[0]
        .checked_mul(dims[1])
        .and_then(|v| v.checked_mul(dims[2]))
    {
        Some(n) if n <= ReadOptions::DEFAULT_MAX_VOXELS => Ok(()),
        _ => Err(PhantomError::TooLarge { dims }),
    }
}

/// Generates the phantom named `name` (see [`PhantomKind`]) at `dims` voxels.
pub fn phantom(name: &str, dims: [usize; 3]) -> Result<Volume, PhantomError> {
    name.parse::<PhantomKind>()?.generate(dims)
}

/// Fills a volume by evaluating `f` at every voxel centre (world mm), in
/// parallel over z slices.
fn fill<T: Copy + Default + Send + Sync>(grid: &Grid, f: impl Fn(DVec3) -> T + Sync) -> Vec<T> {
    let [nx, ny, _] = grid.dims;
    let mut data = vec![T::default(); grid.len()];
    data.par_chunks_mut((nx * ny).max(1))
        .enumerate()
        .for_each(|(k, slice)| {
            let z = grid.origin.z + k as f64 * grid.spacing.z;
            for j in 0..ny {
                let y = grid.origin.y + j as f64 * grid.spacing.y;
                let row = &mut slice[j * nx..(j + 1) * nx];
                for (i, v) in row.iter_mut().enumerate() {
                    let x = grid.origin.x + i as f64 * grid.spacing.x;
                    *v = f(DVec3::new(x, y, z));
                }
            }
        });
    data
}

/// An axis-aligned ellipsoid (centre and semi-axes in mm).
#[derive(Clone, Copy, Debug)]
struct Ellipsoid {
    centre: DVec3,
    semi: DVec3,
    inv_semi: DVec3,
}

impl Ellipsoid {
    fn new(centre: DVec3, semi: DVec3) -> Self {
        Self {
            centre,
            semi,
            inv_semi: semi.recip(),
        }
    }
    /// The same ellipsoid with every semi-axis shortened by `t` mm (an
    /// approximately uniform inner shell).
    fn shrunk(&self, t: f64) -> Self {
        Self::new(self.centre, self.semi - DVec3::splat(t))
    }
    #[inline]
    fn contains(&self, p: DVec3) -> bool {
        let q = (p - self.centre) * self.inv_semi;
        q.length_squared() <= 1.0
    }

    /// Fraction in [0, 1] of the voxel box centred at `p` with half-edges
    /// `half` (mm) inside the ellipsoid. Exactly 0 or 1 when the box lies
    /// wholly outside or inside: a point at normalised radius `r` is at
    /// least `|r − 1| · min semi-axis` from the surface (the ellipsoid
    /// holds the ball of that radius and is convex). Otherwise the surface
    /// is taken as its tangent plane at signed distance
    /// `d ≈ (r − 1) / |∇r|` (normal `n = ∇r / |∇r|`) and the coverage is the
    /// exact fraction of the box behind that plane ([`box_cut`]); the error
    /// is the surface's curvature across one voxel.
    fn coverage(&self, p: DVec3, half: DVec3) -> f64 {
        let q = (p - self.centre) * self.inv_semi;
        let r = q.length();
        if r <= 1e-9 {
            return 1.0;
        }
        let reach = half.length();
        let min_semi = self.semi.min_element();
        if (r - 1.0).abs() * min_semi >= reach {
            return if r < 1.0 { 1.0 } else { 0.0 };
        }
        let g = q * self.inv_semi / r;
        let gl = g.length();
        let n = g / gl;
        let d = (r - 1.0) / gl;
        let w = 2.0 * n.abs() * half;
        // Inside is the side `n · x < −d` of the plane through the box's
        // centre frame; from the box's lowest corner along n that is
        // `s < w_sum / 2 − d`.
        box_cut(w.to_array(), 0.5 * w.element_sum() - d)
    }
}

/// Physical size of the head phantom (mm).
pub const HEAD_SIZE_MM: DVec3 = DVec3::new(200.0, 240.0, 220.0);

/// Hounsfield values of the head phantom's materials.
pub mod hu {
    /// Air outside the head.
    pub const AIR: i16 = -1000;
    /// Skin / soft tissue.
    pub const SKIN: i16 = 40;
    /// Subcutaneous fat.
    pub const FAT: i16 = -100;
    /// Cortical bone (outer and inner tables of the skull).
    pub const CORTICAL: i16 = 1200;
    /// Diploë (spongy bone between the tables).
    pub const DIPLOE: i16 = 1000;
    /// Brain parenchyma.
    pub const BRAIN: i16 = 30;
    /// Cerebrospinal fluid in the ventricles.
    pub const VENTRICLE: i16 = 5;
    /// Vitreous humour of the eyes.
    pub const EYE: i16 = 10;
}

/// The CT-like head phantom (i16, Hounsfield units), 200 × 240 × 220 mm.
///
/// Nested axis-aligned ellipsoids centred on the origin, outer semi-axes
/// 92 × 112 × 102 mm (long axis anterior–posterior), from outside in:
/// air −1000 outside; skin 40 (0–3 mm deep); subcutaneous fat −100 (3–7 mm);
/// skull outer table 1200 (7–9.5 mm), diploë 1000 (9.5–12.5 mm), inner table
/// 1200 (12.5–14 mm); brain 30 inside. Two lateral ventricles 5 (semi-axes
/// 5 × 22 × 10 mm at x = ±10, y = −5, z = +15) and two eyes 10 (radius
/// 12 mm at x = ±32, y = −86, z = −20, cutting the orbits through the
/// skull; anterior is −y).
///
/// **Partial volume.** Like a scanner's, each voxel holds the
/// volume-weighted mix of the materials its box overlaps (rounded to whole
/// HU), not the material at its centre: hard voxel steps make every
/// iso-surface a staircase, which gradient shading draws as terraced rings.
/// The mix is exact for nested shells — `air + Σ coverage(shell) · Δvalue`
/// — with each ellipsoid's coverage of the voxel box from its tangent
/// plane (the exact box–plane cut; the error is the surface's curvature
/// across one voxel). Voxels farther than half a voxel diagonal from every
/// surface (a conservative bound) keep their exact material. The eyes
/// replace what they cover; voxels an eye's surface cuts are averaged over
/// 4³ sub-samples of the hard-edged materials instead.
///
/// `dims` are not checked here (a zero-sized axis gives an empty volume);
/// [`phantom`] and [`PhantomKind::generate`] refuse empty or oversized dims.
pub fn head(dims: [usize; 3]) -> Volume {
    let grid = PhantomKind::Head.grid(dims);
    let model = HeadModel::new();
    let half = 0.5 * grid.spacing;
    let data = fill(&grid, |p| model.voxel(p, half).round() as i16);
    Volume {
        grid,
        data: VoxelData::I16(data),
    }
}

/// The head phantom's geometry (see [`head`]).
struct HeadModel {
    /// Outside in: (ellipsoid, value inside − value outside, HU); the first
    /// [`NESTED_SHELLS`] nest, the ventricles follow.
    shells: [(Ellipsoid, i16); 8],
    /// The eyes, which replace what they cover.
    eyes: [Ellipsoid; 2],
}

/// The first shells of [`HeadModel::shells`] nest (skin to brain); the
/// rest (the ventricles) sit side by side inside the last of them.
const NESTED_SHELLS: usize = 6;

/// Sub-samples per axis where an eye cuts a voxel (the layered mix does not
/// hold there: the eyes replace skull, fat and skin alike).
const EYE_SUPERSAMPLE: usize = 4;

impl HeadModel {
    fn new() -> Self {
        let outer = Ellipsoid::new(DVec3::ZERO, DVec3::new(92.0, 112.0, 102.0));
        let ventricle =
            |x: f64| Ellipsoid::new(DVec3::new(x, -5.0, 15.0), DVec3::new(5.0, 22.0, 10.0));
        Self {
            shells: [
                (outer, hu::SKIN - hu::AIR),
                (outer.shrunk(3.0), hu::FAT - hu::SKIN),
                (outer.shrunk(7.0), hu::CORTICAL - hu::FAT),
                (outer.shrunk(9.5), hu::DIPLOE - hu::CORTICAL),
                (outer.shrunk(12.5), hu::CORTICAL - hu::DIPLOE),
                (outer.shrunk(14.0), hu::BRAIN - hu::CORTICAL),
                (ventricle(-10.0), hu::VENTRICLE - hu::BRAIN),
                (ventricle(10.0), hu::VENTRICLE - hu::BRAIN),
            ],
            eyes: [-32.0, 32.0]
                .map(|x| Ellipsoid::new(DVec3::new(x, -86.0, -20.0), DVec3::splat(12.0))),
        }
    }

    /// The material (HU) at point `p` (mm): hard edges.
    fn material(&self, p: DVec3) -> i16 {
        let mut v = hu::AIR;
        if !self.shells[0].0.contains(p) {
            return v;
        }
        if self.eyes.iter().any(|e| e.contains(p)) {
            return hu::EYE;
        }
        for (n, (e, dv)) in self.shells.iter().enumerate() {
            if e.contains(p) {
                v += dv;
            } else if n < NESTED_SHELLS {
                break;
            }
        }
        v
    }

    /// The partial-volume value (HU) of the voxel box centred at `p` with
    /// half-edges `half` (mm).
    fn voxel(&self, p: DVec3, half: DVec3) -> f64 {
        let eye: f64 = self.eyes.iter().map(|e| e.coverage(p, half)).sum();
        if eye > 0.0 && eye < 1.0 {
            let n = EYE_SUPERSAMPLE;
            let sum: f64 = (0..n * n * n)
                .map(|s| {
                    let f = DVec3::new((s % n) as f64, ((s / n) % n) as f64, (s / (n * n)) as f64);
                    f64::from(self.material(p + ((f + 0.5) / n as f64 - 0.5) * 2.0 * half))
                })
                .sum();
            return sum / (n * n * n) as f64;
        }
        let mut v = f64::from(hu::AIR);
        for (n, (e, dv)) in self.shells.iter().enumerate() {
            let c = e.coverage(p, half);
            if c == 0.0 && n < NESTED_SHELLS {
                // Nested: nothing inside an uncovered shell is covered
                // (the ventricles sit inside the brain).
                break;
            }
            v += c * f64::from(*dv);
        }
        v + eye * (f64::from(hu::EYE) - v)
    }
}

/// Fraction of a box cut off by a plane: `P(U₁ + U₂ + U₃ ≤ t)` for
/// independent `Uₐ` uniform on `[0, wₐ]` (the box's extents along the
/// plane's normal), `t` the distance from the box's lowest corner to the
/// plane along the normal. Exact (the piecewise-cubic box spline); widths
/// below 1e-6 of the largest are dropped (a plane parallel to a face).
fn box_cut(widths: [f64; 3], t: f64) -> f64 {
    let top = widths.iter().copied().fold(0.0, f64::max);
    let w: Vec<f64> = widths.into_iter().filter(|&x| x > 1e-6 * top).collect();
    let total: f64 = w.iter().sum();
    if t <= 0.0 {
        return 0.0;
    }
    if t >= total {
        return 1.0;
    }
    let k = w.len() as i32;
    let mut acc = 0.0;
    for subset in 0..(1u32 << k) {
        let shift: f64 = (0..k as usize)
            .filter(|&i| subset & (1 << i) != 0)
            .map(|i| w[i])
            .sum();
        let sign = if subset.count_ones() % 2 == 0 {
            1.0
        } else {
            -1.0
        };
        acc += sign * (t - shift).max(0.0).powi(k);
    }
    let factorial = (1..=k).product::<i32>() as f64;
    (acc / (factorial * w.iter().product::<f64>())).clamp(0.0, 1.0)
}

/// Value inside the [`cube`] phantom.
pub const CUBE_VALUE: u8 = 100;

/// The cube phantom (u8), 100 mm field: value [`CUBE_VALUE`] (100) in every
/// voxel whose index lies in `[⌊n/4⌋, n − ⌊n/4⌋)` on each axis (the central
/// half, by voxel index so the boundary is exact at any resolution), air 0
/// in the margin of `⌊n/4⌋` voxels on each side.
///
/// `dims` are not checked here (a zero-sized axis gives an empty volume);
/// [`phantom`] and [`PhantomKind::generate`] refuse empty or oversized dims.
pub fn cube(dims: [usize; 3]) -> Volume {
    let grid = PhantomKind::Cube.grid(dims);
    let [nx, ny, _] = dims;
    let inside = |i: usize, n: usize| i >= n / 4 && i < n - n / 4;
    let mut data = vec![0u8; grid.len()];
    data.par_chunks_mut((nx * ny).max(1))
        .enumerate()
        .for_each(|(k, slice)| {
            if !inside(k, dims[2]) {
                return;
            }
            for (l, v) in slice.iter_mut().enumerate() {
                if inside(l % nx, nx) && inside(l / nx, ny) {
                    *v = CUBE_VALUE;
                }
            }
        });
    Volume {
        grid,
        data: VoxelData::U8(data),
    }
}

/// Values of the [`rings`] phantom.
pub mod rings_values {
    /// Background.
    pub const BACKGROUND: u8 = 0;
    /// The soft half (x < 0).
    pub const SOFT: u8 = 100;
    /// The hard half (x ≥ 0).
    pub const HARD: u8 = 200;
}

/// The two-material ring phantom (u8), 100 mm field, after Fig. 5 of
/// "Parallel deformation of heterogeneous ChainMail models": an annulus
/// around the z axis (inner radius 20 mm, outer radius 40 mm, |z| ≤ 10 mm)
/// split by the plane x = 0 into a soft half (x < 0, value 100) and a hard
/// half (x ≥ 0, value 200); background 0.
///
/// `dims` are not checked here (a zero-sized axis gives an empty volume);
/// [`phantom`] and [`PhantomKind::generate`] refuse empty or oversized dims.
pub fn rings(dims: [usize; 3]) -> Volume {
    let grid = PhantomKind::Rings.grid(dims);
    let data = fill(&grid, |p| {
        let r = (p.x * p.x + p.y * p.y).sqrt();
        if (20.0..=40.0).contains(&r) && p.z.abs() <= 10.0 {
            if p.x < 0.0 {
                rings_values::SOFT
            } else {
                rings_values::HARD
            }
        } else {
            rings_values::BACKGROUND
        }
    });
    Volume {
        grid,
        data: VoxelData::U8(data),
    }
}

/// Coefficients `(a, b, c)` (value units per mm) of the [`ramp`] phantom.
pub const RAMP_COEFFS: DVec3 = DVec3::new(1.0, 0.5, 0.25);

/// The ramp phantom (f32), 100 mm field: value `a·x + b·y + c·z` at the
/// voxel centre `(x, y, z)` in mm, with `(a, b, c)` = [`RAMP_COEFFS`]. A
/// linear field, which trilinear and barycentric (piecewise-linear)
/// interpolation reproduce exactly, up to f32 rounding.
///
/// `dims` are not checked here (a zero-sized axis gives an empty volume);
/// [`phantom`] and [`PhantomKind::generate`] refuse empty or oversized dims.
pub fn ramp(dims: [usize; 3]) -> Volume {
    ramp_on(PhantomKind::Ramp.grid(dims), RAMP_COEFFS, 0.0)
}

/// A linear field `coeffs · p + offset` (f32) on any grid, `p` the voxel
/// centre in world mm.
pub fn ramp_on(grid: Grid, coeffs: DVec3, offset: f64) -> Volume {
    let data = fill(&grid, |p| (coeffs.dot(p) + offset) as f32);
    Volume {
        grid,
        data: VoxelData::F32(data),
    }
}

/// Where a scene's volume comes from.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum VolumeSource {
    /// A built-in phantom, by name (`phantom:<name>`; the name is checked
    /// when loaded).
    Phantom(String),
    /// A volume file, read with [`voxflex_io::read_volume`].
    File(PathBuf),
}

/// Parses a source string: `"phantom:<name>"` (e.g. `phantom:head`) is a
/// built-in phantom; anything else is a file path.
pub fn parse_source(s: &str) -> VolumeSource {
    match s.trim().strip_prefix("phantom:") {
        Some(name) => VolumeSource::Phantom(name.trim().to_string()),
        None => VolumeSource::File(PathBuf::from(s)),
    }
}

impl std::fmt::Display for VolumeSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VolumeSource::Phantom(n) => write!(f, "phantom:{n}"),
            VolumeSource::File(p) => write!(f, "{}", p.display()),
        }
    }
}

/// A [`VolumeSource`] could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The phantom could not be generated.
    #[error(transparent)]
    Phantom(#[from] PhantomError),
    /// The file could not be read.
    #[error(transparent)]
    Io(#[from] IoError),
}

impl VolumeSource {
    /// Loads the volume: a phantom is generated at `phantom_dims` voxels; a
    /// file is read with `opts` (its own dims win).
    pub fn load(
        &self,
        phantom_dims: [usize; 3],
        opts: &ReadOptions,
    ) -> Result<Volume, SourceError> {
        match self {
            VolumeSource::Phantom(name) => Ok(phantom(name, phantom_dims)?),
            VolumeSource::File(p) => Ok(voxflex_io::read_volume(p, opts)?),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(v: &Volume, p: DVec3) -> f32 {
        let idx = v.grid.world_to_index(p).round();
        v.get_f32(idx.x as usize, idx.y as usize, idx.z as usize)
    }

    #[test]
    fn head_has_its_materials_where_documented() {
        let v = phantom("head", [100, 120, 110]).unwrap();
        assert_eq!(v.grid.spacing, DVec3::splat(2.0));
        assert!(v.grid.centre().length() < 1e-9);
        assert_eq!(at(&v, DVec3::new(0.0, 0.0, 0.0)), hu::BRAIN as f32);
        assert_eq!(at(&v, DVec3::new(95.0, 0.0, 0.0)), hu::AIR as f32);
        // The voxel nearest (91, 0, 0) is centred at (91, 1, 1): its corner
        // pokes a hair out of the curved skin surface (partial volume).
        let skin = at(&v, DVec3::new(91.0, 0.0, 0.0));
        assert!((skin - hu::SKIN as f32).abs() <= 5.0, "{skin}");
        assert_eq!(at(&v, DVec3::new(87.0, 0.0, 0.0)), hu::FAT as f32);
        // Partial volume: the voxel [92, 94] mm in z straddles the outer
        // table's inner surface at z = 92.5 (102 − 9.5): ¾ cortical, ¼ diploë
        // (to 2 HU: the voxel is centred at x = y = 1, where the surface tilts).
        let mix = at(&v, DVec3::new(0.0, 0.0, 93.0));
        let want = 0.75 * hu::CORTICAL as f32 + 0.25 * hu::DIPLOE as f32;
        assert!((mix - want).abs() <= 2.0, "{mix} vs {want}");
        assert_eq!(at(&v, DVec3::new(0.0, 0.0, 91.0)), hu::DIPLOE as f32);
        assert_eq!(at(&v, DVec3::new(10.0, -5.0, 15.0)), hu::VENTRICLE as f32);
        assert_eq!(at(&v, DVec3::new(-10.0, -5.0, 15.0)), hu::VENTRICLE as f32);
        assert_eq!(at(&v, DVec3::new(32.0, -86.0, -20.0)), hu::EYE as f32);
        let (lo, hi) = v.value_range();
        assert_eq!((lo, hi), (-1000.0, 1200.0));
        // Left–right symmetric.
        let g = v.grid;
        for (i, j, k) in [(10, 60, 55), (30, 20, 70), (45, 100, 30)] {
            assert_eq!(v.get_f32(i, j, k), v.get_f32(g.dims[0] - 1 - i, j, k));
        }
    }

    /// Mirror-symmetric in x voxel for voxel (partial-volume values too),
    /// at even and odd widths.
    #[test]
    fn head_is_left_right_symmetric_everywhere() {
        for dims in [[50, 60, 55], [51, 40, 33]] {
            let v = head(dims);
            let mut worst = 0.0f32;
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        let d = (v.get_f32(i, j, k) - v.get_f32(dims[0] - 1 - i, j, k)).abs();
                        worst = worst.max(d);
                    }
                }
            }
            assert!(
                worst <= 1.0,
                "{dims:?}: mirrored voxels differ by {worst} HU"
            );
        }
    }

    #[test]
    fn cube_rings_ramp() {
        let c = phantom("cube", [8, 8, 4]).unwrap();
        assert_eq!(c.get_f32(2, 2, 1), 100.0);
        assert_eq!(c.get_f32(5, 5, 2), 100.0);
        assert_eq!(c.get_f32(1, 4, 2), 0.0);
        assert_eq!(c.get_f32(6, 4, 2), 0.0);
        assert_eq!(c.get_f32(4, 4, 0), 0.0);
        let VoxelData::U8(d) = &c.data else { panic!() };
        assert_eq!(d.iter().filter(|&&v| v == 100).count(), 4 * 4 * 2);

        let r = phantom("Rings", [50, 50, 50]).unwrap();
        assert_eq!(at(&r, DVec3::new(-30.0, 0.0, 0.0)), 100.0);
        assert_eq!(at(&r, DVec3::new(30.0, 0.0, 0.0)), 200.0);
        assert_eq!(at(&r, DVec3::new(0.0, 30.0, 0.0)), 200.0);
        assert_eq!(at(&r, DVec3::new(0.0, 0.0, 0.0)), 0.0);
        assert_eq!(at(&r, DVec3::new(-30.0, 0.0, 20.0)), 0.0);

        let m = phantom("ramp", [10, 20, 5]).unwrap();
        let g = m.grid;
        for l in [0, 17, 503, g.len() - 1] {
            let [i, j, k] = g.unlinear(l);
            let p = g.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
            let want = RAMP_COEFFS.dot(p) as f32;
            assert!((m.get_f32(i, j, k) - want).abs() < 1e-5);
        }
    }

    #[test]
    fn names_dims_and_sources() {
        assert_eq!(
            phantom("skull", [4, 4, 4]).unwrap_err().to_string(),
            "unknown phantom `skull`; built-in phantoms: head, cube, rings, ramp, abdomen, finger, cylinder, pendulum (e.g. `phantom:head`)"
        );
        assert_eq!(
            phantom("head", [4, 0, 4]).unwrap_err(),
            PhantomError::EmptyDims { dims: [4, 0, 4] }
        );
        assert!(matches!(
            phantom("head", [usize::MAX, 2, 2]),
            Err(PhantomError::TooLarge { .. })
        ));
        assert_eq!(
            parse_source("phantom:head"),
            VolumeSource::Phantom("head".into())
        );
        assert_eq!(
            parse_source("data/ct.nii.gz"),
            VolumeSource::File(PathBuf::from("data/ct.nii.gz"))
        );
        assert_eq!(parse_source(" phantom: cube ").to_string(), "phantom:cube");
        let v = parse_source("phantom:cube")
            .load([4, 4, 4], &ReadOptions::default())
            .unwrap();
        assert_eq!(v.grid.dims, [4, 4, 4]);
        let e = parse_source("/nonexistent/x.nii")
            .load([4, 4, 4], &ReadOptions::default())
            .unwrap_err();
        assert!(e.to_string().contains("/nonexistent/x.nii"), "{e}");
        for k in PhantomKind::ALL {
            let v = k.generate([3, 1, 2]).unwrap();
            assert_eq!(v.grid.dims, [3, 1, 2]);
        }
    }

    /// The head's voxels against a brute-force 8³ supersampling of its
    /// hard-edged materials: every voxel between the materials it
    /// overlaps, and the analytic coverage close to the supersampled mix.
    #[test]
    fn head_voxels_are_partial_volume_mixes() {
        let dims = [40, 48, 44];
        let v = head(dims);
        let g = v.grid;
        let hard = |p: DVec3| -> f64 {
            let outer = Ellipsoid::new(DVec3::ZERO, DVec3::new(92.0, 112.0, 102.0));
            let eyes = [-32.0, 32.0]
                .map(|x| Ellipsoid::new(DVec3::new(x, -86.0, -20.0), DVec3::splat(12.0)));
            let vents = [-10.0, 10.0]
                .map(|x| Ellipsoid::new(DVec3::new(x, -5.0, 15.0), DVec3::new(5.0, 22.0, 10.0)));
            let m = if !outer.contains(p) {
                hu::AIR
            } else if eyes.iter().any(|e| e.contains(p)) {
                hu::EYE
            } else if !outer.shrunk(3.0).contains(p) {
                hu::SKIN
            } else if !outer.shrunk(7.0).contains(p) {
                hu::FAT
            } else if !outer.shrunk(9.5).contains(p) {
                hu::CORTICAL
            } else if !outer.shrunk(12.5).contains(p) {
                hu::DIPLOE
            } else if !outer.shrunk(14.0).contains(p) {
                hu::CORTICAL
            } else if vents.iter().any(|e| e.contains(p)) {
                hu::VENTRICLE
            } else {
                hu::BRAIN
            };
            f64::from(m)
        };
        let (mut n_mixed, mut sum_err, mut max_err) = (0usize, 0.0f64, 0.0f64);
        // A line of voxels through the skull along x, and every 7th voxel.
        for l in (0..g.len()).step_by(7) {
            let [i, j, k] = g.unlinear(l);
            let c = g.index_to_world(DVec3::new(i as f64, j as f64, k as f64));
            let mut subs = Vec::with_capacity(512);
            for s in 0..512 {
                let f = DVec3::new((s % 8) as f64, ((s / 8) % 8) as f64, (s / 64) as f64);
                subs.push(hard(c + ((f + 0.5) / 8.0 - 0.5) * g.spacing));
            }
            let (lo, hi) = subs
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
            let got = f64::from(v.get_f32(i, j, k));
            if lo == hi {
                continue;
            }
            n_mixed += 1;
            // Between the materials the box overlaps (± rounding and the
            // tangent-plane model's slack at thin shells).
            assert!(
                got >= lo - 0.1 * (hi - lo) && got <= hi + 0.1 * (hi - lo),
                "{got} ∉ [{lo}, {hi}] at {c}"
            );
            let mean = subs.iter().sum::<f64>() / 512.0;
            let e = (got - mean).abs() / (hi - lo);
            sum_err += e;
            max_err = max_err.max(e);
        }
        let mean_err = sum_err / n_mixed as f64;
        eprintln!(
            "{n_mixed} mixed voxels: |analytic − 8³ supersampled| / range: mean {mean_err:.3}, max {max_err:.3}"
        );
        assert!(n_mixed > 500, "{n_mixed}");
        assert!(
            mean_err < 0.02 && max_err < 0.2,
            "relative error mean {mean_err}, max {max_err}"
        );
        // A boundary voxel between two materials holds a value strictly between.
        let x = g.world_to_index(DVec3::new(92.0, 0.0, 0.0)).round();
        let b = v.get_f32(x.x as usize, x.y as usize, x.z as usize);
        assert!(b > hu::AIR as f32 && b < hu::SKIN as f32, "{b}");
    }

    #[test]
    fn big_phantoms_are_fast() {
        // Generous bound: debug-ish test profile on 2 shared cores.
        let t = std::time::Instant::now();
        let v = head([256, 256, 256]);
        let dt = t.elapsed();
        assert_eq!(v.grid.len(), 1 << 24);
        assert!(dt.as_secs_f64() < 5.0, "head 256³ took {dt:?}");
        eprintln!("head 256³: {dt:?}");
    }

    #[test]
    fn head_phantom_summary() {
        let v = head([64, 64, 64]);
        let s = voxflex_core::stats::VolumeStats::compute(v.view());
        // Partial volume: at ~3.4 mm voxels no voxel lies wholly in the
        // 2.5 mm outer table, so the maximum is a cortical/diploë mix.
        assert_eq!(s.min, -1000.0);
        assert!(
            s.max > hu::DIPLOE as f32 && s.max < hu::CORTICAL as f32,
            "{}",
            s.max
        );
        assert_eq!(s.p1, -1000.0);
        let text = s.to_string();
        assert!(text.lines().count() == 6, "{text}");
        eprintln!("{text}");
    }
}
