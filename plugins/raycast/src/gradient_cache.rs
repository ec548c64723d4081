//! [`GradientCache`]: the CPU path's Sobel gradients at the voxels, built
//! per brick of [`EDGE`]³ cells on first use and dropped where the volume
//! changes.
//!
//! [`crate::filters::sobel`] evaluates the 3×3×3 Sobel operator at the 8
//! corners of a sample's footprint and interpolates them trilinearly: 84
//! four-tap filters per shaded sample, about a quarter of a shaded frame.
//! The corner values depend on the voxels alone, so they are cached: a
//! brick holds the gradients of the `(EDGE + 1)³` voxels that are corners
//! of its cells (neighbouring bricks share a face), computed with the same
//! f32 operations in the same order as `filters::sobel` (difference or
//! `[1, 2, 1] / 4` smoothing along x, then y, then z, indices clamped to
//! the grid one by one), so a cached gradient is **bit-identical** to the
//! uncached one — the GPU twin, which keeps computing it per sample, stays
//! within the existing parity tolerance, and the CPU image does not change.
//!
//! Only bricks a shaded sample reaches are built (a bone transfer function
//! on a head CT touches a small part of the volume), on the rendering
//! threads, once each, packed in one pool ([`crate::lazy_bricks`]). The
//! cache holds at most as many bytes as the f32 volume itself
//! ([`GradientCache::new`]'s budget); past that a brick is marked over
//! budget and its samples compute the gradient as before.
//! [`GradientCache::invalidate`] drops the bricks whose gradients read a
//! changed voxel (the dirty region of `set_volume`).
//!
//! **Size.** A first frame writes every brick it builds into fresh pages,
//! and on the 512 × 512 × 133 CT's `ct-bone` frame their page faults cost
//! more than the filtering (4,770 bricks). So a corner keeps its three
//! components only (12 bytes, read as four floats of which the fourth is
//! the next corner's and is ignored): 42 MB of bricks instead of 56 (with
//! the pool, the first frame ~5 ms faster, the later ones ~1.5 ms: the
//! same cache holds more corners). Bricks of 4³ cells would cover the
//! 417 k shaded cells with 2.71 M corners instead of 3.48 M, but made
//! every frame slower (docs/BENCHMARKS.md).
//!
//! Units: gradients in value units per voxel step × 2 (a difference over
//! two voxels, as `filters::sobel`); indices are voxel indices, x fastest.

use crate::filters::tap3;
use crate::lazy_bricks::{LazyBricks, Reach};
use crate::macrocell::IndexBox;
use voxflex_core::glam::{Vec3, Vec4};
use voxflex_core::volume::Sample;

/// Cells per gradient brick edge.
pub const EDGE: usize = 8;
/// Corner voxels per brick edge.
const SIDE: usize = EDGE + 1;
/// Voxels per brick edge with the one-voxel halo the filter reads.
const HALO: usize = EDGE + 3;
/// Floats per brick: three per corner, and one so that the last corner
/// too is read as four.
const BRICK_FLOATS: usize = 3 * SIDE * SIDE * SIDE + 1;
/// Bytes of one built brick.
pub const BRICK_BYTES: usize = 4 * BRICK_FLOATS;
/// The Sobel filter reads one voxel beyond a brick's corners.
const REACH: Reach = Reach {
    before: 1,
    after: 1,
};

/// One brick's corner gradients: `[3 (cx + S (cy + S cz)) + axis]`,
/// `S = EDGE + 1`, then one 0.
type Brick = [f32; BRICK_FLOATS];

/// Sobel gradients of a volume, per [`EDGE`]³-cell brick, built on first
/// use.
pub struct GradientCache {
    bricks: LazyBricks<Brick, EDGE>,
}

impl GradientCache {
    /// An empty cache for a volume of `dims` voxels holding at most
    /// `budget_bytes` of gradients.
    pub fn new(dims: [usize; 3], budget_bytes: usize) -> Self {
        Self {
            bricks: LazyBricks::new(dims, budget_bytes / BRICK_BYTES),
        }
    }

    /// The volume size the cache was made for (voxels).
    pub fn dims(&self) -> [usize; 3] {
        self.bricks.dims()
    }

    /// Bricks built so far.
    pub fn built(&self) -> usize {
        self.bricks.built()
    }

    /// Drops every brick whose gradients read a voxel of `region` (a corner
    /// reads its neighbours one voxel away).
    pub fn invalidate(&mut self, region: IndexBox) {
        self.bricks.invalidate(region, REACH);
    }

