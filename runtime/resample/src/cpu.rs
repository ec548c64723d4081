//! The rayon kernels of the resampler (the CPU twin of
//! `shaders/resample/*.wgsl`).
//!
//! - block bounds: one task per block, min/max of its vertices' positions
//!   (a vertex row of the block per 8-wide SIMD load);
//! - both passes, fused per **output tile** (`TILE` voxels; one rayon task
//!   per tile, tiles are disjoint boxes of the region): the blocks whose
//!   deformed bounds meet the tile are binned to it first (a counting sort
//!   over the block list); the tile's rows of cells go sixteen at a time —
//!   the even and the odd cells of a row strip as two lane groups of one
//!   parity, their corners from contiguous loads of the four vertex rows
//!   (`lanes::strip_corners`, prefetched a layer ahead) — through
//!   `super::lanes`: per cell the face planes and, per candidate voxel
//!   centre of the cell's box clipped to the tile, the containing
//!   tetrahedron of smallest owner key (`sampling_mesh::WEAK_OWNER`). A
//!   claim that beats the tile's key stores its key and its payload, both
//!   in the thread's own tile arrays (no atomics): the lower corner and
//!   fractions of the trilinear sample at the barycentric rest position
//!   (trilinear mode) or the interpolated value (tetrahedral mode), from
//!   the weights `λ_a = t_a / D_a` that pass 1 has in hand — the bits pass 2
//!   of the WGSL kernels (and of the previous CPU kernel) compute from
//!   scratch. A block none of whose vertices moved claims its vertices
//!   directly (`claim_still_block`: every claim weak, weight 1 at the
//!   vertex). Then every voxel of the tile is written once: the trilinear
//!   sample (`super::fill_lanes`), the value, or the background.
//!
//! Per thread one tile's arrays (20 bytes per tile voxel, 640 KiB, kept
//! between calls); no other per-voxel memory; every output word of the region is written
//! exactly once, so nothing is cleared first.

// Lane loops index several arrays by the lane number.
#![allow(clippy::needless_range_loop)]

use super::blocks::BlockBounds;
use super::counters;
use super::fill_lanes::{FILL_LANES, trilinear_group};
use super::lanes::{LANES, LaneCtx, TileSink, raster_cells, strip_corners};
use super::sampling_mesh::{
    CELL_TETS, TETS_PER_CELL, WEAK_OWNER, cell_parity, deformed_coordinate,
};
use super::{
    DisplacementsRef, Interpolation, Job, KernelConsts, Kernels, OutputGrid, ResampleError,
    TetMask, VoxelBox,
};
use crate::volume::{Sample, VoxelSlice};
use rayon::prelude::*;
use voxflex_core::prefetch::prefetch_read;
use wide::{f32x8, i32x8};

