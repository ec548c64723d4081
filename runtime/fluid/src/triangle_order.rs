//! The order the CPU's row scan visits a surface's triangles in: along a
//! Z-order (Morton) curve through their centroids, so consecutive
//! triangles share corners and lie in the same rows.
//!
//! A mesh's own order may be anything — the shared bunny's is shuffled
//! (consecutive triangles' first corners lie a median 8,391 vertex ids
//! apart) — and a scan in that order gathers each triangle's corners from
//! anywhere in a vertex array larger than a core's L2 cache, and scatters
//! its runs over every row band. Visiting the triangles along the curve
//! made the 75,408-triangle bunny's weighing at 200² about a quarter
//! faster on the 2-core reference machine (see `docs/BENCHMARKS.md`).
//!
//! The order keeps each triangle's corner ids beside its index, so the
//! scan reads them in sequence too; it is kept while the surface keeps its
//! triangles (checked every call: a comparison of the id arrays, tens of
//! microseconds for the bunny), so a deforming cavity computes it once.
//! The order changes no crossing, only the order in which sums are taken
//! (results differ from another order's in the last bits). Coordinates:
//! world frame, mm.

use crate::FluidError;
use glam::DVec3;
use rayon::prelude::*;
use voxflex_core::triangle_surface::TriangleSurface;

/// Triangles whose ids one task compares in [`TriangleOrder::fits`].
const COMPARED_PER_TASK: usize = 16_384;

/// Bits per axis of the Morton key (3 × 21 = 63).
const BITS: u32 = 21;

/// A permutation of a surface's triangles, with their corner ids.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TriangleOrder {
    /// The surface's triangles as they were when the order was made.
    source: Vec<[u32; 3]>,
    /// One past the largest corner id: the vertices a surface must have.
    needs: usize,
    /// Triangle index and corner ids, in visiting order.
    visits: Vec<(u32, [u32; 3])>,
}

impl TriangleOrder {
    /// `surface`'s triangles sorted by the Morton key of their centroids
    /// in the vertices' bounding box (ties and non-finite centroids keep
    /// their index order). Refuses a triangle that names a vertex the
    /// surface does not have, naming the first one: every later call whose
    /// surface [`TriangleOrder::fits`] this order is then checked for free.
    pub fn of(surface: &TriangleSurface) -> Result<Self, FluidError> {
        let v = &surface.vertices;
        let needs = check_corner_ids(surface)?;
        let finite = v.iter().filter(|p| p.is_finite());
        let lo = finite.clone().fold(DVec3::INFINITY, |a, &b| a.min(b));
        let hi = finite.fold(DVec3::NEG_INFINITY, |a, &b| a.max(b));
        let scale = ((1u32 << BITS) - 1) as f64 / (hi - lo).max(DVec3::splat(f64::MIN_POSITIVE));
        let mut keyed: Vec<(u64, u32)> = surface
            .triangles
            .par_iter()
            .enumerate()
            .map(|(t, ids)| {
                let c = ids.iter().map(|&i| v[i as usize]).sum::<DVec3>() / 3.0;
                (morton_key((c - lo) * scale), t as u32)
            })
            .collect();
        keyed.par_sort_unstable();
        let triangles = &surface.triangles;
        Ok(Self {
            source: triangles.clone(),
            needs,
            visits: keyed
                .into_iter()
                .map(|(_, t)| (t, triangles[t as usize]))
                .collect(),
        })
    }

    /// Whether this order was made for `surface`'s triangles and `surface`
    /// has every vertex they name (its vertices may have moved since: the
    /// order only decides speed).
    pub fn fits(&self, surface: &TriangleSurface) -> bool {
        // compared in pieces on every thread (the bunny's ids are 905 KB)
        let (a, b) = (&self.source, &surface.triangles);
        a.len() == b.len()
            && surface.vertices.len() >= self.needs
            && a.par_chunks(COMPARED_PER_TASK)
                .zip(b.par_chunks(COMPARED_PER_TASK))
                .all(|(a, b)| a == b)
    }

    /// Each triangle's index and corner ids, in visiting order.
    pub fn visits(&self) -> &[(u32, [u32; 3])] {
        &self.visits
    }
}

