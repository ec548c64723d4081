//! The WGSL path of the opacity growth, written against [`GpuService`]
//! (`shaders/opacity/*.wgsl`; the CPU twin is [`super::cpu`] with
//! `super::frontier`).
//!
//! One Jacobi step is four kernels, each one invocation per list entry
//! (3-D-folded dispatch, workgroups of 64):
//!
//! - `enumerate` — per frontier voxel: the neighbours (26, or 6) its new value
//!   lifts, skipping voxels marked done, deduplicated by `atomicOr` on a
//!   candidate mark, appended to the candidate list (one `atomicAdd` per
//!   workgroup on the global counter);
//! - `evaluate` — per candidate: the update rule (field read-only), the new
//!   value kept per candidate; the candidate mark cleared and the done mark
//!   set at the ceiling (one `atomicXor`);
//! - `apply` — per candidate: the risen values stored (an `atomicAdd` on
//!   the voxel's half of a packed u32 word), appended to the next frontier,
//!   and the region box grown (workgroup min/max, then one global atomic
//!   per workgroup);
//! - `pump` — per voxel of the next frontier: the pump shortcut on the
//!   values after the step ([`super::Extinction::pumps`]).
//!
//! The CPU computes the same values in two phases (lift in place, finish);
//! the kernels split the work differently (the GPU evaluates candidates on
//! an untouched field instead of lifting in place) but every step yields
//! the same field, the same set of changed voxels and the same counts.
//!
//! **Counts.** `size_candidates` (one invocation, between `enumerate` and
//! `evaluate`) turns the candidate count into the indirect arguments of
//! `evaluate`, `apply` and `pump` ([`GpuService::dispatch_indirect`]), so
//! a step reads back once: 40 bytes at its end (candidates, next-frontier
//! length and region box, which size the next `enumerate` and decide
//! whether the working box must grow). Before dispatch-indirect each step
//! also read back the candidate count between `enumerate` and `evaluate`;
//! on a real GPU a step is bounded by that sync latency (tens of µs), so
//! this halves it. The candidate and next-frontier lists are sized for the
//! most a step can produce (26 per frontier entry, at most the working
//! box).
//!
//! **Memory** (all 32-bit storage): the volume's values as f32 (4 bytes
//! per volume voxel, one buffer shared by every growth of a
//! [`GpuOpacityVolume`]); per growth, the field as packed u16 (2 bytes per
//! working-box voxel), the marks (2 bits per working-box voxel), and four
//! lists of u32 (frontier, next frontier, candidates, new values), grown
//! geometrically with the largest step (at most 4 bytes per working-box
//! voxel each). The kernels bind only the x-y planes of the values that
//! the working box spans (a window from the box's first plane, its start
//! aligned down to the device's offset alignment; `Params.bdim.w` holds
//! its first value's volume index), so the volume may be larger than one
//! storage binding (a 512 × 512 × 133 CT is 133 MiB of f32): only a
//! working box whose planes exceed one binding is refused, with
//! [`OpacityError::BindingTooLarge`] — and that window bounds every other
//! per-growth buffer. Where the box the growth would take (the region and
//! a geometric margin) spans more planes than a binding holds, it is cut
//! to those planes around the region (`fit_to_binding`): the field then
//! moves more often, the map is the same. The volume must fit one buffer
//! ([`OpacityError::BufferTooLarge`]).
//!
//! Buffers are not freed on drop (the growth holds no GPU handle): call
//! [`GpuGrowth::release`] and [`GpuOpacityVolume::release`].

use super::bounds::{VoxelBounds, grown_working_box};
use super::extinction::sanitize;
use super::params::GrowthParams;
use super::report::GrowthReport;
use super::seed::Seed;
use super::state::{Growth, GrowthState};
use super::{OpacityError, check_volume};
use crate::grid::Grid;
use crate::opacity_map::OpacityMap;
use crate::volume::VolumeView;
use voxflex_core::error::GpuError;
use voxflex_core::gpu::{
    BufferBinding, BufferId, GpuLimits, GpuService, GpuServiceExt, PipelineId,
};

const COMMON: &str = include_str!("../../../shaders/opacity/common.wgsl");
const STEP: &str = include_str!("../../../shaders/opacity/step.wgsl");
const REGROW: &str = include_str!("../../../shaders/opacity/regrow.wgsl");

/// Threads per workgroup (`WG` in `common.wgsl`).
const WORKGROUP: u32 = 64;

