//! The optional reconstruction filters of the renderer, shared formula for
//! formula with `shaders/raycast/raycast.wgsl` (same f32 operations in the
//! same order):
//!
//! - [`jitter`]: the per-pixel ray-start offset, a fraction of a step in
//!   `[0, 1)` from an integer hash of the pixel coordinates — the same on
//!   every frame (no flicker) and on both paths.
//! - [`bspline_axis`]: the cubic B-spline weights of Sigg & Hadwiger (GPU
//!   Gems 2, ch. 20) folded into two linear fetches per axis, so a tricubic
//!   B-spline sample is 8 trilinear fetches. The B-spline (not Catmull–Rom)
//!   because its weights are non-negative: a sample lies within the range of
//!   its 4³ voxels (empty-space skipping stays exact with a one-voxel
//!   macro-cell halo) and never overshoots into a transfer-function band the
//!   data does not reach; it reproduces linear data exactly. It smooths (it
//!   approximates, not interpolates), which is what hides voxel steps.
//! - [`sobel`]: the 3×3×3 Sobel gradient — central difference along the
//!   axis, `[1, 2, 1] / 4` smoothing across it — of the voxels, trilinearly
//!   interpolated. Equal to the Sobel operator applied to the trilinear
//!   field at offsets of ±1 voxel; exact for linear data.
//!
//! Voxel-index space throughout (voxel centres at integers).

use voxflex_core::glam::Vec3;
use voxflex_core::volume::Sample;

