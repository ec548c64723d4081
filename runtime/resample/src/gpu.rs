//! The WGSL path of the resampler, written against [`GpuService`]
//! (`shaders/resample/*.wgsl`; the CPU twin is [`super::cpu`]).
//!
//! Kernels, each a 3-D-folded dispatch (no dimension above the device's
//! workgroup limit):
//!
//! - `block_bounds` — one workgroup of 64 per listed block; min/max of the
//!   deformed vertices with workgroup atomics on order-preserving `u32`
//!   encodings; the 24 bytes per block are read back so the shared planner
//!   can size the output and pick the dirty region;
//! - `clear` — `u32::MAX` ("no owner") over the clip box;
//! - `raster` (pass 1) — one invocation per cell of the listed blocks,
//!   `atomicMin(tet id)` into `array<atomic<u32>>`;
//! - `fill` (pass 2) — one invocation per voxel of the clip box; the
//!   interpolation mode is `Params.chi.w` (0 tetrahedral, 1 trilinear).
//!
//! Bindings (group 0): 0 parameters, 1–3 displacements x/y/z (f32, mm),
//! 4 block list, 5 block bounds, 6 output (slab), 7 mask (u8 per cell packed
//! in u32), 8 source values (f32), 9 filled bits (one per output voxel),
//! 10 the count of trilinear samples outside their source slab.
//!
//! **Binding limit** (see [`slabs`]). An output larger than one storage
//! binding is processed in z-slabs of output planes; pass 1 runs per output
//! slab on the blocks whose bounds meet it, writing only inside it. A source
//! larger than one binding (its f32 values, each displacement array) is
//! bound as z-slabs of whole cell blocks plus a halo of vertex planes; every
//! kernel runs per source slab on the blocks in it (`atomicMin` keys
//! accumulate across the passes) and `fill` per source slab on the voxels
//! whose owner cell is in it, a filled bit per output voxel telling the
//! values already written from the keys still waiting. The mask is bound
//! per source slab too. Results do not depend on the split: the kernels do
//! the same arithmetic on the same values, only the indices are relative to
//! the bound ranges.
//!
//! Each slab has its own parameter and block-list buffers, so the result is
//! right even if the host batches `write_buffer` calls ahead of earlier
//! dispatches.

use super::blocks::{BlockBounds, CELLS_PER_BLOCK, decode_ordered};
use super::{Job, KernelConsts, Kernels, OutputGrid, ResampleError, TetMask, VoxelBox};
use crate::error::GpuError;
use crate::grid::Grid;
use crate::volume::VolumeView;
use slabs::{OutputSlab, SourceSlab};
use voxflex_core::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt, PipelineId};

const COMMON: &str = include_str!("../../../shaders/resample/common.wgsl");
const DISPLACEMENT: &str = include_str!("../../../shaders/resample/displacement.wgsl");
const BOUNDS: &str = include_str!("../../../shaders/resample/bounds.wgsl");
const CLEAR: &str = include_str!("../../../shaders/resample/clear.wgsl");
const RASTER: &str = include_str!("../../../shaders/resample/raster.wgsl");
const FILL: &str = include_str!("../../../shaders/resample/fill.wgsl");

/// Threads per workgroup of every kernel (`WG` in `common.wgsl`).
const WORKGROUP: u32 = 64;

/// Binding numbers (see the module docs).
mod bind {
    pub const PARAMS: u32 = 0;
    pub const DX: u32 = 1;
    pub const DY: u32 = 2;
    pub const DZ: u32 = 3;
    pub const BLOCKS: u32 = 4;
    pub const BOUNDS: u32 = 5;
    pub const OUT: u32 = 6;
    pub const MASK: u32 = 7;
    pub const VALUES: u32 = 8;
    pub const FILLED: u32 = 9;
    pub const MISSED: u32 = 10;
}

#[path = "gpu_slabs.rs"]
pub(crate) mod slabs;

