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
//! bottom run ([`RunBarycentric`], from the fill rule's edge functions:
//! [`crate::hits`]), so the section pass, which weighs each band's runs,
//! reads no triangle (a random read per run, which on a large mesh misses
//! the caches).
//!
//! Units: mm, µN.

use crate::sections::RunResult;

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
    fn a_runs_weights_sum_to_its_fluids_and_follow_the_coordinates() {
        // columns first + 0 and + 2 hold 2 mm and 1 mm: H = 3, M = 2
        let b = RunBarycentric {
            corners: [7, 8, 9],
            at_first: [0.5, 0.25],
            per_column: [-0.1, 0.05],
        };
        let w = run_weights(&b, [3.0, 2.0], 1.5);
        assert_eq!(w.corners, [7, 8, 9]);
        assert!((w.weights.iter().sum::<f64>() - 4.5).abs() < 1e-12);
        // corner 0: 1.5 · (2 · 0.5 + 1 · (0.5 − 0.2)) = 1.95
        assert!((w.weights[0] - 1.95).abs() < 1e-12, "{:?}", w.weights);
        // corner 1: 1.5 · (2 · 0.25 + 1 · (0.25 + 0.1)) = 1.275
        assert!((w.weights[1] - 1.275).abs() < 1e-12, "{:?}", w.weights);
    }
}