/// The CPU half of a resampling call.
pub(crate) struct CpuKernels<'a> {
    pub source: VoxelSlice<'a>,
    pub disp: DisplacementsRef<'a>,
    pub mask: Option<&'a TetMask>,
    pub out: &'a mut Vec<f32>,
    /// Write values (false only in tests that inspect the owner keys).
    pub fill: bool,
    /// Let still blocks claim their vertices directly (false only in tests
    /// that compare the shortcut with the lanes).
    pub still_shortcut: bool,
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
        // Every word of the output is rewritten by the tiles; new words are
        // written in parallel so that both cores share the first-touch page
        // faults.
        let len = self.out.len();
        if n < len {
            self.out.truncate(n);
        } else {
            self.out.par_extend(rayon::iter::repeat_n(0.0, n - len));
        }
        Ok(())
    }

    fn rasterise(&mut self, job: &Job<'_>) -> Result<(), ResampleError> {
        let t0 = std::time::Instant::now();
        let tiles = Tiles::new(job.region);
        let (offsets, list) = tiles.bin(job);
        let t1 = std::time::Instant::now();
        let mask = self.mask.filter(|m| !m.is_empty());
        let ctx = RasterCtx {
            c: job.consts,
            bounds: job.bounds,
            still_blocks: self.still_shortcut && mask.is_none() && job.consts.eps < 0.25,
            mask,
            output: *job.output,
            fill: self.fill,
        };
        let lanes = LaneCtx {
            vertex_dims: job.consts.mesh.vertex_dims(),
            cell_dims: job.consts.mesh.cell_dims(),
            inv_spacing: job.consts.inv_spacing,
            eps: job.consts.eps,
            disp: self.disp,
            clip: job.region,
        };
        assert_eq!(self.out.len(), job.output.len());
        let out = OutPtr(self.out.as_mut_ptr());
        let work = |t: usize| (t, &list[offsets[t] as usize..offsets[t + 1] as usize]);
        macro_rules! run {
            ($tri:literal) => {
                crate::with_voxels!(self.source, |s| (0..tiles.count())
                    .into_par_iter()
                    .map(work)
                    .for_each(|(t, blocks)| {
                        SCRATCH.with_borrow_mut(|scratch| {
                            tile::<_, $tri>(&ctx, &lanes, s, tiles.tile(t), blocks, scratch, &out)
                        })
                    }))
            };
        }
        match job.consts.interpolation {
            Interpolation::Tetrahedral => run!(false),
            Interpolation::Trilinear => run!(true),
        }
        let t2 = std::time::Instant::now();
        counters::report(job.consts.mesh.cell_count(), job.region.count() as usize);
        tracing::trace!(
            voxels = job.region.count(),
            blocks = job.blocks.len(),
            tiles = tiles.count(),
            binned = list.len(),
            bin = ?(t1 - t0),
            tiles_time = ?(t2 - t1),
            "resample: tiles (cpu)"
        );
        Ok(())
    }
}

