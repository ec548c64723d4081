//! Pass 1 on eight cells at once: the CPU's fast form of
//! `raster::CellRaster`.
//!
//! Eight cells of the same parity are the eight lanes of every operation, so
//! the corner, face and tetrahedron tables are compile-time constants and
//! every plane, orientation and inclusion test is one 8-wide SIMD operation
//! ([`wide::f32x8`]: one AVX instruction with the workspace's x86-64-v3
//! target, two SSE2 instructions on baseline x86-64, NEON pairs on aarch64)
//! with no shuffles and no data-dependent branches; the lanes' candidate
//! cursors advance with vector selects. Each lane computes exactly the scalar
//! expressions of `raster` (same IEEE operations, same order, no fused
//! multiply-add), so the owners are those of `raster::CellRaster` and of the
//! WGSL kernel, bit for bit.

use super::sampling_mesh::{
    CELL_TETS, CORNER_TABLES, FACE_TABLES, ORIENTATION, WEAK_OWNER, corner_offset,
};
use super::{DisplacementsRef, OutputGrid, VoxelBox};
use std::sync::atomic::{AtomicU32, Ordering::Relaxed};
use wide::{f32x8, i32x8};

/// Lanes (cells) per group.
pub(crate) const LANES: usize = 8;

type F = f32x8;
type I = i32x8;

/// A face plane per lane: `t(q) = n · (q − b)`.
#[derive(Clone, Copy)]
struct PlaneV {
    n: [F; 3],
    b: [F; 3],
}

/// `raster::FacePlane::new` per lane.
#[inline(always)]
fn plane(p: &[[F; 3]; 8], u: u8, v: u8, w: u8) -> PlaneV {
    let (pu, pv, pw) = (&p[u as usize], &p[v as usize], &p[w as usize]);
    let a = [pv[0] - pu[0], pv[1] - pu[1], pv[2] - pu[2]];
    let c = [pw[0] - pu[0], pw[1] - pu[1], pw[2] - pu[2]];
    PlaneV {
        n: [
            a[1] * c[2] - a[2] * c[1],
            a[2] * c[0] - a[0] * c[2],
            a[0] * c[1] - a[1] * c[0],
        ],
        b: *pu,
    }
}

/// `raster::FacePlane::eval` per lane.
#[inline(always)]
fn eval(pl: &PlaneV, q: &[F; 3]) -> F {
    pl.n[0] * (q[0] - pl.b[0]) + (pl.n[1] * (q[1] - pl.b[1]) + pl.n[2] * (q[2] - pl.b[2]))
}

/// One face test of one tetrahedron per lane: `sign(D) · t ≥ −ε |D|`, with
/// lanes whose `D` is zero or not finite never passing.
#[derive(Clone, Copy)]
struct Test {
    sign: F,
    thr: F,
    /// Lanes with a usable `D` (bit per lane).
    ok: u32,
    /// Lanes with `D > 0` (bit per lane).
    positive: u32,
}

#[inline(always)]
fn test(d: F, eps: f32) -> Test {
    let abs = d.abs();
    let usable = d.simd_ne(F::ZERO) & abs.simd_lt(F::splat(f32::INFINITY));
    let positive = d.simd_gt(F::ZERO);
    Test {
        sign: positive.select(F::ONE, F::splat(-1.0)),
        thr: F::splat(-eps) * abs,
        ok: usable.to_bitmask(),
        positive: positive.to_bitmask(),
    }
}

/// Lanes where tetrahedron `t` is a weak owner (`WEAK_OWNER`) wherever it
/// is: none of its corners moved (`moved[c]`: lanes where corner `c` moved), or its
/// orientation `D` (`d_positive`: lanes with `D > 0`) has the other sign
/// than at rest.
#[inline(always)]
fn weak_lanes<const P: usize>(t: usize, moved: &[u32; 8], d_positive: u32) -> u32 {
    let [a, b, c, d] = CELL_TETS[P][t];
    let any_moved = moved[a as usize] | moved[b as usize] | moved[c as usize] | moved[d as usize];
    let inverted = if ORIENTATION[P][t].1 {
        !d_positive
    } else {
        d_positive
    };
    (!any_moved | inverted) & ((1 << LANES) - 1)
}

