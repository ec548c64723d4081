//! Pass 1 on four cells at once: the CPU's fast form of
//! [`super::raster::CellRaster`].
//!
//! Four cells of the same parity are the four lanes of every operation, so
//! the corner, face and tetrahedron tables are compile-time constants and
//! every plane, orientation and inclusion test is one 4-wide operation with
//! no shuffles and no data-dependent branches. Each lane computes exactly the
//! scalar expressions of [`super::raster`] (same operations, same order), so
//! the owners are those of [`super::raster::CellRaster`] and of the WGSL
//! kernel, bit for bit.

// Lane loops index several arrays by the lane number: that is the SIMD idiom.
#![allow(clippy::needless_range_loop)]

use super::raster::{ceil_i32, floor_i32};
use super::sampling_mesh::{CORNER_TABLES, FACE_TABLES, corner_offset, deformed_coordinate};
use super::{DisplacementsRef, OutputGrid, VoxelBox};
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};

/// Lanes (cells) per group.
pub(crate) const LANES: usize = 4;

type V = [f32; LANES];

/// A face plane per lane: `t(q) = n · (q − b)`.
#[derive(Clone, Copy)]
struct PlaneV {
    n: [V; 3],
    b: [V; 3],
}

impl PlaneV {
    const ZERO: PlaneV = PlaneV {
        n: [[0.0; LANES]; 3],
        b: [[0.0; LANES]; 3],
    };
}

/// [`super::raster::FacePlane::new`] per lane.
#[inline(always)]
fn plane(p: &[[V; 3]; 8], u: u8, v: u8, w: u8) -> PlaneV {
    let (pu, pv, pw) = (&p[u as usize], &p[v as usize], &p[w as usize]);
    let mut n = [[0.0; LANES]; 3];
    for l in 0..LANES {
        let a = [
            pv[0][l] - pu[0][l],
            pv[1][l] - pu[1][l],
            pv[2][l] - pu[2][l],
        ];
        let c = [
            pw[0][l] - pu[0][l],
            pw[1][l] - pu[1][l],
            pw[2][l] - pu[2][l],
        ];
        n[0][l] = a[1] * c[2] - a[2] * c[1];
        n[1][l] = a[2] * c[0] - a[0] * c[2];
        n[2][l] = a[0] * c[1] - a[1] * c[0];
    }
    PlaneV { n, b: *pu }
}

/// [`super::raster::FacePlane::eval`] per lane.
#[inline(always)]
fn eval(pl: &PlaneV, q: &[V; 3]) -> V {
    let mut t = [0.0; LANES];
    for l in 0..LANES {
        t[l] = pl.n[0][l] * (q[0][l] - pl.b[0][l])
            + (pl.n[1][l] * (q[1][l] - pl.b[1][l]) + pl.n[2][l] * (q[2][l] - pl.b[2][l]));
    }
    t
}

/// One face test of one tetrahedron per lane: `sign(D) · t ≥ −ε |D|`, with
/// lanes whose `D` is zero or not finite never passing.
#[derive(Clone, Copy)]
struct Test {
    sign: V,
    thr: V,
    /// Lanes with a usable `D`.
    ok: u32,
}

impl Test {
    const NONE: Test = Test {
        sign: [0.0; LANES],
        thr: [0.0; LANES],
        ok: 0,
    };
}

#[inline(always)]
fn test(d: &V, eps: f32) -> Test {
    let mut t = Test {
        sign: [0.0; LANES],
        thr: [0.0; LANES],
        ok: 0,
    };
    // The two halves of "usable" are separate lane masks so that each is
    // one vector compare (as one condition LLVM tests it lane by lane).
    let (mut nonzero, mut finite) = (0u32, 0u32);
    for l in 0..LANES {
        t.sign[l] = if d[l] > 0.0 { 1.0 } else { -1.0 };
        t.thr[l] = -eps * d[l].abs();
        nonzero |= ((d[l] != 0.0) as u32) << l;
    }
    for l in 0..LANES {
        finite |= ((d[l].abs() < f32::INFINITY) as u32) << l;
    }
    t.ok = nonzero & finite;
    t
}

#[inline(always)]
fn pass(t: &Test, v: &V) -> u32 {
    let mut m = 0;
    for l in 0..LANES {
        m |= ((t.sign[l] * v[l] >= t.thr[l]) as u32) << l;
    }
    m & t.ok
}

/// What every group needs.
pub(crate) struct LaneCtx<'a> {
    pub vertex_dims: [usize; 3],
    pub cell_dims: [usize; 3],
    pub inv_spacing: [f32; 3],
    pub eps: f32,
    pub disp: DisplacementsRef<'a>,
    pub output: OutputGrid,
    pub clip: VoxelBox,
}

