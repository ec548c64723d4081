//! The WGSL path: buffers on the host's GPU through [`GpuService`] and the
//! two kernels `shaders/raycast/cells.wgsl` (macro-cell min/max over a box of
//! cells) and `shaders/raycast/raycast.wgsl` (one invocation per pixel).
//!
//! Buffers (32-bit scalars only, see docs/DESIGN.md "Backends"):
//! - the volume, f32 per voxel: the caller's own buffer for
//!   `RenderVolume::Gpu` (bound as is, no copy), else ours, uploaded once per
//!   version and only over the z-slab of planes the dirty region touches;
//! - `lut`: [`LUT_SIZE`] `vec4<f32>` (linear RGB, κ);
//! - `accel`: the TF's non-zero prefix counts, then cell minima, maxima,
//!   leap distances and a scratch copy (three `leap.wgsl` passes per change
//!   of cells or transfer function);
//! - `maps`: the combined opacity map, u16 packed two per u32;
//! - the output, RGBA8 packed per u32; `stats`: three u32 counters.
//!
//! A volume above `max_storage_buffer_binding_size` (128 MiB on lavapipe,
//! i.e. 32 Mi voxels of f32) is bound as z-slabs (`slabs.rs`): the
//! macro-cell kernel runs per slab over the cells in it, and the ray caster
//! runs one pass per slab for the rays going up in z (slabs ascending),
//! then one per slab for the rays going down (descending), each ray
//! resuming its loop from a per-pixel state (`state`, 32 bytes per pixel)
//! where the previous pass stopped; the opacity map is bound per slab too.
//! The image equals the unsplit one bit for bit. The image, the per-pixel
//! state and the macro-cell grid must each fit one binding.

use crate::macrocell::{IndexBox, MacroCells};
use crate::slabs::{self, Slab};
use crate::transfer::{LUT_SIZE, Lut};
use crate::uniforms::{
    ACCEL_CELLS_OFFSET, PASS_DOWN, PASS_FIRST, PASS_LAST, PASS_SPLIT, PASS_UP, PASS_WHOLE,
    RayUniforms,
};
use std::sync::Arc;
use voxflex_core::error::ModelError;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt};
use voxflex_core::opacity_map::OpacityMap;
use voxflex_core::render::RenderStats;
use voxflex_core::volume::{Sample, VolumeView};
use voxflex_core::with_voxels;

/// The WGSL of the ray-casting kernel.
pub const RAYCAST_WGSL: &str = include_str!("../../../shaders/raycast/raycast.wgsl");
/// The WGSL of the macro-cell kernel.
pub const CELLS_WGSL: &str = include_str!("../../../shaders/raycast/cells.wgsl");
/// The WGSL of the leap-distance kernel (one separable pass per dispatch).
pub const LEAP_WGSL: &str = include_str!("../../../shaders/raycast/leap.wgsl");

/// Threads per workgroup of the `cells.wgsl` and `leap.wgsl` kernels (one
/// invocation per macro-cell, `@workgroup_size(64, 1, 1)`).
const CELL_WORKGROUP: u32 = 64;
/// Pixels per side of a `raycast.wgsl` workgroup (`@workgroup_size(8, 8, 1)`).
const PIXEL_TILE: u64 = 8;

/// Binding numbers of the kernels' variables, per shader (named as there).
mod bind {
    /// `raycast.wgsl`.
    pub mod ray {
        pub const U: u32 = 0;
        pub const VOL: u32 = 1;
        pub const LUT: u32 = 2;
        pub const ACCEL: u32 = 3;
        pub const MAPS: u32 = 4;
        pub const OUT_PX: u32 = 5;
        pub const STATS: u32 = 6;
        pub const STATE: u32 = 7;
    }
    /// `cells.wgsl`.
    pub mod cells {
        pub const C: u32 = 0;
        pub const VOL: u32 = 1;
        pub const ACCEL: u32 = 2;
    }
    /// `leap.wgsl`.
    pub mod leap {
        pub const P: u32 = 0;
        pub const ACCEL: u32 = 1;
    }
}

/// Uniforms of `leap.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct LeapUniforms {
    counts: [u32; 4],
    offs: [u32; 4],
    lut: [f32; 4],
}

/// Uniforms of `cells.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
struct CellUniforms {
    dims: [u32; 4],
    counts: [u32; 4],
    lo: [u32; 4],
    size: [u32; 4],
    base: [u32; 4],
}