/// Lanes passing test `t` with plane value `v` (bit per lane).
#[inline(always)]
fn pass(t: &Test, v: F) -> u32 {
    (t.sign * v).simd_ge(t.thr).to_bitmask() & t.ok
}

/// Corner tetrahedron `k` of a cell, per lane: its interior face (shared
/// with the central tetrahedron) and its three boundary faces, with the
/// orientation tests of each.
struct CornerTet {
    interior: PlaneV,
    /// Interior face, oriented towards the corner vertex.
    t_corner: Test,
    /// Interior face, oriented towards the central tetrahedron's vertex.
    t_central: Test,
    boundary: [PlaneV; 3],
    t_boundary: [Test; 3],
}

#[inline(always)]
fn corner<const P: usize>(p: &[[F; 3]; 8], k: usize, eps: f32) -> CornerTet {
    let faces = &FACE_TABLES.faces[P];
    let it = &CORNER_TABLES.interior[P][k];
    let bt = &CORNER_TABLES.boundary[P][k];
    let face = |f: u8| {
        let [u, v, w] = faces[f as usize];
        plane(p, u, v, w)
    };
    let interior = face(it[0]);
    let boundary = [face(bt[0][0]), face(bt[1][0]), face(bt[2][0])];
    CornerTet {
        t_corner: test(eval(&interior, &p[it[1] as usize]), eps),
        t_central: test(eval(&interior, &p[it[2] as usize]), eps),
        t_boundary: [
            test(eval(&boundary[0], &p[bt[0][1] as usize]), eps),
            test(eval(&boundary[1], &p[bt[1][1] as usize]), eps),
            test(eval(&boundary[2], &p[bt[2][1] as usize]), eps),
        ],
        interior,
        boundary,
    }
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

/// Rasterises up to [`LANES`] cells of parity `P` (`cells[l]`, `n` of them valid;
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
    // Corner positions p[corner][axis] (lanes = cells), source index units:
    // `index + displacement · (1 / spacing)`, as `deformed_coordinate`
    // (indices are far below 2^24, so `(i + o) as f32 = i as f32 + o as f32`
    // exactly, and the i32 conversion is the branch-free one).
    let disp = [ctx.disp.x, ctx.disp.y, ctx.disp.z];
    let mut base = [0usize; LANES];
    let mut cell_f = [[0f32; LANES]; 3];
    for l in 0..LANES {
        let c = cells[l];
        base[l] = c[0] + nx * (c[1] + ny * c[2]);
        for a in 0..3 {
            cell_f[a][l] = c[a] as i32 as f32;
        }
    }
    // The farthest corner is the last one: one bounds check per lane.
    let last = 1 + nx * (1 + ny);
    let n_vertices = disp[0].len().min(disp[1].len()).min(disp[2].len());
    assert!(base.iter().all(|&b| b + last < n_vertices));
    let cell_i = [0, 1, 2].map(|a| I::new(cell_f[a].map(|v| v as i32)));
    let cell_f = [F::new(cell_f[0]), F::new(cell_f[1]), F::new(cell_f[2])];
    let inv = [
        F::splat(ctx.inv_spacing[0]),
        F::splat(ctx.inv_spacing[1]),
        F::splat(ctx.inv_spacing[2]),
    ];
    let mut p = [[F::ZERO; 3]; 8];
    // Lanes where corner c moved (its position is not its rest index).
    let mut moved = [0u32; 8];
    for c in 0..8u8 {
        let o = corner_offset(c);
        let off = o[0] + nx * (o[1] + ny * o[2]);
        let mut m = F::ZERO.simd_ne(F::ZERO);
        for a in 0..3 {
            let d = &disp[a];
            let mut v = [0f32; LANES];
            for l in 0..LANES {
                // SAFETY: `off <= last` and every `base[l] + last` is in
                // bounds (asserted above).
                v[l] = unsafe { *d.get_unchecked(base[l] + off) };
            }
            let rest = cell_f[a] + F::splat(o[a] as f32);
            p[c as usize][a] = rest + F::new(v) * inv[a];
            m |= p[c as usize][a].simd_ne(rest);
        }
        moved[c as usize] = m.to_bitmask();
    }
    // Candidate boxes: ⌈min⌉ ..= ⌊max⌋ of the corners per axis, clipped
    // (`ceil_i32` / `floor_i32` per lane: saturating truncation, then ±1).
    let mut lo = [I::ZERO; 3];
    let mut hi = [I::ZERO; 3];
    let mut empty = I::ZERO;
    for a in 0..3 {
        let mut mn = p[0][a];
        let mut mx = p[0][a];
        for pc in &p[1..] {
            mn = mn.min(pc[a]);
            mx = mx.max(pc[a]);
        }
        let (tn, tx) = (mn.trunc_int(), mx.trunc_int());
        let up: I = bytemuck::cast(F::from_i32x8(tn).simd_lt(mn));
        let down: I = bytemuck::cast(F::from_i32x8(tx).simd_gt(mx));
        lo[a] = tn.saturating_sub(up).max(I::splat(ctx.clip.lo[a]));
        hi[a] = tx.saturating_add(down).min(I::splat(ctx.clip.hi[a]));
        empty |= lo[a].simd_gt(hi[a]);
    }
    let mut active = ((1u32 << n) - 1) & !empty.to_bitmask();
    for (l, r) in removed.iter().enumerate() {
        if r & 0x1f == 0x1f {
            active &= !(1 << l);
        }
    }
    if active == 0 {
        return;
    }
    // Planes and orientation tests, built in place (no zeroed scratch).
    let eps = ctx.eps;
    let cs = [
        corner::<P>(&p, 0, eps),
        corner::<P>(&p, 1, eps),
        corner::<P>(&p, 2, eps),
        corner::<P>(&p, 3, eps),
    ];
    // Live tetrahedra per lane (bit per lane).
    let mut live = [(1u32 << LANES) - 1; 5];
    if *removed != [0; LANES] {
        for (t, lv) in live.iter_mut().enumerate() {
            *lv = 0;
            for (l, r) in removed.iter().enumerate() {
                *lv |= (((r >> t) & 1 == 0) as u32) << l;
            }
        }
    }
    // Owner keys' weak bit per tetrahedron and lane (see `WEAK_OWNER`).
    let weak = [
        weak_lanes::<P>(0, &moved, cs[0].t_corner.positive),
        weak_lanes::<P>(1, &moved, cs[1].t_corner.positive),
        weak_lanes::<P>(2, &moved, cs[2].t_corner.positive),
        weak_lanes::<P>(3, &moved, cs[3].t_corner.positive),
        weak_lanes::<P>(4, &moved, cs[0].t_central.positive),
    ];
    // Walk every lane's box in step; lanes that run out drop out. Cursors
    // stay inside their box (they wrap), so "at the end" is equality.
    let mut q = lo;
    let [cx, cy, _] = ctx.cell_dims;
    let base_id = |l: usize| {
        let c = cells[l];
        (5 * (c[0] + cx * (c[1] + cy * c[2]))) as u32
    };
    while active != 0 {
        let qf = [
            F::from_i32x8(q[0]),
            F::from_i32x8(q[1]),
            F::from_i32x8(q[2]),
        ];
        let ti = [
            eval(&cs[0].interior, &qf),
            eval(&cs[1].interior, &qf),
            eval(&cs[2].interior, &qf),
            eval(&cs[3].interior, &qf),
        ];
        // Lanes passing each tetrahedron's four faces: corner tetrahedra
        // 0..4, then the central one.
        let mut passing = [0u32; 5];
        for k in 0..4 {
            let c = &cs[k];
            let mut m = pass(&c.t_corner, ti[k]) & live[k] & active;
            if m != 0 {
                for mm in 0..3 {
                    m &= pass(&c.t_boundary[mm], eval(&c.boundary[mm], &qf));
                }
            }
            passing[k] = m;
        }
        passing[4] = live[4]
            & pass(&cs[0].t_central, ti[0])
            & pass(&cs[1].t_central, ti[1])
            & pass(&cs[2].t_central, ti[2])
            & pass(&cs[3].t_central, ti[3])
            & active;
        let mut found = passing.iter().fold(0, |a, &m| a | m);
        if found != 0 {
            // Lanes whose centre is the rest position of a still corner c:
            // a tetrahedron touching it only there claims it weakly.
            let at = [0, 1, 2].map(|a| [q[a].simd_eq(cell_i[a]), q[a].simd_eq(cell_i[a] + I::ONE)]);
            let mut at_still = [0u32; 8];
            for (c, s) in at_still.iter_mut().enumerate() {
                let m = at[0][c & 1] & at[1][(c >> 1) & 1] & at[2][c >> 2];
                *s = m.to_bitmask() & !moved[c];
            }
            let (qx, qy, qz) = (q[0].to_array(), q[1].to_array(), q[2].to_array());
            while found != 0 {
                let l = found.trailing_zeros() as usize;
                found &= found - 1;
                // The lane's smallest key among its passing tetrahedra.
                let mut key = u32::MAX;
                for t in 0..5 {
                    if (passing[t] >> l) & 1 != 0 {
                        let [a, b, c, d] = CELL_TETS[P][t];
                        let touch = at_still[a as usize]
                            | at_still[b as usize]
                            | at_still[c as usize]
                            | at_still[d as usize];
                        let w = (((weak[t] | touch) >> l) & 1) * WEAK_OWNER;
                        key = key.min(w | (base_id(l) + t as u32));
                    }
                }
                let o = &out[ctx.output.linear([qx[l], qy[l], qz[l]])];
                if o.load(Relaxed) > key {
                    o.fetch_min(key, Relaxed);
                }
            }
        }
        // Advance every lane's cursor: x, then y on wrap, then z.
        let wx = q[0].simd_eq(hi[0]);
        q[0] = wx.select(lo[0], q[0] + I::ONE);
        let wy = wx & q[1].simd_eq(hi[1]);
        q[1] = wy.select(lo[1], q[1] - wx);
        let wz = wy & q[2].simd_eq(hi[2]);
        q[2] = wz.select(lo[2], q[2] - wy);
        active &= !(wz.to_bitmask());
    }
}

