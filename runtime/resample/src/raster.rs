//! The scalar statement of the tetrahedron geometry of both passes: face
//! planes, the inclusion test of pass 1 and the barycentric weights of
//! pass 2. The CPU kernels run it eight lanes at a time (`super::lanes`,
//! `super::fill_lanes`) and the GPU in WGSL; this file is the reference
//! they are tested against, bit for bit, so it is compiled for tests only
//! — but for `interpolate`, which the CPU kernel calls per winning claim
//! in tetrahedral mode.
//!
//! All coordinates here are **source voxel index** units (see
//! [`super::sampling_mesh::deformed_coordinate`]); a voxel centre of the
//! output is an integer point of that space.
//!
//! ## Exactness rules (mirrored line for line in `shaders/resample/common.wgsl`)
//!
//! - A face with ascending corners `u < v < w` has the plane function
//!   `t(q) = n · (q − P_u)` with `n = (P_v − P_u) × (P_w − P_u)`, evaluated as
//!   `n.x (q.x − P_u.x) + (n.y (q.y − P_u.y) + n.z (q.z − P_u.z))`. Two
//!   tetrahedra sharing a face compute the same bits, with opposite signs
//!   relative to their opposite vertices, so a voxel centre on a shared face
//!   passes at least one of them: no holes, whatever the epsilon.
//! - Each tetrahedron has **one** orientation `D = t_o(P_o)`, the plane of
//!   the face opposite its `ORIENTATION` slot `o` at that corner; face `a`'s
//!   is `D_a = (−1)^(a−o) D` (`sampling_mesh::D_SIGN`: the determinant with
//!   slot `a` moved last), so a cell evaluates 5 orientations, not 20, and
//!   all faces of a tetrahedron agree on its orientation. Barycentric
//!   `λ_a = t_a(q) / D_a`. With integer positions (the identity field)
//!   every product is exact, so a voxel centre on vertex `a` gets
//!   `λ_a = 1` and the other weights exactly 0: the interpolated value is
//!   the vertex's value, bit for bit.
//! - Inclusion: voxel centre `q` lies in the integer box of its cell (the
//!   cell's deformed bounding box, clipped) and `sign(D_a) · t_a(q) ≥ −ε |D_a|`
//!   (with `D_a` finite and non-zero) for the four faces of the tetrahedron.
//!   Pass 1 works per cell: every candidate voxel centre of the cell's box
//!   goes to the passing tetrahedron of the cell with the smallest *owner
//!   key* — its id, with [`super::sampling_mesh::WEAK_OWNER`] set when none
//!   of its corners moved, it is inverted (the sign of its `D` in
//!   `sampling_mesh::ORIENTATION` differs from the rest sign) or the
//!   voxel centre is the rest position of one of its corners that did not
//!   move; the output keeps the smallest key over all cells. Cells are about a
//!   voxel across, so this is much cheaper than scanning the five
//!   tetrahedra's boxes separately (x-runs per tetrahedron pay off only for
//!   cells many voxels long). `CellRaster` (test builds) is the scalar
//!   statement of this predicate; the CPU kernel evaluates it eight cells at a
//!   time in `super::lanes` and the GPU in `raster.wgsl`, all three with
//!   the same expressions.

// Per-lane and per-face loops index several arrays by the same number.
#![allow(clippy::needless_range_loop)]
#[cfg(test)]
use super::output_grid::VoxelBox;
#[cfg(test)]
use super::sampling_mesh::{
    CELL_TETS, CORNER_TABLES, D_SIGN, FACE_TABLES, ORIENTATION, TETS_PER_CELL, slot_of,
};

#[cfg(test)]
/// Deformed positions of the eight corners of a cell (source index units),
/// structure of arrays, indexed by corner `c = cx + 2 cy + 4 cz`; which
/// corners moved (bit `c`: the deformed position differs from the rest one)
/// and the rest position of corner 0 (the cell's index).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct CellCorners {
    pub x: [f32; 8],
    pub y: [f32; 8],
    pub z: [f32; 8],
    pub moved: u8,
    pub rest: [i32; 3],
}

