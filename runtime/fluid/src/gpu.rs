//! The WGSL path of the fluid weights (`shaders/fluid/weights.wgsl`),
//! written against [`GpuService`]; the rayon twin is [`crate::hits`],
//! [`crate::sections`] and [`crate::weighing`].
//!
//! The projection ([`FluidWeighing::project`]: the gravity frame and the
//! grid) and each triangle's side and candidate columns with the
//! leveraging `k` ([`crate::projection::ProjectedSurface::classify`], the
//! classification the CPU's row scan makes as it goes) run on the CPU and
//! are uploaded, so both paths test the same candidates. Two kernels
//! follow:
//!
//! - `emit` — one invocation per (triangle, worker), `k` workers per
//!   triangle (the paper's parallel leveraging): the fill-rule test at each
//!   candidate column centre, the crossing appended to the column's slots
//!   (an `atomicAdd` on the column's count);
//! - `sections` — one invocation per column: its crossings sorted by height
//!   and matched bottom → top, each section's weight added to its bottom
//!   triangle's three vertices (an f32 compare-and-swap add), the volume
//!   summed per workgroup.
//!
//! **Slots.** Each column has `cap` slots. `emit` records the most
//! crossings any column saw; when that exceeds `cap` the counts are cleared
//! and `emit` runs again with enough slots (the next call starts from the
//! larger `cap`), so a result is never cut short. More than
//! [`MAX_CROSSINGS_PER_COLUMN`] crossings in one column (a cavity folded
//! that often) is refused.
//!
//! **Precision.** The kernels work in f32 on coordinates relative to the
//! grid's corner and the lowest vertex; the CPU works in f64. A column
//! centre within f32 rounding of an edge may go to the neighbouring
//! triangle on one path, moving that column's weight between neighbouring
//! vertices, so the parity test compares the weights against the largest
//! vertex weight (1e-5) and the volume relatively (1e-5).

use crate::error::FluidError;
use crate::hits::TOP;
use crate::params::FluidWeightParams;
use crate::projection::Side;
use crate::sections::SectionCount;
use crate::weighing::{FluidWeighing, FluidWeights};
use voxflex_core::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt};
use voxflex_core::triangle_surface::TriangleSurface;

const WEIGHTS: &str = include_str!("../../../shaders/fluid/weights.wgsl");

/// Threads per workgroup (`WG` in `weights.wgsl`).
const WORKGROUP: u32 = 64;
/// Most crossings one column may hold (`MAX_CAP` in `weights.wgsl`).
pub const MAX_CROSSINGS_PER_COLUMN: u32 = 32;
/// u32 words of the status buffer before the per-workgroup volumes
/// (`STATUS_HEADER` in `weights.wgsl`).
const STATUS_HEADER: usize = 8;

/// Binding numbers (see `weights.wgsl`).
mod bind {
    pub const PARAMS: u32 = 0;
    pub const UVH: u32 = 1;
    pub const TRIS: u32 = 2;
    pub const INFO: u32 = 3;
    pub const COUNTS: u32 = 4;
    pub const REC_TRI: u32 = 5;
    pub const REC_H: u32 = 6;
    pub const WEIGHTS: u32 = 7;
    pub const STATUS: u32 = 8;
}

/// The full WGSL source of each kernel (for tools that validate shaders).
pub fn kernel_sources() -> [(&'static str, String); 2] {
    [
        ("emit", WEIGHTS.to_string()),
        ("sections", WEIGHTS.to_string()),
    ]
}

/// `Params` of `weights.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub(crate) struct Params {
    grid: [u32; 4],
    more: [u32; 4],
    geom: [f32; 4],
}

/// The GPU fluid-weight computation: the slot count and working memory
/// kept between calls (the device is given to each call, so a plugin can
/// hold this beside the host's shared service).
#[derive(Debug)]
pub struct GpuFluidWeighing {
    cap: u32,
    scratch: crate::weighing::Scratch,
}

impl Default for GpuFluidWeighing {
    fn default() -> Self {
        Self::new()
    }
}

impl GpuFluidWeighing {
    /// A computation starting with 4 slots per column.
    pub fn new() -> Self {
        Self {
            cap: 4,
            scratch: Default::default(),
        }
    }