/// Where the GPU volume lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VolumeBuffer {
    /// The caller's buffer (`RenderVolume::Gpu`), bound directly.
    External(BufferId),
    /// Ours, uploaded from a CPU volume.
    Owned(BufferId),
}

/// GPU state of one renderer.
pub struct GpuRenderer {
    gpu: Arc<dyn GpuService>,
    /// Ray uniforms, one buffer per pass.
    uniforms: Vec<BufferId>,
    /// Cell uniforms, one buffer per slab.
    cell_uniforms: Vec<BufferId>,
    stats: BufferId,
    lut: BufferId,
    /// One uniforms buffer per leap pass.
    leap_uniforms: [BufferId; 3],
    volume: Option<VolumeBuffer>,
    /// Voxels of the current volume.
    voxels: usize,
    /// The accel buffer and its cell count.
    accel: Option<(BufferId, usize)>,
    /// The prefix currently written into `accel` (rewritten when either changes).
    accel_prefix: Option<Vec<u32>>,
    maps: Option<BufferId>,
    output: Option<(BufferId, u64)>,
    /// The rays' state between passes (a 32-byte stand-in when unsplit).
    state: (BufferId, u64),
}

fn too_big(what: &str, bytes: u64, limit: u64) -> ModelError {
    ModelError(format!(
        "{what} needs {:.1} MiB in one GPU binding, above this GPU's max_storage_buffer_binding_size \
         of {:.1} MiB; render on the CPU (backend = \"cpu\") or use a smaller volume/image",
        bytes as f64 / 1048576.0,
        limit as f64 / 1048576.0
    ))
}

impl GpuRenderer {
    /// Creates the fixed buffers.
    pub fn new(gpu: Arc<dyn GpuService>) -> Result<Self, ModelError> {
        let uniforms = vec![gpu.create_buffer(
            std::mem::size_of::<RayUniforms>() as u64,
            "raycast uniforms",
        )?];
        let cell_uniforms = vec![gpu.create_buffer(
            std::mem::size_of::<CellUniforms>() as u64,
            "raycast cell uniforms",
        )?];
        let state = (gpu.create_buffer(32, "raycast ray state")?, 32);
        let stats = gpu.create_buffer(16, "raycast stats")?;
        let lut = gpu.create_buffer((LUT_SIZE * 16) as u64, "raycast lut")?;
        let bytes = std::mem::size_of::<LeapUniforms>() as u64;
        let leap_uniforms = [
            gpu.create_buffer(bytes, "raycast leap uniforms x")?,
            gpu.create_buffer(bytes, "raycast leap uniforms y")?,
            gpu.create_buffer(bytes, "raycast leap uniforms z")?,
        ];
        Ok(Self {
            leap_uniforms,
            gpu,
            uniforms,
            cell_uniforms,
            stats,
            lut,
            volume: None,
            voxels: 0,
            accel: None,
            accel_prefix: None,
            maps: None,
            output: None,
            state,
        })
    }

    fn max_binding(&self) -> u64 {
        self.gpu.limits().max_storage_buffer_binding_size
    }

    /// The z-slabs of a volume of `dims` voxels with macro-cells of `cell`.
    fn slabs(&self, dims: [usize; 3], cell: usize) -> Result<Vec<Slab>, ModelError> {
        let l = self.gpu.limits();
        slabs::plan(
            dims,
            cell,
            l.max_storage_buffer_binding_size,
            l.min_storage_buffer_offset_alignment as u64,
        )
    }

    /// `n` buffers of `bytes` each in `list` (grown, never shrunk).
    fn buffers(
        gpu: &dyn GpuService,
        list: &mut Vec<BufferId>,
        n: usize,
        bytes: usize,
        label: &str,
    ) -> Result<(), ModelError> {
        while list.len() < n {
            list.push(gpu.create_buffer(bytes as u64, label)?);
        }
        Ok(())
    }

    fn volume_id(&self) -> Result<BufferId, ModelError> {
        match self.volume {
            Some(VolumeBuffer::External(id) | VolumeBuffer::Owned(id)) => Ok(id),
            None => Err(ModelError::new(
                "render before set_volume: no volume on the GPU",
            )),
        }
    }

    fn drop_owned_volume(&mut self) {
        if let Some(VolumeBuffer::Owned(id)) = self.volume.take() {
            self.gpu.destroy_buffer(id);
        }
    }