#[cfg(test)]
impl CellCorners {
    #[inline(always)]
    pub fn point(&self, c: usize) -> [f32; 3] {
        [self.x[c], self.y[c], self.z[c]]
    }
}

#[cfg(test)]
/// The plane function of one triangular face: `t(q) = n · (q − b)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct FacePlane {
    pub n: [f32; 3],
    pub b: [f32; 3],
}

#[cfg(test)]
impl FacePlane {
    /// The plane through `pu`, `pv`, `pw` (ascending vertex order).
    #[inline(always)]
    pub fn new(pu: [f32; 3], pv: [f32; 3], pw: [f32; 3]) -> Self {
        let a = [pv[0] - pu[0], pv[1] - pu[1], pv[2] - pu[2]];
        let c = [pw[0] - pu[0], pw[1] - pu[1], pw[2] - pu[2]];
        Self {
            n: [
                a[1] * c[2] - a[2] * c[1],
                a[2] * c[0] - a[0] * c[2],
                a[0] * c[1] - a[1] * c[0],
            ],
            b: pu,
        }
    }

    /// The part of `t` that is constant along a row `(y, z)`.
    #[inline(always)]
    pub fn row(&self, y: f32, z: f32) -> f32 {
        self.n[1] * (y - self.b[1]) + self.n[2] * (z - self.b[2])
    }

    /// `t` at `x` on a row whose constant part is `row`.
    #[inline(always)]
    pub fn at(&self, x: f32, row: f32) -> f32 {
        self.n[0] * (x - self.b[0]) + row
    }

    /// `t(q)`.
    #[inline(always)]
    pub fn eval(&self, q: [f32; 3]) -> f32 {
        self.at(q[0], self.row(q[1], q[2]))
    }
}

#[cfg(test)]
/// `⌈v⌉` as `i32` (saturating; no libm call on baseline x86-64).
#[inline(always)]
pub(crate) fn ceil_i32(v: f32) -> i32 {
    let t = v as i32;
    if (t as f32) < v {
        t.saturating_add(1)
    } else {
        t
    }
}

#[cfg(test)]
/// `⌊v⌋` as `i32` (saturating; no libm call on baseline x86-64).
#[inline(always)]
pub(crate) fn floor_i32(v: f32) -> i32 {
    let t = v as i32;
    if (t as f32) > v {
        t.saturating_sub(1)
    } else {
        t
    }
}

#[cfg(test)]
/// Up to four face planes as structure of arrays (lanes = faces), with the
/// orientation `D` of each face in the tetrahedron being tested.
#[derive(Clone, Copy, Debug, Default)]
struct Planes4 {
    nx: [f32; 4],
    ny: [f32; 4],
    nz: [f32; 4],
    bx: [f32; 4],
    by: [f32; 4],
    bz: [f32; 4],
}

#[cfg(test)]
impl Planes4 {
    #[inline(always)]
    fn set(&mut self, lane: usize, p: &FacePlane) {
        self.nx[lane] = p.n[0];
        self.ny[lane] = p.n[1];
        self.nz[lane] = p.n[2];
        self.bx[lane] = p.b[0];
        self.by[lane] = p.b[1];
        self.bz[lane] = p.b[2];
    }

    /// `t(q)` of every lane, exactly as [`FacePlane::eval`].
    #[inline(always)]
    fn eval(&self, q: [f32; 3]) -> [f32; 4] {
        let mut t = [0.0; 4];
        for l in 0..4 {
            t[l] = self.nx[l] * (q[0] - self.bx[l])
                + (self.ny[l] * (q[1] - self.by[l]) + self.nz[l] * (q[2] - self.bz[l]));
        }
        t
    }
}

#[cfg(test)]
/// Per lane: `sign(D) · t ≥ −ε |D|` with `D` finite and non-zero, as a bit mask.
#[inline(always)]
fn pass_mask(d: &[f32; 4], t: &[f32; 4], eps: f32) -> u32 {
    let mut m = 0;
    for l in 0..4 {
        let sign = if d[l] > 0.0 { 1.0 } else { -1.0 };
        let ok = d[l] != 0.0 && d[l].abs() < f32::INFINITY && sign * t[l] >= -eps * d[l].abs();
        m |= (ok as u32) << l;
    }
    m
}

