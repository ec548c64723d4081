//! Pass 2 on eight voxels at once: the CPU's fast form of
//! `raster::barycentric` + `raster::interpolate`.
//!
//! Eight consecutive voxels of an output row are the lanes. Each lane
//! gathers its owner tetrahedron's corners and values (scalar loads), then
//! the face planes, orientations, weights and the interpolation run as 8-wide
//! SIMD ([`wide::f32x8`]) with exactly the scalar expressions (same IEEE
//! operations, same order, no fused multiply-add), so every value is the
//! scalar reference's bit for bit (checked by a test below).

// Lane loops index several arrays by the lane or corner number.
#![allow(clippy::needless_range_loop)]

use wide::f32x8;

type F = f32x8;

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

/// The interpolated value of every lane (see the module doc).
#[inline(always)]
pub(crate) fn interpolate_group(g: &FillGroup) -> [f32; FILL_LANES] {
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
    let v = [
        F::new(g.v[0]),
        F::new(g.v[1]),
        F::new(g.v[2]),
        F::new(g.v[3]),
    ];
    let sum = ((w[0] * v[0] + w[1] * v[1]) + w[2] * v[2]) + w[3] * v[3];
    // A weight of exactly 1 copies its vertex's value; the first such
    // vertex wins, as in `interpolate`.
    let mut r = w[3].simd_eq(F::ONE).select(v[3], sum);
    r = w[2].simd_eq(F::ONE).select(v[2], r);
    r = w[1].simd_eq(F::ONE).select(v[1], r);
    r = w[0].simd_eq(F::ONE).select(v[0], r);
    r.to_array()
}

#[cfg(test)]
mod tests {
    use super::super::raster::{barycentric, interpolate};
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
    }
}