/// The full WGSL source of each kernel (for tools that validate shaders).
pub fn kernel_sources() -> [(&'static str, String); 4] {
    [
        (
            "block_bounds",
            format!("{COMMON}\n{DISPLACEMENT}\n{BOUNDS}"),
        ),
        ("clear", format!("{COMMON}\n{CLEAR}")),
        ("raster", format!("{COMMON}\n{DISPLACEMENT}\n{RASTER}")),
        ("fill", format!("{COMMON}\n{DISPLACEMENT}\n{FILL}")),
    ]
}

/// `Params` of `common.wgsl` (all 16-byte vectors of 32-bit scalars).
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
struct Params {
    vdim: [u32; 4],
    cdim: [u32; 4],
    bdim: [u32; 4],
    inv: [f32; 4],
    oorg: [i32; 4],
    odim: [u32; 4],
    clo: [i32; 4],
    chi: [i32; 4],
    misc: [f32; 4],
    slab: [u32; 4],
    cells: [u32; 4],
}

/// A source volume on the GPU: its grid and its values as f32 (one buffer,
/// x fastest; bound in z-slabs when larger than one storage binding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuSource {
    /// Geometry (mm).
    pub grid: Grid,
    /// `grid.len()` f32 values.
    pub values: BufferId,
}

impl GpuSource {
    /// Converts a volume to f32 and uploads it; fails when it does not fit
    /// one buffer (`max_buffer_size`) or when one cell block of its z-planes
    /// and their halo do not fit one storage binding.
    pub fn upload(gpu: &dyn GpuService, volume: VolumeView<'_>) -> Result<Self, ResampleError> {
        super::check_len("source volume", &volume.grid, volume.data.len())?;
        check_source(gpu, &volume.grid)?;
        let values = volume.data.to_f32_vec();
        let id = gpu.upload(&values, "voxflex.resample.source")?;
        Ok(Self {
            grid: volume.grid,
            values: id,
        })
    }

    /// Frees the values buffer.
    pub fn release(self, gpu: &dyn GpuService) {
        gpu.destroy_buffer(self.values);
    }
}

fn check_binding(
    gpu: &dyn GpuService,
    what: &'static str,
    bytes: u64,
) -> Result<(), ResampleError> {
    let limit = gpu.limits().max_storage_buffer_binding_size;
    if bytes > limit {
        return Err(ResampleError::BindingTooLarge { what, bytes, limit });
    }
    Ok(())
}

/// The source slabs of a grid on this device, or why it cannot be bound.
fn check_source(gpu: &dyn GpuService, grid: &Grid) -> Result<Vec<SourceSlab>, ResampleError> {
    let l = gpu.limits();
    let bytes = grid.len() as u64 * 4;
    if bytes > l.max_buffer_size {
        return Err(ResampleError::Gpu(GpuError(format!(
            "the source grid {:?} needs {bytes}-byte buffers (f32) but the device allows {} \
             (max_buffer_size); use the CPU backend or a smaller volume",
            grid.dims, l.max_buffer_size
        ))));
    }
    slabs::source_slabs(
        grid.dims,
        l.max_storage_buffer_binding_size,
        l.min_storage_buffer_offset_alignment as u64,
    )
}

/// Reads `out.len()` f32 from the start of a buffer in pieces of ≤ 64 MiB.
pub(crate) fn read_f32(
    gpu: &dyn GpuService,
    buf: BufferId,
    out: &mut [f32],
) -> Result<(), GpuError> {
    const CHUNK: usize = 16 << 20;
    for (n, chunk) in out.chunks_mut(CHUNK).enumerate() {
        gpu.read_buffer(buf, (n * CHUNK * 4) as u64, bytemuck::cast_slice_mut(chunk))?;
    }
    Ok(())
}

#[derive(Clone, Copy, Debug)]
struct Pipelines {
    bounds: PipelineId,
    clear: PipelineId,
    raster: PipelineId,
    fill: PipelineId,
}

/// A buffer this resampler owns, with its size in bytes.
#[derive(Clone, Copy, Debug)]
struct Owned {
    id: BufferId,
    bytes: u64,
}

/// Reuses `slot`'s buffer when it holds at least `bytes`, else replaces it.
fn ensure(
    gpu: &dyn GpuService,
    slot: &mut Option<Owned>,
    bytes: u64,
    label: &str,
) -> Result<BufferId, GpuError> {
    let bytes = bytes.max(4).next_multiple_of(4);
    if let Some(o) = slot
        && o.bytes >= bytes
    {
        return Ok(o.id);
    }
    if let Some(o) = slot.take() {
        gpu.destroy_buffer(o.id);
    }
    let id = gpu.create_buffer(bytes, label)?;
    *slot = Some(Owned { id, bytes });
    Ok(id)
}

