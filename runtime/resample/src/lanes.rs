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
//!
//! Claims go into a [`TileSink`], an output tile's own key and payload
//! arrays (no atomics: one thread owns a tile). A claim that beats the
//! tile's key also stores its payload, computed from the face values and
//! orientations the inclusion test already has: the barycentric weights
//! `λ_a = t_a(q) / D_a` of the claiming tetrahedron — the very expressions
//! `raster::barycentric` evaluates (same planes from the same corners in the
//! same order), so the same bits — turned into the rest offset in the
//! owner's cell (`raster::rest_offset`) and from it the trilinear sample's
//! lower corner and fractions ([`trilinear_box`], `raster::trilinear_axis`;
//! trilinear mode), or into the interpolated value (`raster::interpolate`;
//! tetrahedral mode). The lanes find a row's cells' corners with contiguous
//! loads ([`strip_corners`]): the even and the odd cells of a strip of 16
//! are the two lane groups.
//!
//! Before a lane tests a candidate it reads the tile's key there
//! ([`TileSink::decided`]): a strong claim of an id below the lane's cell's
//! first id wins whatever the cell finds, so the lane skips to its next
//! candidate first, and the planes are evaluated for undecided voxels only.
//! Owners and payloads are unchanged (property-tested in both orders of the
//! rows). Where voxel centres sit on shared cell faces — a twist about z
//! keeps every centre on a z-face of two cells — about half of the
//! candidates are decided this way.

// Lane and corner loops index several arrays by the same number.
#![allow(clippy::needless_range_loop)]

use super::counters::{Counter, add};
use super::raster::interpolate;
use super::sampling_mesh::{
    CELL_TETS, CORNER_TABLES, D_SIGN, FACE_TABLES, ORIENTATION, WEAK_OWNER, corner_offset, slot_of,
};
use super::{DisplacementsRef, VoxelBox};
use crate::volume::Sample;
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
    /// The `D`s of `t_corner`, `t_central` and `t_boundary` (for the weights).
    d_corner: F,
    d_central: F,
    d_boundary: [F; 3],
}

/// Corner tetrahedron `k`'s planes, orientations and face tests, per lane.
///
/// Each tetrahedron has one `D` (at its `ORIENTATION` slot), the others are
/// `±D` (`D_SIGN`): corner tetrahedron `k`'s is `d_corner`; the central
/// one's is `d_central` of corner tetrahedron 0, which `central` passes to
/// the others (`None` for `k = 0`).
#[inline(always)]
fn corner<const P: usize>(p: &[[F; 3]; 8], k: usize, eps: f32, central: Option<F>) -> CornerTet {
    let faces = &FACE_TABLES.faces[P];
    let it = &CORNER_TABLES.interior[P][k];
    let bt = &CORNER_TABLES.boundary[P][k];
    let face = |f: u8| {
        let [u, v, w] = faces[f as usize];
        plane(p, u, v, w)
    };
    let interior = face(it[0]);
    let boundary = [face(bt[0][0]), face(bt[1][0]), face(bt[2][0])];
    let d_corner = eval(&interior, &p[it[1] as usize]);
    let sign = |t: usize, v: u8| F::splat(D_SIGN[P][t][slot_of(&CELL_TETS[P][t], v)]);
    let d_central = match central {
        None => eval(&interior, &p[it[2] as usize]),
        Some(d) => d * sign(4, it[2]),
    };
    let d_boundary = [
        d_corner * sign(k, bt[0][1]),
        d_corner * sign(k, bt[1][1]),
        d_corner * sign(k, bt[2][1]),
    ];
    CornerTet {
        t_corner: test(d_corner, eps),
        t_central: test(d_central, eps),
        t_boundary: [
            test(d_boundary[0], eps),
            test(d_boundary[1], eps),
            test(d_boundary[2], eps),
        ],
        interior,
        boundary,
        d_corner,
        d_central,
        d_boundary,
    }
}

/// Per parity, tetrahedron and corner slot (its corners ascending, as
/// `raster::barycentric` numbers them): where pass 1 keeps the value `t` of
/// the face opposite that slot — index into the per-iteration face values
/// (interior plane `k`: `k`; boundary plane `m` of corner tetrahedron `k`:
/// `4 + 3k + m`) — and its `D` — index into the per-group orientations
/// (`d_corner` of `k`: `k`; `d_central` of `k`: `4 + k`; `d_boundary[m]`
/// of `k`: `8 + 3k + m`).
const SLOT_SRC: [[[(u8, u8); 4]; 5]; 2] = [slot_src(0), slot_src(1)];

