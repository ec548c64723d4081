//! The barycentric map's WGSL path against its rayon twin on a real device
//! (lavapipe in CI), whole and in slabs. The checks live in
//! `voxflex_core::barycentric::parity`; on a machine without an adapter
//! these tests print SKIPPED, except under `CI=true`.

use voxflex_core::barycentric::parity;
use voxflex_integration_tests::run_parity as run;

#[test]
fn map_matches_cpu() {
    run(parity::check_map_matches_cpu);
}

#[test]
fn map_slabs_match_cpu() {
    run(parity::check_map_slabs);
}
