//! Each section's weight `A·h·ρ·g` onto its bottom triangle's corners by
//! the barycentric coordinates of the column centre — summed per run (a
//! triangle's columns in one row) first.
//!
//! The barycentric coordinates are affine in the centre, so a run's
//! columns `first + m` with fluid heights `h` give corner `a` the weight
//! `ρ·g·A·(H·b_a(c₀) + ∂b_a/∂u · w·M)`, with `H = Σ h`, `M = Σ h·m` and
//! `c₀` the centre of column `first`: one evaluation per run instead of one
//! per column, the same sum up to rounding. The third corner takes
//! `ρ·g·A·H` less the other two, so the weights sum to the fluid's weight
//! to rounding. The row scan stores `b_a(c₀)` and `w·∂b_a/∂u` with each
//! run ([`RunBarycentric`]), so the section pass, which weighs each band's
//! runs, reads no triangle (a random read per run, which on a large mesh
//! misses the caches).
//!
//! Units: mm, µN; coordinates (u, v) in the [`crate::GravityFrame`].

use crate::projection::signed_area2;
use crate::sections::RunResult;
use glam::DVec2;

/// One bottom triangle's weight on its three corners, µN.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Weighted {
    /// The corners' vertex indices.
    pub corners: [u32; 3],
    /// Their weights, µN.
    pub weights: [f64; 3],
}

/// A run's barycentric coordinates, found by the row scan while its
/// triangle's corners are at hand (so the weight pass reads no triangle):
/// the triangle's corners and the first two coordinates at the centre of
/// column `first` and their step from one column to the next.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RunBarycentric {
    /// The triangle's vertex indices.
    pub corners: [u32; 3],
    /// `b₀, b₁` at the centre of the run's first column.
    pub at_first: [f64; 2],
    /// `w·∂b₀/∂u, w·∂b₁/∂u`: their change per column.
    pub per_column: [f64; 2],
}

/// A projected triangle's barycentric coordinates as affine functions of
/// the point (u, v) (mm).
#[derive(Clone, Copy, Debug)]
pub struct BarycentricPlane {
    corners: [u32; 3],
    q: [DVec2; 3],
    inv_area2: f64,
    per_column: [f64; 2],
}

impl BarycentricPlane {
    /// The triangle with vertices `corners` at `q` ((u, v), mm; non-zero
    /// area) on columns `cell_u` wide (mm).
    #[inline(always)]
    pub fn new(corners: [u32; 3], q: [DVec2; 3], cell_u: f64) -> Self {
        let inv_area2 = 1.0 / signed_area2(q[0], q[1], q[2]);
        Self {
            corners,
            q,
            inv_area2,
            // ∂b₀/∂u = (q₁.v − q₂.v)/2A, ∂b₁/∂u = (q₂.v − q₀.v)/2A
            per_column: [
                (q[1].y - q[2].y) * inv_area2 * cell_u,
                (q[2].y - q[0].y) * inv_area2 * cell_u,
            ],
        }
    }

    /// `1 / (twice the signed area)`, 1/mm².
    #[inline(always)]
    pub fn inv_area2(&self) -> f64 {
        self.inv_area2
    }

    /// The coordinates of a run starting at the column centre `c` (mm).
    #[inline(always)]
    pub fn run(&self, c: DVec2) -> RunBarycentric {
        let q = self.q;
        RunBarycentric {
            corners: self.corners,
            at_first: [
                signed_area2(c, q[1], q[2]) * self.inv_area2,
                signed_area2(q[0], c, q[2]) * self.inv_area2,
            ],
            per_column: self.per_column,
        }
    }
}

/// The weight a bottom run's fluid puts on its triangle's corners:
/// `result = [H, M]` from the section pass ([`RunResult`]: `H = Σ h`,
/// `M = Σ h·m` over its columns `first + m`, mm and mm·columns), `scale =
/// ρ·|g|·A` in µN per mm of fluid height.
#[inline]
pub fn run_weights(b: &RunBarycentric, result: RunResult, scale: f64) -> Weighted {
    let [height, moment] = result;
    let w0 = scale * (height * b.at_first[0] + b.per_column[0] * moment);
    let w1 = scale * (height * b.at_first[1] + b.per_column[1] * moment);
    Weighted {
        corners: b.corners,
        weights: [w0, w1, scale * height - w0 - w1],
    }
}

/// Adds every `Weighted` to its corners' weights (µN).
pub fn add_weights<'w>(node_weights: &mut [f64], weighted: impl IntoIterator<Item = &'w Weighted>) {
    for w in weighted {
        for (&corner, weight) in w.corners.iter().zip(w.weights) {
            node_weights[corner as usize] += weight;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_runs_barycentric_coordinates_match_the_pointwise_ones() {
        let q = [
            DVec2::new(0.3, -0.2),
            DVec2::new(4.0, 1.0),
            DVec2::new(1.0, 3.5),
        ];
        let (plane, w) = (BarycentricPlane::new([7, 8, 9], q, 0.25), 0.25);
        let c0 = DVec2::new(-2.0, 1.1);
        let run = plane.run(c0);
        let area2 = signed_area2(q[0], q[1], q[2]);
        for m in [0.0, 1.0, 7.0, 40.0] {
            let p = c0 + DVec2::new(m * w, 0.0);
            let b0 = signed_area2(p, q[1], q[2]) / area2;
            let b1 = signed_area2(q[0], p, q[2]) / area2;
            assert!(
                (run.at_first[0] + m * run.per_column[0] - b0).abs() < 1e-12,
                "{m}"
            );
            assert!(
                (run.at_first[1] + m * run.per_column[1] - b1).abs() < 1e-12,
                "{m}"
            );
        }
        // a run's weights sum to its fluid's
        let w = run_weights(&run, [2.0, 3.0], 1.5);
        assert_eq!(w.corners, [7, 8, 9]);
        assert!((w.weights.iter().sum::<f64>() - 3.0).abs() < 1e-12);
    }
}