/// [`SLOT_SRC`] as `[t index, D index]` pairs.
const SLOT_SRC_PAIRS: [[[[u8; 2]; 4]; 5]; 2] = {
    let mut out = [[[[0u8; 2]; 4]; 5]; 2];
    let mut p = 0;
    while p < 2 {
        let mut t = 0;
        while t < 5 {
            let mut a = 0;
            while a < 4 {
                out[p][t][a] = [SLOT_SRC[p][t][a].0, SLOT_SRC[p][t][a].1];
                a += 1;
            }
            t += 1;
        }
        p += 1;
    }
    out
};

const fn slot_src(p: usize) -> [[(u8, u8); 4]; 5] {
    let mut out = [[(255u8, 255u8); 4]; 5];
    let mut k = 0;
    while k < 4 {
        let tet = &CELL_TETS[p][k];
        let it = &CORNER_TABLES.interior[p][k];
        out[k][slot_of(tet, it[1])] = (k as u8, k as u8);
        let mut m = 0;
        while m < 3 {
            let b = &CORNER_TABLES.boundary[p][k][m];
            out[k][slot_of(tet, b[1])] = ((4 + 3 * k + m) as u8, (8 + 3 * k + m) as u8);
            m += 1;
        }
        out[4][slot_of(&CELL_TETS[p][4], it[2])] = (k as u8, (4 + k) as u8);
        k += 1;
    }
    // Every slot of every tetrahedron got its face.
    let mut t = 0;
    while t < 5 {
        let mut a = 0;
        while a < 4 {
            assert!(out[t][a].0 != 255, "a slot without its face");
            a += 1;
        }
        t += 1;
    }
    out
}

/// Per parity, tetrahedron and slot: the corner's offset in the cell (0 or
/// 1 per axis), as f32 (trilinear mode's rest offsets).
const SLOT_OFFSETS: [[[[f32; 3]; 4]; 5]; 2] = [slot_offsets(0), slot_offsets(1)];

const fn slot_offsets(p: usize) -> [[[f32; 3]; 4]; 5] {
    let mut out = [[[0.0; 3]; 4]; 5];
    let mut t = 0;
    while t < 5 {
        let mut a = 0;
        while a < 4 {
            let o = corner_offset(CELL_TETS[p][t][a]);
            out[t][a] = [o[0] as f32, o[1] as f32, o[2] as f32];
            a += 1;
        }
        t += 1;
    }
    out
}

/// An output tile's claims: per voxel of the tile (x fastest) the smallest
/// owner key so far (`u32::MAX`: none) and its payload — trilinear mode:
/// the source sample's lower corner (linear index, as `f32` bits) and its
/// three fractions ([`trilinear_box`]); tetrahedral mode: the value (in
/// `[0]`).
pub(crate) struct TileSink<'s> {
    pub keys: &'s mut [u32],
    pub payload: &'s mut [[f32; 4]],
    /// The tile's lowest voxel, source index units.
    pub lo: [i32; 3],
    /// The tile's voxels along x and y.
    pub dims: [usize; 2],
}

impl TileSink<'_> {
    /// Index in the tile of voxel `q` (source index units, inside the tile).
    #[inline(always)]
    pub fn local(&self, q: [i32; 3]) -> usize {
        let x = (q[0] - self.lo[0]) as usize;
        let y = (q[1] - self.lo[1]) as usize;
        let z = (q[2] - self.lo[2]) as usize;
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// Lanes of `lanes` (bit per lane) whose voxel `q[l]` already holds a
    /// strong claim (`WEAK_OWNER` clear) of an id below `first_id[l]`: no
    /// claim of ids from `first_id[l]` on can beat it there. The tile
    /// indices are [`Self::local`]'s, computed for all lanes at once.
    #[inline(always)]
    pub fn decided(&self, q: &[I; 3], mut lanes: u32, first_id: I) -> u32 {
        let [dx, dy] = self.dims.map(|d| I::splat(d as i32));
        let lo = self.lo.map(I::splat);
        let at = ((q[2] - lo[2]) * dy + (q[1] - lo[1])) * dx + (q[0] - lo[0]);
        let (at, first) = (at.to_array(), first_id.to_array());
        let mut out = 0;
        while lanes != 0 {
            let l = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let key = self.keys[at[l] as usize];
            out |= ((key < first[l] as u32) as u32) << l;
        }
        out
    }

    /// Claims voxel `q[l]` for lane `l` of every bit set in `found` with
    /// `keys[l]`, where it beats the tile's key; `payload(l)` is computed
    /// only for a winning claim.
    #[inline(always)]
    pub fn claim_lanes(
        &mut self,
        mut found: u32,
        q: [[i32; LANES]; 3],
        keys: &[i32; LANES],
        mut payload: impl FnMut(usize) -> [f32; 4],
    ) {
        while found != 0 {
            let l = found.trailing_zeros() as usize;
            found &= found - 1;
            let i = self.local([q[0][l], q[1][l], q[2][l]]);
            let key = keys[l] as u32;
            if key < self.keys[i] {
                add(Counter::Claims, 1);
                self.keys[i] = key;
                self.payload[i] = payload(l);
            }
        }
    }
}

