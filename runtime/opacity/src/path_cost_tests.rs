//! Tests of [`crate::path_cost::PathCostScan`] against the growth it stands
//! in for, on mirrored volumes, with bounds, and on bad input.

use super::OpacityError;
use super::limits::GrowthLimits;
use super::params::GrowthParams;
use super::parity::{three_spheres, three_spheres_with};
use super::path_cost::{PathCostScan, ScanInput};
use super::runner::{CpuRunner, GrowRunner, voxels_above_half};
use super::seed::Seed;
use crate::volume::{Volume, VoxelData};

pub(crate) fn input(values: &Volume, seed: [usize; 3]) -> ScanInput<'_> {
    ScanInput {
        volume: values.view(),
        values: values.view(),
        limits: GrowthLimits::default(),
        seed: Seed::Voxel(seed),
    }
}

/// Every phase's size, no bound.
fn sizes(input: ScanInput<'_>, params: GrowthParams) -> Vec<(f32, usize)> {
    let mut scan = PathCostScan::new(input, params).unwrap();
    std::iter::from_fn(|| scan.next_phase(None))
        .map(|(l, r)| {
            assert!(!r.cut);
            (l, r.voxels)
        })
        .collect()
}

/// The growth's region (opacity ≥ ½) at `lambda`.
fn grown(values: &Volume, seed: [usize; 3], params: GrowthParams, lambda: f32) -> usize {
    let mut r = CpuRunner {
        volume: values.view(),
        values: values.view(),
        seed: Seed::Voxel(seed),
    };
    let g = r.grow(GrowthParams { lambda, ..params }, None).unwrap();
    assert!(g.report.converged);
    voxels_above_half(&g.map)
}

/// After every phase, each voxel on which the scan (`D ≤ T(λ)`) and the
/// growth at that λ (fixed point ≥ 32768) disagree lies within the
/// growth's rounding of ½: its real-valued opacity is within half a
/// fixed-point unit per growth step of the threshold (the growth rounds
/// each step's extinction; a value is set by a path no longer than the
/// steps run). Returns the voxels that disagreed.
fn disagreements_within_rounding(v: &Volume, seed: [usize; 3], params: GrowthParams) -> usize {
    let dims = v.grid.dims;
    let mut scan = PathCostScan::new(input(v, seed), params).unwrap();
    let mut r = CpuRunner {
        volume: v.view(),
        values: v.view(),
        seed: Seed::Voxel(seed),
    };
    let mut differ = 0;
    while let Some((lambda, phase)) = scan.next_phase(None) {
        let g = r.grow(GrowthParams { lambda, ..params }, None).unwrap();
        let map = g.map.dense(dims);
        let per_unit = 65535.0 / (lambda as f64 * g.stats.sigma as f64);
        let slack = g.report.steps as f64 / 2.0 + 1.0;
        // `T(λ)` as the scan computes it (f64, rounded to f32).
        let half = (g.ext.q_max as f64 - 32768.0) / 65535.0 * g.stats.sigma as f64;
        let threshold = (half * lambda as f64) as f32;
        let mut count = 0;
        for (l, &q) in map.iter().enumerate() {
            let p = [
                l % dims[0],
                (l / dims[0]) % dims[1],
                l / (dims[0] * dims[1]),
            ];
            let o = g.ext.q_max as f64 - scan.cost_at(p) as f64 * per_unit;
            count += (scan.cost_at(p) <= threshold) as usize;
            if (q >= 32768) != (o >= 32768.0) {
                differ += 1;
                assert!(
                    (o - 32767.5).abs() <= slack,
                    "λ {lambda}, voxel {p:?}: growth {q}, real-valued {o:.2} (slack {slack})"
                );
            }
        }
        assert_eq!(count, phase.voxels, "λ {lambda}: the scan's count");
    }
    differ
}

/// The scan's `V(λ)` is the growth's at every candidate, on a noisy
/// phantom whose region runs from one sphere into a touching one 2.7 σ
/// brighter at λ = 16 (both neighbourhoods). The two differ only where rounding puts a
/// voxel on the other side of ½: allowed 1 in 10,000 here.
#[test]
fn scan_sizes_equal_the_growths_at_every_lambda() {
    for connectivity in [6, 26] {
        let p = three_spheres_with(48, 108.0, 3.0, 5);
        let seed = p.a.centre_voxel();
        let params = GrowthParams {
            connectivity,
            ..GrowthParams::default()
        };
        let all = sizes(input(&p.volume, seed), params);
        assert_eq!(all.len(), crate::auto_lambda::CANDIDATES.len());
        assert!(all.windows(2).all(|w| w[0].1 <= w[1].1), "{all:?}");
        for &(lambda, voxels) in &all {
            let want = grown(&p.volume, seed, params, lambda);
            eprintln!("connectivity {connectivity}, λ {lambda}: scan {voxels}, growth {want}");
            assert!(
                voxels.abs_diff(want) as f64 <= 1e-4 * want as f64 + 1.0,
                "connectivity {connectivity}, λ {lambda}: scan {voxels}, growth {want}"
            );
        }
        assert!(all[0].1 > 1000 && all.last().unwrap().1 > 3 * all[0].1 / 2);
        let differ = disagreements_within_rounding(&p.volume, seed, params);
        eprintln!(
            "connectivity {connectivity}: {differ} voxel-λ pairs differ, all within rounding"
        );
    }
}