    /// Binds the caller's f32 buffer of `voxels` values as the volume.
    pub fn set_external_volume(&mut self, id: BufferId, voxels: usize) -> Result<(), ModelError> {
        let need = voxels as u64 * 4;
        let have = self.gpu.buffer_size(id)?;
        if have < need {
            return Err(ModelError(format!(
                "RenderVolume::Gpu buffer {} holds {have} bytes but the grid needs {need} (f32 per voxel)",
                id.0
            )));
        }
        if self.volume != Some(VolumeBuffer::External(id)) {
            self.drop_owned_volume();
        }
        self.volume = Some(VolumeBuffer::External(id));
        self.voxels = voxels;
        Ok(())
    }

    /// Uploads the z-slab of planes `region` touches of a CPU volume (the
    /// whole volume when the buffer is new or resized).
    pub fn upload_volume(
        &mut self,
        view: &VolumeView<'_>,
        region: IndexBox,
    ) -> Result<(), ModelError> {
        let voxels = view.grid.len();
        let need = voxels as u64 * 4;
        let most = self.gpu.limits().max_buffer_size;
        if need > most {
            return Err(ModelError(format!(
                "the volume needs a {need}-byte GPU buffer (f32) but the device allows {most} \
                 (max_buffer_size); render on the CPU (backend = \"cpu\") or use a smaller volume"
            )));
        }
        let mut region = region;
        let fresh = !matches!(self.volume, Some(VolumeBuffer::Owned(_))) || self.voxels != voxels;
        if fresh {
            self.drop_owned_volume();
            let id = self.gpu.create_buffer(need.max(4), "raycast volume")?;
            self.volume = Some(VolumeBuffer::Owned(id));
            self.voxels = voxels;
            region = IndexBox::all(view.grid.dims);
        }
        let id = self.volume_id()?;
        let plane = view.grid.dims[0] * view.grid.dims[1];
        let (k0, k1) = (region.lo[2], region.hi[2]);
        // Convert in chunks of planes to bound the staging memory (≤ 16 MiB).
        let per_chunk = ((4usize << 20) / plane.max(1)).max(1);
        let mut k = k0;
        while k <= k1 {
            let kend = (k + per_chunk - 1).min(k1);
            let (a, b) = (k * plane, (kend + 1) * plane);
            let staging: Vec<f32> = with_voxels!(view.data, |s| s[a..b]
                .iter()
                .map(|v| {
                    let v = v.to_f32();
                    if v.is_nan() { 0.0 } else { v }
                })
                .collect());
            self.gpu
                .write_buffer(id, a as u64 * 4, bytemuck::cast_slice(&staging))?;
            k = kend + 1;
        }
        Ok(())
    }

    /// Makes sure the accel buffer holds `cells` cells (new buffers start
    /// unbuilt; the caller rebuilds every cell then).
    fn ensure_accel(&mut self, cells: usize) -> Result<(BufferId, bool), ModelError> {
        if let Some((id, n)) = self.accel
            && n == cells
        {
            return Ok((id, false));
        }
        if let Some((id, _)) = self.accel.take() {
            self.gpu.destroy_buffer(id);
        }
        let bytes = ((ACCEL_CELLS_OFFSET + 4 * cells) * 4) as u64;
        if bytes > self.max_binding() {
            return Err(too_big("the macro-cell grid", bytes, self.max_binding()));
        }
        let id = self.gpu.create_buffer(bytes, "raycast accel")?;
        self.accel = Some((id, cells));
        self.accel_prefix = None;
        Ok((id, true))
    }

