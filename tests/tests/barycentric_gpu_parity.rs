//! The barycentric map's WGSL path against its rayon twin on a real device
//! (lavapipe in CI), whole and in slabs. The checks live in
//! `voxflex_mesh::barycentric::parity`; on a machine without an adapter
//! these tests print SKIPPED, except under `CI=true`.

use voxflex_integration_tests::run_parity as run;
use voxflex_mesh::barycentric::parity;

#[test]
fn map_matches_cpu() {
    run(parity::check_map_matches_cpu);
}

#[test]
fn map_slabs_match_cpu() {
    run(parity::check_map_slabs);
}