/// Deformed bounds of one block's vertices (same expressions as
/// `deformed_coordinate`; NaN-propagating min/max: a NaN displacement must
/// show): each vertex row of the block (at most 5 vertices) is one 8-wide
/// load per axis, the lanes past the block repeating its first vertex
/// (which changes neither minimum nor maximum).
fn block_bounds(c: &KernelConsts, disp: &DisplacementsRef<'_>, b: usize) -> BlockBounds {
    let (lo, hi) = c.layout.vertices(b);
    let [nx, ny, _] = c.mesh.vertex_dims();
    let width = hi[0] - lo[0] + 1;
    debug_assert!(width <= 8);
    let lane = f32x8::from([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    let valid: f32x8 =
        bytemuck::cast(i32x8::from([0, 1, 2, 3, 4, 5, 6, 7]).simd_lt(i32x8::splat(width as i32)));
    let inv = c.inv_spacing.map(f32x8::splat);
    let x0 = f32x8::splat(lo[0] as u32 as f32) + lane;
    let mut mn = [f32x8::splat(f32::INFINITY); 3];
    let mut mx = [f32x8::splat(f32::NEG_INFINITY); 3];
    let d = [disp.x, disp.y, disp.z];
    for k in lo[2]..=hi[2] {
        let z0 = f32x8::splat(k as u32 as f32);
        for j in lo[1]..=hi[1] {
            let y0 = f32x8::splat(j as u32 as f32);
            let row = lo[0] + nx * (j + ny * k);
            for a in 0..3 {
                let s = d[a];
                let v = if row + 8 <= s.len() {
                    f32x8::from(<[f32; 8]>::try_from(&s[row..row + 8]).expect("8 values"))
                } else {
                    f32x8::from(std::array::from_fn(|l| s[row + l.min(width - 1)]))
                };
                let rest = match a {
                    0 => x0,
                    1 => y0,
                    _ => z0,
                };
                let p = rest + v * inv[a];
                // Lanes past the block repeat its first vertex.
                let first = f32x8::splat(p.as_array()[0]);
                let p = valid.select(p, first);
                mn[a] = (p.simd_lt(mn[a]) | p.is_nan()).select(p, mn[a]);
                mx[a] = (p.simd_gt(mx[a]) | p.is_nan()).select(p, mx[a]);
            }
        }
    }
    let reduce = |v: f32x8, take: fn(f32, f32) -> bool| {
        v.to_array()
            .into_iter()
            .reduce(|acc, p| if take(p, acc) || p.is_nan() { p } else { acc })
            .expect("eight lanes")
    };
    BlockBounds {
        min: [0, 1, 2].map(|a| reduce(mn[a], |p, acc| p < acc)),
        max: [0, 1, 2].map(|a| reduce(mx[a], |p, acc| p > acc)),
    }
}

/// Output tile edge, voxels (x, y, z): a tile's keys and payloads (20 bytes
/// per voxel, 640 KiB) stay in a core's L2 cache while its blocks are
/// rasterised into it. Measured on the 256³ twist (2 cores): 64 × 32 × 16
/// and 128 × 32 × 8 were the fastest of the shapes tried, 32 × 32 × 16 and
/// 256 × 16 × 4 about 8 % slower (more blocks seen from two tiles, more
/// part-filled lane groups).
pub(crate) const TILE: [usize; 3] = [64, 32, 16];

/// The tiles of an output region.
struct Tiles {
    region: VoxelBox,
    n: [usize; 3],
}

impl Tiles {
    fn new(region: VoxelBox) -> Self {
        let d = region.dims();
        Self {
            region,
            n: [0, 1, 2].map(|a| d[a].div_ceil(TILE[a])),
        }
    }

    fn count(&self) -> usize {
        self.n[0] * self.n[1] * self.n[2]
    }

    /// Tile `t`'s voxels (x fastest over tiles), clipped to the region.
    fn tile(&self, t: usize) -> VoxelBox {
        let ti = [
            t % self.n[0],
            (t / self.n[0]) % self.n[1],
            t / (self.n[0] * self.n[1]),
        ];
        let r = &self.region;
        let lo = [0, 1, 2].map(|a| r.lo[a] + (ti[a] * TILE[a]) as i32);
        VoxelBox {
            lo,
            hi: [0, 1, 2].map(|a| (lo[a] + TILE[a] as i32 - 1).min(r.hi[a])),
        }
    }

    /// Per tile, the job's blocks whose deformed bounds hold a voxel centre
    /// of the tile, in the job's order: `list[offsets[t]..offsets[t + 1]]`.
    fn bin(&self, job: &Job<'_>) -> (Vec<u32>, Vec<u32>) {
        let r = &self.region;
        let n = self.n;
        let span = |b: u32| {
            let bb = &job.bounds[b as usize];
            let v = VoxelBox::from_continuous(bb.min, bb.max, 0).intersect(r);
            (!v.is_empty()).then(|| {
                let t = |p: [i32; 3]| [0, 1, 2].map(|a| (p[a] - r.lo[a]) as usize / TILE[a]);
                (t(v.lo), t(v.hi))
            })
        };
        let spans: Vec<Option<([usize; 3], [usize; 3])>> =
            job.blocks.par_iter().map(|&b| span(b)).collect();
        let mut offsets = vec![0u32; self.count() + 1];
        let each = |(lo, hi): ([usize; 3], [usize; 3]), f: &mut dyn FnMut(usize)| {
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        f(x + n[0] * (y + n[1] * z));
                    }
                }
            }
        };
        for s in spans.iter().flatten() {
            each(*s, &mut |t| offsets[t + 1] += 1);
        }
        for t in 0..self.count() {
            offsets[t + 1] += offsets[t];
        }
        let mut fill = offsets.clone();
        let mut list = vec![0u32; offsets[self.count()] as usize];
        for (s, &b) in spans.iter().zip(job.blocks) {
            if let Some(s) = s {
                each(*s, &mut |t| {
                    list[fill[t] as usize] = b;
                    fill[t] += 1;
                });
            }
        }
        (offsets, list)
    }
}

/// A thread's tile arrays (see [`TileSink`]).
#[derive(Default)]
struct Scratch {
    keys: Vec<u32>,
    payload: Vec<[f32; 4]>,
}