    /// The Sobel gradient at fractions `f` of the footprint whose lower
    /// corner is voxel `i`, as [`crate::filters::sobel`] computes it from
    /// `values` (the volume, x fastest); `None` when the brick is over the
    /// budget.
    #[inline]
    pub fn sobel<T: Sample>(&self, values: &[T], i: [usize; 3], f: Vec3) -> Option<Vec3> {
        let place = self.bricks.place(i);
        let brick = self
            .bricks
            .get_or_build(&place, |b| brick_gradients(values, self.bricks.dims(), b))?;
        let l = place.local;
        let at = |dx: usize, dy: usize, dz: usize| {
            let k = 3 * (l[0] + dx + SIDE * (l[1] + dy + SIDE * (l[2] + dz)));
            Vec4::from_slice(&brick[k..k + 4])
        };
        // `trilinear8`'s operations, on the three components at once (lane
        // by lane the same f32 operations in the same order).
        let lerp = |a: Vec4, b: Vec4, t: f32| a + Vec4::splat(t) * (b - a);
        let x00 = lerp(at(0, 0, 0), at(1, 0, 0), f.x);
        let x10 = lerp(at(0, 1, 0), at(1, 1, 0), f.x);
        let x01 = lerp(at(0, 0, 1), at(1, 0, 1), f.x);
        let x11 = lerp(at(0, 1, 1), at(1, 1, 1), f.x);
        let g = lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z);
        Some(g.truncate())
    }
}

/// The corner gradients of brick `b`: separable passes over the brick's
/// `(EDGE + 3)³` voxels (indices clamped to the grid axis by axis, as
/// `gather` does).
///
/// Each pass runs over whole rows of fixed-size arrays on the stack, so the
/// compiler keeps it in SIMD registers; per element it is the same [`tap3`]
/// as the per-sample filter, so the result is bit-identical.
fn brick_gradients<T: Sample>(values: &[T], dims: [usize; 3], b: [usize; 3]) -> Brick {
    let index = |a: usize, h: usize| (b[a] * EDGE + h).saturating_sub(1).min(dims[a] - 1);
    let xs: [usize; HALO] = std::array::from_fn(|h| index(0, h));
    // A brick clear of the grid's x faces reads its halo rows as one run.
    let run = (xs[HALO - 1] == xs[0] + HALO - 1).then_some(xs[0]);
    // Along x, per halo row (hy, hz): [D, S][hz][hy][cx].
    let mut x_pass = [[[[0f32; SIDE]; HALO]; HALO]; 2];
    for hz in 0..HALO {
        for hy in 0..HALO {
            let row = &values[dims[0] * (index(1, hy) + dims[1] * index(2, hz))..];
            let h: [f32; HALO] = match run {
                Some(x0) => {
                    let r: &[T; HALO] = row[x0..x0 + HALO].try_into().expect("HALO voxels");
                    r.map(T::to_f32)
                }
                None => std::array::from_fn(|x| row[xs[x]].to_f32()),
            };
            for (k, pass) in x_pass.iter_mut().enumerate() {
                pass[hz][hy] = taps(&h, k == 0);
            }
        }
    }
    // Along y: DxSy, SxDy, SxSy [hz][cy][cx].
    let y_of = |src: &[[[f32; SIDE]; HALO]; HALO], diff: bool| {
        let mut out = [[[0f32; SIDE]; SIDE]; HALO];
        for (plane, rows) in out.iter_mut().zip(src) {
            for (cy, row) in plane.iter_mut().enumerate() {
                *row = tap_rows(&rows[cy], &rows[cy + 1], &rows[cy + 2], diff);
            }
        }
        out
    };
    let y_pass = [
        y_of(&x_pass[0], false),
        y_of(&x_pass[1], true),
        y_of(&x_pass[1], false),
    ];
    // Along z: gx = S(DxSy), gy = S(SxDy), gz = D(SxSy), then interleaved.
    let mut out = [0f32; BRICK_FLOATS];
    for (axis, src) in y_pass.iter().enumerate() {
        for cz in 0..SIDE {
            for cy in 0..SIDE {
                let g = tap_rows(&src[cz][cy], &src[cz + 1][cy], &src[cz + 2][cy], axis == 2);
                for (cx, v) in g.into_iter().enumerate() {
                    out[3 * (cx + SIDE * (cy + SIDE * cz)) + axis] = v;
                }
            }
        }
    }
    out
}