/// GPU resources a [`super::Resampler`] keeps between calls (all created on
/// one [`GpuService`]; freed by [`super::Resampler::release_gpu`]).
#[derive(Debug, Default)]
pub(crate) struct GpuState {
    pipelines: Option<Pipelines>,
    output: Option<Owned>,
    bounds: Option<Owned>,
    /// Parameters per slab (index 0 also serves the bounds kernel).
    params: Vec<Option<Owned>>,
    /// Block list per slab (index 0 also serves the bounds kernel).
    lists: Vec<Option<Owned>>,
    mask: Option<Owned>,
    mask_generation: Option<u64>,
    dummy: Option<Owned>,
    /// One bit per output voxel (used while the source is split).
    filled: Option<Owned>,
    /// One `u32`: trilinear samples outside their source slab's window.
    missed: Option<Owned>,
    /// The source slabs of the prepared source (one when it fits a binding).
    source_slabs: Vec<SourceSlab>,
}

impl GpuState {
    /// Checks the inputs, compiles the kernels once and uploads a changed mask.
    pub(crate) fn prepare(
        &mut self,
        gpu: &dyn GpuService,
        source: &GpuSource,
        disp: [BufferId; 3],
        mask: Option<&TetMask>,
    ) -> Result<(), ResampleError> {
        let n = source.grid.len() as u64 * 4;
        self.source_slabs = check_source(gpu, &source.grid)?;
        check_buffer(gpu, "source values buffer", source.values, n)?;
        for (what, id) in [
            ("x displacement buffer", disp[0]),
            ("y displacement buffer", disp[1]),
            ("z displacement buffer", disp[2]),
        ] {
            check_buffer(gpu, what, id, n)?;
        }
        if self.pipelines.is_none() {
            let [b, c, r, f] = kernel_sources();
            self.pipelines = Some(Pipelines {
                bounds: gpu.compile(&b.1, b.0)?,
                clear: gpu.compile(&c.1, c.0)?,
                raster: gpu.compile(&r.1, r.0)?,
                fill: gpu.compile(&f.1, f.0)?,
            });
        }
        ensure(gpu, &mut self.dummy, 4, "voxflex.resample.dummy")?;
        ensure(gpu, &mut self.missed, 4, "voxflex.resample.missed")?;
        match mask.filter(|m| !m.is_empty()) {
            None => self.mask_generation = None,
            Some(m) if self.mask_generation != Some(m.generation()) => {
                let bytes = m.bytes();
                if self.source_slabs.len() == 1 {
                    check_binding(gpu, "tetrahedron mask", bytes.len() as u64)?;
                }
                let mut padded = bytes.to_vec();
                padded.resize(bytes.len().next_multiple_of(4), 0);
                let id = ensure(
                    gpu,
                    &mut self.mask,
                    padded.len() as u64,
                    "voxflex.resample.mask",
                )?;
                gpu.write_buffer(id, 0, &padded)?;
                self.mask_generation = Some(m.generation());
            }
            Some(_) => {}
        }
        Ok(())
    }

    pub(crate) fn kernels<'a>(
        &'a mut self,
        gpu: &'a dyn GpuService,
        source: &'a GpuSource,
        disp: [BufferId; 3],
        has_mask: bool,
    ) -> GpuKernels<'a> {
        GpuKernels {
            state: self,
            gpu,
            source,
            disp,
            has_mask,
        }
    }

    pub(crate) fn output_buffer(&self) -> Option<BufferId> {
        self.output.map(|o| o.id)
    }

    pub(crate) fn release(&mut self, gpu: &dyn GpuService) {
        let mut all = vec![
            self.output.take(),
            self.bounds.take(),
            self.mask.take(),
            self.dummy.take(),
            self.filled.take(),
            self.missed.take(),
        ];
        all.append(&mut self.params);
        all.append(&mut self.lists);
        for o in all.into_iter().flatten() {
            gpu.destroy_buffer(o.id);
        }
        *self = GpuState::default();
    }

    fn slot_buffers(
        &mut self,
        gpu: &dyn GpuService,
        slot: usize,
        list_bytes: u64,
    ) -> Result<(BufferId, BufferId), GpuError> {
        if self.params.len() <= slot {
            self.params.resize(slot + 1, None);
            self.lists.resize(slot + 1, None);
        }
        let p = ensure(
            gpu,
            &mut self.params[slot],
            size_of::<Params>() as u64,
            "voxflex.resample.params",
        )?;
        let l = ensure(
            gpu,
            &mut self.lists[slot],
            list_bytes,
            "voxflex.resample.blocks",
        )?;
        Ok((p, l))
    }
}

