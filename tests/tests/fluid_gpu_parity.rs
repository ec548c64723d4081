//! The fluid-weight WGSL path against its rayon twin on a real device
//! (lavapipe in CI): volumes, vertex weights and section counts on the
//! icosphere (two grids, with and without parallel leveraging, a slanted
//! gravity) and the non-convex bunny (the GPU's crossing slots must grow).
//! The checks live in `voxflex_fluid::parity`; on a machine without an
//! adapter these tests print SKIPPED, except under `CI=true`.

use voxflex_fluid::parity;
use voxflex_integration_tests::run_parity as run;

#[test]
fn the_icosphere_weighs_the_same_on_both_paths() {
    run(parity::check_sphere_matches_cpu);
}

#[test]
fn the_bunny_weighs_the_same_on_both_paths() {
    run(parity::check_bunny_matches_cpu);
}
