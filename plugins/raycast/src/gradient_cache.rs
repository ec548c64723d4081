//! [`GradientCache`]: the CPU path's Sobel gradients at the voxels, built
//! per brick of 8³ cells on first use and dropped where the volume changes.
//!
//! [`crate::filters::sobel`] evaluates the 3×3×3 Sobel operator at the 8
//! corners of a sample's footprint and interpolates them trilinearly: 84
//! four-tap filters per shaded sample, about a quarter of a shaded frame.
//! The corner values depend on the voxels alone, so they are cached: a
//! brick holds the gradients of the 9³ voxels that are corners of its 8³
//! cells (neighbouring bricks share a face), computed with the same f32
//! operations in the same order as `filters::sobel` (difference or
//! `[1, 2, 1] / 4` smoothing along x, then y, then z, indices clamped to
//! the grid one by one), so a cached gradient is **bit-identical** to the
//! uncached one — the GPU twin, which keeps computing it per sample, stays
//! within the existing parity tolerance, and the CPU image does not change.
//!
//! Only bricks a shaded sample reaches are built (a bone transfer function
//! on a head CT touches a small part of the volume), on the rendering
//! threads, once each ([`crate::lazy_bricks`]). The cache holds at most as many bytes
//! as the f32 volume itself ([`GradientCache::new`]'s budget); past that a
//! brick is marked uncached and its samples compute the gradient as before.
//! [`GradientCache::invalidate`] drops the bricks whose gradients read a
//! changed voxel (the dirty region of `set_volume`).
//!
//! Units: gradients in value units per voxel step × 2 (a difference over
//! two voxels, as `filters::sobel`); indices are voxel indices, x fastest.

use crate::filters::tap3;
use crate::lazy_bricks::{LazyBricks, Reach};
use crate::macrocell::IndexBox;
use std::sync::atomic::{AtomicUsize, Ordering};
use voxflex_core::glam::{Vec3, Vec4};
use voxflex_core::volume::Sample;

pub use crate::lazy_bricks::BRICK;
/// Corner voxels per brick edge.
const SIDE: usize = BRICK + 1;
/// Voxels per brick edge with the one-voxel halo the filter reads.
const HALO: usize = BRICK + 3;
/// Gradient components stored per brick (3 per corner, padded to 4 so a
/// corner is one SIMD load and the three components interpolate together).
const BRICK_FLOATS: usize = 4 * SIDE * SIDE * SIDE;
/// Bytes of one built brick.
pub const BRICK_BYTES: usize = 4 * BRICK_FLOATS;
/// The Sobel filter reads one voxel beyond a brick's corners.
const REACH: Reach = Reach {
    before: 1,
    after: 1,
};

/// One brick's corner gradients, `[cx + 9 (cy + 9 cz)] = [gx, gy, gz, 0]`.
type Brick = Box<[Vec4]>;

/// Sobel gradients of a volume, per 8³-cell brick, built on first use.
pub struct GradientCache {
    /// `None` inside: the brick was over budget (computed per sample).
    bricks: LazyBricks<Option<Brick>>,
    /// Bricks that may be built.
    budget: usize,
    /// Bricks built (or being built).
    built: AtomicUsize,
}

impl GradientCache {
    /// An empty cache for a volume of `dims` voxels holding at most
    /// `budget_bytes` of gradients.
    pub fn new(dims: [usize; 3], budget_bytes: usize) -> Self {
        Self {
            bricks: LazyBricks::new(dims),
            budget: budget_bytes / BRICK_BYTES,
            built: AtomicUsize::new(0),
        }
    }

    /// The volume size the cache was made for (voxels).
    pub fn dims(&self) -> [usize; 3] {
        self.bricks.dims()
    }

    /// Bricks built so far.
    pub fn built(&self) -> usize {
        self.built.load(Ordering::Relaxed).min(self.budget)
    }

    /// Drops every brick whose gradients read a voxel of `region` (a corner
    /// reads its neighbours one voxel away).
    pub fn invalidate(&mut self, region: IndexBox) {
        let built = self.built.get_mut();
        self.bricks.invalidate(region, REACH, |b| {
            if b.is_some() {
                *built -= 1;
            }
        });
        *built = (*built).min(self.budget);
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
            .get_or_build(&place, |b| self.build(values, b))
            .as_deref()?;
        let l = place.local;
        let at = |dx: usize, dy: usize, dz: usize| {
            brick[l[0] + dx + SIDE * (l[1] + dy + SIDE * (l[2] + dz))]
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

    /// Builds brick `b` (or marks it uncached when the budget is spent).
    #[cold]
    fn build<T: Sample>(&self, values: &[T], b: [usize; 3]) -> Option<Brick> {
        if self.built.fetch_add(1, Ordering::Relaxed) >= self.budget {
            return None;
        }
        Some(brick_gradients(values, self.bricks.dims(), b))
    }
}

/// The corner gradients of brick `b`: separable passes over the brick's
/// 11³ voxels (indices clamped to the grid axis by axis, as `gather` does).
///
/// Each pass runs over whole rows of fixed-size arrays on the stack, so the
/// compiler keeps it in SIMD registers; per element it is the same [`tap3`]
/// as the per-sample filter, so the result is bit-identical.
fn brick_gradients<T: Sample>(values: &[T], dims: [usize; 3], b: [usize; 3]) -> Brick {
    let index = |a: usize, h: usize| (b[a] * BRICK + h).saturating_sub(1).min(dims[a] - 1);
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
    let mut out = vec![Vec4::ZERO; SIDE * SIDE * SIDE];
    for (axis, src) in y_pass.iter().enumerate() {
        for cz in 0..SIDE {
            for cy in 0..SIDE {
                let g = tap_rows(&src[cz][cy], &src[cz + 1][cy], &src[cz + 2][cy], axis == 2);
                for (cx, v) in g.into_iter().enumerate() {
                    out[cx + SIDE * (cy + SIDE * cz)][axis] = v;
                }
            }
        }
    }
    out.into_boxed_slice()
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
                    cache.sobel(v, [8 * bx, 8 * by, 8 * bz], Vec3::ZERO);
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
            // Brick b reads voxels 8b − 1 ..= 8b + 9 along each axis.
            let along =
                |v: usize, n: usize| (0..n).filter(|b| 8 * b <= v + 1 && v <= 8 * b + 9).count();
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
