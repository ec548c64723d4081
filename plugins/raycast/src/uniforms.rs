//! [`RayUniforms`]: every constant of one frame, shared bit for bit by the
//! rayon path ([`crate::cpu`]) and the WGSL path (`shaders/raycast/raycast.wgsl`,
//! struct `U`). All vectors are 16-byte `[f32; 4]`/`[u32; 4]`, so the
//! `repr(C)` layout equals the WGSL storage layout.
//!
//! Units: the camera vectors and the clip box and planes are in world mm;
//! `origin`/`inv_spacing` map world mm to **voxel indices** (voxel centres
//! at integers), where all sampling happens; the step is in mm along the
//! unit ray direction.

use crate::macrocell::MacroCells;
use crate::params::{GradientFilter, MapInterpolation, RaycastParams, RenderMode, Sampling};
use crate::transfer::{LUT_SIZE, Lut};
use voxflex_core::camera::{Camera, Projection};
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::opacity_map::OpacityMap;

/// `cells[3]` flag: empty-space skipping on.
pub const FLAG_ESS: u32 = 1;
/// `cells[3]` flag: early ray termination on.
pub const FLAG_EARLY_TERMINATION: u32 = 2;
/// `cells[3]` flag: gradient shading on.
pub const FLAG_SHADING: u32 = 4;
/// `cells[3]` flag: opacity maps read at the nearest voxel (else trilinear).
pub const FLAG_MAP_NEAREST: u32 = 8;
/// `cells[3]` flag: composite `background` behind the volume.
pub const FLAG_BACKGROUND: u32 = 16;
/// `cells[3]` flag: Sobel gradients (else central differences).
pub const FLAG_SOBEL: u32 = 32;
/// `cells[3]` flag: tricubic B-spline sampling (else trilinear).
pub const FLAG_TRICUBIC: u32 = 64;
/// `cells[3]` flag: per-pixel ray-start jitter.
pub const FLAG_JITTER: u32 = 128;

/// `pass_flags[0]` bit: the pass marches the rays going up in z (`d.z ≥ 0`).
pub const PASS_UP: u32 = 1;
/// `pass_flags[0]` bit: the pass marches the rays going down in z.
pub const PASS_DOWN: u32 = 2;
/// `pass_flags[0]` bit: the first pass (every ray starts afresh).
pub const PASS_FIRST: u32 = 4;
/// `pass_flags[0]` bit: the last pass (every ray writes its pixel and stats).
pub const PASS_LAST: u32 = 8;
/// `pass_flags[0]` bit: the volume is split into z-slabs (rays keep their
/// state between passes and stop where a sample leaves `slab`).
pub const PASS_SPLIT: u32 = 16;
/// The flags of the one pass over an unsplit volume.
pub const PASS_WHOLE: u32 = PASS_UP | PASS_DOWN | PASS_FIRST | PASS_LAST;

/// Word offset of the macro-cell minima in the GPU `accel` buffer (after the
/// [`LUT_SIZE`] + 1 prefix counts, padded to 4 words).
pub const ACCEL_CELLS_OFFSET: usize = (LUT_SIZE + 1).next_multiple_of(4);

/// The constants of one frame (see the module docs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RayUniforms {
    /// Eye position, world mm.
    pub eye: [f32; 4],
    /// Camera right, scaled to the half image width (ortho: mm; perspective: tan).
    pub right: [f32; 4],
    /// Camera up, scaled to the half image height.
    pub up: [f32; 4],
    /// Unit view direction.
    pub forward: [f32; 4],
    /// Width, height (pixels), projection (0 ortho, 1 perspective), mode (0 composite, 1 MIP).
    pub image: [u32; 4],
    /// Volume dims (voxels) and macro-cell edge (voxels).
    pub dims: [u32; 4],
    /// Macro-cells per axis and the `FLAG_*` bits.
    pub cells: [u32; 4],
    /// World position (mm) of voxel (0, 0, 0).
    pub origin: [f32; 4],
    /// 1 / spacing (voxels per mm) per axis.
    pub inv_spacing: [f32; 4],
    /// 1 / (2 · spacing) per axis: central differences → gradient per mm.
    pub grad_scale: [f32; 4],
    /// Step (mm), termination threshold, opacity unit distance (mm), macro-cell edge (f32).
    pub step: [f32; 4],
    /// TF table: value of entry 0, entries per value unit, entries, unused.
    pub lut: [f32; 4],
    /// Ambient, diffuse, specular, shininess.
    pub shading: [f32; 4],
    /// Background, linear premultiplied RGBA.
    pub background: [f32; 4],
    /// Lower corner of the ray box (voxel-centre box ∩ crop box), world mm.
    pub box_min: [f32; 4],
    /// Upper corner of the ray box, world mm.
    pub box_max: [f32; 4],
    /// Clip planes: unit normal (xyz) and `w = −n·p`; kept where `n·x + w ≥ 0`.
    pub planes: [[f32; 4]; 6],
    /// Clip planes in use, opacity map present (0/1), accel word offset of the cell minima, total cells.
    pub counts: [u32; 4],
    /// Combined opacity map box origin (voxels), `w` = outside value (u16 fixed point).
    pub map_origin: [u32; 4],
    /// Combined opacity map box dims (voxels), unused w.
    pub map_dims: [u32; 4],
    /// GPU only, a volume split into z-slabs: the footprint z-planes
    /// `[x, y)` of this pass, the first element of the bound volume window
    /// (z) and the first word of the bound opacity-map window (w).
    pub slab: [u32; 4],
    /// GPU only: `PASS_*` bits (x) of this pass.
    pub pass_flags: [u32; 4],
}