/// Binding numbers (see `common.wgsl`).
mod bind {
    pub const PARAMS: u32 = 0;
    pub const VALUES: u32 = 1;
    pub const FIELD: u32 = 2;
    pub const MARKS: u32 = 3;
    pub const FRONT: u32 = 4;
    pub const CAND: u32 = 5;
    pub const NEWVAL: u32 = 6;
    pub const NEXT: u32 = 7;
    pub const COUNTERS: u32 = 8;
    pub const OLD_FIELD: u32 = 9;
    pub const REGROW: u32 = 10;
    pub const ARGS: u32 = 11;
}

/// The full WGSL source of each kernel (for tools that validate shaders).
pub fn kernel_sources() -> [(&'static str, String); 8] {
    let step = format!("{COMMON}\n{STEP}");
    let regrow = format!("{COMMON}\n{REGROW}");
    [
        ("enumerate", step.clone()),
        ("size_candidates", step.clone()),
        ("evaluate", step.clone()),
        ("apply", step.clone()),
        ("pump", step),
        ("regrow", regrow.clone()),
        ("remap", regrow.clone()),
        ("mark", regrow),
    ]
}

/// `Params` of `common.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
struct Params {
    vdim: [u32; 4],
    blo: [u32; 4],
    bdim: [u32; 4],
    ext: [f32; 4],
    q: [u32; 4],
}

/// `Regrow` of `common.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
struct Regrow {
    olo: [u32; 4],
    odim: [u32; 4],
    nlo: [u32; 4],
    ndim: [u32; 4],
}

/// u32 words of the counters buffer.
const COUNTERS: usize = 12;

/// A volume's values on the GPU, as sanitised f32 (see
/// [`super::extinction::sanitize`]), one storage binding; shared by any
/// number of [`GpuGrowth`]s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpuOpacityVolume {
    /// Geometry (voxel index ↔ mm).
    pub grid: Grid,
    /// `grid.len()` f32 values, x fastest.
    pub values: BufferId,
}