/// [`tap3`] along a halo row: output `c` from inputs `c, c + 1, c + 2`.
#[inline(always)]
fn taps(h: &[f32; HALO], d: bool) -> [f32; SIDE] {
    std::array::from_fn(|c| tap3(h[c], h[c + 1], h[c + 2], d))
}

/// [`tap3`] across three rows, element by element.
#[inline(always)]
fn tap_rows(a: &[f32; SIDE], b: &[f32; SIDE], c: &[f32; SIDE], d: bool) -> [f32; SIDE] {
    std::array::from_fn(|x| tap3(a[x], b[x], c[x], d))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filters::{gather, sobel};

    fn volume(dims: [usize; 3]) -> Vec<f32> {
        (0..dims.iter().product::<usize>())
            .map(|l| ((l as u32).wrapping_mul(2_654_435_761) >> 8) as f32 * 1e-3 - 3.0e3)
            .collect()
    }

    /// Every cell (footprint lower corner) and a spread of fractions,
    /// including the grid's faces and 1- and 2-voxel axes.
    #[test]
    fn cached_gradients_are_bit_identical_to_filters_sobel() {
        for dims in [[19, 10, 17], [1, 9, 3], [2, 2, 2], [8, 9, 1], [17, 17, 17]] {
            let v = volume(dims);
            let cache = GradientCache::new(dims, usize::MAX);
            let max0 = dims.map(|n| n.max(2) - 2);
            for k in 0..=max0[2] {
                for j in 0..=max0[1] {
                    for i in 0..=max0[0] {
                        for f in [Vec3::ZERO, Vec3::new(0.25, 0.5, 0.999), Vec3::ONE] {
                            let want = sobel(&gather(&v, dims, [i, j, k]), f);
                            let got = cache.sobel(&v, [i, j, k], f).unwrap();
                            assert_eq!(
                                got.to_array().map(f32::to_bits),
                                want.to_array().map(f32::to_bits),
                                "{dims:?} cell {:?} f {f}",
                                [i, j, k]
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn over_budget_bricks_are_left_to_the_caller() {
        let dims = [20, 20, 20];
        let v = volume(dims);
        let cache = GradientCache::new(dims, BRICK_BYTES);
        assert!(cache.sobel(&v, [0, 0, 0], Vec3::ZERO).is_some());
        assert!(cache.sobel(&v, [9, 0, 0], Vec3::ZERO).is_none());
        assert!(cache.sobel(&v, [0, 0, 0], Vec3::ONE).is_some());
        assert_eq!(cache.built(), 1);
    }

    /// Builds every brick of `cache`.
    fn fill(cache: &GradientCache, v: &[f32]) {
        let [nx, ny, nz] = cache.bricks.counts();
        for bz in 0..nz {
            for by in 0..ny {
                for bx in 0..nx {
                    cache.sobel(v, [EDGE * bx, EDGE * by, EDGE * bz], Vec3::ZERO);
                }
            }
        }
    }

    #[test]
    fn invalidation_drops_exactly_the_bricks_that_read_the_region() {
        let dims = [33, 26, 20];
        for x in [7, 8, 9, 10, 16, 17, 31, 32] {
            let mut v = volume(dims);
            let mut cache = GradientCache::new(dims, usize::MAX);
            fill(&cache, &v);
            let all = cache.built();
            v[x + dims[0] * (12 + dims[1] * 4)] += 100.0;
            cache.invalidate(IndexBox {
                lo: [x, 12, 4],
                hi: [x, 12, 4],
            });
            // Brick b reads voxels E·b − 1 ..= E·b + E + 1 along each axis.
            let along = |v: usize, n: usize| {
                (0..n)
                    .filter(|b| EDGE * b <= v + 1 && v <= EDGE * b + EDGE + 1)
                    .count()
            };
            let dropped = along(x, cache.bricks.counts()[0])
                * along(12, cache.bricks.counts()[1])
                * along(4, cache.bricks.counts()[2]);
            assert_eq!(cache.built(), all - dropped, "voxel x = {x}");
            // Every gradient is the filter's on the changed volume.
            let max0 = dims.map(|n| n - 2);
            for k in 0..=max0[2] {
                for j in 0..=max0[1] {
                    for i in 0..=max0[0] {
                        let f = Vec3::new(0.3, 0.6, 0.9);
                        let want = sobel(&gather(&v, dims, [i, j, k]), f);
                        assert_eq!(
                            cache.sobel(&v, [i, j, k], f),
                            Some(want),
                            "x = {x}, cell {:?}",
                            [i, j, k]
                        );
                    }
                }
            }
        }
    }
}
