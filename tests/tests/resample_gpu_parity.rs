//! The resampler's WGSL path against its rayon twin on a real device
//! (lavapipe in CI): identity bit for bit, deformed fields within 1e-5 of the
//! data range, folds (moved tissue over still and inverted cells) bit for
//! bit, output split into z-slabs under a tiny storage-binding limit, the
//! source split into z-slabs (equal to the unsplit GPU bit for bit),
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
fn source_slabs_match_unsplit_and_cpu() {
    run(parity::check_source_slabs);
}

#[test]
fn removed_tetrahedra_match_cpu() {
    run(parity::check_mask_matches_cpu);
}

#[test]
fn dirty_region_matches_full() {
    run(parity::check_dirty_matches_full);
}

/// Issue 17's goal: a 512³ source (512 MiB as f32) on 128 MiB bindings.
/// Minutes and ~8 GiB on lavapipe, hence ignored; run with `--ignored`.
#[test]
#[ignore]
fn source_of_512_cubed_resamples_on_128_mib_bindings() {
    run(|gpu| {
        let times = parity::check_512_cubed_source(gpu)?;
        eprintln!("512³ GPU resample (incl. upload and read-back): {times:?} s");
        Ok(())
    });
}