/// With the ceiling `o_max` at or below ½ the scan's thresholds are not
/// ascending but all ≤ 0 (`T(λ) ∝ o_max − ½`): below ½ no voxel reaches
/// ½ in either search, at ½ exactly the voxels of cost 0 do — the scan's
/// count is the growth's, voxel by voxel, at every λ.
#[test]
fn a_ceiling_at_or_below_one_half_counts_as_the_growth_does() {
    let p = three_spheres_with(24, 108.0, 3.0, 5);
    let seed = p.a.centre_voxel();
    for o_max in [0.3, 0.5] {
        let params = GrowthParams {
            o_max,
            ..GrowthParams::default()
        };
        let all = sizes(input(&p.volume, seed), params);
        if o_max < 0.5 {
            assert!(all.iter().all(|&(_, v)| v == 0), "o_max {o_max}: {all:?}");
        } else {
            assert!(all.iter().all(|&(_, v)| v > 0), "o_max {o_max}: {all:?}");
        }
        disagreements_within_rounding(&p.volume, seed, params);
    }
}

/// The volume mirrored along `axis`.
pub(crate) fn mirrored(v: &Volume, axis: usize) -> Volume {
    let d = v.grid.dims;
    let src = v.view().data.to_f32_vec();
    let mut out = vec![0f32; src.len()];
    for z in 0..d[2] {
        for y in 0..d[1] {
            for x in 0..d[0] {
                let mut m = [x, y, z];
                m[axis] = d[axis] - 1 - m[axis];
                out[m[0] + d[0] * (m[1] + d[1] * m[2])] = src[x + d[0] * (y + d[1] * z)];
            }
        }
    }
    Volume {
        grid: v.grid,
        data: VoxelData::F32(out),
    }
}

/// The scan visits voxels in an order set by its queues, but the costs it
/// converges to are the minimum over paths: mirrored volumes give the same
/// sizes, exactly, along every axis.
#[test]
fn mirrored_volumes_give_the_same_sizes() {
    let p = three_spheres(40, 3.0, 9);
    let seed = p.a.centre_voxel();
    let params = GrowthParams::default();
    let want = sizes(input(&p.volume, seed), params);
    for axis in 0..3 {
        let m = mirrored(&p.volume, axis);
        let mut s = seed;
        s[axis] = p.volume.grid.dims[axis] - 1 - s[axis];
        assert_eq!(sizes(input(&m, s), params), want, "mirrored along {axis}");
    }
}

/// Bounds applied by the scan on the fly (the GPU path's case: the bounded
/// copy lives on the device) give the sizes the bounded copy gives, and
/// those are the bounded growth's.
#[test]
fn bounds_applied_on_the_fly_equal_the_bounded_copy() {
    let p = three_spheres(40, 3.0, 3);
    let seed = p.a.centre_voxel();
    let params = GrowthParams::default();
    let limits = GrowthLimits {
        intensity: Some([92.0, 108.0]),
        max_distance_mm: Some(5.0),
    };
    let bounded = limits.apply(p.volume.view(), seed).unwrap().unwrap();
    let on_the_fly = sizes(
        ScanInput {
            limits,
            ..input(&p.volume, seed)
        },
        params,
    );
    let copy = sizes(
        ScanInput {
            volume: p.volume.view(),
            ..input(&bounded, seed)
        },
        params,
    );
    assert_eq!(on_the_fly, copy);
    let free = sizes(input(&p.volume, seed), params);
    assert!(copy.last().unwrap().1 < free.last().unwrap().1 * 4 / 5);
    let mut r = CpuRunner {
        volume: p.volume.view(),
        values: bounded.view(),
        seed: Seed::Voxel(seed),
    };
    for &(lambda, voxels) in copy.iter().step_by(3) {
        let g = r.grow(GrowthParams { lambda, ..params }, None).unwrap();
        let want = voxels_above_half(&g.map);
        assert!(voxels.abs_diff(want) <= 1 + want / 10_000, "λ {lambda}");
    }
}

