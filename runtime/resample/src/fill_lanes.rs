//! Pass 2 on eight voxels at once: the CPU's fast form of
//! `raster::barycentric` + `raster::interpolate` (tetrahedral mode) or
//! `raster::rest_offset` + `raster::trilinear_axis` + `raster::trilinear`
//! (trilinear mode).
//!
//! Eight consecutive voxels of an output row are the lanes. Each lane
//! gathers its owner tetrahedron's corners and values (scalar loads), then
//! the face planes, orientations, weights and the interpolation run as 8-wide
//! SIMD ([`wide::f32x8`]) with exactly the scalar expressions (same IEEE
//! operations, same order, no fused multiply-add), so every value is the
//! scalar reference's bit for bit (checked by a test below). In trilinear
//! mode the rest position, the clamped corner indices and the three lerp
//! levels are SIMD too; only the eight source loads per lane are scalar
//! (data-dependent addresses).

// Lane loops index several arrays by the lane or corner number.
#![allow(clippy::needless_range_loop)]

use wide::{f32x8, i32x8};

type F = f32x8;
type I = i32x8;

/// Voxels per group.
pub(crate) const FILL_LANES: usize = 8;

/// Per lane: the four corners of the owner tetrahedron (source index units,
/// as `p[corner][axis]`), their source values and the voxel centre `q`.
/// Lanes without an owner hold zeros; their result is to be discarded.
#[derive(Clone, Copy, Default)]
pub(crate) struct FillGroup {
    pub p: [[[f32; FILL_LANES]; 3]; 4],
    pub v: [[f32; FILL_LANES]; 4],
    pub q: [[f32; FILL_LANES]; 3],
    /// Trilinear mode: the owner's corner offsets in its cell (0 or 1, as
    /// `o[corner][axis]`), in place of the values `v`.
    pub o: [[[f32; FILL_LANES]; 3]; 4],
}

/// A face plane per lane, as `FacePlane::new`.
#[inline(always)]
fn plane(pu: &[F; 3], pv: &[F; 3], pw: &[F; 3]) -> ([F; 3], [F; 3]) {
    let a = [pv[0] - pu[0], pv[1] - pu[1], pv[2] - pu[2]];
    let c = [pw[0] - pu[0], pw[1] - pu[1], pw[2] - pu[2]];
    (
        [
            a[1] * c[2] - a[2] * c[1],
            a[2] * c[0] - a[0] * c[2],
            a[0] * c[1] - a[1] * c[0],
        ],
        *pu,
    )
}

/// `FacePlane::eval` per lane.
#[inline(always)]
fn eval(n: &[F; 3], b: &[F; 3], q: &[F; 3]) -> F {
    n[0] * (q[0] - b[0]) + (n[1] * (q[1] - b[1]) + n[2] * (q[2] - b[2]))
}

/// The barycentric weights of every lane, as `raster::barycentric`.
#[inline(always)]
fn weights(g: &FillGroup) -> [F; 4] {
    const OTHERS: [[usize; 3]; 4] = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]];
    let mut p = [[F::ZERO; 3]; 4];
    for c in 0..4 {
        for a in 0..3 {
            p[c][a] = F::new(g.p[c][a]);
        }
    }
    let q = [F::new(g.q[0]), F::new(g.q[1]), F::new(g.q[2])];
    let mut w = [F::ZERO; 4];
    for a in 0..4 {
        let [u, v, x] = OTHERS[a];
        let (n, b) = plane(&p[u], &p[v], &p[x]);
        let d = eval(&n, &b, &p[a]);
        w[a] = d.simd_ne(F::ZERO).select(eval(&n, &b, &q) / d, F::ZERO);
    }
    w
}

/// `Σ w_a v_a`, or exactly `v_a` for the first `w_a == 1` (as
/// `raster::interpolate` / `raster::rest_offset`).
#[inline(always)]
fn blend(w: &[F; 4], v: &[F; 4]) -> F {
    let sum = ((w[0] * v[0] + w[1] * v[1]) + w[2] * v[2]) + w[3] * v[3];
    // A weight of exactly 1 copies its vertex's value; the first such
    // vertex wins.
    let mut r = w[3].simd_eq(F::ONE).select(v[3], sum);
    r = w[2].simd_eq(F::ONE).select(v[2], r);
    r = w[1].simd_eq(F::ONE).select(v[1], r);
    w[0].simd_eq(F::ONE).select(v[0], r)
}

