//! # voxflex-opacity
//!
//! Its own crate because only the host (ROI maps) and the raycast renderer
//! (the Gaussian transfer function) use it; the maps reach a renderer as
//! voxflex-core's [`OpacityMap`]. Test support (the CPU/GPU `parity`
//! checks and their phantoms) is behind the `test-support` feature.
//!
//! Spatial opacity maps: region growing of an **opacity field** from a seed,
//! after "Spatial opacity maps for direct volume rendering of regions of
//! interest" (CEIG 2016), made sparse, on the CPU (rayon) or the GPU (WGSL
//! through [`voxflex_core::gpu::GpuService`]).
//!
//! # The method
//!
//! The seed voxel starts at `o_max`, every other voxel at `o_min`
//! ([`GrowthParams`]). Each step every voxel takes
//!
//! ```text
//! o_v ← clamp(max(o_v, max_n o_n − E_v), o_min, o_max),   E_v = (|d_s − d_v| − σ_s) / (λ σ_s)
//! ```
//!
//! over its neighbours `n` (the 6 face neighbours by default, all 26 — the
//! paper's — with [`GrowthParams::connectivity`] = 26), where `d_v` is the voxel's value and `d_s`,
//! σ_s the mean and standard deviation of the seed's neighbourhood (the
//! cube of half-width [`GrowthParams::seed_radius`] voxels around it,
//! [`seed::seed_stats`]; the paper's 1-ring is radius 1, the default is 2 —
//! see the field's docs for why). Voxels within σ_s of `d_s` have
//! `E_v < 0` and take the full opacity of their neighbour; the further a
//! value lies from the seed's, the faster opacity dies out along a path. The
//! growth converges when no voxel changes. σ_s has a floor
//! ([`GrowthParams::sigma_floor`], `1e-3` of the volume's value range) so a
//! seed in a homogeneous region (σ_s = 0) still has a finite extinction.
//!
//! A step is **Jacobi**: every value it reads is the previous step's, so the
//! state after `n` steps is defined independently of threads and backends
//! (with the pump shortcut described below).
//! Opacities live as u16 fixed point ([`crate::opacity_map`]); the
//! extinction is computed in f32 by the same five operations on both paths
//! and rounded to fixed point, and the update is integer arithmetic (see
//! [`extinction`]), so the CPU and GPU maps are **bit-identical** after
//! every step. The converged map is the least fixed point of a monotone
//! update, hence also independent of the visiting order.
//!
//! # Sparse expansion
//!
//! The thesis's kernel swept the whole volume each step, with 0.7–12 % of
//! the threads doing useful work. Here a step works from the **frontier**,
//! the voxels that changed in the previous step (with their new values):
//! each of their neighbours that is not yet at its ceiling is lifted,
//! `q_v ← max(q_v, rise(q_u, e_v))`, and a voxel is listed once, when it
//! first rises in the step. A voxel that no changed neighbour lifts cannot
//! change, so this is the dense sweep's result, step for step (tested
//! against a dense reference), and every voxel the step updates changes:
//! the **useful fraction is 1 by construction**. Each run reports steps,
//! visits, useful visits and their fraction ([`GrowthReport`]); the work
//! left is the neighbour scan, at most 26 per change — proportional to the
//! changes, not to the volume (see the crate's `opacity` benchmark for
//! figures). CPU details (state bits, the lock-free parallel schedule):
//! [`cpu`] and the private `frontier` module; GPU: [`gpu`].
//!
//! # Storage
//!
//! The result is an [`OpacityMap`] over the box of the voxels that ever
//! rose above `o_min` (plus the seed), 2 bytes per voxel of that box,
//! `outside = o_min`. While growing, the field lives over a **working box**
//! that grows with the region (a margin of `max(8, extent/2)` voxels, grown
//! geometrically, [`bounds::grown_working_box`]): CPU state is the u16 field
//! (2 bytes per working-box voxel) + 2 state bits per working-box voxel +
//! the frontier (8 bytes per frontier voxel: index and value) and, during a
//! step, the raised list (12 bytes per raised voxel) — 2.25 bytes per
//! working-box voxel plus the lists. GPU state: see [`gpu`].

