//! Tests of the map written from a path-cost scan
//! ([`crate::path_cost::PathCostScan::into_map`], [`crate::auto_lambda::auto_map`]):
//! the undo log against scans stopped at each phase, the values against
//! the growth within its rounding, mirrored volumes, and bad λ.

use super::OpacityError;
use super::auto_lambda::{CANDIDATES, auto_map, map_at};
use super::parity::three_spheres_with;
use super::path_cost::{PathCostScan, ScanInput};
use super::path_cost_tests::{input, mirrored, random};
use super::runner::{CpuRunner, GrowRunner, Grown, voxels_above_half};
use super::{GrowthParams, OpacityMap, Seed, VoxelBounds};
use crate::volume::Volume;

/// A scan run through every phase (none cut short).
fn full_scan(input: ScanInput<'_>, params: GrowthParams) -> (PathCostScan<'_>, Vec<usize>) {
    let mut scan = PathCostScan::new(input, params).unwrap();
    let sizes = std::iter::from_fn(|| scan.next_phase(None))
        .map(|(_, r)| r.voxels)
        .collect();
    (scan, sizes)
}

/// The box of `map`'s voxels above `o_min`.
fn lifted_box(map: &OpacityMap) -> Option<VoxelBounds> {
    (0..map.values.len())
        .filter(|&l| map.values[l] > map.outside)
        .map(|l| VoxelBounds::point(map.voxel(l)))
        .reduce(|a, b| a.union(&b))
}

/// The map written at every λ, from a scan run through all of them and
/// rewound, is the map of a scan stopped at that λ's phase, exactly; its
/// region is the phase's count, its box its voxels above `o_min`, and its
/// values lie within the growth's rounding of the growth's map.
fn check_every_phase(v: &Volume, seed: [usize; 3], params: GrowthParams) {
    let sizes = full_scan(input(v, seed), params).1;
    let mut r = CpuRunner {
        volume: v.view(),
        values: v.view(),
        seed: Seed::Voxel(seed),
    };
    for (k, &lambda) in CANDIDATES.iter().enumerate() {
        let rewound = full_scan(input(v, seed), params)
            .0
            .into_map(lambda)
            .unwrap();
        let stopped = map_at(input(v, seed), params, lambda).unwrap();
        assert_eq!(rewound.map, stopped.map, "λ {lambda}: rewound vs stopped");
        assert_eq!(rewound.ext, stopped.ext);
        assert!(rewound.report.converged && rewound.report.steps == 0);
        assert_eq!(voxels_above_half(&rewound.map), sizes[k], "λ {lambda}");
        assert_eq!(
            lifted_box(&rewound.map),
            Some(VoxelBounds {
                lo: rewound.map.origin,
                hi: [0, 1, 2].map(|a| rewound.map.origin[a] + rewound.map.dims[a] - 1),
            }),
            "λ {lambda}: the box is the lifted voxels'"
        );
        let grown = r.grow(GrowthParams { lambda, ..params }, None).unwrap();
        within_rounding(&rewound, &grown, v.grid.dims, lambda);
    }
}

/// Each voxel of `written` lies within the growth's rounding of `grown`'s:
/// half a fixed-point unit per growth step (a path is no longer than the
/// steps run), plus the one rounding of the written map.
pub(crate) fn within_rounding(written: &Grown, grown: &Grown, dims: [usize; 3], lambda: f32) {
    assert_eq!(written.ext, grown.ext, "λ {lambda}");
    let slack = grown.report.steps / 2 + 1;
    let (a, b) = (written.map.dense(dims), grown.map.dense(dims));
    for (l, (&w, &g)) in a.iter().zip(&b).enumerate() {
        assert!(
            u64::from(w.abs_diff(g)) <= slack,
            "λ {lambda}, voxel {l}: written {w}, grown {g} (slack {slack})"
        );
    }
}