/// The interpolated value of every lane (tetrahedral mode; see the module doc).
#[inline(always)]
pub(crate) fn interpolate_group(g: &FillGroup) -> [f32; FILL_LANES] {
    let w = weights(g);
    let v = [
        F::new(g.v[0]),
        F::new(g.v[1]),
        F::new(g.v[2]),
        F::new(g.v[3]),
    ];
    blend(&w, &v).to_array()
}

/// Trilinear mode: the rest position of every lane relative to its owner's
/// cell (source index units), as `raster::rest_offset`.
#[inline(always)]
pub(crate) fn rest_group(g: &FillGroup) -> [[f32; FILL_LANES]; 3] {
    let w = weights(g);
    [0, 1, 2].map(|ax| {
        let o = [
            F::new(g.o[0][ax]),
            F::new(g.o[1][ax]),
            F::new(g.o[2][ax]),
            F::new(g.o[3][ax]),
        ];
        blend(&w, &o).to_array()
    })
}

/// Per lane and axis: the trilinear box's lower and upper source index and
/// the fraction, as `raster::trilinear_axis`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct TrilinearCorners {
    pub i0: [[i32; FILL_LANES]; 3],
    pub i1: [[i32; FILL_LANES]; 3],
    pub f: [[f32; FILL_LANES]; 3],
}

/// [`TrilinearCorners`] of the rest positions `cell + r` (source index
/// units), clamped to the source grid `n` (voxels per axis, each ≥ 2).
#[inline(always)]
pub(crate) fn trilinear_corners(
    cell: &[[i32; FILL_LANES]; 3],
    r: &[[f32; FILL_LANES]; 3],
    n: [i32; 3],
) -> TrilinearCorners {
    let mut out = TrilinearCorners::default();
    for a in 0..3 {
        let rv = F::new(r[a]);
        // ⌊r⌋ as `floor_i32`: saturating truncation, then −1 where it rounded up.
        let t = rv.trunc_int();
        let down: I = bytemuck::cast(F::from_i32x8(t).simd_gt(rv));
        let fl = t.saturating_add(down);
        let g = I::new(cell[a]).saturating_add(fl);
        let last = I::splat(n[a] - 1);
        let clamped: F = bytemuck::cast(g.simd_lt(I::ZERO) | g.simd_gt(I::splat(n[a] - 2)));
        let i0 = g.max(I::ZERO).min(last);
        out.i0[a] = i0.to_array();
        out.i1[a] = (i0 + I::ONE).min(last).to_array();
        out.f[a] = clamped.select(F::ZERO, rv - F::from_i32x8(fl)).to_array();
    }
    out
}

/// `raster::lerp` per lane.
#[inline(always)]
fn lerp(a: F, b: F, f: F) -> F {
    f.simd_eq(F::ZERO).select(a, a + f * (b - a))
}

/// The trilinear sample of every lane from its eight corner values
/// (`v[c]`, `c = cx + 2 cy + 4 cz`) and fractions, as `raster::trilinear`.
#[inline(always)]
pub(crate) fn trilinear_group(
    v: &[[f32; FILL_LANES]; 8],
    f: &[[f32; FILL_LANES]; 3],
) -> [f32; FILL_LANES] {
    let v = v.map(F::new);
    let [fx, fy, fz] = f.map(F::new);
    let x00 = lerp(v[0], v[1], fx);
    let x10 = lerp(v[2], v[3], fx);
    let x01 = lerp(v[4], v[5], fx);
    let x11 = lerp(v[6], v[7], fx);
    let y0 = lerp(x00, x10, fy);
    let y1 = lerp(x01, x11, fy);
    lerp(y0, y1, fz).to_array()
}

#[cfg(test)]
mod tests {
    use super::super::raster::{barycentric, interpolate, rest_offset, trilinear, trilinear_axis};
    use super::*;
    use proptest::prelude::*;