/// Trilinear mode, per lane: the source sample at the rest position
/// `cell + r` (source index units) as the linear index of its lower corner
/// and the fractions along x, y, z — `raster::trilinear_axis` per axis,
/// clamped to the grid `dims`: outside, or exactly on the last voxel, the
/// fraction is 0 (and the upper neighbour is never read).
#[inline(always)]
pub(crate) fn trilinear_box(cell: &[I; 3], r: &[F; 3], dims: [usize; 3]) -> (I, [F; 3]) {
    let mut i0 = [I::ZERO; 3];
    let mut f = [F::ZERO; 3];
    for a in 0..3 {
        let n = dims[a] as i32;
        // ⌊r⌋ as `floor_i32`: saturating truncation, then −1 where it rounded up.
        let t = r[a].trunc_int();
        let down: I = bytemuck::cast(F::from_i32x8(t).simd_gt(r[a]));
        let fl = t.saturating_add(down);
        let g = cell[a].saturating_add(fl);
        let clamped: F = bytemuck::cast(g.simd_lt(I::ZERO) | g.simd_gt(I::splat(n - 2)));
        i0[a] = g.max(I::ZERO).min(I::splat(n - 1));
        f[a] = clamped.select(F::ZERO, r[a] - F::from_i32x8(fl));
    }
    let (nx, ny) = (dims[0] as i32, dims[1] as i32);
    (i0[0] + I::splat(nx) * (i0[1] + I::splat(ny) * i0[2]), f)
}

/// What every group needs.
pub(crate) struct LaneCtx<'a> {
    pub vertex_dims: [usize; 3],
    pub cell_dims: [usize; 3],
    pub inv_spacing: [f32; 3],
    pub eps: f32,
    pub disp: DisplacementsRef<'a>,
    /// Voxels that may be claimed (inside the sink's tile), source index units.
    pub clip: VoxelBox,
}

/// The deformed corners of [`LANES`] cells: `p[corner][axis]` (lanes =
/// cells), source index units, `index + displacement · (1 / spacing)` as
/// `deformed_coordinate` (indices are far below 2^24, so
/// `(i + o) as f32 = i as f32 + o as f32` exactly); `moved[corner]`: the
/// lanes where that corner's position is not its rest index.
pub(crate) struct Corners {
    pub p: [[F; 3]; 8],
    pub moved: [u32; 8],
}

/// The vertices `v[2l]`, `v[2l + 1]` and `v[2l + 2]`, `l < LANES`, of a
/// row slice of at least `2 LANES + 2` values.
#[inline(always)]
fn deinterleave(v: &[f32]) -> [F; 3] {
    assert!(v.len() >= 2 * LANES + 2);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::*;
        // SAFETY: AVX2 is enabled at compile time; the four unaligned loads
        // read v[0..16] and v[2..18], in bounds (asserted above).
        unsafe {
            let p = v.as_ptr();
            let (a, b) = (_mm256_loadu_ps(p), _mm256_loadu_ps(p.add(8)));
            let (c, d) = (_mm256_loadu_ps(p.add(2)), _mm256_loadu_ps(p.add(10)));
            // shuffle: [a0 a2 b0 b2 | a4 a6 b4 b6]; permute: 64-bit pairs 0 2 1 3.
            let even = |a: __m256, b: __m256| {
                _mm256_castpd_ps(_mm256_permute4x64_pd(
                    _mm256_castps_pd(_mm256_shuffle_ps(a, b, 0b10_00_10_00)),
                    0b11_01_10_00,
                ))
            };
            let odd = _mm256_castpd_ps(_mm256_permute4x64_pd(
                _mm256_castps_pd(_mm256_shuffle_ps(a, b, 0b11_01_11_01)),
                0b11_01_10_00,
            ));
            [
                bytemuck::cast(even(a, b)),
                bytemuck::cast(odd),
                bytemuck::cast(even(c, d)),
            ]
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        let pick = |o: usize| {
            F::new([
                v[o],
                v[o + 2],
                v[o + 4],
                v[o + 6],
                v[o + 8],
                v[o + 10],
                v[o + 12],
                v[o + 14],
            ])
        };
        [pick(0), pick(1), pick(2)]
    }
}

