//! The rayon kernels of the resampler (the CPU twin of
//! `shaders/resample/*.wgsl`).
//!
//! - block bounds: one task per block, min/max of its vertices' positions;
//! - clear: the region's output words set to `u32::MAX` ("no owner");
//! - pass 1: one task per cell block; its cells go four at a time, by
//!   parity, through [`super::lanes`] (per cell the eight deformed corners,
//!   the face planes and, per candidate voxel centre of the cell's clipped
//!   box, the smallest containing tetrahedron), then `fetch_min(tet id)`
//!   after a relaxed load, so voxels that already hold a smaller id cost no
//!   atomic read-modify-write;
//! - pass 2: one task per output row; owner → barycentric weights → value.
//!
//! The output `Vec<f32>` is viewed as `[AtomicU32]` during a call; no other
//! per-voxel memory is used.

use super::blocks::BlockBounds;
use super::lanes::{LANES, LaneCtx, raster_group};
use super::raster::{barycentric, interpolate};
use super::sampling_mesh::{
    CELL_TETS, TetDecoder, cell_parity, corner_offset, deformed_coordinate,
};
use super::{
    DisplacementsRef, Job, KernelConsts, Kernels, OutputGrid, ResampleError, TetMask, VoxelBox,
};
use crate::volume::{Sample, VoxelSlice};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// The CPU half of a resampling call.
pub(crate) struct CpuKernels<'a> {
    pub source: VoxelSlice<'a>,
    pub disp: DisplacementsRef<'a>,
    pub mask: Option<&'a TetMask>,
    pub out: &'a mut Vec<f32>,
    /// Run pass 2 (false only in tests that inspect pass-1 owners).
    pub fill: bool,
}

/// Views f32 storage as atomics for the duration of a borrow.
fn as_atomic(v: &mut [f32]) -> &[AtomicU32] {
    let words: &mut [u32] = bytemuck::cast_slice_mut(v);
    // SAFETY: `AtomicU32` has the same size and bit validity as `u32`, and its
    // alignment (4) equals `u32`'s on every target with 32-bit atomics; we
    // hold the only (mutable) borrow, so no non-atomic access can overlap.
    unsafe { &*(words as *mut [u32] as *const [AtomicU32]) }
}

impl Kernels for CpuKernels<'_> {
    fn block_bounds(
        &mut self,
        c: &KernelConsts,
        blocks: &[u32],
        out: &mut [BlockBounds],
    ) -> Result<(), ResampleError> {
        let disp = self.disp;
        let t0 = std::time::Instant::now();
        out.par_iter_mut()
            .zip(blocks.par_iter())
            .for_each(|(o, &b)| *o = block_bounds(c, &disp, b as usize));
        tracing::trace!(blocks = blocks.len(), elapsed = ?t0.elapsed(), "resample: block bounds (cpu)");
        Ok(())
    }

    fn allocate_output(&mut self, output: &OutputGrid) -> Result<(), ResampleError> {
        let n = output.len();
        if self.out.len() != n {
            *self.out = Vec::new();
            let mut v = Vec::new();
            v.try_reserve_exact(n)
                .map_err(|_| ResampleError::OutOfMemory {
                    voxels: n,
                    bytes: n * 4,
                })?;
            v.resize(n, 0.0);
            *self.out = v;
        }
        Ok(())
    }

    fn rasterise(&mut self, job: &Job<'_>) -> Result<(), ResampleError> {
        let out = as_atomic(self.out);
        let t0 = std::time::Instant::now();
        clear(job, out);
        let t1 = std::time::Instant::now();
        let ctx = RasterCtx {
            c: job.consts,
            disp: self.disp,
            mask: self.mask.filter(|m| !m.is_empty()),
            output: *job.output,
            clip: job.region,
            decoder: TetDecoder::new(&job.consts.mesh),
        };
        let lanes = LaneCtx {
            vertex_dims: job.consts.mesh.vertex_dims(),
            cell_dims: job.consts.mesh.cell_dims(),
            inv_spacing: job.consts.inv_spacing,
            eps: job.consts.eps,
            disp: self.disp,
            output: *job.output,
            clip: job.region,
        };
        job.blocks
            .par_iter()
            .for_each(|&b| raster_block(&ctx, &lanes, b as usize, out));
        let t2 = std::time::Instant::now();
        if self.fill {
            crate::with_voxels!(self.source, |s| fill(s, &ctx, out));
        }
        let t3 = std::time::Instant::now();
        tracing::trace!(
            voxels = job.region.count(),
            blocks = job.blocks.len(),
            clear = ?(t1 - t0),
            raster = ?(t2 - t1),
            fill = ?(t3 - t2),
            "resample: passes (cpu)"
        );
        Ok(())
    }
}

/// Deformed bounds of one block's vertices.
fn block_bounds(c: &KernelConsts, disp: &DisplacementsRef<'_>, b: usize) -> BlockBounds {
    let (lo, hi) = c.layout.vertices(b);
    let [nx, ny, _] = c.mesh.vertex_dims();
    let inv = c.inv_spacing;
    let mut mn = [f32::INFINITY; 3];
    let mut mx = [f32::NEG_INFINITY; 3];
    for k in lo[2]..=hi[2] {
        let z0 = k as f32;
        for j in lo[1]..=hi[1] {
            let y0 = j as f32;
            let row = nx * (j + ny * k);
            let (dx, dy, dz) = (
                &disp.x[row + lo[0]..=row + hi[0]],
                &disp.y[row + lo[0]..=row + hi[0]],
                &disp.z[row + lo[0]..=row + hi[0]],
            );
            for (n, i) in (lo[0]..=hi[0]).enumerate() {
                let p = [
                    deformed_coordinate(i, dx[n], inv[0]),
                    y0 + dy[n] * inv[1],
                    z0 + dz[n] * inv[2],
                ];
                for a in 0..3 {
                    // NaN-propagating min/max: a NaN displacement must show.
                    mn[a] = if p[a] < mn[a] || p[a].is_nan() {
                        p[a]
                    } else {
                        mn[a]
                    };
                    mx[a] = if p[a] > mx[a] || p[a].is_nan() {
                        p[a]
                    } else {
                        mx[a]
                    };
                }
            }
        }
    }
    BlockBounds { min: mn, max: mx }
}