    /// [`crate::fluid_weights`] on `gpu`: the same result within f32
    /// rounding (see the module docs).
    pub fn weigh(
        &mut self,
        gpu: &dyn GpuService,
        surface: &TriangleSurface,
        params: &FluidWeightParams,
    ) -> Result<FluidWeights, FluidError> {
        let mut scratch = std::mem::take(&mut self.scratch);
        let mut w = FluidWeighing::project(surface, params, &mut scratch)?;
        w.classify();
        let buffers = Buffers::upload(gpu, &w)?;
        let result = run(gpu, &mut self.cap, &w, &buffers);
        buffers.release(gpu);
        let (node_weights, volume, count, crossings) = result?;
        let weights = w.finish(node_weights, volume, count, crossings);
        self.scratch = scratch;
        Ok(weights)
    }
}

/// The kernels on the uploaded projection; grows `cap` when a column holds
/// more crossings.
fn run(
    gpu: &dyn GpuService,
    cap: &mut u32,
    w: &FluidWeighing<'_>,
    b: &Buffers,
) -> Result<(Vec<f64>, f64, SectionCount, usize), FluidError> {
    let p = w.projected();
    let columns = p.grid.len() as u64;
    let workers = (p.triangles.len() * w.workers()) as u64;
    let emit = gpu.compile(WEIGHTS, "emit")?;
    let sections = gpu.compile(WEIGHTS, "sections")?;
    let mut status = [0u32; STATUS_HEADER];
    let (rec_tri, rec_h) = loop {
        let limit = gpu.limits().max_storage_buffer_binding_size;
        let bytes = columns * *cap as u64 * 4;
        if bytes > limit {
            return Err(FluidError::Param {
                key: "columns",
                value: p.grid.n[0].to_string(),
                message: format!(
                    "{} crossing slots per column need a {bytes}-byte binding, above this device's {limit}; use fewer columns",
                    *cap
                ),
            });
        }
        let rec_tri = gpu.create_buffer(bytes, "fluid crossing triangles")?;
        let rec_h = gpu.create_buffer(bytes, "fluid crossing heights")?;
        gpu.write_buffer(b.params, 0, bytemuck::bytes_of(&params(w, *cap)))?;
        gpu.write_buffer(b.counts, 0, &vec![0u8; (columns * 4) as usize])?;
        gpu.write_buffer(b.status, 0, &[0u8; STATUS_HEADER * 4])?;
        gpu.dispatch(
            emit,
            &b.bindings(
                &[rec_tri, rec_h],
                &[
                    bind::PARAMS,
                    bind::UVH,
                    bind::TRIS,
                    bind::INFO,
                    bind::COUNTS,
                    bind::STATUS,
                ],
            ),
            gpu.workgroups_for(workers, WORKGROUP)?,
        )?;
        gpu.download(b.status, &mut status)?;
        if status[0] <= *cap {
            break (rec_tri, rec_h);
        }
        gpu.destroy_buffer(rec_tri);
        gpu.destroy_buffer(rec_h);
        if status[0] > MAX_CROSSINGS_PER_COLUMN {
            return Err(FluidError::Surface(format!(
                "a column crosses the cavity surface {} times; at most {MAX_CROSSINGS_PER_COLUMN} are supported on the GPU (use backend = \"cpu\")",
                status[0]
            )));
        }
        *cap = status[0].next_power_of_two();
    };
    let groups = gpu.workgroups_for(columns, WORKGROUP)?;
    let result = gpu.dispatch(
        sections,
        &b.bindings(
            &[rec_tri, rec_h],
            &[
                bind::PARAMS,
                bind::UVH,
                bind::TRIS,
                bind::COUNTS,
                bind::WEIGHTS,
                bind::STATUS,
            ],
        ),
        groups,
    );
    gpu.destroy_buffer(rec_tri);
    gpu.destroy_buffer(rec_h);
    result?;
    let n_groups = groups.iter().map(|&g| g as usize).product::<usize>();
    let mut out = vec![0u32; STATUS_HEADER + n_groups];
    gpu.download(b.status, &mut out)?;
    let volume: f64 = out[STATUS_HEADER..]
        .iter()
        .map(|&v| f32::from_bits(v) as f64)
        .sum();
    let mut weights = vec![0f32; p.surface.vertices.len()];
    gpu.download(b.weights, &mut weights)?;
    let count = SectionCount {
        sections: out[1] as usize,
        columns_with_fluid: out[2] as usize,
        irregular_columns: out[3] as usize,
    };
    Ok((
        weights.iter().map(|&x| x as f64).collect(),
        volume,
        count,
        out[4] as usize,
    ))
}

