//! The last step of trilinear mode on eight voxels at once: the CPU's fast
//! form of `raster::trilinear` (the three lerp levels as 8-wide SIMD,
//! [`wide::f32x8`], with exactly the scalar expressions — same IEEE
//! operations, same order, no fused multiply-add — so every value is the
//! scalar reference's bit for bit, checked by a test below). The weights and
//! the rest position come from pass 1's claims (`super::lanes`); only the
//! eight source loads per voxel are scalar (data-dependent addresses).

// Lane loops index several arrays by the lane or corner number.
#![allow(clippy::needless_range_loop)]

use wide::f32x8;

type F = f32x8;

/// Voxels per group.
pub(crate) const FILL_LANES: usize = 8;

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
    use super::super::raster::trilinear;
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Every lane equals the scalar `raster::trilinear` bit for bit (NaN
        /// as NaN), exact grid points (zero fractions) and NaN neighbours of
        /// zero weight included.
        #[test]
        fn trilinear_lanes_equal_scalar_reference(
            lanes in prop::array::uniform8((
                prop::array::uniform8(prop_oneof![
                    1 => Just(f32::NAN),
                    9 => -1000.0f32..2000.0
                ]),
                prop::array::uniform3(prop_oneof![Just(0.0f32), 0.0f32..1.0]),
            )),
        ) {
            let mut v = [[0f32; FILL_LANES]; 8];
            let mut f = [[0f32; FILL_LANES]; 3];
            for (l, (vals, fr)) in lanes.iter().enumerate() {
                for k in 0..8 {
                    v[k][l] = vals[k];
                }
                for a in 0..3 {
                    f[a][l] = fr[a];
                }
            }
            let got = trilinear_group(&v, &f);
            let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
            for (l, (vals, fr)) in lanes.iter().enumerate() {
                let want = trilinear(*vals, *fr);
                prop_assert!(same(got[l], want), "lane {l}: {} vs {}", got[l], want);
            }
        }
    }
}