/// Rasterises up to four cells of parity `P` (`cells[l]`, `n` of them valid;
/// `removed[l]`: removed-tetrahedra bits) into `out`.
#[inline(always)]
pub(crate) fn raster_group<const P: usize>(
    ctx: &LaneCtx<'_>,
    cells: &[[usize; 3]; LANES],
    removed: &[u8; LANES],
    n: usize,
    out: &[AtomicU32],
) {
    let [nx, ny, _] = ctx.vertex_dims;
    let inv = ctx.inv_spacing;
    // Corner positions, per lane first, then as p[corner][axis][lane].
    let mut pos = [[[0f32; 3]; 8]; LANES];
    for (l, cell) in cells.iter().enumerate() {
        let base = cell[0] + nx * (cell[1] + ny * cell[2]);
        for c in 0..8u8 {
            let o = corner_offset(c);
            let g = base + o[0] + nx * (o[1] + ny * o[2]);
            pos[l][c as usize] = [
                deformed_coordinate(cell[0] + o[0], ctx.disp.x[g], inv[0]),
                deformed_coordinate(cell[1] + o[1], ctx.disp.y[g], inv[1]),
                deformed_coordinate(cell[2] + o[2], ctx.disp.z[g], inv[2]),
            ];
        }
    }
    let mut p = [[[0f32; LANES]; 3]; 8];
    for c in 0..8 {
        for a in 0..3 {
            p[c][a] = [pos[0][c][a], pos[1][c][a], pos[2][c][a], pos[3][c][a]];
        }
    }
    // Candidate boxes.
    let mut lo = [[0i32; LANES]; 3];
    let mut hi = [[0i32; LANES]; 3];
    let mut active = (1u32 << n) - 1;
    for a in 0..3 {
        let mut mn = p[0][a];
        let mut mx = p[0][a];
        for pc in &p[1..] {
            for l in 0..LANES {
                mn[l] = mn[l].min(pc[a][l]);
                mx[l] = mx[l].max(pc[a][l]);
            }
        }
        for l in 0..LANES {
            lo[a][l] = ceil_i32(mn[l]).max(ctx.clip.lo[a]);
            hi[a][l] = floor_i32(mx[l]).min(ctx.clip.hi[a]);
            if lo[a][l] > hi[a][l] {
                active &= !(1 << l);
            }
        }
    }
    for (l, r) in removed.iter().enumerate() {
        if r & 0x1f == 0x1f {
            active &= !(1 << l);
        }
    }
    if active == 0 {
        return;
    }
    // Planes and orientation tests.
    let faces = &FACE_TABLES.faces[P];
    let it = &CORNER_TABLES.interior[P];
    let bt = &CORNER_TABLES.boundary[P];
    let eps = ctx.eps;
    let mut interior = [PlaneV::ZERO; 4];
    let mut t_corner = [Test::NONE; 4];
    let mut t_central = [Test::NONE; 4];
    let mut boundary = [[PlaneV::ZERO; 3]; 4];
    let mut t_boundary = [[Test::NONE; 3]; 4];
    for k in 0..4 {
        let [u, v, w] = faces[it[k][0] as usize];
        interior[k] = plane(&p, u, v, w);
        t_corner[k] = test(&eval(&interior[k], &p[it[k][1] as usize]), eps);
        t_central[k] = test(&eval(&interior[k], &p[it[k][2] as usize]), eps);
        for m in 0..3 {
            let [u, v, w] = faces[bt[k][m][0] as usize];
            boundary[k][m] = plane(&p, u, v, w);
            t_boundary[k][m] = test(&eval(&boundary[k][m], &p[bt[k][m][1] as usize]), eps);
        }
    }
    // Live tetrahedra per lane.
    let mut live = [0u32; 5];
    for (t, lv) in live.iter_mut().enumerate() {
        for (l, r) in removed.iter().enumerate() {
            *lv |= (((r >> t) & 1 == 0) as u32) << l;
        }
    }
    // Walk every lane's box in step; lanes that run out drop out.
    let mut q = lo;
    let mut base_id = [0u32; LANES];
    for l in 0..LANES {
        let c = cells[l];
        base_id[l] = (5 * (c[0] + ctx.cell_dims[0] * (c[1] + ctx.cell_dims[1] * c[2]))) as u32;
    }
    while active != 0 {
        let mut qf = [[0f32; LANES]; 3];
        for a in 0..3 {
            for l in 0..LANES {
                qf[a][l] = q[a][l] as f32;
            }
        }
        let mut ti = [[0f32; LANES]; 4];
        for k in 0..4 {
            ti[k] = eval(&interior[k], &qf);
        }
        let mut found = 0u32;
        let mut owner = [4u32; LANES];
        for k in 0..4 {
            let mut m = pass(&t_corner[k], &ti[k]) & live[k] & !found;
            if m != 0 {
                for mm in 0..3 {
                    m &= pass(&t_boundary[k][mm], &eval(&boundary[k][mm], &qf));
                }
                for (l, o) in owner.iter_mut().enumerate() {
                    if m & (1 << l) != 0 {
                        *o = k as u32;
                    }
                }
                found |= m;
            }
        }
        let central = live[4] & (0..4).fold(u32::MAX, |acc, k| acc & pass(&t_central[k], &ti[k]));
        found |= central;
        found &= active;
        while found != 0 {
            let l = found.trailing_zeros() as usize;
            found &= found - 1;
            let id = base_id[l] + owner[l];
            let o = &out[ctx.output.linear([q[0][l], q[1][l], q[2][l]])];
            if o.load(Relaxed) > id {
                o.fetch_min(id, Relaxed);
            }
        }
        // Advance each active lane's cursor.
        let mut m = active;
        while m != 0 {
            let l = m.trailing_zeros() as usize;
            m &= m - 1;
            q[0][l] += 1;
            if q[0][l] > hi[0][l] {
                q[0][l] = lo[0][l];
                q[1][l] += 1;
                if q[1][l] > hi[1][l] {
                    q[1][l] = lo[1][l];
                    q[2][l] += 1;
                    if q[2][l] > hi[2][l] {
                        active &= !(1 << l);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::raster::{CellCorners, CellRaster};
    use super::super::sampling_mesh::{SamplingMesh, cell_parity};
    use super::*;
    use crate::grid::Grid;
    use glam::DVec3;
    use proptest::prelude::*;

    proptest! {
        /// Four-lane groups (any mix of cells, tails, removed tetrahedra) give
        /// the owners of the scalar reference, cell by cell.
        #[test]
        fn lanes_equal_scalar_reference(
            d in proptest::collection::vec(-0.6f32..0.6, 3 * 7 * 5 * 4),
            picks in proptest::collection::vec((0usize..72, 0u8..32), 1..5),
            eps in prop::sample::select(vec![0.0f32, 1e-6, 1e-2]),
        ) {
            let grid = Grid::new([7, 5, 4], DVec3::new(1.0, 0.8, 1.3), DVec3::ZERO);
            let mesh = SamplingMesh::new(&grid).unwrap();
            let n = grid.len();
            let (x, rest) = d.split_at(n);
            let (y, z) = rest.split_at(n);
            let disp = DisplacementsRef { x, y, z };
            let inv = [1.0f32, 1.0 / 0.8, 1.0 / 1.3];
            let clip = VoxelBox { lo: [-3; 3], hi: [9; 3] };
            let output = OutputGrid { origin_index: [-3; 3], dims: [13; 3] };
            let ctx = LaneCtx {
                vertex_dims: mesh.vertex_dims(), cell_dims: mesh.cell_dims(), inv_spacing: inv,
                eps, disp, output, clip,
            };
            for parity in 0..2 {
                let chosen: Vec<([usize; 3], u8)> = picks.iter()
                    .map(|&(c, r)| (mesh.cell_of_linear(c % mesh.cell_count()), r))
                    .filter(|(c, _)| cell_parity(*c) == parity)
                    .collect();
                if chosen.is_empty() { continue; }
                let mut cells = [chosen[0].0; LANES];
                let mut removed = [chosen[0].1; LANES];
                for (l, (c, r)) in chosen.iter().enumerate().take(LANES) {
                    cells[l] = *c;
                    removed[l] = *r;
                }
                let k = chosen.len().min(LANES);
                let out: Vec<AtomicU32> = (0..output.len()).map(|_| AtomicU32::new(u32::MAX)).collect();
                if parity == 0 {
                    raster_group::<0>(&ctx, &cells, &removed, k, &out);
                } else {
                    raster_group::<1>(&ctx, &cells, &removed, k, &out);
                }
                let mut want = vec![u32::MAX; output.len()];
                for l in 0..k {
                    let cell = cells[l];
                    let mut c = CellCorners::default();
                    for q in 0..8u8 {
                        let o = corner_offset(q);
                        let v = [cell[0] + o[0], cell[1] + o[1], cell[2] + o[2]];
                        let g = grid.linear(v[0], v[1], v[2]);
                        c.x[q as usize] = deformed_coordinate(v[0], x[g], inv[0]);
                        c.y[q as usize] = deformed_coordinate(v[1], y[g], inv[1]);
                        c.z[q as usize] = deformed_coordinate(v[2], z[g], inv[2]);
                    }
                    let owner = |r: &mut dyn FnMut([f32; 3]) -> Option<usize>, lo: [i32; 3], hi: [i32; 3], want: &mut Vec<u32>| {
                        for zz in lo[2]..=hi[2] {
                            for yy in lo[1]..=hi[1] {
                                for xx in lo[0]..=hi[0] {
                                    if let Some(t) = r([xx as f32, yy as f32, zz as f32]) {
                                        let o = output.linear([xx, yy, zz]);
                                        want[o] = want[o].min(mesh.tet_id(cell, t));
                                    }
                                }
                            }
                        }
                    };
                    if parity == 0 {
                        if let Some(mut r) = CellRaster::<0>::new(&c, removed[l], eps, &clip) {
                            let (lo, hi) = (r.lo, r.hi);
                            owner(&mut |q| r.owner(q), lo, hi, &mut want);
                        }
                    } else if let Some(mut r) = CellRaster::<1>::new(&c, removed[l], eps, &clip) {
                        let (lo, hi) = (r.lo, r.hi);
                        owner(&mut |q| r.owner(q), lo, hi, &mut want);
                    }
                }
                let got: Vec<u32> = out.iter().map(|a| a.load(Relaxed)).collect();
                prop_assert_eq!(got, want);
            }
        }
    }
}