/// The kernels' `Params` for `w` with `cap` slots per column.
fn params(w: &FluidWeighing<'_>, cap: u32) -> Params {
    let p = w.projected();
    let g = p.grid;
    Params {
        grid: [
            g.n[0] as u32,
            g.n[1] as u32,
            w.workers() as u32,
            p.triangles.len() as u32,
        ],
        more: [cap, g.len() as u32, p.uvh.len() as u32, 0],
        geom: [
            g.cell.x as f32,
            g.cell.y as f32,
            g.column_area() as f32,
            w.rho_g() as f32,
        ],
    }
}

/// The buffers one call uploads and reads.
struct Buffers {
    params: BufferId,
    uvh: BufferId,
    tris: BufferId,
    info: BufferId,
    counts: BufferId,
    weights: BufferId,
    status: BufferId,
}

impl Buffers {
    fn upload(gpu: &dyn GpuService, w: &FluidWeighing<'_>) -> Result<Self, FluidError> {
        let p = w.projected();
        let h0 = p.uvh.iter().map(|q| q.z).fold(f64::INFINITY, f64::min);
        // (u, v) from the grid's index space back to mm from its corner
        let cell = p.grid.cell;
        let uvh: Vec<f32> = p
            .uvh
            .iter()
            .flat_map(|q| {
                [
                    ((q.x + 0.5) * cell.x) as f32,
                    ((q.y + 0.5) * cell.y) as f32,
                    (q.z - h0) as f32,
                ]
            })
            .collect();
        let tris: Vec<u32> = p.surface.triangles.iter().flatten().copied().collect();
        let info: Vec<u32> = p
            .triangles
            .iter()
            .flat_map(|t| {
                // a vertical triangle's candidate ranges are empty
                let ([i0, i1], [j0, j1]) = (t.columns, t.rows);
                let top = if t.side == Side::Top { TOP } else { 0 };
                [i0, i1, j0, j1 | top]
            })
            .collect();
        let columns = p.grid.len() as u64;
        let groups = columns.div_ceil(WORKGROUP as u64);
        Ok(Self {
            params: gpu.create_buffer(std::mem::size_of::<Params>() as u64, "fluid params")?,
            uvh: gpu.upload(&uvh, "fluid uvh")?,
            tris: gpu.upload(&tris, "fluid triangles")?,
            info: gpu.upload(&info, "fluid candidates")?,
            counts: gpu.create_buffer(columns * 4, "fluid column counts")?,
            weights: gpu.create_buffer(p.uvh.len() as u64 * 4, "fluid vertex weights")?,
            status: gpu.create_buffer((STATUS_HEADER as u64 + groups) * 4, "fluid status")?,
        })
    }

    /// The bindings `wanted` plus the two slot buffers.
    fn bindings(&self, slots: &[BufferId; 2], wanted: &[u32]) -> Vec<BufferBinding> {
        let all = [
            (bind::PARAMS, self.params),
            (bind::UVH, self.uvh),
            (bind::TRIS, self.tris),
            (bind::INFO, self.info),
            (bind::COUNTS, self.counts),
            (bind::WEIGHTS, self.weights),
            (bind::STATUS, self.status),
        ];
        let mut out: Vec<BufferBinding> = all
            .iter()
            .filter(|(b, _)| wanted.contains(b))
            .map(|&(b, id)| BufferBinding::whole(b, id))
            .collect();
        out.push(BufferBinding::whole(bind::REC_TRI, slots[0]));
        out.push(BufferBinding::whole(bind::REC_H, slots[1]));
        out
    }

    fn release(self, gpu: &dyn GpuService) {
        for id in [
            self.params,
            self.uvh,
            self.tris,
            self.info,
            self.counts,
            self.weights,
            self.status,
        ] {
            gpu.destroy_buffer(id);
        }
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;
