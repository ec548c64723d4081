//! The WGSL path: the model's lattice and state mirrored in GPU buffers, in
//! the same red-black storage order, and the kernels of
//! `shaders/chainmail/chainmail.wgsl` (the twins of `sponsor`,
//! `relax_one` and `copy_identity`).
//!
//! The schedule lives on the device too (`crate::gpu_schedule`):
//! [`crate::model::ChainMail`] hands a run its starting active-block list
//! (the one its rayon path would build) and a cap, and the device builds
//! each next list itself, so the host queues batches of iterations and
//! reads back a dozen words per batch instead of every listed block's
//! results per iteration. What the model needs from the run — the next
//! list, the blocks that changed, were activated or ran, the visit and
//! update counts and the largest relaxation move — comes back at its end.
//! The lists' order on the device differs from the CPU's ascending order;
//! a launch's result does not depend on it (a propagation iteration reads
//! one Jacobi copy and writes the other; a relaxation colour touches no
//! two linked elements), which the parity tests check iteration by
//! iteration.
//!
//! Buffers (32-bit structure of arrays, see the shader's header): `u` (both
//! copies, 3 axes: 24 B per site), `keys` (both copies: 8 B), `sites`
//! (material, flags and cut bits: 4 B), the link table, a control buffer
//! (two `Params` slots, written once per run) and four result words per
//! listed block, which each workgroup writes whole, so nothing is cleared
//! between launches. A propagation iteration is three dispatches (the
//! kernel, `schedule`, `retire`); a relaxation sweep four (one per colour,
//! then the same two). The displacement buffer is bound whole, so a model
//! needs `24 · sites ≤ max_storage_buffer_binding_size` (128 MiB on
//! lavapipe: 5.5 M sites); larger ones are refused with what to do.

use crate::blocks::Blocks;
use crate::gpu_schedule::{DeviceSchedule, RunReport};
use crate::lattice::ElementLattice;
use crate::state::State;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use voxflex_core::error::ModelError;
use voxflex_core::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt, PipelineId};

/// The kernels.
pub const CHAINMAIL_WGSL: &str = include_str!("../../../shaders/chainmail/chainmail.wgsl");

/// Words of the shader's `Params`.
const PARAM_WORDS: usize = 20;
/// Result words per listed block: face mask, visits, updates, largest move.
const STAT_WORDS: usize = 4;
/// Words per material pair in the link table: d x, y, z and weight (f32
/// bits), tau (`LINK_WORDS` in the shader).
const LINK_WORDS: usize = 5;
/// Threads per workgroup of `map_identity` (one invocation per voxel).
const MAP_WORKGROUP: u32 = 64;

/// Binding numbers of `chainmail.wgsl`'s variables (named as there; `PARAMS` is `p`).
mod bind {
    pub const PARAMS: u32 = 0;
    pub const U: u32 = 1;
    pub const KEYS: u32 = 2;
    pub const SITES: u32 = 3;
    pub const LINKS: u32 = 4;
    pub const LIST: u32 = 5;
    pub const STATS: u32 = 6;
    pub const OUT_X: u32 = 7;
    pub const OUT_Y: u32 = 8;
    pub const OUT_Z: u32 = 9;
}

fn gpu_err(e: impl std::fmt::Display) -> ModelError {
    ModelError(format!("chainmail (GPU): {e}"))
}

/// The model's buffers on the device.
pub struct GpuChainMail {
    gpu: Arc<dyn GpuService>,
    sites: usize,
    /// A run's two `Params` slots, each at a multiple of the device's
    /// storage offset alignment, written with one call.
    control: BufferId,
    /// Byte stride of the two `Params` slots.
    slot_bytes: u64,
    /// The active-block lists and their builder.
    schedule: DeviceSchedule,
    u: BufferId,
    keys: BufferId,
    cells: BufferId,
    links: BufferId,
    stats: BufferId,
    propagate: PipelineId,
    relax: PipelineId,
    sync: PipelineId,
    map: PipelineId,
    /// `Params` without the per-dispatch words.
    base: [u32; PARAM_WORDS],
}