thread_local! {
    /// Each thread's tile arrays, kept from call to call (640 KiB), so no
    /// call allocates them or faults their pages in again.
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// The output values, written by the tiles (disjoint boxes) in parallel.
struct OutPtr(*mut f32);

// SAFETY: every tile writes only the output words of its own voxel box, and
// the boxes of a job's tiles are disjoint; the vector outlives the parallel
// loop that writes through the pointer.
unsafe impl Sync for OutPtr {}

/// What the per-tile kernels read besides the lanes' context.
struct RasterCtx<'a> {
    c: &'a KernelConsts,
    /// Every block's deformed bounds.
    bounds: &'a [BlockBounds],
    /// Still blocks may take the shortcut (no mask, inclusion slack below
    /// one half: a still tetrahedron then holds no voxel centre but its
    /// corners).
    still_blocks: bool,
    mask: Option<&'a TetMask>,
    output: OutputGrid,
    /// Write values (false: the owner keys, for tests).
    fill: bool,
}

/// One output tile: claims of every listed block's cells (clipped to the
/// tile) into the thread's tile arrays, then each voxel's value — the
/// trilinear sample at its owner's rest position, the interpolated value or
/// the background — written once into the output.
fn tile<T: Sample, const TRI: bool>(
    ctx: &RasterCtx<'_>,
    lanes: &LaneCtx<'_>,
    src: &[T],
    tile: VoxelBox,
    blocks: &[u32],
    scratch: &mut Scratch,
    out: &OutPtr,
) {
    let d = tile.dims();
    let len = d[0] * d[1] * d[2];
    if scratch.keys.len() < len {
        scratch.keys.resize(len, u32::MAX);
        scratch.payload.resize(len, [0.0; 4]);
    }
    let keys = &mut scratch.keys[..len];
    keys.fill(u32::MAX);
    let mut sink = TileSink {
        keys,
        payload: &mut scratch.payload[..len],
        lo: tile.lo,
        dims: [d[0], d[1]],
    };
    let lanes = LaneCtx {
        clip: tile,
        ..*lanes
    };
    // Runs of blocks along x (the list is in block order, x fastest), whose
    // cell rows go through the lanes sixteen cells at a time.
    let layout = &ctx.c.layout;
    let bdims = layout.block_dims();
    // Blocks whose vertices all sit at rest claim their vertices directly.
    let still = |b: usize| ctx.still_blocks && is_still(ctx.c, lanes.disp, &ctx.bounds[b], b);
    let mut i = 0;
    while i < blocks.len() {
        let b0 = blocks[i] as usize;
        if still(b0) {
            claim_still_block::<T, TRI>(ctx.c, &lanes.clip, b0, &mut sink, src);
            i += 1;
            continue;
        }
        let [bx0, by, bz] = layout.block_of_linear(b0);
        let mut bx1 = bx0;
        i += 1;
        while i < blocks.len()
            && bx1 + 1 < bdims[0]
            && blocks[i] as usize == layout.linear([bx1 + 1, by, bz])
            && !still(blocks[i] as usize)
        {
            bx1 += 1;
            i += 1;
        }
        let (lo, _) = layout.cells(b0);
        let (_, hi) = layout.cells(layout.linear([bx1, by, bz]));
        // The run's vertex rows come from memory in short pieces: ask for
        // each vertex layer two cell layers ahead.
        prefetch_layer(lanes.disp, ctx.c.mesh.vertex_dims(), lo, hi, lo[2]);
        prefetch_layer(lanes.disp, ctx.c.mesh.vertex_dims(), lo, hi, lo[2] + 1);
        for k in lo[2]..hi[2] {
            prefetch_layer(lanes.disp, ctx.c.mesh.vertex_dims(), lo, hi, k + 2);
            for j in lo[1]..hi[1] {
                for x0 in (lo[0]..hi[0]).step_by(2 * LANES) {
                    raster_strip::<T, TRI>(ctx, &lanes, [x0, j, k], hi[0] - x0, &mut sink, src);
                }
            }
        }
    }
    let dims = ctx.c.mesh.vertex_dims();
    let bg = ctx.c.background;
    for z in 0..d[2] {
        for y in 0..d[1] {
            let row = d[0] * (y + d[1] * z);
            let base =
                ctx.output
                    .linear([tile.lo[0], tile.lo[1] + y as i32, tile.lo[2] + z as i32]);
            for x0 in (0..d[0]).step_by(FILL_LANES) {
                let w = FILL_LANES.min(d[0] - x0);
                let mut keys = [u32::MAX; FILL_LANES];
                keys[..w].copy_from_slice(&sink.keys[row + x0..row + x0 + w]);
                let mut v = [bg; FILL_LANES];
                if !ctx.fill {
                    v = keys.map(f32::from_bits);
                } else if keys.iter().any(|&k| k != u32::MAX) {
                    let p = &sink.payload[row + x0..row + x0 + w];
                    if TRI {
                        // Eight corners per lane from the lower corner; a
                        // zero fraction reads the same voxel twice (its
                        // neighbour's weight is zero: never read).
                        let mut c = [[0f32; FILL_LANES]; 8];
                        let mut f = [[0f32; FILL_LANES]; 3];
                        for l in 0..w {
                            if keys[l] != u32::MAX {
                                let [b, fx, fy, fz] = p[l];
                                let b = b.to_bits() as usize;
                                let sx = (fx != 0.0) as usize;
                                let sy = if fy != 0.0 { dims[0] } else { 0 };
                                let sz = if fz != 0.0 { dims[0] * dims[1] } else { 0 };
                                assert!(b + sx + sy + sz < src.len());
                                for (k, corner) in c.iter_mut().enumerate() {
                                    let i = b
                                        + if k & 1 != 0 { sx } else { 0 }
                                        + if k & 2 != 0 { sy } else { 0 }
                                        + if k & 4 != 0 { sz } else { 0 };
                                    // SAFETY: `i <= b + sx + sy + sz`, in
                                    // bounds (asserted above).
                                    corner[l] = unsafe { src.get_unchecked(i) }.to_f32();
                                }
                                f[0][l] = fx;
                                f[1][l] = fy;
                                f[2][l] = fz;
                            }
                        }
                        let s = trilinear_group(&c, &f);
                        for l in 0..w {
                            if keys[l] != u32::MAX {
                                v[l] = s[l];
                            }
                        }
                    } else {
                        for l in 0..w {
                            if keys[l] != u32::MAX {
                                v[l] = p[l][0];
                            }
                        }
                    }
                }
                for (l, &value) in v[..w].iter().enumerate() {
                    // SAFETY: the voxel is inside this tile, which lies
                    // inside the output (`base + x0 + l < out.len()`), and no
                    // other tile writes it.
                    unsafe { *out.0.add(base + x0 + l) = value };
                }
            }
        }
    }
}