/// [`Corners`] of the cells `(x0 + 2l, j, k)` (`[0]`) and
/// `(x0 + 1 + 2l, j, k)` (`[1]`), `l < LANES`: a strip of 16 cells of one
/// row, split by parity, from contiguous loads of the four vertex rows.
/// Lanes past the row's last cell hold garbage (finite or not) and must be
/// left out by the caller.
#[inline(always)]
pub(crate) fn strip_corners(ctx: &LaneCtx<'_>, x0: usize, j: usize, k: usize) -> [Corners; 2] {
    const W: usize = 2 * LANES + 2;
    let [nx, ny, _] = ctx.vertex_dims;
    let disp = [ctx.disp.x, ctx.disp.y, ctx.disp.z];
    let lane = F::from([0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]);
    // Rest x of the lanes' vertices at offsets 0, 1, 2 along the strip.
    let x = x0 as i32 as f32;
    let xr = [
        F::splat(x) + lane,
        F::splat(x + 1.0) + lane,
        F::splat(x + 2.0) + lane,
    ];
    let mut out = [
        Corners {
            p: [[F::ZERO; 3]; 8],
            moved: [0; 8],
        },
        Corners {
            p: [[F::ZERO; 3]; 8],
            moved: [0; 8],
        },
    ];
    for oz in 0..2 {
        for oy in 0..2 {
            let start = x0 + nx * (j + oy + ny * (k + oz));
            let ry = F::splat((j + oy) as i32 as f32);
            let rz = F::splat((k + oz) as i32 as f32);
            let mut mv = [F::ZERO; 3];
            for a in 0..3 {
                let d = disp[a];
                // The row's vertices x0 ..= x0 + 17: read in place when in
                // bounds, else from a copy padded with zeros.
                let e = if start + W <= d.len() {
                    deinterleave(&d[start..start + W])
                } else {
                    let mut row = [0f32; W];
                    let n = d.len().saturating_sub(start).min(W);
                    row[..n].copy_from_slice(&d[start..start + n]);
                    deinterleave(&row)
                };
                for o in 0..3 {
                    let r = match a {
                        0 => xr[o],
                        1 => ry,
                        _ => rz,
                    };
                    let pos = r + e[o] * F::splat(ctx.inv_spacing[a]);
                    // Corner (ox, oy, oz) of parity group g sits at offset g + ox.
                    let c = 2 * oy + 4 * oz;
                    if o < 2 {
                        out[0].p[c + o][a] = pos;
                    }
                    if o > 0 {
                        out[1].p[c + o - 1][a] = pos;
                    }
                    let m: F = pos.simd_ne(r);
                    mv[o] = if a == 0 { m } else { mv[o] | m };
                }
            }
            let c = 2 * oy + 4 * oz;
            let bits = mv.map(|m| m.to_bitmask());
            out[0].moved[c] = bits[0];
            out[0].moved[c + 1] = bits[1];
            out[1].moved[c] = bits[1];
            out[1].moved[c + 1] = bits[2];
        }
    }
    out
}