/// One past the largest corner id of `surface`'s triangles; an error
/// naming the first triangle whose corner is not one of its vertices.
fn check_corner_ids(surface: &TriangleSurface) -> Result<usize, FluidError> {
    let n = surface.vertices.len();
    let largest = surface
        .triangles
        .par_iter()
        .map(|t| t.iter().copied().max().unwrap_or(0))
        .max()
        .map_or(0, |m| m as usize + 1);
    if largest <= n {
        return Ok(largest);
    }
    let (t, ids) = (surface.triangles.iter().enumerate())
        .find(|(_, ids)| ids.iter().any(|&i| i as usize >= n))
        .expect("a corner id past the vertices was found above");
    Err(FluidError::Surface(format!(
        "triangle {t} names vertices {ids:?}, but the surface has {n} vertices (ids 0..{n}); \
         fix the cavity mesh's triangle list"
    )))
}

/// Interleaves the bits of `p`'s coordinates (each clamped to
/// `0..2^BITS`; NaN counts as 0).
fn morton_key(p: DVec3) -> u64 {
    let max = ((1u32 << BITS) - 1) as f64;
    let spread = |x: f64| {
        // `as` saturates and maps NaN to 0
        let mut x = x.clamp(0.0, max) as u64;
        x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
        x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
        x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
        x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
        (x | (x << 2)) & 0x1249_2492_4924_9249
    };
    spread(p.x) | (spread(p.y) << 1) | (spread(p.z) << 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_key_interleaves_the_bits_of_each_axis() {
        assert_eq!(morton_key(DVec3::new(1.0, 0.0, 0.0)), 0b001);
        assert_eq!(morton_key(DVec3::new(0.0, 1.0, 0.0)), 0b010);
        assert_eq!(morton_key(DVec3::new(0.0, 0.0, 1.0)), 0b100);
        assert_eq!(morton_key(DVec3::new(3.0, 0.0, 2.0)), 0b101_001);
        let max = ((1u32 << BITS) - 1) as f64;
        assert_eq!(morton_key(DVec3::splat(max)), (1u64 << 63) - 1);
        assert_eq!(morton_key(DVec3::splat(f64::NAN)), 0);
        assert_eq!(morton_key(DVec3::splat(-5.0)), 0);
    }

    #[test]
    fn the_order_is_a_permutation_that_keeps_neighbours_together() {
        // a 2 × 64 strip of triangles listed far end first, alternately
        let vertices: Vec<DVec3> = (0..65)
            .flat_map(|i| {
                [
                    DVec3::new(i as f64, 0.0, 0.0),
                    DVec3::new(i as f64, 1.0, 0.0),
                ]
            })
            .collect();
        let mut triangles = Vec::new();
        for i in 0..64u32 {
            let c = if i % 2 == 0 { 63 - i / 2 } else { i / 2 };
            triangles.push([2 * c, 2 * c + 2, 2 * c + 1]);
        }
        let s = TriangleSurface {
            vertices,
            triangles,
        };
        let order = TriangleOrder::of(&s).unwrap();
        assert!(order.fits(&s));
        let mut seen: Vec<u32> = order.visits().iter().map(|v| v.0).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..64).collect::<Vec<_>>());
        assert!(
            order
                .visits()
                .iter()
                .all(|&(t, ids)| s.triangles[t as usize] == ids)
        );
        // along the curve, consecutive triangles are neighbours on the strip
        for w in order.visits().windows(2) {
            assert_eq!((w[0].1[0] / 2).abs_diff(w[1].1[0] / 2), 1, "{w:?}");
        }
        // the same triangles fit; others do not, even as many
        let mut other = s.clone();
        assert!(order.fits(&other));
        other.vertices[0].x += 1.0;
        assert!(order.fits(&other), "moved vertices keep the order");
        other.triangles.swap(0, 1);
        assert!(!order.fits(&other));
        // the same triangles over too few vertices do not fit either
        let mut fewer = s.clone();
        let largest = s.triangles.iter().flatten().copied().max().unwrap();
        fewer.vertices.truncate(largest as usize);
        assert!(!order.fits(&fewer));
        fewer.vertices.push(DVec3::ZERO);
        assert!(
            order.fits(&fewer),
            "one more vertex and every corner exists"
        );
    }
}