/// Bytes of [`RayUniforms`].
pub const UNIFORM_BYTES: usize = std::mem::size_of::<RayUniforms>();

fn v4(v: DVec3, w: f32) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w]
}

impl RayUniforms {
    /// The constants for rendering `grid` (macro-cells of edge `cell`
    /// voxels) from `camera`, with the combined opacity `map` (if any).
    pub fn new(
        p: &RaycastParams,
        grid: &Grid,
        camera: &Camera,
        lut: &Lut,
        cell: usize,
        map: Option<&OpacityMap>,
    ) -> Self {
        let counts = MacroCells::counts_for(grid.dims, cell);
        let (right, up, forward) = camera.basis();
        let aspect = camera.width as f64 / camera.height.max(1) as f64;
        let (half_h, proj) = match camera.projection {
            Projection::Orthographic { height_mm } => (0.5 * height_mm, 0),
            Projection::Perspective { fov_y_deg } => ((0.5 * fov_y_deg.to_radians()).tan(), 1),
        };
        let mode = match p.mode {
            RenderMode::Composite => 0,
            RenderMode::Mip => 1,
        };
        let mut flags = 0;
        if p.empty_space_skipping {
            flags |= FLAG_ESS;
        }
        if p.early_termination {
            flags |= FLAG_EARLY_TERMINATION;
        }
        if p.shading.enabled {
            flags |= FLAG_SHADING;
        }
        if p.opacity_map_interpolation == MapInterpolation::Nearest {
            flags |= FLAG_MAP_NEAREST;
        }
        if p.gradient == GradientFilter::Sobel {
            flags |= FLAG_SOBEL;
        }
        if p.sampling == Sampling::Tricubic {
            flags |= FLAG_TRICUBIC;
        }
        if p.jitter {
            flags |= FLAG_JITTER;
        }
        let background = p.background_linear();
        if background.is_some() {
            flags |= FLAG_BACKGROUND;
        }
        let spacing = grid.spacing;
        let min_spacing = spacing.min_element();
        let (mut lo, mut hi) = grid.world_bounds();
        if let Some(b) = &p.crop_box {
            lo = lo.max(DVec3::from_array(b.min));
            hi = hi.min(DVec3::from_array(b.max));
        }
        let mut planes = [[0f32; 4]; 6];
        for (slot, cp) in planes.iter_mut().zip(&p.clip_planes) {
            let n = DVec3::from_array(cp.normal).normalize();
            *slot = v4(n, -n.dot(DVec3::from_array(cp.point)) as f32);
        }
        let s = &p.shading;
        let (map_origin, map_dims) = match map {
            Some(m) => (
                [
                    m.origin[0] as u32,
                    m.origin[1] as u32,
                    m.origin[2] as u32,
                    m.outside as u32,
                ],
                [m.dims[0] as u32, m.dims[1] as u32, m.dims[2] as u32, 0],
            ),
            None => ([0; 4], [0; 4]),
        };
        Self {
            eye: v4(camera.eye(), 0.0),
            right: v4(right * half_h * aspect, 0.0),
            up: v4(up * half_h, 0.0),
            forward: v4(forward, 0.0),
            image: [camera.width, camera.height, proj, mode],
            dims: [
                grid.dims[0] as u32,
                grid.dims[1] as u32,
                grid.dims[2] as u32,
                cell as u32,
            ],
            cells: [counts[0] as u32, counts[1] as u32, counts[2] as u32, flags],
            origin: v4(grid.origin, 0.0),
            inv_spacing: v4(1.0 / spacing, 0.0),
            grad_scale: v4(0.5 / spacing, 0.0),
            step: [
                (p.sample_distance * min_spacing) as f32,
                p.termination_threshold as f32,
                p.opacity_unit_distance as f32,
                cell as f32,
            ],
            lut: [lut.lo, lut.scale, LUT_SIZE as f32, 0.0],
            shading: [
                s.ambient as f32,
                s.diffuse as f32,
                s.specular as f32,
                s.shininess as f32,
            ],
            background: background.unwrap_or([0.0; 4]),
            box_min: v4(lo, 0.0),
            box_max: v4(hi, 0.0),
            planes,
            counts: [
                p.clip_planes.len() as u32,
                map.is_some() as u32,
                ACCEL_CELLS_OFFSET as u32,
                counts.iter().product::<usize>() as u32,
            ],
            map_origin,
            map_dims,
            slab: [0, grid.dims[2] as u32, 0, 0],
            pass_flags: [PASS_WHOLE, 0, 0, 0],
        }
    }

    /// Flag bits.
    #[inline]
    pub fn flags(&self) -> u32 {
        self.cells[3]
    }
}