/// True when no vertex of block `b` moved (every deformed position is its
/// rest index; `bounds`: the block's, a quick first test).
fn is_still(c: &KernelConsts, disp: DisplacementsRef<'_>, bounds: &BlockBounds, b: usize) -> bool {
    let (lo, hi) = c.layout.vertices(b);
    if (0..3).any(|a| bounds.min[a] != lo[a] as u32 as f32 || bounds.max[a] != hi[a] as u32 as f32)
    {
        return false;
    }
    let [nx, ny, _] = c.mesh.vertex_dims();
    let d = [disp.x, disp.y, disp.z];
    for k in lo[2]..=hi[2] {
        for j in lo[1]..=hi[1] {
            let row = nx * (j + ny * k);
            for i in lo[0]..=hi[0] {
                let v = [i, j, k];
                for a in 0..3 {
                    let rest = v[a] as u32 as f32;
                    if deformed_coordinate(v[a], d[a][row + i], c.inv_spacing[a]) != rest {
                        return false;
                    }
                }
            }
        }
    }
    true
}

/// Per parity and cell corner, the smallest tetrahedron (0..5) that has it.
const MIN_TET: [[u8; 8]; 2] = {
    let mut out = [[255u8; 8]; 2];
    let mut p = 0;
    while p < 2 {
        let mut t = TETS_PER_CELL;
        while t > 0 {
            t -= 1;
            let mut a = 0;
            while a < 4 {
                out[p][CELL_TETS[p][t][a] as usize] = t as u8;
                a += 1;
            }
        }
        p += 1;
    }
    out
};