#[cfg(test)]
/// One cell in pass 1: its corners, the clipped integer box of candidate
/// voxel centres, and — computed lazily, when a candidate's test first needs
/// them — face planes and orientations. `P` is the cell parity.
///
/// The inclusion predicate of voxel centre `q` (integer, inside `[lo, hi]`)
/// and tetrahedron `t`: `t` not removed and, for its four faces, `D_a ≠ 0`
/// and `sign(D_a) · t_a(q) ≥ −ε |D_a|`. Each candidate goes to the smallest
/// passing `t` of the cell (pass 1 only keeps the minimum id).
///
/// Evaluation order (the answers are those of testing every face, since each
/// test is a pure function of the corners): the four interior planes first;
/// corner tetrahedron `k` (ids 0–3) is tried only when `q` is on its side of
/// interior face `k`, and only then are its three boundary planes built;
/// the central tetrahedron (id 4) reuses the interior values. A cell's box
/// holds about two candidates, so most boundary planes are never built.
#[derive(Clone, Debug)]
pub(crate) struct CellRaster<'c, const P: usize> {
    c: &'c CellCorners,
    /// The four interior planes (lane `k`: shared by corner tetrahedron `k`
    /// and the central one).
    interior: Planes4,
    /// `D` of interior plane `k` at corner tetrahedron `k`'s corner vertex.
    d_corner: [f32; 4],
    /// `D` of interior plane `k` at the central tetrahedron's opposite vertex.
    d_central: [f32; 4],
    /// Boundary planes of corner tetrahedron `k` (lanes 0..3), built on demand.
    boundary: [Planes4; 4],
    /// Their `D` (lane 3 is a pass-through: `D = 1`, `t = 0`).
    d_boundary: [[f32; 4]; 4],
    /// Bit `k`: `boundary[k]` is built.
    have_boundary: u32,
    /// Live corner tetrahedra (bit `k`) and central (bit 4).
    live: u32,
    eps: f32,
    /// Lower corner of the candidate box (source index units).
    pub lo: [i32; 3],
    /// Upper corner (inclusive).
    pub hi: [i32; 3],
}

#[cfg(test)]
impl<'c, const P: usize> CellRaster<'c, P> {
    /// `None` when no candidate voxel centre lies in the clipped box of the
    /// cell or every tetrahedron is removed (`removed`: bit `t` = removed).
    #[inline(always)]
    pub fn new(c: &'c CellCorners, removed: u8, eps: f32, clip: &VoxelBox) -> Option<Self> {
        if removed & 0x1f == 0x1f {
            return None;
        }
        let mut lo = [0i32; 3];
        let mut hi = [0i32; 3];
        let coords = [&c.x, &c.y, &c.z];
        for a in 0..3 {
            let s = coords[a];
            let mn = (s[0].min(s[1]))
                .min(s[2].min(s[3]))
                .min((s[4].min(s[5])).min(s[6].min(s[7])));
            let mx = (s[0].max(s[1]))
                .max(s[2].max(s[3]))
                .max((s[4].max(s[5])).max(s[6].max(s[7])));
            lo[a] = ceil_i32(mn).max(clip.lo[a]);
            hi[a] = floor_i32(mx).min(clip.hi[a]);
            if lo[a] > hi[a] {
                return None;
            }
        }
        let tab = &CORNER_TABLES.interior[P];
        let mut interior = Planes4::default();
        let mut d_corner = [0.0; 4];
        let mut d_central = [0.0; 4];
        for k in 0..4 {
            let p = plane_of::<P>(c, tab[k][0]);
            interior.set(k, &p);
            // Each tetrahedron's one `D` (its `ORIENTATION` slot): corner
            // tetrahedron k's at its corner vertex, the central one's from
            // interior face 0; the other faces' `D`s follow by `D_SIGN`.
            d_corner[k] = p.eval(c.point(tab[k][1] as usize));
            if k == 0 {
                d_central[0] = p.eval(c.point(tab[0][2] as usize));
            }
            d_central[k] = d_central[0] * D_SIGN[P][4][slot_of(&CELL_TETS[P][4], tab[k][2])];
        }
        Some(CellRaster {
            c,
            interior,
            d_corner,
            d_central,
            boundary: [Planes4::default(); 4],
            d_boundary: [[1.0; 4]; 4],
            have_boundary: 0,
            live: !(removed as u32) & 0x1f,
            eps,
            lo,
            hi,
        })
    }