fn check_buffer(
    gpu: &dyn GpuService,
    what: &'static str,
    id: BufferId,
    need: u64,
) -> Result<(), ResampleError> {
    let size = gpu.buffer_size(id)?;
    if size < need {
        return Err(ResampleError::Gpu(GpuError(format!(
            "{what} {id:?} holds {size} bytes but the source grid needs {need}"
        ))));
    }
    Ok(())
}

/// The GPU half of one resampling call.
pub(crate) struct GpuKernels<'a> {
    state: &'a mut GpuState,
    gpu: &'a dyn GpuService,
    source: &'a GpuSource,
    disp: [BufferId; 3],
    has_mask: bool,
}

/// Positions in `blocks` of the blocks whose cells lie in `slab` (all of
/// them when `all`); `per_plane` blocks per block z-layer.
fn blocks_in(slab: &SourceSlab, blocks: &[u32], per_plane: u32, all: bool) -> Vec<usize> {
    (0..blocks.len())
        .filter(|&n| {
            let z = (blocks[n] / per_plane) as usize * super::blocks::BLOCK_EDGE;
            all || (slab.z0..slab.z1).contains(&z)
        })
        .collect()
}

impl GpuKernels<'_> {
    fn split(&self) -> bool {
        self.state.source_slabs.len() > 1
    }

    /// Parameters of a pass over source slab `s` (mask base word included).
    fn base_params(&self, c: &KernelConsts, s: &SourceSlab) -> Params {
        let v = c.mesh.vertex_dims();
        let cd = c.mesh.cell_dims();
        let bd = c.layout.block_dims();
        Params {
            vdim: [v[0] as u32, v[1] as u32, v[2] as u32, 0],
            cdim: [
                cd[0] as u32,
                cd[1] as u32,
                cd[2] as u32,
                (self.mask_range(c, s).0 / 4) as u32,
            ],
            bdim: [bd[0] as u32, bd[1] as u32, bd[2] as u32, 0],
            inv: [c.inv_spacing[0], c.inv_spacing[1], c.inv_spacing[2], c.eps],
            oorg: [0, 0, 0, self.has_mask as i32],
            chi: [0, 0, 0, c.interpolation.code()],
            misc: [c.background, 0.0, 0.0, 0.0],
            slab: [(s.offset / 4) as u32, s.v0 as u32, s.v1 as u32, 0],
            cells: [s.z0 as u32, s.z1 as u32, 0, self.split() as u32],
            ..Default::default()
        }
    }

    /// Source values, bound over slab `s`'s window.
    fn values_binding(&self, s: &SourceSlab) -> BufferBinding {
        BufferBinding {
            binding: bind::VALUES,
            buffer: self.source.values,
            offset: s.offset,
            size: s.bytes,
        }
    }

    /// Displacements x, y, z, bound over slab `s`'s window.
    fn disp_bindings(&self, s: &SourceSlab) -> [BufferBinding; 3] {
        [bind::DX, bind::DY, bind::DZ].map(|b| BufferBinding {
            binding: b,
            buffer: self.disp[(b - bind::DX) as usize],
            offset: s.offset,
            size: s.bytes,
        })
    }

    /// `(byte offset, bytes)` of the mask bytes of slab `s`'s cells (`(0, 0)`:
    /// the whole buffer).
    fn mask_range(&self, c: &KernelConsts, s: &SourceSlab) -> (u64, u64) {
        if !self.has_mask || !self.split() {
            return (0, 0);
        }
        let cd = c.mesh.cell_dims();
        let plane = (cd[0] * cd[1]) as u64;
        let align = (self.gpu.limits().min_storage_buffer_offset_alignment as u64).max(4);
        let offset = s.z0 as u64 * plane / align * align;
        let end = (s.z1 as u64 * plane).next_multiple_of(4);
        (offset, (end - offset).max(4))
    }

    fn mask_binding(&self, c: &KernelConsts, s: &SourceSlab) -> BufferBinding {
        let id = match (self.has_mask, self.state.mask, self.state.dummy) {
            (true, Some(m), _) => m.id,
            (_, _, Some(d)) => d.id,
            _ => unreachable!("prepare() creates the dummy buffer"),
        };
        let (offset, size) = self.mask_range(c, s);
        BufferBinding {
            binding: bind::MASK,
            buffer: id,
            offset,
            size,
        }
    }

    /// The filled bits of output slab `o` (a 4-byte stand-in when the
    /// source is not split) and the word index of the bound range's start.
    fn filled_binding(&self, o: &OutputSlab) -> (BufferBinding, u32) {
        let id = self.state.filled.expect("rasterise() creates it").id;
        let (offset, size) = if self.split() {
            let align = self.gpu.limits().min_storage_buffer_offset_alignment as u64;
            slabs::filled_bits(o.offset / 4, (o.offset + o.bytes) / 4, align)
        } else {
            (0, 4)
        };
        let b = BufferBinding {
            binding: bind::FILLED,
            buffer: id,
            offset,
            size,
        };
        (b, (offset / 4) as u32)
    }
}