    fn lane_strategy() -> impl Strategy<Value = ([[f32; 3]; 4], [f32; 4], [f32; 3])> {
        // Corners near a unit tetrahedron (sometimes exactly on grid
        // points), values from a CT range, voxel centres around it.
        let coord = prop_oneof![(-2i32..3).prop_map(|v| v as f32), -2.0f32..3.0];
        (
            prop::array::uniform4(prop::array::uniform3(coord.clone())),
            prop::array::uniform4(prop_oneof![Just(f32::NAN), -1000.0f32..2000.0]),
            prop::array::uniform3(coord),
        )
    }

    proptest! {
        /// Every lane equals the scalar barycentric + interpolate, bit for
        /// bit (NaN lanes compare as NaN).
        #[test]
        fn lanes_equal_scalar_reference(lanes in prop::array::uniform8(lane_strategy())) {
            let mut g = FillGroup::default();
            for (l, (p, v, q)) in lanes.iter().enumerate() {
                for c in 0..4 {
                    for a in 0..3 {
                        g.p[c][a][l] = p[c][a];
                    }
                    g.v[c][l] = v[c];
                }
                for a in 0..3 {
                    g.q[a][l] = q[a];
                }
            }
            let got = interpolate_group(&g);
            for (l, (p, v, q)) in lanes.iter().enumerate() {
                let want = interpolate(barycentric(p, *q), *v);
                prop_assert!(
                    got[l].to_bits() == want.to_bits() || (got[l].is_nan() && want.is_nan()),
                    "lane {l}: {} vs {}", got[l], want
                );
            }
        }

        /// Trilinear mode: rest positions, clamped corners and samples
        /// equal the scalar steps bit for bit (NaN as NaN), including rest
        /// positions outside the grid and exact vertex hits.
        #[test]
        fn trilinear_lanes_equal_scalar_reference(
            lanes in prop::array::uniform8((
                lane_strategy(),
                prop::array::uniform4(prop::array::uniform3(0u8..2)),
                prop::array::uniform3(-1i32..6),
                prop::array::uniform8(prop_oneof![
                    1 => Just(f32::NAN),
                    9 => -1000.0f32..2000.0
                ]),
                prop::array::uniform3(-3.0f32..4.0),
            )),
            n in prop::array::uniform3(2i32..6),
        ) {
            let mut g = FillGroup::default();
            let mut cell = [[0i32; FILL_LANES]; 3];
            let mut r = [[0f32; FILL_LANES]; 3];
            let mut v = [[0f32; FILL_LANES]; 8];
            let mut f = [[0f32; FILL_LANES]; 3];
            for (l, ((p, _, q), o, c, vals, rr)) in lanes.iter().enumerate() {
                for k in 0..4 {
                    for a in 0..3 {
                        g.p[k][a][l] = p[k][a];
                        g.o[k][a][l] = o[k][a] as f32;
                    }
                }
                for a in 0..3 {
                    g.q[a][l] = q[a];
                    cell[a][l] = c[a];
                    r[a][l] = rr[a];
                    f[a][l] = rr[a] - rr[a].floor();
                }
                for k in 0..8 {
                    v[k][l] = vals[k];
                }
                // Some lanes sample exactly on a grid point.
                if l % 3 == 0 {
                    f[l % 3][l] = 0.0;
                }
            }
            let rest = rest_group(&g);
            let corners = trilinear_corners(&cell, &r, n);
            let got = trilinear_group(&v, &f);
            let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
            for (l, ((p, _, q), o, c, vals, rr)) in lanes.iter().enumerate() {
                let of = o.map(|x| x.map(|y| y as f32));
                let want = rest_offset(barycentric(p, *q), of);
                for a in 0..3 {
                    prop_assert!(same(rest[a][l], want[a]), "lane {l} axis {a}: {} vs {}", rest[a][l], want[a]);
                    let (i0, i1, fr) = trilinear_axis(c[a], rr[a], n[a]);
                    prop_assert_eq!((corners.i0[a][l], corners.i1[a][l]), (i0, i1), "lane {} axis {}", l, a);
                    prop_assert!(same(corners.f[a][l], fr), "lane {l} axis {a}: fraction");
                    prop_assert!((0..n[a]).contains(&i0) && (0..n[a]).contains(&i1));
                }
                let want = trilinear(*vals, [f[0][l], f[1][l], f[2][l]]);
                prop_assert!(same(got[l], want), "lane {l}: {} vs {}", got[l], want);
            }
        }
    }
}