/// Rasterises up to [`LANES`] cells of parity `P` (`cells[l]`, `n` of them
/// valid, corners `corners`; `removed[l]`: removed-tetrahedra bits) into
/// `sink`, whose tile must hold `ctx.clip`. `src`: the source values (read
/// in tetrahedral mode, `!TRI`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn raster_cells<const P: usize, T: Sample, const TRI: bool>(
    ctx: &LaneCtx<'_>,
    cells: &[[usize; 3]; LANES],
    corners: &Corners,
    removed: &[u8; LANES],
    n: usize,
    sink: &mut TileSink<'_>,
    src: &[T],
) {
    let Corners { p, moved } = corners;
    let cell_i = [0, 1, 2].map(|a| I::new(std::array::from_fn(|l| cells[l][a] as i32)));
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
    add(Counter::Cells, n as u32);
    if active == 0 {
        return;
    }
    add(Counter::BusyGroups, 1);
    add(Counter::BusyCells, active.count_ones());
    // Planes and orientation tests, built in place (no zeroed scratch).
    let eps = ctx.eps;
    let c0 = corner::<P>(p, 0, eps, None);
    let central = Some(c0.d_central);
    let cs = [
        c0,
        corner::<P>(p, 1, eps, central),
        corner::<P>(p, 2, eps, central),
        corner::<P>(p, 3, eps, central),
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
        weak_lanes::<P>(0, moved, cs[0].t_corner.positive),
        weak_lanes::<P>(1, moved, cs[1].t_corner.positive),
        weak_lanes::<P>(2, moved, cs[2].t_corner.positive),
        weak_lanes::<P>(3, moved, cs[3].t_corner.positive),
        weak_lanes::<P>(4, moved, cs[0].t_central.positive),
    ];
    // Walk every lane's box in step; lanes that run out drop out. Cursors
    // stay inside their box (they wrap), so "at the end" is equality.
    let mut q = lo;
    let [cx, cy, _] = ctx.cell_dims;
    // Each lane's first tetrahedron id (ids are below 2^31).
    let base_id = I::new(std::array::from_fn(|l| {
        let c = cells[l];
        (5 * (c[0] + cx * (c[1] + cy * c[2]))) as i32
    }));
    let lane_bits = I::new([1, 2, 4, 8, 16, 32, 64, 128]);
    let mask_of = |bits: u32| (I::splat(bits as i32) & lane_bits).simd_eq(lane_bits);
    // The face value `t` and orientation `D` sources of `SLOT_SRC`.
    let d_src = |i: u8| -> F {
        let i = i as usize;
        match i {
            0..4 => cs[i].d_corner,
            4..8 => cs[i - 4].d_central,
            _ => cs[(i - 8) / 3].d_boundary[(i - 8) % 3],
        }
    };
    while active != 0 {
        // A lane whose voxel already holds a strong claim of a smaller id
        // than its cell's would lose whatever it finds there (exact: the
        // owner and payload are unchanged). Each lane skips such voxels
        // first, so that the planes are evaluated for as many undecided
        // voxels as possible at once.
        let mut decided = sink.decided(&q, active, base_id);
        while decided != 0 {
            add(Counter::Decided, decided.count_ones());
            advance(&mut q, &lo, &hi, &mut active, mask_of(decided));
            decided = sink.decided(&q, decided & active, base_id);
        }
        if active == 0 {
            break;
        }
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
        // 0..4, then the central one. `tb`: the boundary planes' values
        // (only where some lane needs them).
        let mut passing = [0u32; 5];
        let mut tb = [[F::ZERO; 3]; 4];
        for k in 0..4 {
            let c = &cs[k];
            let mut m = pass(&c.t_corner, ti[k]) & live[k] & active;
            if m != 0 {
                for mm in 0..3 {
                    tb[k][mm] = eval(&c.boundary[mm], &qf);
                    m &= pass(&c.t_boundary[mm], tb[k][mm]);
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
        let found = passing.iter().fold(0, |a, &m| a | m);
        add(Counter::Iterations, 1);
        add(Counter::Tested, active.count_ones());
        add(Counter::Found, found.count_ones());
        if found != 0 {
            // Lanes whose centre is the rest position of a still corner c:
            // a tetrahedron touching it only there claims it weakly.
            let at = [0, 1, 2].map(|a| [q[a].simd_eq(cell_i[a]), q[a].simd_eq(cell_i[a] + I::ONE)]);
            let mut at_still = [0u32; 8];
            for (c, s) in at_still.iter_mut().enumerate() {
                let m = at[0][c & 1] & at[1][(c >> 1) & 1] & at[2][c >> 2];
                *s = m.to_bitmask() & !moved[c];
            }
            // Per lane, the passing tetrahedron of smallest owner key, all
            // lanes at once. Keys are compared as `key ^ 2^31` in i32 (the
            // unsigned order): a strong claim is `id | 2^31` there, a weak
            // one `id`.
            let mut best = I::splat(i32::MAX);
            let mut owner = I::ZERO;
            for t in 0..5 {
                let [a, b, c, d] = CELL_TETS[P][t];
                let touch = at_still[a as usize]
                    | at_still[b as usize]
                    | at_still[c as usize]
                    | at_still[d as usize];
                let strong = mask_of(!(weak[t] | touch));
                let key = (base_id + I::splat(t as i32)) | (strong & I::splat(WEAK_OWNER as i32));
                let better = mask_of(passing[t]) & key.simd_lt(best);
                best = better.select(key, best);
                owner = better.select(I::splat(t as i32), owner);
            }
            // The owner's barycentric weights `λ_a = t_a / D_a` (every D of
            // a passing tetrahedron is finite and non-zero; other lanes'
            // values are never read).
            let is = [0, 1, 2, 3].map(|t| bytemuck::cast::<I, F>(owner.simd_eq(I::splat(t))));
            let t_src = |i: u8| -> F {
                let i = i as usize;
                if i < 4 {
                    ti[i]
                } else {
                    tb[(i - 4) / 3][(i - 4) % 3]
                }
            };
            let pick_t = |a: usize| {
                let mut v = t_src(SLOT_SRC_PAIRS[P][4][a][0]);
                for t in (0..4).rev() {
                    v = is[t].select(t_src(SLOT_SRC_PAIRS[P][t][a][0]), v);
                }
                v
            };
            let pick_d = |a: usize| {
                let mut v = d_src(SLOT_SRC_PAIRS[P][4][a][1]);
                for t in (0..4).rev() {
                    v = is[t].select(d_src(SLOT_SRC_PAIRS[P][t][a][1]), v);
                }
                v
            };
            let w = [
                pick_t(0) / pick_d(0),
                pick_t(1) / pick_d(1),
                pick_t(2) / pick_d(2),
                pick_t(3) / pick_d(3),
            ];
            let keys = (best ^ I::splat(WEAK_OWNER as i32)).to_array();
            let qa = [q[0].to_array(), q[1].to_array(), q[2].to_array()];
            if TRI {
                // Rest offset in the owner's cell, as `raster::rest_offset`:
                // `Σ λ_a o_a` over the slots in order (`o_a` 0 or 1, so the
                // products are the weights or zeros), or exactly `o_a` for
                // the first `λ_a == 1`.
                let one = w.map(|v| v.simd_eq(F::ONE));
                let r: [F; 3] = std::array::from_fn(|axis| {
                    let o: [F; 4] = std::array::from_fn(|a| {
                        let mut v = F::splat(SLOT_OFFSETS[P][4][a][axis]);
                        for t in (0..4).rev() {
                            v = is[t].select(F::splat(SLOT_OFFSETS[P][t][a][axis]), v);
                        }
                        v
                    });
                    let mut sum = ((w[0] * o[0] + w[1] * o[1]) + w[2] * o[2]) + w[3] * o[3];
                    for a in (0..4).rev() {
                        sum = one[a].select(o[a], sum);
                    }
                    sum
                });
                let (base, f) = trilinear_box(&cell_i, &r, ctx.vertex_dims);
                let base = base.to_array();
                let f = f.map(|v| v.to_array());
                sink.claim_lanes(found, qa, &keys, |l| {
                    [f32::from_bits(base[l] as u32), f[0][l], f[1][l], f[2][l]]
                });
            } else {
                let w = w.map(|v| v.to_array());
                let owner = owner.to_array();
                let [nx, ny, _] = ctx.vertex_dims;
                sink.claim_lanes(found, qa, &keys, |l| {
                    let c = cells[l];
                    let base = c[0] + nx * (c[1] + ny * c[2]);
                    let v = CELL_TETS[P][owner[l] as usize].map(|corner| {
                        let o = corner_offset(corner);
                        src[base + o[0] + nx * (o[1] + ny * o[2])].to_f32()
                    });
                    let wl = [w[0][l], w[1][l], w[2][l], w[3][l]];
                    [interpolate(wl, v), 0.0, 0.0, 0.0]
                });
            }
        }
        advance(&mut q, &lo, &hi, &mut active, I::splat(-1));
    }
}

/// Advances the cursor `q` of the lanes set in `lanes` (all bits of a lane
/// set) through its box `lo ..= hi`: x, then y on wrap, then z; lanes that
/// wrap in z leave `active`.
#[inline(always)]
fn advance(q: &mut [I; 3], lo: &[I; 3], hi: &[I; 3], active: &mut u32, lanes: I) {
    let wx = lanes & q[0].simd_eq(hi[0]);
    q[0] = wx.select(lo[0], q[0] - lanes);
    let wy = wx & q[1].simd_eq(hi[1]);
    q[1] = wy.select(lo[1], q[1] - wx);
    let wz = wy & q[2].simd_eq(hi[2]);
    q[2] = wz.select(lo[2], q[2] - wy);
    *active &= !(wz.to_bitmask());
}

#[cfg(test)]
mod tests {
    use super::super::raster::{
        CellCorners, CellRaster, barycentric, interpolate, rest_offset, trilinear_axis,
    };
    use super::super::sampling_mesh::{SamplingMesh, cell_parity, deformed_coordinate};
    use super::*;
    use crate::grid::Grid;
    use glam::DVec3;
    use proptest::prelude::*;

    /// Runs every cell of the mesh through `strip_corners` + `raster_cells`
    /// (strips of 16 along each row, as the CPU kernel does) into one tile,
    /// rows in ascending order or, with `descending`, the last row first (a
    /// tile meets its blocks' cells in neither order exactly, and a voxel
    /// already decided by a smaller id is skipped only then).
    fn lanes_claims<const TRI: bool>(
        ctx: &LaneCtx<'_>,
        mesh: &SamplingMesh,
        removed: &[u8],
        src: &[f32],
        descending: bool,
    ) -> (Vec<u32>, Vec<[f32; 4]>) {
        let clip = ctx.clip;
        let d = clip.dims();
        let n = d[0] * d[1] * d[2];
        let (mut keys, mut payload) = (vec![u32::MAX; n], vec![[0f32; 4]; n]);
        let mut sink = TileSink {
            keys: &mut keys,
            payload: &mut payload,
            lo: clip.lo,
            dims: [d[0], d[1]],
        };
        let c = mesh.cell_dims();
        let rows = (0..c[2]).flat_map(|k| (0..c[1]).map(move |j| (j, k)));
        let rows: Vec<_> = if descending {
            rows.rev().collect()
        } else {
            rows.collect()
        };
        for (j, k) in rows {
            for x0 in (0..c[0]).step_by(2 * LANES) {
                let count = (c[0] - x0).min(2 * LANES);
                let corners = strip_corners(ctx, x0, j, k);
                for (g, cs) in corners.iter().enumerate() {
                    let n = (count + 1 - g) / 2;
                    if n == 0 {
                        continue;
                    }
                    let cells: [[usize; 3]; LANES] =
                        std::array::from_fn(|l| [x0 + g + 2 * l.min(n - 1), j, k]);
                    let rm = cells.map(|cell| removed[mesh.cell_linear(cell)]);
                    if cell_parity(cells[0]) == 0 {
                        raster_cells::<0, f32, TRI>(ctx, &cells, cs, &rm, n, &mut sink, src);
                    } else {
                        raster_cells::<1, f32, TRI>(ctx, &cells, cs, &rm, n, &mut sink, src);
                    }
                }
            }
        }
        (keys, payload)
    }

    proptest! {
        /// Lane groups (rows split into strips of 16, tails, removed
        /// tetrahedra, still and moved corners) claim what the scalar
        /// reference does, cell by cell: the smallest owner key per voxel,
        /// and for it the payload of `raster::barycentric` +
        /// `raster::rest_offset` + `raster::trilinear_axis` (trilinear) or
        /// `raster::interpolate` (tetrahedral), bit for bit.
        #[test]
        fn lanes_equal_scalar_reference(
            d in proptest::collection::vec(prop_oneof![Just(0.0f32), -1.2f32..1.2], 3 * 19 * 5 * 4),
            removed in proptest::collection::vec(prop_oneof![4 => Just(0u8), 1 => 0u8..32], 18 * 4 * 3),
            values in proptest::collection::vec(-1000.0f32..2000.0, 19 * 5 * 4),
            eps in prop::sample::select(vec![0.0f32, 1e-6, 1e-2]),
        ) {
            let grid = Grid::new([19, 5, 4], DVec3::new(1.0, 0.8, 1.3), DVec3::ZERO);
            let mesh = SamplingMesh::new(&grid).unwrap();
            let n = grid.len();
            let (x, rest) = d.split_at(n);
            let (y, z) = rest.split_at(n);
            let disp = DisplacementsRef { x, y, z };
            let inv = [1.0f32, 1.0 / 0.8, 1.0 / 1.3];
            let clip = VoxelBox { lo: [-3; 3], hi: [21, 9, 9] };
            let ctx = LaneCtx {
                vertex_dims: mesh.vertex_dims(), cell_dims: mesh.cell_dims(), inv_spacing: inv,
                eps, disp, clip,
            };
            let d = clip.dims();
            let local = |q: [i32; 3]| {
                (q[0] - clip.lo[0]) as usize
                    + d[0] * ((q[1] - clip.lo[1]) as usize + d[1] * (q[2] - clip.lo[2]) as usize)
            };
            // The reference: per cell, `CellRaster`'s owner of every candidate.
            let mut want = vec![(u32::MAX, [0usize; 3], 0usize); d[0] * d[1] * d[2]];
            let mut corners_of = Vec::new();
            for l in 0..mesh.cell_count() {
                let cell = mesh.cell_of_linear(l);
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
                corners_of.push(c);
                let mut claim = |r: &mut dyn FnMut([f32; 3]) -> Option<(usize, bool)>, lo: [i32; 3], hi: [i32; 3]| {
                    for zz in lo[2]..=hi[2] {
                        for yy in lo[1]..=hi[1] {
                            for xx in lo[0]..=hi[0] {
                                if let Some((t, weak)) = r([xx as f32, yy as f32, zz as f32]) {
                                    let key = mesh.tet_id(cell, t) | ((weak as u32) * WEAK_OWNER);
                                    let w = &mut want[local([xx, yy, zz])];
                                    if key < w.0 {
                                        *w = (key, cell, t);
                                    }
                                }
                            }
                        }
                    }
                };
                let c = corners_of.last().unwrap();
                if cell_parity(cell) == 0 {
                    if let Some(mut r) = CellRaster::<0>::new(c, removed[l], eps, &clip) {
                        let (lo, hi) = (r.lo, r.hi);
                        claim(&mut |q| r.owner(q), lo, hi);
                    }
                } else if let Some(mut r) = CellRaster::<1>::new(c, removed[l], eps, &clip) {
                    let (lo, hi) = (r.lo, r.hi);
                    claim(&mut |q| r.owner(q), lo, hi);
                }
            }
            let (keys_t, pay_t) = lanes_claims::<true>(&ctx, &mesh, &removed, &values, false);
            let (keys_v, pay_v) = lanes_claims::<false>(&ctx, &mesh, &removed, &values, false);
            prop_assert_eq!(&keys_t, &keys_v);
            // The other order skips other claims, and ends the same.
            let (keys_r, pay_r) = lanes_claims::<true>(&ctx, &mesh, &removed, &values, true);
            prop_assert_eq!(&keys_r, &keys_t);
            let bits = |p: &[[f32; 4]], k: &[u32]| -> Vec<[u32; 4]> {
                p.iter().zip(k).filter(|(_, k)| **k != u32::MAX).map(|(v, _)| v.map(f32::to_bits)).collect()
            };
            prop_assert_eq!(bits(&pay_r, &keys_r), bits(&pay_t, &keys_t));
            let (keys_rv, pay_rv) = lanes_claims::<false>(&ctx, &mesh, &removed, &values, true);
            prop_assert_eq!(&keys_rv, &keys_v);
            prop_assert_eq!(bits(&pay_rv, &keys_rv), bits(&pay_v, &keys_v));
            let dims = grid.dims.map(|v| v as i32);
            for (i, &(key, cell, t)) in want.iter().enumerate() {
                prop_assert_eq!(keys_t[i], key, "voxel {}", i);
                if key == u32::MAX {
                    continue;
                }
                let q = [
                    clip.lo[0] + (i % d[0]) as i32,
                    clip.lo[1] + ((i / d[0]) % d[1]) as i32,
                    clip.lo[2] + (i / (d[0] * d[1])) as i32,
                ];
                let c = &corners_of[mesh.cell_linear(cell)];
                let parity = cell_parity(cell);
                let tet = CELL_TETS[parity][t];
                let p = tet.map(|k| c.point(k as usize));
                let w = barycentric(parity, t, &p, q.map(|v| v as f32));
                let o = tet.map(|k| corner_offset(k).map(|v| v as f32));
                let r = rest_offset(w, o);
                let ax = [0, 1, 2].map(|a| trilinear_axis(cell[a] as i32, r[a], dims[a]));
                let base = ax[0].0 + dims[0] * (ax[1].0 + dims[1] * ax[2].0);
                let want_t = [f32::from_bits(base as u32), ax[0].2, ax[1].2, ax[2].2];
                prop_assert_eq!(pay_t[i].map(f32::to_bits), want_t.map(f32::to_bits), "voxel {:?}", q);
                let v = tet.map(|k| {
                    let off = corner_offset(k);
                    values[grid.linear(cell[0] + off[0], cell[1] + off[1], cell[2] + off[2])]
                });
                let want_v = interpolate(w, v);
                prop_assert_eq!(pay_v[i][0].to_bits(), want_v.to_bits(), "voxel {:?}", q);
            }
        }
    }
}