    #[inline(always)]
    fn boundary(&mut self, k: usize) -> (&Planes4, &[f32; 4]) {
        if self.have_boundary & (1 << k) == 0 {
            let tab = &CORNER_TABLES.boundary[P][k];
            for m in 0..3 {
                let p = plane_of::<P>(self.c, tab[m][0]);
                self.boundary[k].set(m, &p);
                let sign = D_SIGN[P][k][slot_of(&CELL_TETS[P][k], tab[m][1])];
                self.d_boundary[k][m] = self.d_corner[k] * sign;
            }
            self.have_boundary |= 1 << k;
        }
        (&self.boundary[k], &self.d_boundary[k])
    }

    /// True when tetrahedron `t` (0..5) is weak wherever it is: none of its
    /// corners moved, or it is inverted.
    pub fn weak(&self, t: usize) -> bool {
        let moved = CELL_TETS[P][t]
            .iter()
            .any(|&c| self.c.moved & (1 << c) != 0);
        let d = if t < 4 {
            self.d_corner[t]
        } else {
            self.d_central[0]
        };
        !moved || (d > 0.0) != ORIENTATION[P][t].1
    }

    /// True when `q` is the rest position of a corner of tetrahedron `t`
    /// that did not move (the tetrahedron touches `q` only there).
    pub fn at_still_corner(&self, t: usize, q: [f32; 3]) -> bool {
        CELL_TETS[P][t].iter().any(|&c| {
            let o = [c & 1, (c >> 1) & 1, c >> 2];
            self.c.moved & (1 << c) == 0
                && (0..3).all(|a| q[a] == (self.c.rest[a] + o[a] as i32) as f32)
        })
    }

    /// The tetrahedron (0..5) of the cell containing voxel centre `q` with
    /// the smallest owner key, and whether that key is weak (see
    /// [`super::sampling_mesh::WEAK_OWNER`]: still, inverted, or `q` at one
    /// of its corners that did not move).
    #[inline(always)]
    pub fn owner(&mut self, q: [f32; 3]) -> Option<(usize, bool)> {
        let ti = self.interior.eval(q);
        let eps = self.eps;
        let mut best: Option<(bool, usize)> = None;
        let mut consider = |t: usize, weak: bool| {
            if best.is_none_or(|b| (weak, t) < b) {
                best = Some((weak, t));
            }
        };
        let mut corners = pass_mask(&self.d_corner, &ti, eps) & self.live;
        while corners != 0 {
            let k = corners.trailing_zeros() as usize;
            corners &= corners - 1;
            let (b, d) = self.boundary(k);
            let t = b.eval(q);
            if pass_mask(d, &t, eps) == 0xf {
                consider(k, self.weak(k) || self.at_still_corner(k, q));
            }
        }
        if self.live & 0x10 != 0 && pass_mask(&self.d_central, &ti, eps) == 0xf {
            consider(4, self.weak(4) || self.at_still_corner(4, q));
        }
        best.map(|(w, t)| (t, w))
    }
}

#[cfg(test)]
/// Face plane `f` of a cell of parity `P`.
#[inline(always)]
fn plane_of<const P: usize>(c: &CellCorners, f: u8) -> FacePlane {
    let [u, v, w] = FACE_TABLES.faces[P][f as usize];
    FacePlane::new(
        c.point(u as usize),
        c.point(v as usize),
        c.point(w as usize),
    )
}