impl Kernels for GpuKernels<'_> {
    fn block_bounds(
        &mut self,
        c: &KernelConsts,
        blocks: &[u32],
        out: &mut [BlockBounds],
    ) -> Result<(), ResampleError> {
        if blocks.is_empty() {
            return Ok(());
        }
        let gpu = self.gpu;
        let pl = self
            .state
            .pipelines
            .expect("prepare() compiles the kernels");
        let bd = c.layout.block_dims();
        let per_plane = (bd[0] * bd[1]) as u32;
        let sources = self.state.source_slabs.clone();
        let all = sources.len() == 1;
        for (n, src) in sources.iter().enumerate() {
            // Positions in `blocks` (`None`: all of them, in order).
            let picked = (!all).then(|| blocks_in(src, blocks, per_plane, false));
            let list: std::borrow::Cow<'_, [u32]> = match &picked {
                None => blocks.into(),
                Some(p) => p.iter().map(|&i| blocks[i]).collect(),
            };
            if list.is_empty() {
                continue;
            }
            let mut p = self.base_params(c, src);
            p.bdim[3] = list.len() as u32;
            let (pb, lb) = self.state.slot_buffers(gpu, n, list.len() as u64 * 4)?;
            let bb = ensure(
                gpu,
                &mut self.state.bounds,
                list.len() as u64 * 24,
                "voxflex.resample.bounds",
            )?;
            gpu.write_buffer(pb, 0, bytemuck::bytes_of(&p))?;
            gpu.write_buffer(lb, 0, bytemuck::cast_slice(&list[..]))?;
            let mut b = vec![
                BufferBinding::whole(bind::PARAMS, pb),
                BufferBinding::whole(bind::BLOCKS, lb),
                BufferBinding::whole(bind::BOUNDS, bb),
            ];
            b.extend(self.disp_bindings(src));
            let groups = voxflex_core::gpu::workgroups_1d(
                list.len() as u64,
                1,
                gpu.limits().max_compute_workgroups_per_dimension,
            )?;
            gpu.dispatch(pl.bounds, &b, groups)?;
            let mut words = vec![0u32; list.len() * 6];
            gpu.read_buffer(bb, 0, bytemuck::cast_slice_mut(&mut words))?;
            for (k, w) in words.chunks_exact(6).enumerate() {
                let i = picked.as_ref().map_or(k, |p| p[k]);
                out[i] = BlockBounds {
                    min: [
                        decode_ordered(w[0]),
                        decode_ordered(w[1]),
                        decode_ordered(w[2]),
                    ],
                    max: [
                        decode_ordered(w[3]),
                        decode_ordered(w[4]),
                        decode_ordered(w[5]),
                    ],
                };
            }
        }
        Ok(())
    }

    fn allocate_output(&mut self, output: &OutputGrid) -> Result<(), ResampleError> {
        let bytes = output.len() as u64 * 4;
        let limits = self.gpu.limits();
        if bytes > limits.max_buffer_size {
            return Err(ResampleError::Gpu(GpuError(format!(
                "the output grid {:?} needs a {bytes}-byte buffer but the device allows {} (max_buffer_size)",
                output.dims, limits.max_buffer_size
            ))));
        }
        if self.state.output.is_some_and(|o| o.bytes == bytes.max(4)) {
            return Ok(());
        }
        if let Some(o) = self.state.output.take() {
            self.gpu.destroy_buffer(o.id);
        }
        ensure(
            self.gpu,
            &mut self.state.output,
            bytes,
            "voxflex.resample.output",
        )?;
        Ok(())
    }

    fn rasterise(&mut self, job: &Job<'_>) -> Result<(), ResampleError> {
        let gpu = self.gpu;
        let limits = gpu.limits();
        let pl = self
            .state
            .pipelines
            .expect("prepare() compiles the kernels");
        let out_id = self.state.output.expect("allocate_output() ran").id;
        let missed = self.state.missed.expect("prepare() creates it").id;
        let o = job.output;
        let r = job.region;
        let oz0 = (r.lo[2] - o.origin_index[2]) as usize;
        let oz1 = (r.hi[2] - o.origin_index[2]) as usize;
        let outs = slabs::output_slabs(
            o.dims,
            oz0,
            oz1,
            limits.max_storage_buffer_binding_size,
            limits.min_storage_buffer_offset_alignment as u64,
        )?;
        let sources = self.state.source_slabs.clone();
        let split = self.split();
        let filled = if split {
            slabs::filled_bytes(o.len() as u64)
        } else {
            4
        };
        ensure(
            gpu,
            &mut self.state.filled,
            filled,
            "voxflex.resample.filled",
        )?;
        if split {
            gpu.write_buffer(missed, 0, &[0; 4])?;
        }
        let bd = job.consts.layout.block_dims();
        let per_plane = (bd[0] * bd[1]) as u32;
        let missed = BufferBinding {
            binding: bind::MISSED,
            buffer: missed,
            offset: 0,
            size: 4,
        };
        let mut slot = 0;
        for os in &outs {
            let clip = VoxelBox {
                lo: [r.lo[0], r.lo[1], os.z0 as i32 + o.origin_index[2]],
                hi: [r.hi[0], r.hi[1], os.z1 as i32 + o.origin_index[2]],
            };
            let out = BufferBinding {
                binding: bind::OUT,
                buffer: out_id,
                offset: os.offset,
                size: os.bytes,
            };
            let (filled, filled_base) = self.filled_binding(os);
            let voxels = clip.count();
            let vgroups = gpu.workgroups_for(voxels, WORKGROUP)?;
            // Parameters per source slab; clear once; pass 1 for every
            // source slab; then pass 2 for those that rasterised something
            // (or the first alone: every voxel gets the background).
            let mut passes = Vec::with_capacity(sources.len());
            for src in &sources {
                let blocks: Vec<u32> = if outs.len() == 1 && !split {
                    job.blocks.to_vec()
                } else {
                    blocks_in(src, job.blocks, per_plane, !split)
                        .into_iter()
                        .map(|n| job.blocks[n])
                        .filter(|&b| job.bounds[b as usize].touches(clip.lo, clip.hi))
                        .collect()
                };
                let mut p = self.base_params(job.consts, src);
                p.bdim[3] = blocks.len() as u32;
                p.oorg[..3].copy_from_slice(&o.origin_index);
                p.odim = [
                    o.dims[0] as u32,
                    o.dims[1] as u32,
                    o.dims[2] as u32,
                    (os.offset / 4) as u32,
                ];
                p.clo[..3].copy_from_slice(&clip.lo);
                p.chi[..3].copy_from_slice(&clip.hi);
                p.cells[2] = filled_base;
                let (pb, lb) = self
                    .state
                    .slot_buffers(gpu, slot, blocks.len() as u64 * 4)?;
                slot += 1;
                gpu.write_buffer(pb, 0, bytemuck::bytes_of(&p))?;
                if !blocks.is_empty() {
                    gpu.write_buffer(lb, 0, bytemuck::cast_slice(&blocks))?;
                }
                let params = BufferBinding::whole(bind::PARAMS, pb);
                passes.push((params, src, lb, blocks.len() as u64));
            }
            gpu.dispatch(pl.clear, &[passes[0].0, out, filled], vgroups)?;
            for &(params, src, lb, n) in passes.iter().filter(|p| p.3 > 0) {
                let mut b = vec![
                    params,
                    out,
                    BufferBinding::whole(bind::BLOCKS, lb),
                    self.mask_binding(job.consts, src),
                ];
                b.extend(self.disp_bindings(src));
                let cells = n * CELLS_PER_BLOCK as u64;
                gpu.dispatch(pl.raster, &b, gpu.workgroups_for(cells, WORKGROUP)?)?;
            }
            let mut fills: Vec<_> = passes.iter().filter(|p| p.3 > 0).collect();
            if fills.is_empty() {
                fills.push(&passes[0]);
            }
            for &&(params, src, _, _) in &fills {
                let mut b = vec![params, out, self.values_binding(src), filled, missed];
                b.extend(self.disp_bindings(src));
                gpu.dispatch(pl.fill, &b, vgroups)?;
            }
        }
        if split {
            let mut n = [0u32];
            gpu.read_buffer(missed.buffer, 0, bytemuck::cast_slice_mut(&mut n))?;
            if n[0] > 0 {
                return Err(ResampleError::SlabHaloExceeded { voxels: n[0] });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_layout_matches_wgsl() {
        // 11 vec4 members of 16 bytes, no padding.
        assert_eq!(size_of::<Params>(), 176);
    }

    /// The numbers of a `var<private> NAME: array<u32, N> = array<u32, N>(…);` table.
    fn wgsl_table(src: &str, name: &str) -> Vec<u32> {
        let start = src
            .find(&format!("var<private> {name}:"))
            .unwrap_or_else(|| panic!("{name} missing"));
        let body = &src[start..];
        let open = body.find(">(").expect("array literal") + 2;
        let close = body[open..].find(");").expect("end of literal") + open;
        body[open..close]
            .split(',')
            .map(|t| t.trim().trim_end_matches('u'))
            .filter(|t| !t.is_empty())
            .map(|t| t.parse().expect("u32 literal"))
            .collect()
    }

    #[test]
    fn wgsl_tables_match_rust() {
        use super::super::sampling_mesh::{CELL_TETS, FACE_TABLES};
        let tets: Vec<u32> = CELL_TETS
            .iter()
            .flatten()
            .flatten()
            .map(|&v| v as u32)
            .collect();
        assert_eq!(wgsl_table(COMMON, "TETS"), tets);
        let faces: Vec<u32> = FACE_TABLES
            .faces
            .iter()
            .flatten()
            .flatten()
            .map(|&v| v as u32)
            .collect();
        assert_eq!(wgsl_table(RASTER, "FACES"), faces);
        let tf: Vec<u32> = FACE_TABLES
            .tet_faces
            .iter()
            .flatten()
            .flatten()
            .map(|&v| v as u32)
            .collect();
        assert_eq!(wgsl_table(RASTER, "TET_FACES"), tf);
        let orient: Vec<u32> = super::super::sampling_mesh::ORIENTATION
            .iter()
            .flatten()
            .map(|&(slot, positive)| slot as u32 | (positive as u32) << 2)
            .collect();
        assert_eq!(wgsl_table(COMMON, "ORIENT"), orient);
        assert!(RASTER.contains(&format!(
            "const WEAK_OWNER: u32 = 0x{:08x}u;",
            super::super::sampling_mesh::WEAK_OWNER
        )));
        assert!(FILL.contains(&format!(
            "owner & 0x{:08x}u",
            super::super::sampling_mesh::OWNER_ID
        )));
        assert_eq!(
            wgsl_table(COMMON, "OTHERS"),
            vec![1, 2, 3, 0, 2, 3, 0, 1, 3, 0, 1, 2]
        );
        assert!(COMMON.contains(&format!(
            "const BLOCK_EDGE: u32 = {}u;",
            super::super::blocks::BLOCK_EDGE
        )));
        assert!(COMMON.contains(&format!(
            "const CELLS_PER_BLOCK: u32 = {}u;",
            CELLS_PER_BLOCK
        )));
    }

    #[test]
    fn kernels_are_assembled() {
        for (entry, src) in kernel_sources() {
            assert!(src.contains(&format!("fn {entry}(")), "{entry}");
            assert!(src.contains("struct Params"));
        }
    }
}
