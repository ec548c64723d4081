//! The opacity growth's WGSL path against its rayon twin on a real device
//! (lavapipe in CI): identical maps and identical step / visit / useful
//! counts after every step and at convergence, several growths sharing one
//! uploaded volume, bounded and automatic-λ maps, and clean refusals. The checks live in
//! `voxflex_opacity::parity`; on a machine without an adapter these
//! tests print SKIPPED, except under `CI=true`.

use voxflex_integration_tests::run_parity as run;
use voxflex_opacity::parity;

#[test]
fn converged_maps_are_identical() {
    run(parity::check_converged_matches_cpu);
}

#[test]
fn every_step_is_identical() {
    run(parity::check_stepwise_matches_cpu);
}

/// The same with a device limit of 16 workgroups per dimension: the
/// kernels over the candidates are dispatched indirectly with counts the
/// device folds itself, and larger frontiers fold into 2-D and 3-D.
#[test]
fn every_step_is_identical_when_dispatches_fold() {
    run(|gpu| {
        let limited = voxflex_core::gpu::LimitedDevice::workgroups(gpu, 16);
        parity::check_stepwise_matches_cpu(&limited)
    });
}

#[test]
fn several_maps_share_one_volume() {
    run(parity::check_several_maps);
}

#[test]
fn oversized_and_mismatched_volumes_are_refused() {
    run(parity::check_refusals);
}

/// A volume above one storage binding: the growth binds only its working
/// box's planes of the values.
#[test]
fn a_volume_above_one_binding_grows_in_its_window() {
    run(parity::check_values_window_matches_cpu);
}

#[test]
fn bounded_and_auto_lambda_maps_are_identical() {
    run(parity::check_limits_match_cpu);
}