/// A phase stops once its size passes the bound, says so, and reports at
/// least the bound; unbounded, the same phase runs on.
#[test]
fn a_phase_past_its_bound_is_cut_short() {
    let p = three_spheres(64, 3.0, 7);
    let seed = p.a.centre_voxel();
    let params = GrowthParams::default();
    let mut free = PathCostScan::new(input(&p.volume, seed), params).unwrap();
    let (_, whole) = free.next_phase(None).unwrap();
    let mut cut = PathCostScan::new(input(&p.volume, seed), params).unwrap();
    let (lambda, part) = cut.next_phase(Some(1000)).unwrap();
    assert_eq!(lambda, 1.0);
    assert!(!whole.cut && part.cut, "{whole:?} {part:?}");
    assert!(part.voxels > 1000 && part.voxels <= whole.voxels);
    assert!(part.visits < whole.visits);
}

#[test]
fn bad_input_is_refused_with_the_value() {
    let p = three_spheres(24, 3.0, 1);
    let seed = p.a.centre_voxel();
    let other = three_spheres(20, 3.0, 1);
    let params = GrowthParams::default();
    let e = PathCostScan::new(
        ScanInput {
            values: other.volume.view(),
            ..input(&p.volume, seed)
        },
        params,
    )
    .err()
    .unwrap();
    assert!(matches!(e, OpacityError::VolumeMismatch { .. }), "{e}");
    let e = PathCostScan::new(
        ScanInput {
            limits: GrowthLimits {
                intensity: Some([f32::NAN, 1.0]),
                max_distance_mm: None,
            },
            ..input(&p.volume, seed)
        },
        params,
    )
    .err()
    .unwrap();
    assert!(e.to_string().contains("intensity"), "{e}");
    let e = PathCostScan::new(input(&p.volume, [99, 0, 0]), params)
        .err()
        .unwrap();
    assert!(e.to_string().contains("99"), "{e}");
    let e = PathCostScan::new(
        input(&p.volume, seed),
        GrowthParams {
            connectivity: 5,
            ..params
        },
    )
    .err()
    .unwrap();
    assert!(matches!(e, OpacityError::BadConnectivity { .. }), "{e}");
}

pub(crate) mod random {
    use super::*;
    use proptest::prelude::*;

    /// A small volume of piecewise-constant blobs with noise, i16 (CT's
    /// type) or f32: value `base + step·(x > cut) + noise`.
    fn volume(dims: [usize; 3], cut: usize, step: f32, noise: Vec<f32>, i16: bool) -> Volume {
        let grid = crate::grid::Grid::new(dims, glam::DVec3::new(0.9, 1.0, 1.3), glam::DVec3::ZERO);
        let values: Vec<f32> = (0..grid.len())
            .map(|l| {
                let x = l % dims[0];
                100.0 + if x > cut { step } else { 0.0 } + noise[l % noise.len()]
            })
            .collect();
        let data = if i16 {
            VoxelData::I16(values.iter().map(|&v| v.round() as i16).collect())
        } else {
            VoxelData::F32(values)
        };
        Volume { grid, data }
    }

    prop_compose! {
        /// A random case: a [`volume`] of 6 to `side − 1` voxels along each
        /// axis, a seed near its corner, and growth parameters with a
        /// random opacity range and neighbourhood (σ from the 1-ring).
        pub(crate) fn case(side: usize)(
            dims in prop::array::uniform3(6usize..side),
            cut in 2usize..side - 2,
            step in 5.0f32..60.0,
            noise in prop::collection::vec(-12.0f32..12.0, 97..211),
            seed in prop::array::uniform3(0usize..6),
            o_min in 0.0f32..0.3,
            o_max in 0.6f32..1.0,
            faces in any::<bool>(),
            i16 in any::<bool>(),
        ) -> (Volume, [usize; 3], GrowthParams) {
            let params = GrowthParams {
                o_min,
                o_max,
                connectivity: if faces { 6 } else { 26 },
                seed_radius: 1,
                ..GrowthParams::default()
            };
            (volume(dims, cut, step, noise, i16), seed, params)
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        /// On random volumes, seeds, opacity ranges and neighbourhoods the
        /// scan's region at every candidate λ is the growth's but for
        /// voxels within the growth's rounding of ½.
        #[test]
        fn scan_sizes_equal_the_growths((v, seed, params) in case(20)) {
            disagreements_within_rounding(&v, seed, params);
        }
    }
}
