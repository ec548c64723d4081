//! The WGSL twin of [`super::pcg::solve`]: block-Jacobi PCG with the
//! sparse mat-vec, the vector updates and the dot products (reductions) on
//! the device (`shaders/mesh-model/pcg.wgsl`), in f32.
//!
//! The matrix is assembled on the CPU (rotations and element blocks, as for
//! the rayon path) and its blocks go up once per solve with the right-hand
//! side and the start vector; the structure (row starts, columns) goes up
//! once. An iteration is seven dispatches and no read-back; the residual is
//! read every [`CHECK_EVERY`] iterations for the stopping test. Hanging
//! nodes (octree proxies) are handled as on the CPU: their rows of `A p`
//! and `b − A x` are moved onto their masters (`untie_*`) and `p` follows
//! the masters (`tie_p`), three more dispatches per iteration only when a
//! mesh has them.

use super::block_matrix::BlockMatrix;
use super::boundary::TieTables;
use super::pcg::{CgOutcome, CgSettings};
use crate::error::GpuError;
use crate::gpu::{BufferBinding, BufferId, GpuService, GpuServiceExt, PipelineId};
use crate::proxy::HangingNode;
use glam::{DMat3, DVec3};
use std::sync::Arc;

/// The kernels.
pub const PCG_WGSL: &str = include_str!("../../../../shaders/mesh-model/pcg.wgsl");

/// Iterations between residual read-backs.
pub const CHECK_EVERY: u32 = 8;
/// Workgroup size of the reductions, and the most first-pass partials.
const RED: u64 = 256;
const MAX_PARTIALS: u64 = 1024;
/// Words between scalar slots (256-byte offsets).
const SLOT: usize = 64;
/// Threads per workgroup of the per-node kernels (`WG` in `pcg.wgsl`).
const WORKGROUP: u32 = 64;
/// Bytes of the kernels' `Params` (node count, partials, two unused words).
const PARAMS_BYTES: u64 = 16;

/// Binding numbers of `pcg.wgsl`'s variables (named as there; `PARAMS` is `p_`).
mod bind {
    pub const PARAMS: u32 = 0;
    pub const ROW_START: u32 = 1;
    pub const COL: u32 = 2;
    pub const BLOCKS: u32 = 3;
    pub const INV: u32 = 4;
    pub const FREE: u32 = 5;
    pub const X: u32 = 6;
    pub const R: u32 = 7;
    pub const Z: u32 = 8;
    pub const P: u32 = 9;
    pub const Q: u32 = 10;
    pub const SCALARS: u32 = 11;
    pub const PARTIAL: u32 = 12;
    pub const B: u32 = 13;
    pub const TIE_START: u32 = 14;
    pub const TIE_LIST: u32 = 15;
    pub const UNTIE_START: u32 = 16;
    pub const UNTIE_LIST: u32 = 17;
}

/// The solver's buffers and pipelines on the device.
pub struct GpuPcg {
    gpu: Arc<dyn GpuService>,
    nodes: usize,
    blocks: usize,
    bufs: Buffers,
    kernels: Kernels,
}

struct Buffers {
    params: BufferId,
    row_start: BufferId,
    col: BufferId,
    blocks: BufferId,
    inv: BufferId,
    free: BufferId,
    x: BufferId,
    r: BufferId,
    z: BufferId,
    p: BufferId,
    q: BufferId,
    scalars: BufferId,
    partial: BufferId,
    b: BufferId,
}

struct Kernels {
    start: PipelineId,
    begin_search: PipelineId,
    untie_r: PipelineId,
    untie_q: PipelineId,
    tie_p: PipelineId,
    spmv: PipelineId,
    update_xr: PipelineId,
    update_p: PipelineId,
    advance: PipelineId,
    begin: PipelineId,
    dot_pq: PipelineId,
    dot_rz: PipelineId,
    dot_rr: PipelineId,
    dot_final: PipelineId,
}

/// Three f32 columns of a 3 × 3 block, each padded to a vec4.
fn columns(m: &DMat3) -> [[f32; 4]; 3] {
    [m.x_axis, m.y_axis, m.z_axis].map(|c| [c.x as f32, c.y as f32, c.z as f32, 0.0])
}