/// On a noisy phantom whose region runs from one sphere into a touching
/// one at λ = 16, both neighbourhoods.
#[test]
fn the_map_at_every_lambda_is_a_scan_stopped_there_and_the_growths_within_rounding() {
    let p = three_spheres_with(40, 108.0, 3.0, 5);
    for connectivity in [6, 26] {
        let params = GrowthParams {
            connectivity,
            ..GrowthParams::default()
        };
        check_every_phase(&p.volume, p.a.centre_voxel(), params);
    }
}

/// With the ceiling at or below ½ no voxel (below) or only the cost-0
/// voxels (at ½) reach ½: the written maps still hold every check.
#[test]
fn a_ceiling_at_or_below_one_half_writes_maps_that_hold() {
    let p = three_spheres_with(24, 108.0, 3.0, 5);
    for o_max in [0.3, 0.5] {
        let params = GrowthParams {
            o_max,
            ..GrowthParams::default()
        };
        check_every_phase(&p.volume, p.a.centre_voxel(), params);
    }
}

/// The written map of a mirrored volume is the mirror of the map, exactly.
#[test]
fn mirrored_volumes_give_mirrored_maps() {
    let p = three_spheres_with(32, 108.0, 3.0, 11);
    let seed = p.a.centre_voxel();
    let dims = p.volume.grid.dims;
    let params = GrowthParams::default();
    let want = auto_map(input(&p.volume, seed), params).unwrap();
    let want_map = want.grown.map.dense(dims);
    for axis in 0..3 {
        let m = mirrored(&p.volume, axis);
        let mut s = seed;
        s[axis] = dims[axis] - 1 - s[axis];
        let got = auto_map(input(&m, s), params).unwrap();
        assert_eq!(
            got.search.lambda, want.search.lambda,
            "mirrored along {axis}"
        );
        let got_map = got.grown.map.dense(dims);
        for (l, &q) in want_map.iter().enumerate() {
            let mut p = [
                l % dims[0],
                (l / dims[0]) % dims[1],
                l / (dims[0] * dims[1]),
            ];
            p[axis] = dims[axis] - 1 - p[axis];
            assert_eq!(got_map[p[0] + dims[0] * (p[1] + dims[1] * p[2])], q);
        }
    }
}

#[test]
fn a_lambda_not_scanned_to_its_end_is_refused_by_value() {
    let p = three_spheres_with(24, 108.0, 3.0, 3);
    let seed = p.a.centre_voxel();
    let params = GrowthParams::default();
    let (scan, _) = full_scan(input(&p.volume, seed), params);
    let e = scan.into_map(3.0).err().unwrap();
    assert!(matches!(e, OpacityError::LambdaNotScanned { .. }), "{e}");
    assert!(e.to_string().contains("lambda = 3 "), "{e}");
    let e = map_at(input(&p.volume, seed), params, 3.0).err().unwrap();
    assert!(e.to_string().contains("\"auto\""), "{e}");
    // A phase cut short holds no converged map.
    let mut scan = PathCostScan::new(input(&p.volume, seed), params).unwrap();
    let (lambda, r) = scan.next_phase(Some(10)).unwrap();
    assert!(r.cut);
    let e = scan.into_map(lambda).err().unwrap();
    assert!(matches!(e, OpacityError::LambdaNotScanned { .. }), "{e}");
}

mod random_volumes {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]
        /// On random volumes, seeds, opacity ranges and neighbourhoods:
        /// every phase's map as above, and the automatic λ's map is its
        /// chosen trial's region.
        #[test]
        fn written_maps_hold_on_random_volumes((v, seed, params) in random::case(18)) {
            check_every_phase(&v, seed, params);
            let a = auto_map(input(&v, seed), params).unwrap();
            let chosen = a.search.trials.iter().find(|t| t.lambda == a.search.lambda).unwrap();
            prop_assert_eq!(voxels_above_half(&a.grown.map), chosen.voxels);
        }
    }
}