impl GpuChainMail {
    /// Uploads the lattice and the state.
    pub fn new(
        gpu: Arc<dyn GpuService>,
        lat: &ElementLattice,
        state: &State,
        blocks: &Blocks,
    ) -> Result<Self, ModelError> {
        let n = lat.len();
        let limit = gpu.limits().max_storage_buffer_binding_size;
        let u_bytes = 24 * n as u64;
        if u_bytes > limit || n >= u32::MAX as usize / 6 {
            return Err(ModelError(format!(
                "chainmail (GPU): {n} lattice sites need a {u_bytes}-byte displacement buffer, \
                 above this device's largest storage binding ({limit} bytes); crop the volume, \
                 raise `downsample`, or use backend = \"cpu\""
            )));
        }
        let m = lat.materials.len();
        let mut table = Vec::with_capacity(m * m * LINK_WORDS + m);
        for l in &lat.links {
            let record: [u32; LINK_WORDS] = [
                l.d[0].to_bits(),
                l.d[1].to_bits(),
                l.d[2].to_bits(),
                l.weight.to_bits(),
                l.tau,
            ];
            table.extend(record);
        }
        table.extend(lat.materials.iter().map(|mat| mat.elastic.to_bits()));
        let [nx, ny, nz] = lat.dims.map(|d| d as u32);
        let [sx, sy, sz] = blocks.size.map(|s| s as u32);
        let g_limits = gpu.limits();
        let [cx, cy, _] = blocks.count.map(|c| c as u32);
        let mut base = [0u32; PARAM_WORDS];
        base[..16].copy_from_slice(&[
            nx,
            ny,
            nz,
            lat.hx as u32,
            sx,
            sy,
            sz,
            cx,
            cy,
            lat.half as u32,
            m as u32,
            g_limits.max_compute_workgroups_per_dimension,
            0,
            0,
            n as u32,
            0,
        ]);
        for a in 0..3 {
            base[16 + a] = (lat.spacing[a] as f32).to_bits();
        }
        let g = &gpu;
        let align = (g.limits().min_storage_buffer_offset_alignment as u64).max(4);
        let slot_bytes = (4 * PARAM_WORDS as u64).next_multiple_of(align);
        let this = Self {
            control: g
                .create_buffer(2 * slot_bytes, "chainmail params")
                .map_err(gpu_err)?,
            slot_bytes,
            u: g.create_buffer(u_bytes, "chainmail u").map_err(gpu_err)?,
            keys: g
                .create_buffer(8 * n as u64, "chainmail keys")
                .map_err(gpu_err)?,
            cells: g
                .create_buffer(4 * n as u64, "chainmail sites")
                .map_err(gpu_err)?,
            links: g.upload(&table, "chainmail links").map_err(gpu_err)?,
            stats: g
                .create_buffer(
                    4 * (STAT_WORDS * blocks.len().max(1)) as u64,
                    "chainmail results",
                )
                .map_err(gpu_err)?,
            propagate: g.compile(CHAINMAIL_WGSL, "propagate").map_err(gpu_err)?,
            relax: g.compile(CHAINMAIL_WGSL, "relax").map_err(gpu_err)?,
            sync: g.compile(CHAINMAIL_WGSL, "sync_copies").map_err(gpu_err)?,
            map: g.compile(CHAINMAIL_WGSL, "map_identity").map_err(gpu_err)?,
            schedule: DeviceSchedule::new(g.as_ref(), blocks)?,
            sites: n,
            base,
            gpu,
        };
        this.upload_sites(lat)?;
        this.upload_state(state)?;
        Ok(this)
    }