#[cfg(test)]
/// Barycentric weights of `q` in tetrahedron `t` of a cell of parity
/// `parity`, its corner positions `p` in ascending corner order:
/// `λ_a = t_a(q) / D_a` with `D_a = D_SIGN · D` from the one `D` at the
/// tetrahedron's `ORIENTATION` slot (all 0 for a degenerate tetrahedron).
#[inline(always)]
pub(crate) fn barycentric(parity: usize, t: usize, p: &[[f32; 3]; 4], q: [f32; 3]) -> [f32; 4] {
    std::array::from_fn(|a| {
        let (face, da) = tet_face(parity, t, p, a);
        if da != 0.0 { face.eval(q) / da } else { 0.0 }
    })
}

#[cfg(test)]
/// The plane of the face opposite slot `a` of tetrahedron `t` of a cell of
/// parity `parity` (corner positions `p`, ascending corners) and its
/// `D_a = D_SIGN · D`, `D` the one at the tetrahedron's `ORIENTATION` slot.
pub(crate) fn tet_face(parity: usize, t: usize, p: &[[f32; 3]; 4], a: usize) -> (FacePlane, f32) {
    const OTHERS: [[usize; 3]; 4] = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]];
    let face = |a: usize| {
        let [u, v, x] = OTHERS[a];
        FacePlane::new(p[u], p[v], p[x])
    };
    let o = ORIENTATION[parity][t].0 as usize;
    (face(a), face(o).eval(p[o]) * D_SIGN[parity][t][a])
}

/// `Σ λ_a v_a`, or exactly `v_a` when `λ_a == 1` (a voxel centre on a
/// vertex: copies the value even when a neighbour is NaN or the value is −0).
#[inline(always)]
pub(crate) fn interpolate(w: [f32; 4], v: [f32; 4]) -> f32 {
    if w[0] == 1.0 {
        v[0]
    } else if w[1] == 1.0 {
        v[1]
    } else if w[2] == 1.0 {
        v[2]
    } else if w[3] == 1.0 {
        v[3]
    } else {
        ((w[0] * v[0] + w[1] * v[1]) + w[2] * v[2]) + w[3] * v[3]
    }
}

#[cfg(test)]
/// Trilinear mode, step 1: the rest position of a voxel centre relative to
/// its owner's cell (source voxel index units), `Σ λ_a o_a` with `o_a` the
/// owner's corner offsets (0 or 1 per axis), or exactly `o_a` when
/// `λ_a == 1` (first such vertex, as [`interpolate`]).
#[inline(always)]
pub(crate) fn rest_offset(w: [f32; 4], o: [[f32; 3]; 4]) -> [f32; 3] {
    for a in 0..4 {
        if w[a] == 1.0 {
            return o[a];
        }
    }
    let mut r = [0.0; 3];
    for ax in 0..3 {
        r[ax] = ((w[0] * o[0][ax] + w[1] * o[1][ax]) + w[2] * o[2][ax]) + w[3] * o[3][ax];
    }
    r
}

#[cfg(test)]
/// Trilinear mode, step 2: lower corner `i0`, upper corner `i1` and
/// fraction `f` along one axis for the rest position `cell + r` (source
/// index units), clamped to `[0, n − 1]`: outside, or exactly on the last
/// voxel, the fraction is 0 (`i1 = min(i0 + 1, n − 1)` is then ignored).
#[inline(always)]
pub(crate) fn trilinear_axis(cell: i32, r: f32, n: i32) -> (i32, i32, f32) {
    let fl = floor_i32(r);
    let g = cell.saturating_add(fl);
    let clamped = g < 0 || g >= n - 1;
    let i0 = g.max(0).min(n - 1);
    let i1 = (i0 + 1).min(n - 1);
    (i0, i1, if clamped { 0.0 } else { r - fl as f32 })
}

#[cfg(test)]
/// `a + f (b − a)`, or exactly `a` when `f == 0` (so a zero-weight
/// neighbour never matters, even when it is NaN).
#[inline(always)]
pub(crate) fn lerp(a: f32, b: f32, f: f32) -> f32 {
    if f == 0.0 { a } else { a + f * (b - a) }
}