//! # Seeds and units
//!
//! A [`Seed`] is a voxel index, a world point in millimetres, or a click on
//! a slice image in the orientation of `voxflex_io::png` (see [`seed`] for
//! the exact pixel ↔ voxel table). Voxel values are in the volume's units;
//! opacities are dimensionless in [0, 1]; λ is dimensionless.
//!
//! # Behaviour at close intensities
//!
//! The method grows through every path whose accumulated extinction stays
//! below `o_max − o_min`. Tested on a phantom (seed sphere 100, noise σ 3,
//! λ = 30): a touching sphere at 300 (or the background at 0) is never
//! entered at all — each of its voxels extinguishes more than
//! `o_max − o_min` (contrast above `(λ + 1) σ_s`). A touching sphere at 115
//! (5 σ_s) is entered through the contact and fades within a few voxels
//! (≈ 7 % of it above 0.5, the far side never reached). A touching sphere at
//! 110 (3.4 σ_s) is **absorbed entirely**: about 1 % of its voxels lie
//! within σ_s of `d_s` (negative `E_v`), adjacent pairs of them regenerate
//! each other up to `o_max`, and opacity spreads from them — lower λ (or a
//! seed on a less noisy spot) is needed to separate such structures.
//!
//! Opacity propagates from **reached** voxels only (those above `o_min`):
//! applied literally to unreached voxels, the rule would lift every voxel
//! of the seed's intensity anywhere in the volume (`o_min − E_v > o_min`),
//! connected to the seed or not.
//!
//! **Pumping pairs.** Two neighbours whose extinctions sum below zero lift
//! each other a little every step until `o_max`; the plain iteration needs
//! up to tens of thousands of steps for that. A lifted voxel that forms
//! such a pair therefore jumps straight to `o_max`, the value it would
//! converge to ([`Extinction::pumps`]); the converged map is unchanged (a
//! test compares it with a dense sweep of the plain rule) and a noisy
//! phantom converges in ~50 steps instead of ~1350. Step-by-step states
//! equal the plain Jacobi iteration until the first pump.

//! # Bounds and the automatic λ
//!
//! On contrast CT the paper's λ = 30 lets a seed in the liver flow through
//! vessels and touching organs of similar enhancement. [`GrowthLimits`]
//! (an intensity window, a Euclidean distance from the seed) block voxels
//! outright ([`limits`]); `lambda = "auto"` picks the largest λ before the
//! region jumps and writes the map at it from the same search
//! ([`auto_lambda`]); [`grow_roi`] runs either on either backend and says
//! what stopped the growth ([`roi`]).

//! # Transfer function
//!
//! [`GaussianTf`] / [`gaussian_tf()`] is the paper's automatic transfer
//! function `f(x) = t(x) · (a + b · g(x))`, `g` a Gaussian at `d_s` with
//! standard deviation σ_s, `a = 0.01`, `b = 0.99`.

#![warn(missing_docs)]

pub mod auto_lambda;
pub mod bounds;
pub mod cpu;
mod error;
pub mod extinction;
mod frontier;
pub mod gaussian_tf;
pub mod gpu;
pub mod limits;
pub mod params;
#[cfg(any(test, feature = "test-support"))]
pub mod parity;
pub mod path_cost;
pub mod report;
pub mod roi;
pub mod runner;
pub mod seed;
pub mod set;
pub mod state;

#[cfg(test)]
mod path_cost_tests;
#[cfg(test)]
mod roi_tests;
#[cfg(test)]
mod scan_map_tests;
#[cfg(test)]
mod tests;

pub use auto_lambda::{AutoLambda, AutoSearch};
pub use bounds::VoxelBounds;
pub use cpu::CpuGrowth;
pub use error::OpacityError;
pub use extinction::Extinction;
pub use gaussian_tf::{GaussianTf, gaussian_tf};
pub use gpu::{GpuGrowth, GpuOpacityVolume};
pub use limits::{GrowthLimits, LimitHits};
pub use params::{GrowthParams, MAX_SEED_RADIUS};
pub use path_cost::ScanInput;
pub use report::GrowthReport;
pub use roi::{LambdaChoice, RoiOutcome, RoiRequest, grow_roi};
pub use runner::{CpuRunner, GpuRunner, GrowRunner, Grown};
pub use seed::{Seed, SeedStats, seed_stats};
pub use set::{OpacityMapSet, combine_max};
pub use state::{Growth, GrowthState};

pub use crate::opacity_map::OpacityMap;

// The voxflex-core modules this crate builds on, imported at the root so
// `crate::grid`, `crate::volume`, ... read as they did when opacity maps
// were a module of voxflex-core.
use voxflex_core::{grid, opacity_map, volume, with_voxels};

use crate::volume::VolumeView;

/// Checks that a volume is non-empty, holds one value per voxel and fits
/// 32-bit indices.
pub(crate) fn check_volume(volume: &VolumeView<'_>) -> Result<(), OpacityError> {
    let g = volume.grid;
    if g.dims.contains(&0) {
        return Err(OpacityError::EmptyVolume { dims: g.dims });
    }
    let voxels = g.dims.iter().map(|&d| d as u64).product::<u64>();
    if voxels > u32::MAX as u64 {
        return Err(OpacityError::VolumeTooLarge {
            dims: g.dims,
            voxels,
        });
    }
    if volume.data.len() != g.len() {
        return Err(OpacityError::DataLength {
            dims: g.dims,
            expected: g.len(),
            actual: volume.data.len(),
        });
    }
    Ok(())
}