fn vec4s(v: &[DVec3]) -> Vec<[f32; 4]> {
    v.iter()
        .map(|p| [p.x as f32, p.y as f32, p.z as f32, 0.0])
        .collect()
}

impl GpuPcg {
    /// Uploads the structure of `a`; refuses a matrix whose blocks exceed
    /// one storage binding.
    pub fn new(gpu: Arc<dyn GpuService>, a: &BlockMatrix) -> Result<Self, GpuError> {
        let (nodes, blocks) = (a.rows(), a.col.len());
        let limit = gpu.limits().max_storage_buffer_binding_size;
        if 48 * blocks as u64 > limit {
            return Err(GpuError(format!(
                "PCG: {blocks} matrix blocks need {} bytes in one binding, above this device's \
                 {limit}; use a coarser proxy or the CPU path",
                48 * blocks
            )));
        }
        let g = &*gpu;
        let vector = |label: &str| g.create_buffer(16 * nodes.max(1) as u64, label);
        let bufs = Buffers {
            params: g.create_buffer(PARAMS_BYTES, "pcg params")?,
            row_start: g.upload(&a.row_start, "pcg row starts")?,
            col: g.upload(&a.col, "pcg columns")?,
            blocks: g.create_buffer(48 * blocks.max(1) as u64, "pcg blocks")?,
            inv: g.create_buffer(48 * nodes.max(1) as u64, "pcg preconditioner")?,
            free: g.create_buffer(4 * nodes.max(1) as u64, "pcg free nodes")?,
            x: vector("pcg x")?,
            r: vector("pcg r")?,
            z: vector("pcg z")?,
            p: vector("pcg p")?,
            q: vector("pcg q")?,
            scalars: g.create_buffer(4 * 4 * SLOT as u64, "pcg scalars")?,
            partial: g.create_buffer(4 * 3 * MAX_PARTIALS, "pcg partial sums")?,
            b: vector("pcg b")?,
        };
        let k = |entry: &str| g.compile(PCG_WGSL, entry);
        let kernels = Kernels {
            start: k("start")?,
            begin_search: k("begin_search")?,
            untie_r: k("untie_r")?,
            untie_q: k("untie_q")?,
            tie_p: k("tie_p")?,
            spmv: k("spmv")?,
            update_xr: k("update_xr")?,
            update_p: k("update_p")?,
            advance: k("advance")?,
            begin: k("begin")?,
            dot_pq: k("dot_pq")?,
            dot_rz: k("dot_rz")?,
            dot_rr: k("dot_rr")?,
            dot_final: k("dot_final")?,
        };
        Ok(Self {
            gpu,
            nodes,
            blocks,
            bufs,
            kernels,
        })
    }