    /// Uploads the material, flag and cut bytes (after an interaction
    /// changed them).
    pub fn upload_sites(&self, lat: &ElementLattice) -> Result<(), ModelError> {
        let words: Vec<u32> = lat
            .cells
            .iter()
            .zip(&lat.cut)
            .map(|(&c, &k)| c as u32 | (k as u32) << 8)
            .collect();
        self.gpu
            .write_buffer(self.cells, 0, bytemuck::cast_slice(&words))
            .map_err(gpu_err)
    }

    /// Uploads both copies of the state.
    pub fn upload_state(&self, state: &State) -> Result<(), ModelError> {
        let n = self.sites;
        let mut words = Vec::with_capacity(6 * n);
        for copy in &state.u {
            for axis in copy {
                words.extend(axis.iter().map(|v| v.load(Relaxed)));
            }
        }
        self.gpu
            .write_buffer(self.u, 0, bytemuck::cast_slice(&words))
            .map_err(gpu_err)?;
        words.clear();
        for copy in &state.key {
            words.extend(copy.iter().map(|v| v.load(Relaxed)));
        }
        self.gpu
            .write_buffer(self.keys, 0, bytemuck::cast_slice(&words))
            .map_err(gpu_err)
    }

    /// Downloads both copies of the state (its `cur` is left as is).
    pub fn download_state(&self, state: &State) -> Result<(), ModelError> {
        let n = self.sites;
        let mut words = vec![0u32; 6 * n];
        self.gpu.download(self.u, &mut words).map_err(gpu_err)?;
        for (c, copy) in state.u.iter().enumerate() {
            for (a, axis) in copy.iter().enumerate() {
                let src = &words[(3 * c + a) * n..(3 * c + a + 1) * n];
                axis.iter().zip(src).for_each(|(d, &s)| d.store(s, Relaxed));
            }
        }
        words.truncate(2 * n);
        self.gpu.download(self.keys, &mut words).map_err(gpu_err)?;
        for (c, copy) in state.key.iter().enumerate() {
            copy.iter()
                .zip(&words[c * n..(c + 1) * n])
                .for_each(|(d, &s)| d.store(s, Relaxed));
        }
        Ok(())
    }

    /// Writes element `n`'s displacement (mm) and key into both copies.
    pub fn write_element(&self, n: usize, u: [f32; 3], key: u32) -> Result<(), ModelError> {
        let g = &self.gpu;
        for copy in 0..2 {
            for (a, v) in u.iter().enumerate() {
                let at = ((3 * copy + a) * self.sites + n) as u64 * 4;
                g.write_buffer(self.u, at, &v.to_bits().to_le_bytes())
                    .map_err(gpu_err)?;
            }
            let at = (copy * self.sites + n) as u64 * 4;
            g.write_buffer(self.keys, at, &key.to_le_bytes())
                .map_err(gpu_err)?;
        }
        Ok(())
    }

    /// Writes a run's two `Params` slots with one call: slot `k` reads
    /// copy `copies[k]` and runs colour `k`, with tolerance `tol`.
    fn write_control(&self, copies: [usize; 2], tol: f32) -> Result<(), ModelError> {
        let slot = self.slot_bytes as usize / 4;
        let mut words = vec![0u32; 2 * slot];
        for (colour, &copy) in copies.iter().enumerate() {
            let p = &mut words[colour * slot..colour * slot + PARAM_WORDS];
            p.copy_from_slice(&self.base);
            p[12] = copy as u32;
            p[13] = colour as u32;
            p[15] = tol.to_bits();
        }
        self.gpu
            .write_buffer(self.control, 0, bytemuck::cast_slice(&words))
            .map_err(gpu_err)
    }

    /// The `Params` binding of slot `k`.
    fn params(&self, k: usize) -> BufferBinding {
        BufferBinding {
            binding: bind::PARAMS,
            buffer: self.control,
            offset: k as u64 * self.slot_bytes,
            size: 4 * PARAM_WORDS as u64,
        }
    }