    /// Recomputes the min/max of the cells in `cells` of a grid of `dims`
    /// voxels with cell edge `cell`. Returns true when the whole grid was
    /// rebuilt (a new accel buffer) instead.
    pub fn rebuild_cells(
        &mut self,
        dims: [usize; 3],
        cell: usize,
        cells: IndexBox,
    ) -> Result<bool, ModelError> {
        let counts = MacroCells::counts_for(dims, cell);
        let total: usize = counts.iter().product();
        let (accel, fresh) = self.ensure_accel(total)?;
        let cells = if fresh { IndexBox::all(counts) } else { cells };
        let size = [
            cells.hi[0] + 1 - cells.lo[0],
            cells.hi[1] + 1 - cells.lo[1],
            cells.hi[2] + 1 - cells.lo[2],
        ];
        let slabs = self.slabs(dims, cell)?;
        Self::buffers(
            self.gpu.as_ref(),
            &mut self.cell_uniforms,
            slabs.len(),
            std::mem::size_of::<CellUniforms>(),
            "raycast cell uniforms",
        )?;
        let pipeline = self.gpu.compile(CELLS_WGSL, "main")?;
        let volume = self.volume_id()?;
        for (n, slab) in slabs.iter().enumerate() {
            // The cells of the box whose first footprint plane (c·s) lies in
            // the slab: their voxels (c·s − 1 … (c+1)·s + 1) are bound.
            let lo = cells.lo[2].max(slab.z0.div_ceil(cell));
            let hi = if n + 1 == slabs.len() {
                cells.hi[2]
            } else {
                cells.hi[2].min((slab.z1 / cell).saturating_sub(1))
            };
            if lo > hi {
                continue;
            }
            let nz = hi + 1 - lo;
            let count = size[0] * size[1] * nz;
            let u = CellUniforms {
                dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, cell as u32],
                counts: [
                    counts[0] as u32,
                    counts[1] as u32,
                    counts[2] as u32,
                    ACCEL_CELLS_OFFSET as u32,
                ],
                lo: [
                    cells.lo[0] as u32,
                    cells.lo[1] as u32,
                    lo as u32,
                    total as u32,
                ],
                size: [size[0] as u32, size[1] as u32, nz as u32, count as u32],
                base: [(slab.offset / 4) as u32, 0, 0, 0],
            };
            let ub = self.cell_uniforms[n];
            self.gpu.write_buffer(ub, 0, bytemuck::bytes_of(&u))?;
            self.gpu.dispatch(
                pipeline,
                &[
                    BufferBinding::whole(bind::cells::C, ub),
                    BufferBinding {
                        binding: bind::cells::VOL,
                        buffer: volume,
                        offset: slab.offset,
                        size: slab.bytes,
                    },
                    BufferBinding::whole(bind::cells::ACCEL, accel),
                ],
                self.gpu.workgroups_for(count as u64, CELL_WORKGROUP)?,
            )?;
        }
        Ok(fresh)
    }

    /// Reads the macro-cells back (for the value range and for tests).
    pub fn read_cells(&self, dims: [usize; 3], cell: usize) -> Result<MacroCells, ModelError> {
        let (id, total) = self
            .accel
            .ok_or_else(|| ModelError::new("no macro-cells on the GPU yet"))?;
        let mut words = vec![0u32; 2 * total];
        self.gpu.read_buffer(
            id,
            (ACCEL_CELLS_OFFSET * 4) as u64,
            bytemuck::cast_slice_mut(&mut words),
        )?;
        let mut m = MacroCells::new(dims, cell);
        if m.len() != total {
            return Err(ModelError::new(
                "macro-cell grid on the GPU has a stale size",
            ));
        }
        for l in 0..total {
            m.min[l] = f32::from_bits(words[l]);
            m.max[l] = f32::from_bits(words[total + l]);
        }
        Ok(m)
    }

    /// Recomputes the leap distances from the cells and the TF table (three
    /// separable passes; the result lands where `raycast.wgsl` reads it).
    pub fn update_leap(&mut self, lut: &Lut, counts: [usize; 3]) -> Result<(), ModelError> {
        self.write_prefix(&lut.nonzero_prefix)?;
        let (accel, total) = self
            .accel
            .ok_or_else(|| ModelError::new("leap distances before the macro-cells were built"))?;
        let base = ACCEL_CELLS_OFFSET as u32;
        let t = total as u32;
        let (a, b) = (base + 2 * t, base + 3 * t);
        let pipeline = self.gpu.compile(LEAP_WGSL, "main")?;
        let groups = self.gpu.workgroups_for(total as u64, CELL_WORKGROUP)?;
        // x: emptiness → a, y: a → b, z: b → a.
        for (axis, (src, dst)) in [(a, a), (a, b), (b, a)].into_iter().enumerate() {
            let u = LeapUniforms {
                counts: [counts[0] as u32, counts[1] as u32, counts[2] as u32, t],
                offs: [base, src, dst, axis as u32],
                lut: [lut.lo, lut.scale, LUT_SIZE as f32, 0.0],
            };
            let ub = self.leap_uniforms[axis];
            self.gpu.write_buffer(ub, 0, bytemuck::bytes_of(&u))?;
            self.gpu.dispatch(
                pipeline,
                &[
                    BufferBinding::whole(bind::leap::P, ub),
                    BufferBinding::whole(bind::leap::ACCEL, accel),
                ],
                groups,
            )?;
        }
        Ok(())
    }

    /// Uploads the transfer-function table and its prefix counts.
    pub fn set_lut(&mut self, lut: &Lut) -> Result<(), ModelError> {
        self.gpu
            .write_buffer(self.lut, 0, bytemuck::cast_slice(&lut.entries))?;
        self.write_prefix(&lut.nonzero_prefix)
    }

    fn write_prefix(&mut self, prefix: &[u32]) -> Result<(), ModelError> {
        if self.accel_prefix.as_deref() == Some(prefix) {
            return Ok(());
        }
        if let Some((id, _)) = self.accel {
            self.gpu.write_buffer(id, 0, bytemuck::cast_slice(prefix))?;
            self.accel_prefix = Some(prefix.to_vec());
        }
        Ok(())
    }

    /// Uploads the combined opacity map (or a placeholder when there is none).
    pub fn set_map(&mut self, map: Option<&OpacityMap>) -> Result<(), ModelError> {
        if let Some(id) = self.maps.take() {
            self.gpu.destroy_buffer(id);
        }
        let words: Vec<u32> = match map {
            Some(m) => m
                .values
                .chunks(2)
                .map(|p| p[0] as u32 | (p.get(1).copied().unwrap_or(0) as u32) << 16)
                .collect(),
            None => vec![0],
        };
        let words = if words.is_empty() { vec![0] } else { words };
        self.maps = Some(self.gpu.upload(&words, "raycast opacity map")?);
        Ok(())
    }

    /// Renders one frame into `out` (our buffer when `None`); returns the
    /// buffer written and the statistics.
    pub fn render(
        &mut self,
        u: &RayUniforms,
        lut: &Lut,
        out: Option<BufferId>,
    ) -> Result<(BufferId, RenderStats), ModelError> {
        let (w, h) = (u.image[0] as u64, u.image[1] as u64);
        let bytes = w * h * 4;
        if bytes > self.max_binding() {
            return Err(too_big("the image", bytes, self.max_binding()));
        }
        let limit = self.gpu.limits().max_compute_workgroups_per_dimension as u64;
        let groups = [w.div_ceil(PIXEL_TILE), h.div_ceil(PIXEL_TILE)];
        if groups.iter().any(|&g| g > limit) {
            return Err(ModelError(format!(
                "a {w}×{h} image needs {groups:?} workgroups of {PIXEL_TILE}×{PIXEL_TILE}, above the GPU's {limit} per dimension"
            )));
        }
        let target = match out {
            Some(id) => {
                let have = self.gpu.buffer_size(id)?;
                if have < bytes {
                    return Err(ModelError(format!(
                        "ImageTarget::Gpu buffer {} holds {have} bytes but a {w}×{h} image needs {bytes}",
                        id.0
                    )));
                }
                id
            }
            None => match self.output {
                Some((id, n)) if n == bytes => id,
                _ => {
                    if let Some((id, _)) = self.output.take() {
                        self.gpu.destroy_buffer(id);
                    }
                    let id = self.gpu.create_buffer(bytes, "raycast image")?;
                    self.output = Some((id, bytes));
                    id
                }
            },
        };
        let accel = self
            .accel
            .map(|a| a.0)
            .ok_or_else(|| ModelError::new("render before the macro-cells were built"))?;
        self.write_prefix(&lut.nonzero_prefix)?;
        if self.maps.is_none() {
            self.set_map(None)?;
        }
        let maps = self.maps.expect("map buffer just made");
        let dims = [0, 1, 2].map(|a| u.dims[a] as usize);
        let slabs = self.slabs(dims, u.dims[3] as usize)?;
        let split = slabs.len() > 1;
        let map_bytes = self.gpu.buffer_size(maps)?;
        if !split && map_bytes > self.max_binding() {
            return Err(too_big("the opacity map", map_bytes, self.max_binding()));
        }
        if split {
            let need = w * h * 32;
            if need > self.max_binding() {
                return Err(too_big(
                    "the rays' state for a volume split into slabs (32 bytes per pixel)",
                    need,
                    self.max_binding(),
                ));
            }
            if self.state.1 < need {
                self.gpu.destroy_buffer(self.state.0);
                self.state = (self.gpu.create_buffer(need, "raycast ray state")?, need);
            }
        }
        // Passes: one over an unsplit volume; else every slab ascending for
        // the rays going up, then every slab descending for those going down.
        let passes: Vec<(usize, u32)> = if split {
            let n = slabs.len();
            (0..n)
                .map(|i| (i, PASS_UP))
                .chain((0..n).rev().map(|i| (i, PASS_DOWN)))
                .collect()
        } else {
            vec![(0, PASS_WHOLE)]
        };
        Self::buffers(
            self.gpu.as_ref(),
            &mut self.uniforms,
            passes.len(),
            std::mem::size_of::<RayUniforms>(),
            "raycast uniforms",
        )?;
        self.gpu.write_buffer(self.stats, 0, &[0u8; 16])?;
        let pipeline = self.gpu.compile(RAYCAST_WGSL, "main")?;
        let volume = self.volume_id()?;
        let align = self.gpu.limits().min_storage_buffer_offset_alignment as u64;
        let map_origin = [0, 1, 2].map(|a| u.map_origin[a] as usize);
        let map_dims = [0, 1, 2].map(|a| u.map_dims[a] as usize);
        for (n, &(slab, dir)) in passes.iter().enumerate() {
            let sl = &slabs[slab];
            let mut pu = *u;
            let (map_offset, map_size) = if split {
                slabs::map_window(sl, map_origin, map_dims, align)
            } else {
                (0, map_bytes)
            };
            if split {
                let mut flags = dir | PASS_SPLIT;
                if n == 0 {
                    flags |= PASS_FIRST;
                }
                if n + 1 == passes.len() {
                    flags |= PASS_LAST;
                }
                pu.slab = [
                    sl.z0 as u32,
                    sl.z1 as u32,
                    (sl.offset / 4) as u32,
                    (map_offset / 4) as u32,
                ];
                pu.pass_flags = [flags, 0, 0, 0];
            }
            let ub = self.uniforms[n];
            self.gpu.write_buffer(ub, 0, bytemuck::bytes_of(&pu))?;
            self.gpu.dispatch(
                pipeline,
                &[
                    BufferBinding::whole(bind::ray::U, ub),
                    BufferBinding {
                        binding: bind::ray::VOL,
                        buffer: volume,
                        offset: sl.offset,
                        size: sl.bytes,
                    },
                    BufferBinding::whole(bind::ray::LUT, self.lut),
                    BufferBinding::whole(bind::ray::ACCEL, accel),
                    BufferBinding {
                        binding: bind::ray::MAPS,
                        buffer: maps,
                        offset: map_offset,
                        size: map_size.min(map_bytes - map_offset),
                    },
                    BufferBinding {
                        binding: bind::ray::OUT_PX,
                        buffer: target,
                        offset: 0,
                        size: bytes,
                    },
                    BufferBinding::whole(bind::ray::STATS, self.stats),
                    BufferBinding {
                        binding: bind::ray::STATE,
                        buffer: self.state.0,
                        offset: 0,
                        size: if split { w * h * 32 } else { 32 },
                    },
                ],
                [groups[0] as u32, groups[1] as u32, 1],
            )?;
        }
        let mut s = [0u32; 4];
        self.gpu.download(self.stats, &mut s)?;
        Ok((
            target,
            RenderStats {
                rays: w * h,
                samples: s[0] as u64 | (s[1] as u64) << 32,
                terminated_early: s[2] as u64,
            },
        ))
    }

    /// The service (for read-backs by the caller).
    pub fn service(&self) -> &Arc<dyn GpuService> {
        &self.gpu
    }
}

impl Drop for GpuRenderer {
    fn drop(&mut self) {
        let g = &self.gpu;
        for id in [self.stats, self.lut, self.state.0]
            .into_iter()
            .chain(self.leap_uniforms)
            .chain(self.uniforms.iter().copied())
            .chain(self.cell_uniforms.iter().copied())
        {
            g.destroy_buffer(id);
        }
        if let Some(VolumeBuffer::Owned(id)) = self.volume {
            g.destroy_buffer(id);
        }
        for id in self
            .accel
            .map(|a| a.0)
            .into_iter()
            .chain(self.maps)
            .chain(self.output.map(|o| o.0))
        {
            g.destroy_buffer(id);
        }
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;