    /// Solves `A x = b` for the free nodes from the given `x`, with the
    /// hanging nodes tied to their masters, as [`super::pcg::solve`] does.
    pub fn solve(
        &self,
        a: &BlockMatrix,
        free: &[bool],
        hanging: &[HangingNode],
        b: &[DVec3],
        x: &mut [DVec3],
        settings: CgSettings,
    ) -> Result<CgOutcome, GpuError> {
        assert_eq!(
            a.col.len(),
            self.blocks,
            "the matrix the solver was built for"
        );
        let (g, n) = (&*self.gpu, self.nodes);
        let blocks: Vec<[[f32; 4]; 3]> = a.blocks.iter().map(columns).collect();
        let inv: Vec<[[f32; 4]; 3]> = (0..n)
            .map(|i| {
                let d = a.diagonal(i);
                if free[i] && d.determinant().abs() > f64::MIN_POSITIVE {
                    columns(&d.inverse())
                } else {
                    [[0.0; 4]; 3]
                }
            })
            .collect();
        // 0 constrained, 1 free, 2 hanging (see the shader).
        let mut free_words: Vec<u32> = free.iter().map(|&f| u32::from(f)).collect();
        for h in hanging {
            free_words[h.node as usize] = 2;
        }
        let ties = if hanging.is_empty() {
            None
        } else {
            let t = TieTables::new(hanging, n);
            Some([
                g.upload(&t.tie_start, "pcg tie starts")?,
                g.upload(&t.tie_list, "pcg ties")?,
                g.upload(&t.untie_start, "pcg untie starts")?,
                g.upload(&t.untie_list, "pcg unties")?,
            ])
        };
        let mut tied = x.to_vec();
        for h in hanging {
            tied[h.node as usize] = h
                .masters
                .iter()
                .map(|&(m, w)| w as f64 * tied[m as usize])
                .sum();
        }
        let x_start = tied;
        // The right-hand side as the solve sees it (`Pᵀ b` on the free
        // nodes), for the stopping test's scale; the device gets `b` on the
        // free and hanging nodes and moves the hanging rows itself.
        let mut untied = b.to_vec();
        for h in hanging.iter().rev() {
            let v = std::mem::take(&mut untied[h.node as usize]);
            for &(m, w) in &h.masters {
                untied[m as usize] += w as f64 * v;
            }
        }
        let b_norm = untied
            .iter()
            .zip(free)
            .filter(|(_, f)| **f)
            .map(|(v, _)| v.length_squared())
            .sum::<f64>()
            .sqrt();
        let restricted: Vec<DVec3> = b
            .iter()
            .zip(&free_words)
            .map(|(v, &kind)| if kind != 0 { *v } else { DVec3::ZERO })
            .collect();
        let scale = if b_norm > 0.0 { b_norm } else { 1.0 };
        let partials = (n as u64).div_ceil(RED).clamp(1, MAX_PARTIALS);
        g.write_buffer(
            self.bufs.params,
            0,
            bytemuck::cast_slice(&[n as u32, partials as u32, 0, 0]),
        )?;
        g.write_buffer(self.bufs.blocks, 0, bytemuck::cast_slice(&blocks))?;
        g.write_buffer(self.bufs.inv, 0, bytemuck::cast_slice(&inv))?;
        g.write_buffer(self.bufs.free, 0, bytemuck::cast_slice(&free_words))?;
        g.write_buffer(self.bufs.b, 0, bytemuck::cast_slice(&vec4s(&restricted)))?;
        g.write_buffer(self.bufs.x, 0, bytemuck::cast_slice(&vec4s(&x_start)))?;

        let bb = &self.bufs;
        let w = |i: u32, id: BufferId| BufferBinding::whole(i, id);
        let nodes_groups = g.workgroups_for(n as u64, WORKGROUP)?;
        let red_groups = [partials as u32, 1, 1];
        let k = &self.kernels;
        let run = |pipeline: PipelineId, bindings: &[BufferBinding], groups: [u32; 3]| {
            g.dispatch(pipeline, bindings, groups)
        };
        let dots = [
            w(bind::PARAMS, bb.params),
            w(bind::FREE, bb.free),
            w(bind::R, bb.r),
            w(bind::Z, bb.z),
            w(bind::P, bb.p),
            w(bind::Q, bb.q),
            w(bind::PARTIAL, bb.partial),
        ];
        let finals = [
            w(bind::PARAMS, bb.params),
            w(bind::SCALARS, bb.scalars),
            w(bind::PARTIAL, bb.partial),
        ];
        let scalars = [w(bind::SCALARS, bb.scalars)];
        let tie_bindings = ties.map(|[ts, tl, us, ul]| {
            (
                [
                    w(bind::PARAMS, bb.params),
                    w(bind::FREE, bb.free),
                    w(bind::R, bb.r),
                    w(bind::Q, bb.q),
                    w(bind::UNTIE_START, us),
                    w(bind::UNTIE_LIST, ul),
                ],
                [
                    w(bind::PARAMS, bb.params),
                    w(bind::FREE, bb.free),
                    w(bind::P, bb.p),
                    w(bind::TIE_START, ts),
                    w(bind::TIE_LIST, tl),
                ],
            )
        });
        run(
            k.start,
            &[
                w(bind::PARAMS, bb.params),
                w(bind::ROW_START, bb.row_start),
                w(bind::COL, bb.col),
                w(bind::BLOCKS, bb.blocks),
                w(bind::FREE, bb.free),
                w(bind::X, bb.x),
                w(bind::R, bb.r),
                w(bind::P, bb.p),
                w(bind::B, bb.b),
            ],
            nodes_groups,
        )?;
        if let Some((untie, _)) = &tie_bindings {
            run(k.untie_r, untie, nodes_groups)?;
        }
        run(
            k.begin_search,
            &[
                w(bind::PARAMS, bb.params),
                w(bind::INV, bb.inv),
                w(bind::FREE, bb.free),
                w(bind::R, bb.r),
                w(bind::Z, bb.z),
                w(bind::P, bb.p),
            ],
            nodes_groups,
        )?;
        if let Some((_, tie)) = &tie_bindings {
            run(k.tie_p, tie, nodes_groups)?;
        }
        run(k.dot_rz, &dots, red_groups)?;
        run(k.dot_rr, &dots, red_groups)?;
        run(k.dot_final, &finals, [1, 1, 1])?;
        run(k.begin, &scalars, [1, 1, 1])?;
        let residual = |g: &dyn GpuService| -> Result<f64, GpuError> {
            let mut rr = [0f32; 1];
            g.read_buffer(
                bb.scalars,
                4 * 3 * SLOT as u64,
                bytemuck::cast_slice_mut(&mut rr),
            )?;
            Ok((rr[0].max(0.0) as f64).sqrt() / scale)
        };
        let mut res = residual(g)?;
        let mut iterations = 0;
        let spmv = [
            w(bind::PARAMS, bb.params),
            w(bind::ROW_START, bb.row_start),
            w(bind::COL, bb.col),
            w(bind::BLOCKS, bb.blocks),
            w(bind::FREE, bb.free),
            w(bind::X, bb.x),
            w(bind::P, bb.p),
            w(bind::Q, bb.q),
        ];
        let update_xr = [
            w(bind::PARAMS, bb.params),
            w(bind::INV, bb.inv),
            w(bind::FREE, bb.free),
            w(bind::X, bb.x),
            w(bind::R, bb.r),
            w(bind::Z, bb.z),
            w(bind::P, bb.p),
            w(bind::Q, bb.q),
            w(bind::SCALARS, bb.scalars),
        ];
        let update_p = [
            w(bind::PARAMS, bb.params),
            w(bind::Z, bb.z),
            w(bind::P, bb.p),
            w(bind::SCALARS, bb.scalars),
        ];
        while res > settings.tolerance && iterations < settings.max_iterations {
            let batch = CHECK_EVERY.min(settings.max_iterations - iterations);
            for _ in 0..batch {
                run(k.spmv, &spmv, nodes_groups)?;
                if let Some((untie, _)) = &tie_bindings {
                    run(k.untie_q, untie, nodes_groups)?;
                }
                run(k.dot_pq, &dots, red_groups)?;
                run(k.dot_final, &finals, [1, 1, 1])?;
                run(k.update_xr, &update_xr, nodes_groups)?;
                run(k.dot_rz, &dots, red_groups)?;
                run(k.dot_rr, &dots, red_groups)?;
                run(k.dot_final, &finals, [1, 1, 1])?;
                run(k.update_p, &update_p, nodes_groups)?;
                if let Some((_, tie)) = &tie_bindings {
                    run(k.tie_p, tie, nodes_groups)?;
                }
                run(k.advance, &scalars, [1, 1, 1])?;
            }
            iterations += batch;
            res = residual(g)?;
            if !res.is_finite() {
                break;
            }
        }
        let mut out = vec![[0f32; 4]; n];
        g.download(bb.x, &mut out)?;
        for (xi, o) in x.iter_mut().zip(&out) {
            *xi = DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64);
        }
        for h in hanging {
            x[h.node as usize] = h
                .masters
                .iter()
                .map(|&(m, w)| w as f64 * x[m as usize])
                .sum();
        }
        if let Some(buffers) = ties {
            for id in buffers {
                g.destroy_buffer(id);
            }
        }
        Ok(CgOutcome {
            iterations,
            residual: res,
        })
    }
}

impl Drop for GpuPcg {
    fn drop(&mut self) {
        let b = &self.bufs;
        for id in [
            b.params,
            b.row_start,
            b.col,
            b.blocks,
            b.inv,
            b.free,
            b.x,
            b.r,
            b.z,
            b.p,
            b.q,
            b.scalars,
            b.partial,
            b.b,
        ] {
            self.gpu.destroy_buffer(id);
        }
    }
}

#[cfg(test)]
#[path = "shader_tests.rs"]
mod shader_tests;