impl GpuOpacityVolume {
    /// Converts a volume to sanitised f32 and uploads it; fails when it does
    /// not fit one buffer. (A growth binds only the z-planes its working box
    /// spans, [`GpuGrowth::step`], so the volume may exceed one storage
    /// binding.)
    pub fn upload(gpu: &dyn GpuService, volume: VolumeView<'_>) -> Result<Self, OpacityError> {
        check_volume(&volume)?;
        let bytes = volume.grid.len() as u64 * 4;
        let limit = gpu.limits().max_buffer_size;
        if bytes > limit {
            return Err(OpacityError::BufferTooLarge {
                what: "the volume's values (f32)",
                bytes,
                limit,
            });
        }
        let values: Vec<f32> = volume.data.to_f32_vec().into_iter().map(sanitize).collect();
        let id = gpu.upload(&values, "voxflex.opacity.values")?;
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

/// `wanted`, a working box holding `needed` (voxel indices, a volume of
/// `dims` voxels), cut along z to the planes of the values one storage
/// binding of `limits` holds, still holding `needed`: the kernels bind the
/// values of the box's planes ([`GpuGrowth::values_window`]), and a box cut
/// this way only moves its field more often (the map does not depend on
/// the box). Unchanged when it fits, or when `needed` alone does not (the
/// step then refuses it with [`OpacityError::BindingTooLarge`]).
fn fit_to_binding(
    wanted: VoxelBounds,
    needed: &VoxelBounds,
    dims: [usize; 3],
    limits: &GpuLimits,
) -> VoxelBounds {
    let plane = (dims[0] * dims[1]) as u64 * 4;
    // The window starts up to one alignment before the box's first plane.
    let slack = u64::from(limits.min_storage_buffer_offset_alignment);
    let most =
        (limits.max_storage_buffer_binding_size.saturating_sub(slack) / plane.max(1)) as usize;
    let span = |b: &VoxelBounds| b.hi[2] + 1 - b.lo[2];
    if span(&wanted) <= most || span(needed) > most {
        return wanted;
    }
    // Keep `needed` and share the planes left over between its two sides.
    let spare = most - span(needed);
    let lo = needed.lo[2].saturating_sub(spare / 2).max(wanted.lo[2]);
    let hi = (lo + most - 1).min(wanted.hi[2]);
    let lo = (hi + 1 - most).max(wanted.lo[2]);
    VoxelBounds {
        lo: [wanted.lo[0], wanted.lo[1], lo],
        hi: [wanted.hi[0], wanted.hi[1], hi],
    }
}

fn check_binding(gpu: &dyn GpuService, what: &'static str, bytes: u64) -> Result<(), OpacityError> {
    let limit = gpu.limits().max_storage_buffer_binding_size;
    if bytes > limit {
        return Err(OpacityError::BindingTooLarge { what, bytes, limit });
    }
    Ok(())
}

#[derive(Clone, Copy, Debug)]
struct Pipelines {
    enumerate: PipelineId,
    size_candidates: PipelineId,
    evaluate: PipelineId,
    apply: PipelineId,
    pump: PipelineId,
    regrow: PipelineId,
    remap: PipelineId,
    mark: PipelineId,
}

impl Pipelines {
    fn compile(gpu: &dyn GpuService) -> Result<Self, GpuError> {
        let [a, s, b, c, p, d, e, f] = kernel_sources();
        Ok(Self {
            enumerate: gpu.compile(&a.1, a.0)?,
            size_candidates: gpu.compile(&s.1, s.0)?,
            evaluate: gpu.compile(&b.1, b.0)?,
            apply: gpu.compile(&c.1, c.0)?,
            pump: gpu.compile(&p.1, p.0)?,
            regrow: gpu.compile(&d.1, d.0)?,
            remap: gpu.compile(&e.1, e.0)?,
            mark: gpu.compile(&f.1, f.0)?,
        })
    }
}

/// A buffer the growth owns, with its size in bytes.
#[derive(Clone, Copy, Debug)]
struct Owned {
    id: BufferId,
    bytes: u64,
}

impl Owned {
    fn new(gpu: &dyn GpuService, bytes: u64, label: &str) -> Result<Self, GpuError> {
        let bytes = bytes.max(4).next_multiple_of(4);
        Ok(Self {
            id: gpu.create_buffer(bytes, label)?,
            bytes,
        })
    }

    /// Replaces the buffer by a larger one (contents lost) when it holds
    /// fewer than `bytes`; grows by at least half.
    fn ensure(&mut self, gpu: &dyn GpuService, bytes: u64, label: &str) -> Result<(), GpuError> {
        if self.bytes >= bytes {
            return Ok(());
        }
        let new = Owned::new(gpu, bytes.max(self.bytes + self.bytes / 2), label)?;
        gpu.destroy_buffer(self.id);
        *self = new;
        Ok(())
    }
}

/// A region growing in progress on the GPU: the same steps, maps and counts
/// as [`super::CpuGrowth`], bit for bit.
#[derive(Debug)]
pub struct GpuGrowth {
    state: GrowthState,
    n_front: u32,
    pipes: Pipelines,
    params_buf: Owned,
    regrow_buf: Owned,
    counters: Owned,
    /// Indirect arguments of the kernels over the candidates.
    args: Owned,
    field: Owned,
    marks: Owned,
    front: Owned,
    next: Owned,
    cand: Owned,
    newval: Owned,
}

impl GpuGrowth {
    /// Seeds a growth on the GPU. `volume` is the CPU copy of the volume
    /// behind `values` (the seed's neighbourhood statistics are measured on it,
    /// exactly as on the CPU path).
    pub fn new(
        gpu: &dyn GpuService,
        values: &GpuOpacityVolume,
        volume: VolumeView<'_>,
        seed: &Seed,
        params: GrowthParams,
    ) -> Result<Self, OpacityError> {
        Self::with_room(gpu, values, volume, seed, params, None)
    }

    /// [`GpuGrowth::new`] with a working box that covers `room` (voxel
    /// indices) from the start, as [`crate::CpuGrowth::with_room`].
    pub fn with_room(
        gpu: &dyn GpuService,
        values: &GpuOpacityVolume,
        volume: VolumeView<'_>,
        seed: &Seed,
        params: GrowthParams,
        room: Option<VoxelBounds>,
    ) -> Result<Self, OpacityError> {
        params.validate()?;
        check_volume(&volume)?;
        if values.grid.dims != volume.grid.dims {
            return Err(OpacityError::GpuVolumeMismatch {
                expected: volume.grid.dims,
                actual: values.grid.dims,
            });
        }
        let (mut state, _) = GrowthState::seed(volume, seed, params, room)?;
        // The region is the seed voxel; the first steps read 2 around it.
        let needed = state.region.dilate([2; 3], state.dims);
        state.work = fit_to_binding(state.work, &needed, state.dims, &gpu.limits());
        let s = state.work.local_linear(state.region.lo);
        let (ext, work) = (state.ext, state.work);
        let pipes = Pipelines::compile(gpu)?;

        // Initial field: q_min everywhere, q_max at the seed.
        let mut half = vec![ext.q_min; work.len().next_multiple_of(2)];
        half[s] = ext.q_max;
        let words: Vec<u32> = half
            .chunks(2)
            .map(|p| p[0] as u32 | (p[1] as u32) << 16)
            .collect();
        let mut made: Vec<Owned> = Vec::new();
        let mut mk = |bytes: u64, label: &str| -> Result<Owned, GpuError> {
            let o = Owned::new(gpu, bytes, label)?;
            made.push(o);
            Ok(o)
        };
        let result = (|| -> Result<Self, GpuError> {
            let field = mk(words.len() as u64 * 4, "voxflex.opacity.field")?;
            gpu.write_buffer(field.id, 0, bytemuck::cast_slice(&words))?;
            let front = mk(1024, "voxflex.opacity.frontier")?;
            // The seed (at q_max) is done.
            let mut marks0 = vec![0u32; work.len().div_ceil(16)];
            marks0[s >> 4] = 2 << ((s & 15) * 2);
            gpu.write_buffer(front.id, 0, bytemuck::bytes_of(&(s as u32)))?;
            let g = Self {
                state,
                n_front: 1,
                pipes,
                params_buf: mk(
                    std::mem::size_of::<Params>() as u64,
                    "voxflex.opacity.params",
                )?,
                regrow_buf: mk(
                    std::mem::size_of::<Regrow>() as u64,
                    "voxflex.opacity.regrow",
                )?,
                counters: mk(COUNTERS as u64 * 4, "voxflex.opacity.counters")?,
                args: mk(12, "voxflex.opacity.args")?,
                marks: mk(marks_bytes(work.len()), "voxflex.opacity.marks")?,
                field,
                front,
                next: mk(1024, "voxflex.opacity.next")?,
                cand: mk(1024, "voxflex.opacity.candidates")?,
                newval: mk(1024, "voxflex.opacity.newval")?,
            };
            gpu.write_buffer(g.marks.id, 0, bytemuck::cast_slice(&marks0))?;
            g.write_params(gpu)?;
            Ok(g)
        })();
        match result {
            Ok(g) => Ok(g),
            Err(e) => {
                for o in made {
                    gpu.destroy_buffer(o.id);
                }
                Err(e.into())
            }
        }
    }

    /// Runs up to `n` steps (fewer if it converges first) and reports them.
    /// Resumable, like [`super::CpuGrowth::step`].
    pub fn step(
        &mut self,
        gpu: &dyn GpuService,
        values: &GpuOpacityVolume,
        n: usize,
    ) -> Result<GrowthReport, OpacityError> {
        if values.grid.dims != self.state.dims {
            return Err(OpacityError::GpuVolumeMismatch {
                expected: self.state.dims,
                actual: values.grid.dims,
            });
        }
        let mut rep = GrowthReport::default();
        let result = (|| -> Result<(), OpacityError> {
            for _ in 0..n {
                if self.n_front == 0 {
                    break;
                }
                if let Some(nb) =
                    grown_working_box(&self.state.work, &self.state.region, self.state.dims)
                {
                    let needed = self.state.region.dilate([2; 3], self.state.dims);
                    let nb = fit_to_binding(nb, &needed, self.state.dims, &gpu.limits());
                    self.regrow(gpu, nb)?;
                    rep.regrows += 1;
                }
                // The values are bound over the z-planes the working box
                // spans; that window is at least as large as every other
                // per-box buffer (at most 4 bytes per box voxel).
                let (first, bytes) = self.values_window(gpu);
                check_binding(
                    gpu,
                    "the working box's planes of the volume's values (f32)",
                    bytes,
                )?;
                let window = BufferBinding {
                    binding: bind::VALUES,
                    buffer: values.values,
                    offset: first * 4,
                    size: bytes,
                };
                let (visits, useful) = self.one_step(gpu, window)?;
                rep.steps += 1;
                rep.visits += visits;
                rep.useful += useful;
            }
            Ok(())
        })();
        rep.converged = self.n_front == 0;
        self.state.total.merge(&rep);
        result?;
        Ok(rep)
    }

    /// Runs to convergence and reports the steps it took from here.
    pub fn run(
        &mut self,
        gpu: &dyn GpuService,
        values: &GpuOpacityVolume,
    ) -> Result<GrowthReport, OpacityError> {
        self.step(gpu, values, usize::MAX)
    }

    /// True when no voxel can change any more.
    pub fn is_converged(&self) -> bool {
        self.n_front == 0
    }

    /// Reads the map back: the region's box, `outside = o_min`.
    pub fn map(&self, gpu: &dyn GpuService) -> Result<OpacityMap, OpacityError> {
        let w = self.state.work;
        let mut words = vec![0u32; w.len().div_ceil(2)];
        const CHUNK: usize = 16 << 20;
        for (n, chunk) in words.chunks_mut(CHUNK).enumerate() {
            gpu.read_buffer(
                self.field.id,
                (n * CHUNK * 4) as u64,
                bytemuck::cast_slice_mut(chunk),
            )?;
        }
        let get = |l: usize| (words[l >> 1] >> ((l & 1) * 16)) as u16;
        let r = self.state.region;
        let d = r.dims();
        let mut values = Vec::with_capacity(r.len());
        for z in 0..d[2] {
            for y in 0..d[1] {
                let start = w.local_linear([r.lo[0], r.lo[1] + y, r.lo[2] + z]);
                values.extend((0..d[0]).map(|x| get(start + x)));
            }
        }
        Ok(OpacityMap {
            origin: r.lo,
            dims: d,
            outside: self.state.ext.q_min,
            values,
        })
    }

    /// GPU bytes this growth holds (the shared volume not included).
    pub fn gpu_bytes(&self) -> u64 {
        self.all().iter().map(|o| o.bytes).sum()
    }

    /// Frees every buffer of this growth (not the shared volume).
    pub fn release(self, gpu: &dyn GpuService) {
        for o in self.all() {
            gpu.destroy_buffer(o.id);
        }
    }

    fn all(&self) -> [Owned; 10] {
        [
            self.params_buf,
            self.regrow_buf,
            self.counters,
            self.args,
            self.field,
            self.marks,
            self.front,
            self.next,
            self.cand,
            self.newval,
        ]
    }

    /// The window of the values buffer the kernels bind: every voxel of
    /// the x-y planes the working box spans, from its first plane's first
    /// voxel aligned down to the device's storage offset alignment. Returns
    /// (first value, volume-linear index; bytes). The kernels read a value
    /// at `vol_linear − first` (`Params.bdim.w`).
    fn values_window(&self, gpu: &dyn GpuService) -> (u64, u64) {
        let plane = (self.state.dims[0] * self.state.dims[1]) as u64;
        let start = self.state.work.lo[2] as u64 * plane;
        let end = (self.state.work.hi[2] as u64 + 1) * plane;
        let align = (u64::from(gpu.limits().min_storage_buffer_offset_alignment) / 4).max(1);
        let first = start / align * align;
        (first, (end - first) * 4)
    }

    fn write_params(&self, gpu: &dyn GpuService) -> Result<(), GpuError> {
        let d = self.state.work.dims();
        let p = Params {
            vdim: [
                self.state.dims[0] as u32,
                self.state.dims[1] as u32,
                self.state.dims[2] as u32,
                gpu.limits().max_compute_workgroups_per_dimension,
            ],
            blo: [
                self.state.work.lo[0] as u32,
                self.state.work.lo[1] as u32,
                self.state.work.lo[2] as u32,
                self.state.work.len() as u32,
            ],
            bdim: [
                d[0] as u32,
                d[1] as u32,
                d[2] as u32,
                self.values_window(gpu).0 as u32,
            ],
            ext: [
                self.state.ext.mean,
                self.state.ext.sigma,
                self.state.ext.scale,
                self.state.ext.cap,
            ],
            q: [
                self.state.ext.q_min as u32,
                self.state.ext.q_max as u32,
                (self.state.params.connectivity == 6) as u32,
                0,
            ],
        };
        gpu.write_buffer(self.params_buf.id, 0, bytemuck::bytes_of(&p))
    }

    /// One step, the values bound as `values` (the window the caller
    /// checked, [`Self::values_window`]); returns (visits, useful).
    fn one_step(
        &mut self,
        gpu: &dyn GpuService,
        values: BufferBinding,
    ) -> Result<(u64, u64), GpuError> {
        let b = |binding, o: &Owned| BufferBinding::whole(binding, o.id);
        let box_len = self.state.work.len() as u64;
        let bound = (26 * self.n_front as u64).min(box_len);
        self.cand
            .ensure(gpu, bound * 4, "voxflex.opacity.candidates")?;
        self.newval
            .ensure(gpu, bound * 4, "voxflex.opacity.newval")?;
        self.next.ensure(gpu, bound * 4, "voxflex.opacity.next")?;
        let mut counters = [0u32; COUNTERS];
        counters[0] = self.n_front;
        counters[4..7].fill(u32::MAX);
        gpu.write_buffer(self.counters.id, 0, bytemuck::cast_slice(&counters))?;
        gpu.dispatch(
            self.pipes.enumerate,
            &[
                b(bind::PARAMS, &self.params_buf),
                values,
                b(bind::FIELD, &self.field),
                b(bind::MARKS, &self.marks),
                b(bind::FRONT, &self.front),
                b(bind::CAND, &self.cand),
                b(bind::COUNTERS, &self.counters),
            ],
            gpu.workgroups_for(self.n_front as u64, WORKGROUP)?,
        )?;
        gpu.dispatch(
            self.pipes.size_candidates,
            &[
                b(bind::PARAMS, &self.params_buf),
                b(bind::COUNTERS, &self.counters),
                b(bind::ARGS, &self.args),
            ],
            [1, 1, 1],
        )?;
        let over_candidates = |pipeline, bindings: &[BufferBinding]| {
            gpu.dispatch_indirect(pipeline, bindings, self.args.id, 0)
        };
        over_candidates(
            self.pipes.evaluate,
            &[
                b(bind::PARAMS, &self.params_buf),
                values,
                b(bind::FIELD, &self.field),
                b(bind::MARKS, &self.marks),
                b(bind::CAND, &self.cand),
                b(bind::NEWVAL, &self.newval),
                b(bind::COUNTERS, &self.counters),
            ],
        )?;
        over_candidates(
            self.pipes.apply,
            &[
                b(bind::PARAMS, &self.params_buf),
                b(bind::FIELD, &self.field),
                b(bind::CAND, &self.cand),
                b(bind::NEWVAL, &self.newval),
                b(bind::NEXT, &self.next),
                b(bind::COUNTERS, &self.counters),
            ],
        )?;
        over_candidates(
            self.pipes.pump,
            &[
                b(bind::PARAMS, &self.params_buf),
                values,
                b(bind::FIELD, &self.field),
                b(bind::MARKS, &self.marks),
                b(bind::NEXT, &self.next),
                b(bind::COUNTERS, &self.counters),
            ],
        )?;
        let mut tail = [0u32; COUNTERS - 1];
        gpu.read_buffer(self.counters.id, 4, bytemuck::cast_slice_mut(&mut tail))?;
        let (n_cand, n_next) = (tail[0], tail[1]);
        if n_next > 0 {
            let (lo, hi) = (&tail[3..6], &tail[7..10]);
            let grown = VoxelBounds {
                lo: [lo[0] as usize, lo[1] as usize, lo[2] as usize],
                hi: [hi[0] as usize, hi[1] as usize, hi[2] as usize],
            };
            self.state.region = self.state.region.union(&grown);
        }
        std::mem::swap(&mut self.front, &mut self.next);
        self.n_front = n_next;
        Ok((n_cand as u64, n_next as u64))
    }

    /// Moves the field into a larger working box (`nb ⊇ self.state.work`).
    fn regrow(&mut self, gpu: &dyn GpuService, nb: VoxelBounds) -> Result<(), GpuError> {
        let old = self.state.work;
        let (od, nd) = (old.dims(), nb.dims());
        let r = Regrow {
            olo: [
                old.lo[0] as u32,
                old.lo[1] as u32,
                old.lo[2] as u32,
                self.n_front,
            ],
            odim: [
                od[0] as u32,
                od[1] as u32,
                od[2] as u32,
                self.state.ext.q_min as u32,
            ],
            nlo: [
                nb.lo[0] as u32,
                nb.lo[1] as u32,
                nb.lo[2] as u32,
                nb.len() as u32,
            ],
            ndim: [
                nd[0] as u32,
                nd[1] as u32,
                nd[2] as u32,
                self.state.ext.q_max as u32,
            ],
        };
        gpu.write_buffer(self.regrow_buf.id, 0, bytemuck::bytes_of(&r))?;
        let words = nb.len().div_ceil(2) as u64;
        let field = Owned::new(gpu, words * 4, "voxflex.opacity.field")?;
        let marks = match Owned::new(gpu, marks_bytes(nb.len()), "voxflex.opacity.marks") {
            Ok(f) => f,
            Err(e) => {
                gpu.destroy_buffer(field.id);
                return Err(e);
            }
        };
        let moved = (|| -> Result<(), GpuError> {
            gpu.dispatch(
                self.pipes.regrow,
                &[
                    BufferBinding::whole(bind::FIELD, field.id),
                    BufferBinding::whole(bind::OLD_FIELD, self.field.id),
                    BufferBinding::whole(bind::REGROW, self.regrow_buf.id),
                ],
                gpu.workgroups_for(words, WORKGROUP)?,
            )?;
            gpu.dispatch(
                self.pipes.mark,
                &[
                    BufferBinding::whole(bind::FIELD, field.id),
                    BufferBinding::whole(bind::MARKS, marks.id),
                    BufferBinding::whole(bind::REGROW, self.regrow_buf.id),
                ],
                gpu.workgroups_for(nb.len().div_ceil(16) as u64, WORKGROUP)?,
            )?;
            self.next
                .ensure(gpu, self.n_front as u64 * 4, "voxflex.opacity.next")?;
            gpu.dispatch(
                self.pipes.remap,
                &[
                    BufferBinding::whole(bind::FRONT, self.front.id),
                    BufferBinding::whole(bind::NEXT, self.next.id),
                    BufferBinding::whole(bind::REGROW, self.regrow_buf.id),
                ],
                gpu.workgroups_for(self.n_front as u64, WORKGROUP)?,
            )
        })();
        if let Err(e) = moved {
            gpu.destroy_buffer(field.id);
            gpu.destroy_buffer(marks.id);
            return Err(e);
        }
        gpu.destroy_buffer(self.field.id);
        gpu.destroy_buffer(self.marks.id);
        self.field = field;
        self.marks = marks;
        std::mem::swap(&mut self.front, &mut self.next);
        self.state.work = nb;
        self.write_params(gpu)
    }
}

/// Bytes of the marks of `n` voxels (2 bits each, in u32 words).
fn marks_bytes(n: usize) -> u64 {
    n.div_ceil(16) as u64 * 4
}

impl Growth for GpuGrowth {
    fn state(&self) -> &GrowthState {
        &self.state
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;

#[cfg(test)]
mod fit_tests {
    use super::*;

    /// Over boxes at every z position of a 10 × 10 × 60 volume and
    /// bindings of 3 to 70 planes: the cut box holds what is needed, lies
    /// in the box wanted, and spans at most the planes a binding holds —
    /// or is the box wanted, when it fits or when what is needed does not.
    #[test]
    fn a_cut_box_holds_what_is_needed_within_one_binding() {
        let dims = [10, 10, 60];
        let plane = 10 * 10 * 4;
        for planes in 3..70u64 {
            let limits = GpuLimits {
                max_storage_buffer_binding_size: planes * plane + 256,
                max_buffer_size: u64::MAX,
                max_compute_workgroups_per_dimension: 65_535,
                min_storage_buffer_offset_alignment: 256,
            };
            for z in 0..60usize {
                for r in [0, 2, 5, 20] {
                    let lo = [2, 3, z.saturating_sub(r)];
                    let hi = [7, 8, (z + r).min(59)];
                    let needed = VoxelBounds { lo, hi };
                    let wanted = needed.dilate([3, 3, 17], dims);
                    let got = fit_to_binding(wanted, &needed, dims, &limits);
                    let span = |b: &VoxelBounds| (b.hi[2] + 1 - b.lo[2]) as u64;
                    assert!(wanted.contains(&got) && got.contains(&needed), "{got:?}");
                    if span(&needed) <= planes {
                        assert!(span(&got) <= planes, "{planes} planes: {got:?}");
                        assert_eq!(got.lo[..2], wanted.lo[..2]);
                        assert_eq!(got.hi[..2], wanted.hi[..2]);
                    } else {
                        assert_eq!(got, wanted);
                    }
                }
            }
        }
    }
}