    /// Queues `pipeline` with `Params` slot `k` over the list of iteration
    /// `i`, one workgroup per listed block.
    fn launch(
        &self,
        pipeline: PipelineId,
        k: usize,
        i: u64,
        with: &[(u32, BufferId)],
    ) -> Result<(), ModelError> {
        let mut bindings = vec![self.params(k), self.schedule.list(i, bind::LIST)];
        bindings.extend(with.iter().map(|&(b, id)| BufferBinding::whole(b, id)));
        self.schedule
            .dispatch_over_list(self.gpu.as_ref(), pipeline, &bindings, i)
    }

    /// Up to `max` Jacobi propagation iterations from `active`, the first
    /// reading copy `rd`; iteration `i` reads copy `rd ^ (i & 1)` (the
    /// `Params` slot of its parity), so after the run the current copy is
    /// `rd ^ (iterations & 1)`.
    pub fn propagate(&self, rd: usize, active: &[u32], max: u64) -> Result<RunReport, ModelError> {
        self.write_control([rd, 1 - rd], 0.0)?;
        let with = [
            (bind::U, self.u),
            (bind::KEYS, self.keys),
            (bind::SITES, self.cells),
            (bind::LINKS, self.links),
            (bind::STATS, self.stats),
        ];
        let g = self.gpu.as_ref();
        self.schedule.run(g, active, max, self.stats, |i| {
            self.launch(self.propagate, (i % 2) as usize, i, &with)
        })
    }

    /// Up to `max` red-black relaxation sweeps from `set`, in place in copy
    /// `cur`; a sweep is two launches, one per colour.
    pub fn relax(
        &self,
        cur: usize,
        set: &[u32],
        tol: f64,
        max: u64,
    ) -> Result<RunReport, ModelError> {
        self.write_control([cur, cur], tol as f32)?;
        let with = [
            (bind::U, self.u),
            (bind::SITES, self.cells),
            (bind::LINKS, self.links),
            (bind::STATS, self.stats),
        ];
        let g = self.gpu.as_ref();
        self.schedule.run(g, set, max, self.stats, |i| {
            (0..2).try_for_each(|colour| self.launch(self.relax, colour, i, &with))
        })
    }

    /// Copies the displacements of `blocks` from copy `from` to the other.
    pub fn sync(&self, from: usize, blocks: &[u32]) -> Result<(), ModelError> {
        if blocks.is_empty() {
            return Ok(());
        }
        self.write_control([from, from], 0.0)?;
        self.schedule.write_list(self.gpu.as_ref(), blocks)?;
        self.launch(self.sync, 0, 0, &[(bind::U, self.u)])
    }

    /// The current displacements (copy `cur`) in voxel order into `out`
    /// (x, y, z buffers of at least one f32 per element).
    pub fn map_identity(
        &self,
        cur: usize,
        voxels: usize,
        out: [BufferId; 3],
    ) -> Result<(), ModelError> {
        self.write_control([cur, cur], 0.0)?;
        let bindings = [
            self.params(0),
            BufferBinding::whole(bind::U, self.u),
            BufferBinding::whole(bind::OUT_X, out[0]),
            BufferBinding::whole(bind::OUT_Y, out[1]),
            BufferBinding::whole(bind::OUT_Z, out[2]),
        ];
        let groups = self
            .gpu
            .workgroups_for(voxels as u64, MAP_WORKGROUP)
            .map_err(gpu_err)?;
        self.gpu
            .dispatch(self.map, &bindings, groups)
            .map_err(gpu_err)
    }
}

impl Drop for GpuChainMail {
    fn drop(&mut self) {
        self.schedule.destroy(self.gpu.as_ref());
        for id in [
            self.control,
            self.u,
            self.keys,
            self.cells,
            self.links,
            self.stats,
        ] {
            self.gpu.destroy_buffer(id);
        }
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;