/// The claims of a still block (see [`is_still`]) on its vertices inside
/// `clip`, without the lanes: a still tetrahedron holds no voxel centre but
/// its corners (the inclusion slack is below one half), every claim is weak
/// (`WEAK_OWNER`), and a vertex's smallest key in the block is that of the
/// block's first cell holding it, with that cell's first tetrahedron at the
/// corner; the payload is the vertex itself (barycentric weight 1).
fn claim_still_block<T: Sample, const TRI: bool>(
    c: &KernelConsts,
    clip: &VoxelBox,
    b: usize,
    sink: &mut TileSink<'_>,
    src: &[T],
) {
    let (lo, hi) = c.layout.vertices(b);
    let [nx, ny, _] = c.mesh.vertex_dims();
    let v_lo = [0, 1, 2].map(|a| (lo[a] as i32).max(clip.lo[a]));
    let v_hi = [0, 1, 2].map(|a| (hi[a] as i32).min(clip.hi[a]));
    for z in v_lo[2]..=v_hi[2] {
        for y in v_lo[1]..=v_hi[1] {
            for x in v_lo[0]..=v_hi[0] {
                let v = [x as usize, y as usize, z as usize];
                let cell = [0, 1, 2].map(|a| if v[a] > lo[a] { v[a] - 1 } else { v[a] });
                let corner = (v[0] - cell[0]) + 2 * (v[1] - cell[1]) + 4 * (v[2] - cell[2]);
                let t = MIN_TET[cell_parity(cell)][corner] as u32;
                let key = WEAK_OWNER | (c.mesh.cell_linear(cell) as u32 * TETS_PER_CELL as u32 + t);
                let i = sink.local([x, y, z]);
                if key < sink.keys[i] {
                    sink.keys[i] = key;
                    let lin = v[0] + nx * (v[1] + ny * v[2]);
                    sink.payload[i] = if TRI {
                        [f32::from_bits(lin as u32), 0.0, 0.0, 0.0]
                    } else {
                        [src[lin].to_f32(), 0.0, 0.0, 0.0]
                    };
                }
            }
        }
    }
}

/// Prefetches the displacements of vertex layer `k` (if it exists) over
/// the vertex rows and columns of the cells `lo..hi` (exclusive, so `..=hi`
/// in vertices).
#[inline(always)]
fn prefetch_layer(
    disp: DisplacementsRef<'_>,
    dims: [usize; 3],
    lo: [usize; 3],
    hi: [usize; 3],
    k: usize,
) {
    if k >= dims[2] {
        return;
    }
    for j in lo[1]..=hi[1] {
        let start = lo[0] + dims[0] * (j + dims[1] * k);
        let end = hi[0] + dims[0] * (j + dims[1] * k);
        for d in [disp.x, disp.y, disp.z] {
            let row = &d[start..=end];
            for i in (0..row.len()).step_by(16).chain([row.len() - 1]) {
                prefetch_read(row.as_ptr(), (i * std::mem::size_of::<f32>()) as isize);
            }
        }
    }
}

/// The cells `(x0 .. x0 + min(count, 16), j, k)` of one row: the even
/// offsets as one lane group, the odd ones as another (the two parities).
fn raster_strip<T: Sample, const TRI: bool>(
    ctx: &RasterCtx<'_>,
    lanes: &LaneCtx<'_>,
    [x0, j, k]: [usize; 3],
    count: usize,
    sink: &mut TileSink<'_>,
    src: &[T],
) {
    let count = count.min(2 * LANES);
    let corners = strip_corners(lanes, x0, j, k);
    let mesh = &ctx.c.mesh;
    for (g, c) in corners.iter().enumerate() {
        let n = (count + 1 - g) / 2;
        if n == 0 {
            continue;
        }
        let cells: [[usize; 3]; LANES] = std::array::from_fn(|l| [x0 + g + 2 * l.min(n - 1), j, k]);
        let removed: [u8; LANES] = match ctx.mask {
            Some(m) => cells.map(|c| m.cell_bits(mesh.cell_linear(c))),
            None => [0; LANES],
        };
        if cell_parity(cells[0]) == 0 {
            raster_cells::<0, T, TRI>(lanes, &cells, c, &removed, n, sink, src);
        } else {
            raster_cells::<1, T, TRI>(lanes, &cells, c, &removed, n, sink, src);
        }
    }
}