#[cfg(test)]
/// Trilinear mode, step 3: the sample from the eight corner values
/// (`v[c]`, corner `c = cx + 2 cy + 4 cz` of the `i0`/`i1` box) and the
/// fractions: x first, then y, then z.
#[inline(always)]
pub(crate) fn trilinear(v: [f32; 8], f: [f32; 3]) -> f32 {
    let x00 = lerp(v[0], v[1], f[0]);
    let x10 = lerp(v[2], v[3], f[0]);
    let x01 = lerp(v[4], v[5], f[0]);
    let x11 = lerp(v[6], v[7], f[0]);
    let y0 = lerp(x00, x10, f[1]);
    let y1 = lerp(x01, x11, f[1]);
    lerp(y0, y1, f[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn corners_from(f: impl Fn(usize) -> [f32; 3]) -> CellCorners {
        let mut c = CellCorners::default();
        for k in 0..8 {
            let p = f(k);
            c.x[k] = p[0];
            c.y[k] = p[1];
            c.z[k] = p[2];
        }
        c
    }

    #[test]
    fn vertex_weights_are_exact_for_integer_positions() {
        let c = corners_from(|k| {
            [
                (k & 1) as f32 + 7.0,
                ((k >> 1) & 1) as f32 - 3.0,
                (k >> 2) as f32 + 100.0,
            ]
        });
        for parity in 0..2 {
            for (t, tet) in CELL_TETS[parity].iter().enumerate() {
                let p = tet.map(|k| c.point(k as usize));
                for (a, q) in p.iter().enumerate() {
                    let w = barycentric(parity, t, &p, *q);
                    let mut e = [0.0; 4];
                    e[a] = 1.0;
                    assert_eq!(w, e);
                    let mut v = [10.0, 20.0, 30.0, 40.0];
                    v[a] = -0.0;
                    v[(a + 1) % 4] = f32::NAN;
                    assert_eq!(interpolate(w, v).to_bits(), (-0.0f32).to_bits());
                }
            }
        }
    }

    /// The straightforward predicate: per tetrahedron, its own four planes;
    /// of the passing ones those moved, positively oriented (its `D` at the
    /// slot of [`ORIENTATION`] with the rest sign) and not at `q` by a still
    /// corner before the others, then the smallest.
    fn owner_spec(
        c: &CellCorners,
        parity: usize,
        removed: u8,
        eps: f32,
        q: [f32; 3],
    ) -> Option<(usize, bool)> {
        // Face `a`'s plane, and its `D` from the tetrahedron's one `D`.
        let plane_d = |t: usize, a: usize| {
            let p = CELL_TETS[parity][t].map(|k| c.point(k as usize));
            super::tet_face(parity, t, &p, a)
        };
        (0..TETS_PER_CELL)
            .filter(|&t| {
                removed & (1 << t) == 0
                    && (0..4).all(|a| {
                        let (f, d) = plane_d(t, a);
                        d != 0.0 && (if d > 0.0 { 1.0 } else { -1.0 }) * f.eval(q) >= -eps * d.abs()
                    })
            })
            .map(|t| {
                let moved = CELL_TETS[parity][t]
                    .iter()
                    .any(|&k| c.moved & (1 << k) != 0);
                let (slot, rest_positive) = ORIENTATION[parity][t];
                let inverted = (plane_d(t, slot as usize).1 > 0.0) != rest_positive;
                let at_still = CELL_TETS[parity][t].iter().any(|&k| {
                    let o = [k & 1, (k >> 1) & 1, k >> 2];
                    c.moved & (1 << k) == 0
                        && (0..3).all(|a| q[a] == (c.rest[a] + o[a] as i32) as f32)
                });
                (!moved || inverted || at_still, t)
            })
            .min()
            .map(|(w, t)| (t, w))
    }

    fn check_cell<const P: usize>(
        c: &CellCorners,
        removed: u8,
        eps: f32,
    ) -> Result<(), TestCaseError> {
        let clip = VoxelBox {
            lo: [-100; 3],
            hi: [100; 3],
        };
        let Some(mut r) = CellRaster::<P>::new(c, removed, eps, &clip) else {
            return Ok(());
        };
        let (lo, hi) = (r.lo, r.hi);
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    let q = [x as f32, y as f32, z as f32];
                    prop_assert_eq!(r.owner(q), owner_spec(c, P, removed, eps, q), "q {:?}", q);
                }
            }
        }
        Ok(())
    }

    #[test]
    fn trilinear_reference_matches_the_product_formula_and_clamps() {
        // Interior: the lerp cascade equals Σ Π weights · values (f64).
        let v = [3.0f32, -7.5, 11.0, 2.25, -1000.0, 1500.0, 40.0, 41.0];
        for f in [[0.25f32, 0.5, 0.75], [0.1, 0.9, 0.3], [0.0, 0.6, 0.0]] {
            let mut want = 0.0f64;
            for (c, &val) in v.iter().enumerate() {
                let mut w = 1.0f64;
                for a in 0..3 {
                    let bit = (c >> a) & 1;
                    w *= if bit == 1 {
                        f[a] as f64
                    } else {
                        1.0 - f[a] as f64
                    };
                }
                want += w * val as f64;
            }
            let got = trilinear(v, f) as f64;
            assert!((got - want).abs() < 1e-3, "{f:?}: {got} vs {want}");
        }
        // Zero fractions select the lower corner exactly, NaN neighbours ignored.
        let mut n = [f32::NAN; 8];
        n[0] = -0.0;
        assert_eq!(trilinear(n, [0.0; 3]).to_bits(), (-0.0f32).to_bits());
        // Clamping: below 0, at and beyond the last voxel, the fraction is 0.
        assert_eq!(trilinear_axis(0, -0.25, 5), (0, 1, 0.0));
        assert_eq!(trilinear_axis(3, 1.0, 5), (4, 4, 0.0));
        assert_eq!(trilinear_axis(3, 1.5, 5), (4, 4, 0.0));
        assert_eq!(trilinear_axis(2, 1.25, 5), (3, 4, 0.25));
        assert_eq!(trilinear_axis(2, -0.25, 5), (1, 2, 0.75));
        assert_eq!(trilinear_axis(2, f32::NAN, 5).0, 2);
        // A weight of exactly 1 gives that corner's offset exactly.
        let o = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [1.0, 1.0, 1.0],
        ];
        assert_eq!(rest_offset([1e-9, 1.0, -1e-9, 0.0], o), o[1]);
        let r = rest_offset([0.25, 0.25, 0.25, 0.25], o);
        assert_eq!(r, [0.75, 0.5, 0.25]);
    }

    #[test]
    fn fast_rounding_matches_libm() {
        for v in [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.0000001,
            -2.9999998,
            1e7 + 0.5,
            -8388607.5,
            3e9,
            -3e9,
        ] {
            assert_eq!(ceil_i32(v), v.ceil() as i32, "ceil {v}");
            assert_eq!(floor_i32(v), v.floor() as i32, "floor {v}");
        }
    }

    proptest! {
        /// The per-cell table-driven test equals the per-tetrahedron predicate.
        #[test]
        fn cell_owner_equals_per_tet_predicate(
            jitter in proptest::collection::vec(-0.8f32..0.8, 24),
            scale in prop::array::uniform3(0.5f32..5.0),
            off in prop::array::uniform3(-20.0f32..20.0),
            parity in 0usize..2,
            removed in 0u8..32,
            moved in 0u8..=255,
            eps in prop::sample::select(vec![0.0f32, 1e-6, 1e-2]),
        ) {
            let mut c = corners_from(|k| {
                [
                    off[0] + scale[0] * ((k & 1) as f32 + jitter[3 * k]),
                    off[1] + scale[1] * (((k >> 1) & 1) as f32 + jitter[3 * k + 1]),
                    off[2] + scale[2] * ((k >> 2) as f32 + jitter[3 * k + 2]),
                ]
            });
            c.moved = moved;
            // Rest corners near the jittered ones, so candidates hit them.
            c.rest = off.map(|v| v.round() as i32);
            if parity == 0 { check_cell::<0>(&c, removed, eps)?; } else { check_cell::<1>(&c, removed, eps)?; }
        }
    }
}