#[cfg(test)]
mod tests {
    use super::super::raster::{CellCorners, CellRaster};
    use super::super::sampling_mesh::{SamplingMesh, cell_parity, deformed_coordinate};
    use super::*;
    use crate::grid::Grid;
    use glam::DVec3;
    use proptest::prelude::*;

    proptest! {
        /// Lane groups (any mix of cells, tails, removed tetrahedra) give
        /// the owners of the scalar reference, cell by cell.
        #[test]
        fn lanes_equal_scalar_reference(
            d in proptest::collection::vec(prop_oneof![Just(0.0f32), -1.2f32..1.2], 3 * 7 * 5 * 4),
            picks in proptest::collection::vec((0usize..72, 0u8..32), 1..2 * LANES + 1),
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
                        let still = c.x[q as usize] == v[0] as f32
                            && c.y[q as usize] == v[1] as f32
                            && c.z[q as usize] == v[2] as f32;
                        c.moved |= (!still as u8) << q;
                    }
                    c.rest = cell.map(|v| v as i32);
                    let owner = |r: &mut dyn FnMut([f32; 3]) -> Option<u32>, lo: [i32; 3], hi: [i32; 3], want: &mut Vec<u32>| {
                        for zz in lo[2]..=hi[2] {
                            for yy in lo[1]..=hi[1] {
                                for xx in lo[0]..=hi[0] {
                                    if let Some(key) = r([xx as f32, yy as f32, zz as f32]) {
                                        let o = output.linear([xx, yy, zz]);
                                        want[o] = want[o].min(key);
                                    }
                                }
                            }
                        }
                    };
                    let key = |t: usize, weak: bool| mesh.tet_id(cell, t) | ((weak as u32) * WEAK_OWNER);
                    if parity == 0 {
                        if let Some(mut r) = CellRaster::<0>::new(&c, removed[l], eps, &clip) {
                            let (lo, hi) = (r.lo, r.hi);
                            owner(&mut |q| r.owner(q).map(|(t, w)| key(t, w)), lo, hi, &mut want);
                        }
                    } else if let Some(mut r) = CellRaster::<1>::new(&c, removed[l], eps, &clip) {
                        let (lo, hi) = (r.lo, r.hi);
                        owner(&mut |q| r.owner(q).map(|(t, w)| key(t, w)), lo, hi, &mut want);
                    }
                }
                let got: Vec<u32> = out.iter().map(|a| a.load(Relaxed)).collect();
                prop_assert_eq!(got, want);
            }
        }
    }
}