fn clear(job: &Job<'_>, out: &[AtomicU32]) {
    let r = job.region;
    let d = r.dims();
    (0..d[1] * d[2]).into_par_iter().for_each(|row| {
        let y = r.lo[1] + (row % d[1]) as i32;
        let z = r.lo[2] + (row / d[1]) as i32;
        let base = job.output.linear([r.lo[0], y, z]);
        for o in &out[base..base + d[0]] {
            o.store(u32::MAX, Relaxed);
        }
    });
}

/// What the per-cell and per-voxel kernels read.
struct RasterCtx<'a> {
    c: &'a KernelConsts,
    disp: DisplacementsRef<'a>,
    mask: Option<&'a TetMask>,
    output: OutputGrid,
    /// Voxels that may be written, source index units.
    clip: VoxelBox,
    decoder: TetDecoder,
}

impl RasterCtx<'_> {
    /// Deformed position of vertex `v` (source voxel indices), linear `g`.
    #[inline(always)]
    fn position(&self, v: [usize; 3], g: usize) -> [f32; 3] {
        let inv = self.c.inv_spacing;
        [
            deformed_coordinate(v[0], self.disp.x[g], inv[0]),
            deformed_coordinate(v[1], self.disp.y[g], inv[1]),
            deformed_coordinate(v[2], self.disp.z[g], inv[2]),
        ]
    }
}

fn raster_block(ctx: &RasterCtx<'_>, lanes: &LaneCtx<'_>, b: usize, out: &[AtomicU32]) {
    let (lo, hi) = ctx.c.layout.cells(b);
    let mesh = &ctx.c.mesh;
    // Same-parity cells of the block, four at a time.
    let mut groups = [([[0usize; 3]; LANES], [0u8; LANES], 0usize); 2];
    for k in lo[2]..hi[2] {
        for j in lo[1]..hi[1] {
            for i in lo[0]..hi[0] {
                let cell = [i, j, k];
                let parity = cell_parity(cell);
                let removed = ctx.mask.map_or(0, |m| m.cell_bits(mesh.cell_linear(cell)));
                let g = &mut groups[parity];
                g.0[g.2] = cell;
                g.1[g.2] = removed;
                g.2 += 1;
                if g.2 == LANES {
                    flush(lanes, parity, g, out);
                }
            }
        }
    }
    for (parity, g) in groups.iter_mut().enumerate() {
        if g.2 > 0 {
            flush(lanes, parity, g, out);
        }
    }
}

fn flush(
    lanes: &LaneCtx<'_>,
    parity: usize,
    g: &mut ([[usize; 3]; LANES], [u8; LANES], usize),
    out: &[AtomicU32],
) {
    for l in g.2..LANES {
        g.0[l] = g.0[0];
        g.1[l] = g.1[0];
    }
    if parity == 0 {
        raster_group::<0>(lanes, &g.0, &g.1, g.2, out);
    } else {
        raster_group::<1>(lanes, &g.0, &g.1, g.2, out);
    }
    g.2 = 0;
}

/// Pass 2 over the region: owner id → interpolated value (f32 bits).
fn fill<T: Sample>(src: &[T], ctx: &RasterCtx<'_>, out: &[AtomicU32]) {
    let r = ctx.clip;
    let d = r.dims();
    let bg = ctx.c.background.to_bits();
    (0..d[1] * d[2]).into_par_iter().for_each(|row| {
        let y = r.lo[1] + (row % d[1]) as i32;
        let z = r.lo[2] + (row / d[1]) as i32;
        let base = ctx.output.linear([r.lo[0], y, z]);
        for (n, o) in out[base..base + d[0]].iter().enumerate() {
            let owner = o.load(Relaxed);
            let v = if owner == u32::MAX {
                bg
            } else {
                let q = [(r.lo[0] + n as i32) as f32, y as f32, z as f32];
                value_at(ctx, src, owner, q).to_bits()
            };
            o.store(v, Relaxed);
        }
    });
}

/// The value at voxel centre `q` (source index units) interpolated in
/// tetrahedron `owner`.
#[inline(always)]
fn value_at<T: Sample>(ctx: &RasterCtx<'_>, src: &[T], owner: u32, q: [f32; 3]) -> f32 {
    let mesh = &ctx.c.mesh;
    let (cell, t) = ctx.decoder.decode(owner);
    let [nx, ny, _] = mesh.vertex_dims();
    let corners = CELL_TETS[cell_parity(cell)][t];
    let mut p = [[0f32; 3]; 4];
    let mut v = [0f32; 4];
    for a in 0..4 {
        let o = corner_offset(corners[a]);
        let vi = [cell[0] + o[0], cell[1] + o[1], cell[2] + o[2]];
        let g = vi[0] + nx * (vi[1] + ny * vi[2]);
        p[a] = ctx.position(vi, g);
        v[a] = src[g].to_f32();
    }
    interpolate(barycentric(&p, q), v)
}