/// A 32-bit integer hash (Chris Wellons' "lowbias32"): full avalanche, a
/// handful of integer operations, identical in WGSL.
#[inline]
pub fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// The ray-start offset of pixel `(px, py)` as a fraction of one step, in
/// `[0, 1)`: the top 24 bits of `hash32(px ^ hash32(py))`, exact in f32.
#[inline]
pub fn jitter(px: u32, py: u32) -> f32 {
    (hash32(px ^ hash32(py)) >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Sigg–Hadwiger's fetch positions and weights along one axis for the
/// voxel-index coordinate `x ≥ 0`: the B-spline sample is
/// `lerp(f(h0), f(h1), g1)` with `f` linear interpolation, where
/// `(h0, h1, g1)` is the result.
#[inline(always)]
pub fn bspline_axis(x: f32) -> (f32, f32, f32) {
    let i = (x as u32) as f32;
    let f = x - i;
    let f2 = f * f;
    let f3 = f2 * f;
    let w0 = (1.0 - 3.0 * f + 3.0 * f2 - f3) * (1.0 / 6.0);
    let w1 = (4.0 - 6.0 * f2 + 3.0 * f3) * (1.0 / 6.0);
    let w2 = (1.0 + 3.0 * f + 3.0 * f2 - 3.0 * f3) * (1.0 / 6.0);
    let w3 = f3 * (1.0 / 6.0);
    let g0 = w0 + w1;
    let g1 = w2 + w3;
    (i - 1.0 + w1 / g0, i + 1.0 + w3 / g1, g1)
}

/// The tricubic B-spline sample at voxel position `p` (clamped to
/// `[0, upper]`), from `trilinear`, the clamped trilinear field.
#[inline(always)]
pub fn tricubic(p: Vec3, upper: Vec3, trilinear: impl Fn(Vec3) -> f32) -> f32 {
    let p = p.clamp(Vec3::ZERO, upper);
    let (x0, x1, gx) = bspline_axis(p.x);
    let (y0, y1, gy) = bspline_axis(p.y);
    let (z0, z1, gz) = bspline_axis(p.z);
    let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
    let plane = |z: f32| {
        let a = lerp(
            trilinear(Vec3::new(x0, y0, z)),
            trilinear(Vec3::new(x1, y0, z)),
            gx,
        );
        let b = lerp(
            trilinear(Vec3::new(x0, y1, z)),
            trilinear(Vec3::new(x1, y1, z)),
            gx,
        );
        lerp(a, b, gy)
    };
    let lo = plane(z0);
    let hi = plane(z1);
    lerp(lo, hi, gz)
}

/// The 4×4×4 voxels around a trilinear footprint: `block[x + 4 (y + 4 z)]`
/// is voxel `(i − 1 + x, j − 1 + y, k − 1 + z)`, indices clamped to the grid.
pub type Block = [f32; 64];

/// One Sobel tap at the middle of three consecutive voxels: the
/// derivative `h2 − h0` (`d = true`) or the smoothing `(h0 + 2 h1 + h2) / 4`
/// — the f32 operations every Sobel value, per sample or cached
/// ([`crate::gradient_cache`]), is made of.
#[inline(always)]
pub fn tap3(h0: f32, h1: f32, h2: f32, d: bool) -> f32 {
    if d {
        h2 - h0
    } else {
        (h0 + 2.0 * h1 + h2) * 0.25
    }
}

/// [`tap3`] at the two inner positions `q = 1, 2` of a 4-tap line.
#[inline(always)]
fn tap(b: [f32; 4], d: bool) -> [f32; 2] {
    [tap3(b[0], b[1], b[2], d), tap3(b[1], b[2], b[3], d)]
}

/// Trilinear interpolation of the 8 corners `c[x + 2 (y + 2 z)]` at
/// fractions `f`: along x, then y, then z.
#[inline(always)]
pub fn trilinear8(c: [f32; 8], f: Vec3) -> f32 {
    let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
    let x00 = lerp(c[0], c[1], f.x);
    let x10 = lerp(c[2], c[3], f.x);
    let x01 = lerp(c[4], c[5], f.x);
    let x11 = lerp(c[6], c[7], f.x);
    lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z)
}

/// One Sobel component: the derivative along `axis` (a difference over two
/// voxels, not halved), smoothed across, at the 8 corners of the footprint,
/// trilinearly interpolated at fractions `f`.
#[inline(always)]
fn sobel_component(block: &Block, axis: usize, f: Vec3) -> f32 {
    // Along x: 4 × 4 lines (y, z) → 2 × 4 × 4.
    let mut sx = [0f32; 32];
    for l in 0..16 {
        let b = [
            block[4 * l],
            block[4 * l + 1],
            block[4 * l + 2],
            block[4 * l + 3],
        ];
        let r = tap(b, axis == 0);
        sx[2 * l] = r[0];
        sx[2 * l + 1] = r[1];
    }
    // Along y: sx[x + 2 (y + 4 z)] → sy[x + 2 (y' + 2 z)].
    let mut sy = [0f32; 16];
    for z in 0..4 {
        for x in 0..2 {
            let at = |y: usize| sx[x + 2 * (y + 4 * z)];
            let r = tap([at(0), at(1), at(2), at(3)], axis == 1);
            sy[x + 2 * (2 * z)] = r[0];
            sy[x + 2 * (1 + 2 * z)] = r[1];
        }
    }
    // Along z: sy[x + 2 (y + 2 z)] → c[x + 2 (y + 2 z')].
    let mut c = [0f32; 8];
    for y in 0..2 {
        for x in 0..2 {
            let at = |z: usize| sy[x + 2 * (y + 2 * z)];
            let r = tap([at(0), at(1), at(2), at(3)], axis == 2);
            c[x + 2 * y] = r[0];
            c[x + 2 * y + 4] = r[1];
        }
    }
    trilinear8(c, f)
}

/// The Sobel gradient (voxel units: differences over two voxels, like the
/// central difference) of `block` at fractions `f` of the footprint.
#[inline]
pub fn sobel(block: &Block, f: Vec3) -> Vec3 {
    Vec3::new(
        sobel_component(block, 0, f),
        sobel_component(block, 1, f),
        sobel_component(block, 2, f),
    )
}

/// Gathers the [`Block`] of the footprint with lower corner `i` from
/// `values` (`dims`, x fastest, in the renderer's [`Sample`] type), clamping
/// indices to the grid.
#[inline]
pub fn gather<T: Sample>(values: &[T], dims: [usize; 3], i: [usize; 3]) -> Block {
    let idx = |a: usize| {
        let n = dims[a] - 1;
        [
            i[a].saturating_sub(1).min(n),
            i[a].min(n),
            (i[a] + 1).min(n),
            (i[a] + 2).min(n),
        ]
    };
    let (ix, iy, iz) = (idx(0), idx(1), idx(2));
    let mut b = [0f32; 64];
    for z in 0..4 {
        for y in 0..4 {
            let row = dims[0] * (iy[y] + dims[1] * iz[z]);
            for x in 0..4 {
                b[x + 4 * (y + 4 * z)] = values[row + ix[x]].to_f32();
            }
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jitter_is_deterministic_in_range_and_spread() {
        let mut sum = 0.0f64;
        let mut seen = std::collections::HashSet::new();
        for y in 0..64 {
            for x in 0..64 {
                let j = jitter(x, y);
                assert_eq!(j, jitter(x, y));
                assert!((0.0..1.0).contains(&j), "{j}");
                sum += j as f64;
                seen.insert(j.to_bits());
            }
        }
        let mean = sum / 4096.0;
        // A uniform mean's standard error over 4096 draws is 0.0045.
        assert!((mean - 0.5).abs() < 0.03, "mean {mean}");
        assert!(seen.len() > 4000, "{} distinct", seen.len());
        // Neighbours differ (not a smooth pattern).
        assert_ne!(jitter(10, 10), jitter(11, 10));
        assert_ne!(jitter(10, 10), jitter(10, 11));
        assert_eq!(jitter(u32::MAX, u32::MAX), jitter(u32::MAX, u32::MAX));
    }

    fn ramp(dims: [usize; 3], a: Vec3, c: f32) -> Vec<f32> {
        (0..dims.iter().product())
            .map(|l: usize| {
                let (x, y, z) = (
                    l % dims[0],
                    (l / dims[0]) % dims[1],
                    l / (dims[0] * dims[1]),
                );
                a.dot(Vec3::new(x as f32, y as f32, z as f32)) + c
            })
            .collect()
    }

    fn trilinear(values: &[f32], dims: [usize; 3], p: Vec3) -> f32 {
        let upper = Vec3::new(
            dims[0] as f32 - 1.0,
            dims[1] as f32 - 1.0,
            dims[2] as f32 - 1.0,
        );
        let p = p.clamp(Vec3::ZERO, upper);
        let i = [0, 1, 2].map(|a| (p[a] as usize).min(dims[a] - 2));
        let f = p - Vec3::new(i[0] as f32, i[1] as f32, i[2] as f32);
        let at = |x, y, z| values[x + dims[0] * (y + dims[1] * z)];
        let lerp = |a: f32, b: f32, t: f32| a + t * (b - a);
        let (x, y, z) = (i[0], i[1], i[2]);
        let x00 = lerp(at(x, y, z), at(x + 1, y, z), f.x);
        let x10 = lerp(at(x, y + 1, z), at(x + 1, y + 1, z), f.x);
        let x01 = lerp(at(x, y, z + 1), at(x + 1, y, z + 1), f.x);
        let x11 = lerp(at(x, y + 1, z + 1), at(x + 1, y + 1, z + 1), f.x);
        lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z)
    }

    #[test]
    fn sobel_of_a_linear_ramp_is_exact() {
        let dims = [9, 8, 7];
        let a = Vec3::new(1.5, -0.75, 0.25);
        let v = ramp(dims, a, 3.0);
        for (i, f) in [
            ([2, 3, 2], Vec3::new(0.25, 0.5, 0.75)),
            ([4, 1, 3], Vec3::new(0.9, 0.1, 0.0)),
            ([6, 5, 4], Vec3::ZERO),
        ] {
            let g = sobel(&gather(&v, dims, i), f);
            // Differences over two voxels: twice the slope.
            assert!((g - 2.0 * a).abs().max_element() < 1e-5, "{g} at {i:?}");
        }
        // At the edge the clamped difference halves (one-sided), as the
        // central difference does.
        let g = sobel(&gather(&v, dims, [0, 3, 3]), Vec3::ZERO);
        assert!((g.x - a.x).abs() < 1e-5, "{g}");
    }

    #[test]
    fn sobel_smooths_across_the_axis() {
        // A single bright voxel: the x-derivative one voxel to its left is
        // spread over the neighbours in y and z with weights 1, 2, 1 (/16).
        let dims = [5, 5, 5];
        let mut v = vec![0f32; 125];
        v[2 + 5 * (2 + 5 * 2)] = 16.0;
        let g_centre = sobel(&gather(&v, dims, [1, 2, 2]), Vec3::ZERO).x;
        let g_side = sobel(&gather(&v, dims, [1, 1, 2]), Vec3::ZERO).x;
        let g_corner = sobel(&gather(&v, dims, [1, 1, 1]), Vec3::ZERO).x;
        assert_eq!((g_centre, g_side, g_corner), (4.0, 2.0, 1.0));
    }

    #[test]
    fn tricubic_reproduces_linear_and_constant_data() {
        let dims = [10, 9, 8];
        let upper = Vec3::new(9.0, 8.0, 7.0);
        let a = Vec3::new(2.0, -1.0, 0.5);
        let v = ramp(dims, a, 10.0);
        let c = vec![7.0f32; 720];
        for p in [
            Vec3::new(2.3, 3.7, 4.1),
            Vec3::new(5.0, 5.0, 5.0),
            Vec3::new(1.01, 6.99, 2.5),
            Vec3::new(7.9, 1.2, 5.999),
        ] {
            let got = tricubic(p, upper, |q| trilinear(&v, dims, q));
            let want = a.dot(p) + 10.0;
            assert!((got - want).abs() < 1e-4, "{got} vs {want} at {p}");
            let k = tricubic(p, upper, |q| trilinear(&c, dims, q));
            assert!((k - 7.0).abs() < 1e-5, "{k}");
        }
        // It smooths: a step becomes a ramp within the 4³ range.
        let step: Vec<f32> = (0..720)
            .map(|l| if l % 10 >= 5 { 1.0 } else { 0.0 })
            .collect();
        let s = tricubic(Vec3::new(4.5, 4.0, 4.0), upper, |q| {
            trilinear(&step, dims, q)
        });
        assert!((s - 0.5).abs() < 1e-5, "{s}");
        let s = tricubic(Vec3::new(4.0, 4.0, 4.0), upper, |q| {
            trilinear(&step, dims, q)
        });
        assert!(s > 0.0 && s < 0.5, "{s}");
    }

    #[test]
    fn bspline_weights_are_a_partition_of_unity() {
        for k in 0..16 {
            let x = 3.0 + k as f32 / 16.0;
            let (h0, h1, g1) = bspline_axis(x);
            assert!(
                (2.0..=3.0).contains(&h0) && (4.0..=5.0).contains(&h1),
                "{h0} {h1}"
            );
            assert!((0.0..=1.0).contains(&g1));
            // Reproduces x: lerp of the positions (linear data) is x.
            assert!((h0 + g1 * (h1 - h0) - x).abs() < 1e-5);
        }
    }
}
