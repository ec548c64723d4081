//! The resampler's WGSL path against its rayon twin on a real device
//! (lavapipe in CI): identity bit for bit, deformed fields within 1e-5 of the
//! data range, folds (moved tissue over still and inverted cells) bit for
//! bit, output split into z-slabs under a tiny storage-binding limit,
//! removed tetrahedra, and dirty-region resampling equal to a full resample.
//! The checks live in `voxflex_resample::parity`; on a machine without
//! an adapter these tests print SKIPPED, except under `CI=true`.

use voxflex_integration_tests::run_parity as run;
use voxflex_resample::parity;

#[test]
fn identity_is_bitwise() {
    run(parity::check_identity_bitwise);
}

#[test]
fn deformed_matches_cpu() {
    run(parity::check_deformed_matches_cpu);
}

#[test]
fn folds_match_cpu_bit_for_bit() {
    run(parity::check_folds_match_cpu);
}

#[test]
fn output_slabs_match_cpu() {
    run(parity::check_output_slabs);
}

#[test]
fn removed_tetrahedra_match_cpu() {
    run(parity::check_mask_matches_cpu);
}

#[test]
fn dirty_region_matches_full() {
    run(parity::check_dirty_matches_full);
}
