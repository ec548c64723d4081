//! The rayon kernels of the resampler (the CPU twin of
//! `shaders/resample/*.wgsl`).
//!
//! - block bounds: one task per block, min/max of its vertices' positions
//!   (four vertices of a row per SIMD operation);
//! - clear: the region's output words set to `u32::MAX` ("no owner");
//! - pass 1: one task per cell block; its cells go eight at a time, by
//!   parity, through `super::lanes` (per cell the eight deformed corners,
//!   the face planes and, per candidate voxel centre of the cell's clipped
//!   box, the containing tetrahedron of smallest owner key — see
//!   `sampling_mesh::WEAK_OWNER`), then `fetch_min(key)` after a relaxed
//!   load, so voxels that already hold a smaller key cost no atomic
//!   read-modify-write;
//! - pass 2: one task per output row; owner → barycentric weights → value
//!   (the owner's vertex values, or in trilinear mode a trilinear sample of
//!   the source at the barycentric rest position), eight voxels per SIMD
//!   operation through `super::fill_lanes`.
//!
//! The output `Vec<f32>` is viewed as `[AtomicU32]` during a call; no other
//! per-voxel memory is used.

use super::blocks::BlockBounds;
use super::fill_lanes::{
    FILL_LANES, FillGroup, interpolate_group, rest_group, trilinear_corners, trilinear_group,
};
use super::lanes::{LANES, LaneCtx, raster_group};
use super::sampling_mesh::{
    CELL_TETS, OWNER_ID, TetDecoder, cell_parity, corner_offset, deformed_coordinate,
};
use super::{
    DisplacementsRef, Interpolation, Job, KernelConsts, Kernels, OutputGrid, ResampleError,
    TetMask, VoxelBox,
};
use crate::volume::{Sample, VoxelSlice};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};
use wide::f32x4;

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
        if self.out.len() == n {
            return Ok(());
        }
        if self.out.capacity() < n {
            // A grid that grew once tends to grow again while a deformation
            // ramps up: keep a quarter in hand so the next growth reuses the
            // pages instead of faulting in a fresh block (the old one goes
            // first, to keep the peak low).
            *self.out = Vec::new();
            let want = n.saturating_add(n / 4);
            let mut v = Vec::new();
            if v.try_reserve_exact(want).is_err() {
                v.try_reserve_exact(n)
                    .map_err(|_| ResampleError::OutOfMemory {
                        voxels: n,
                        bytes: n * 4,
                    })?;
            }
            *self.out = v;
        }
        // Every word of the output is cleared and rewritten by the passes;
        // new words are written in parallel so that both cores share the
        // first-touch page faults.
        let len = self.out.len();
        if n < len {
            self.out.truncate(n);
        } else {
            self.out.par_extend(rayon::iter::repeat_n(0.0, n - len));
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
            match job.consts.interpolation {
                Interpolation::Tetrahedral => {
                    crate::with_voxels!(self.source, |s| fill::<_, false>(s, &ctx, out))
                }
                Interpolation::Trilinear => {
                    crate::with_voxels!(self.source, |s| fill::<_, true>(s, &ctx, out))
                }
            }
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

/// Deformed bounds of one block's vertices, four vertices of a row at a
/// time (same expressions as `deformed_coordinate`; NaN-propagating min/max:
/// a NaN displacement must show).
fn block_bounds(c: &KernelConsts, disp: &DisplacementsRef<'_>, b: usize) -> BlockBounds {
    const W: usize = 4;
    let (lo, hi) = c.layout.vertices(b);
    let [nx, ny, _] = c.mesh.vertex_dims();
    let inv = c.inv_spacing.map(f32x4::splat);
    let mut mn = [f32x4::splat(f32::INFINITY); 3];
    let mut mx = [f32x4::splat(f32::NEG_INFINITY); 3];
    let mut fold = |p: [f32x4; 3]| {
        for a in 0..3 {
            mn[a] = (p[a].simd_lt(mn[a]) | p[a].is_nan()).select(p[a], mn[a]);
            mx[a] = (p[a].simd_gt(mx[a]) | p[a].is_nan()).select(p[a], mx[a]);
        }
    };
    let width = hi[0] - lo[0] + 1;
    for k in lo[2]..=hi[2] {
        let z0 = f32x4::splat(k as f32);
        for j in lo[1]..=hi[1] {
            let y0 = f32x4::splat(j as f32);
            let row = lo[0] + nx * (j + ny * k);
            let (dx, dy, dz) = (
                &disp.x[row..row + width],
                &disp.y[row..row + width],
                &disp.z[row..row + width],
            );
            // Chunks of four; the last one is padded by repeating its final
            // vertex, which changes neither minimum nor maximum.
            let mut n = 0;
            while n < width {
                let mut i = [0usize; W];
                for (l, v) in i.iter_mut().enumerate() {
                    *v = (n + l).min(width - 1);
                }
                let x0 = f32x4::new(i.map(|v| (lo[0] + v) as i32 as f32));
                let d = |s: &[f32]| f32x4::new([s[i[0]], s[i[1]], s[i[2]], s[i[3]]]);
                fold([
                    x0 + d(dx) * inv[0],
                    y0 + d(dy) * inv[1],
                    z0 + d(dz) * inv[2],
                ]);
                n += W;
            }
        }
    }
    let reduce = |v: f32x4, take: fn(f32, f32) -> bool| {
        v.to_array()
            .into_iter()
            .reduce(|acc, p| if take(p, acc) || p.is_nan() { p } else { acc })
            .expect("four lanes")
    };
    BlockBounds {
        min: [0, 1, 2].map(|a| reduce(mn[a], |p, acc| p < acc)),
        max: [0, 1, 2].map(|a| reduce(mx[a], |p, acc| p > acc)),
    }
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

fn raster_block(ctx: &RasterCtx<'_>, lanes: &LaneCtx<'_>, b: usize, out: &[AtomicU32]) {
    let (lo, hi) = ctx.c.layout.cells(b);
    let mesh = &ctx.c.mesh;
    // Same-parity cells of the block, `LANES` at a time.
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

/// Pass 2 over the region: owner key → interpolated value (f32 bits), eight
/// voxels of a row at a time (`super::fill_lanes`); `TRI`: trilinear mode.
fn fill<T: Sample, const TRI: bool>(src: &[T], ctx: &RasterCtx<'_>, out: &[AtomicU32]) {
    let dims = ctx.c.mesh.vertex_dims();
    assert_eq!(src.len(), dims[0] * dims[1] * dims[2]);
    let r = ctx.clip;
    let d = r.dims();
    let bg = ctx.c.background.to_bits();
    (0..d[1] * d[2]).into_par_iter().for_each(|row| {
        let y = r.lo[1] + (row % d[1]) as i32;
        let z = r.lo[2] + (row / d[1]) as i32;
        let base = ctx.output.linear([r.lo[0], y, z]);
        // One group per row: lanes without an owner keep stale corners, and
        // their results are discarded.
        let mut g = FillGroup::default();
        // Trilinear mode: each lane's owner cell (source cell indices).
        let mut cells = [[0i32; FILL_LANES]; 3];
        g.q[1] = [y as f32; FILL_LANES];
        g.q[2] = [z as f32; FILL_LANES];
        for (c, chunk) in out[base..base + d[0]].chunks(FILL_LANES).enumerate() {
            let mut owners = [u32::MAX; FILL_LANES];
            for (o, a) in owners.iter_mut().zip(chunk) {
                *o = a.load(Relaxed);
            }
            if owners.iter().all(|&o| o == u32::MAX) {
                for a in chunk {
                    a.store(bg, Relaxed);
                }
                continue;
            }
            let x0 = r.lo[0] + (c * FILL_LANES) as i32;
            for (l, &owner) in owners.iter().enumerate() {
                g.q[0][l] = (x0 + l as i32) as f32;
                if owner == u32::MAX {
                    continue;
                }
                if l > 0 && owners[l - 1] == owner {
                    // Same tetrahedron as the previous voxel: same corners.
                    for a in 0..4 {
                        for axis in 0..3 {
                            g.p[a][axis][l] = g.p[a][axis][l - 1];
                            g.o[a][axis][l] = g.o[a][axis][l - 1];
                        }
                        g.v[a][l] = g.v[a][l - 1];
                    }
                    for c in &mut cells {
                        c[l] = c[l - 1];
                    }
                } else {
                    let cell = gather::<T, TRI>(ctx, src, owner, l, &mut g);
                    for axis in 0..3 {
                        cells[axis][l] = cell[axis] as i32;
                    }
                }
            }
            let v = if TRI {
                sample_group(src, dims, &g, &cells)
            } else {
                interpolate_group(&g)
            };
            for (l, a) in chunk.iter().enumerate() {
                a.store(
                    if owners[l] == u32::MAX {
                        bg
                    } else {
                        v[l].to_bits()
                    },
                    Relaxed,
                );
            }
        }
    });
}

/// Lane `l` of `g`: the corners (source index units) and source values of
/// the tetrahedron of owner key `owner` (its id, maybe with `WEAK_OWNER`;
/// trilinear mode, `TRI`: the corners' offsets in the cell instead of the
/// values); returns the owner's cell.
#[inline(always)]
fn gather<T: Sample, const TRI: bool>(
    ctx: &RasterCtx<'_>,
    src: &[T],
    owner: u32,
    l: usize,
    g: &mut FillGroup,
) -> [usize; 3] {
    let mesh = &ctx.c.mesh;
    let (cell, t) = ctx.decoder.decode(owner & OWNER_ID);
    let [nx, ny, _] = mesh.vertex_dims();
    let corners = CELL_TETS[cell_parity(cell)][t];
    let base = cell[0] + nx * (cell[1] + ny * cell[2]);
    // The cell's farthest corner bounds every load below.
    let last = base + 1 + nx * (1 + ny);
    let d = &ctx.disp;
    assert!(last < src.len() && last < d.x.len() && last < d.y.len() && last < d.z.len());
    let inv = ctx.c.inv_spacing;
    for (a, &corner) in corners.iter().enumerate() {
        let o = corner_offset(corner);
        let gi = base + o[0] + nx * (o[1] + ny * o[2]);
        // SAFETY: `gi <= last`, which is in bounds of all four slices.
        let (dx, dy, dz, v) = unsafe {
            (
                *d.x.get_unchecked(gi),
                *d.y.get_unchecked(gi),
                *d.z.get_unchecked(gi),
                *src.get_unchecked(gi),
            )
        };
        g.p[a][0][l] = deformed_coordinate(cell[0] + o[0], dx, inv[0]);
        g.p[a][1][l] = deformed_coordinate(cell[1] + o[1], dy, inv[1]);
        g.p[a][2][l] = deformed_coordinate(cell[2] + o[2], dz, inv[2]);
        if TRI {
            for (dst, &off) in g.o[a].iter_mut().zip(&o) {
                dst[l] = off as f32;
            }
        } else {
            g.v[a][l] = v.to_f32();
        }
    }
    cell
}

/// Trilinear mode: the sample of the source at every lane's barycentric
/// rest position (lanes without an owner compute garbage from stale or zero
/// corners, in bounds, and are discarded by the caller).
#[inline(always)]
fn sample_group<T: Sample>(
    src: &[T],
    dims: [usize; 3],
    g: &FillGroup,
    cells: &[[i32; FILL_LANES]; 3],
) -> [f32; FILL_LANES] {
    let rest = rest_group(g);
    let n = dims.map(|d| d as i32);
    let c = trilinear_corners(cells, &rest, n);
    let mut v = [[0f32; FILL_LANES]; 8];
    let (nx, ny) = (dims[0], dims[0] * dims[1]);
    for l in 0..FILL_LANES {
        let xs = [c.i0[0][l] as usize, c.i1[0][l] as usize];
        let ys = [c.i0[1][l] as usize * nx, c.i1[1][l] as usize * nx];
        let zs = [c.i0[2][l] as usize * ny, c.i1[2][l] as usize * ny];
        for (k, corner) in v.iter_mut().enumerate() {
            let i = xs[k & 1] + ys[(k >> 1) & 1] + zs[k >> 2];
            debug_assert!(i < src.len());
            // SAFETY: `trilinear_corners` clamps every index to
            // `0..dims[axis]`, and `fill` asserted `src.len()` is the
            // product of `dims`.
            corner[l] = unsafe { src.get_unchecked(i) }.to_f32();
        }
    }
    trilinear_group(&v, &c.f)
}
