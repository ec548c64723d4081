#!/usr/bin/env bash
# The project's one test command (README): formatting, lints, build, tests.
#
# Order, chosen so nothing is compiled twice more than it must be:
#   1. fmt --check        no compilation; fails fastest.
#   2. clippy             `cargo check` of the dependencies (metadata only) plus
#                         clippy on every workspace target; lint errors fail
#                         before any code generation.
#   3. build              code generation of every dependency and workspace
#                         crate, the plugin cdylibs included (the integration
#                         tests load target/debug/libvoxflex_*.so).
#   4. test --no-run      the test harnesses only; dependencies are reused
#                         from step 3 (same target dir, same dev profile).
#   5. test               runs them (unit, integration, doc tests).
#   6. counters           the resampler's profiling counters (cargo feature
#                         `counters`, off in every other build): clippy and
#                         their test; only voxflex-resample is compiled again.
# Check-mode and build-mode artifacts are distinct in cargo, so dependencies
# are compiled twice (once `check`, once `build`) whatever the order; the
# order only decides how early a failure shows.
#
# Under CI (CI=true) the lock file must be up to date (--locked) and a
# missing GPU adapter fails the GPU tests instead of skipping them.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

locked=()
if [[ "${CI:-}" == "true" || "${CI:-}" == "1" ]]; then
    locked=(--locked)
fi

total_start=$SECONDS
step() {
    local name=$1
    shift
    local start=$SECONDS
    echo "==> ${name}: $*" >&2
    "$@"
    echo "==> ${name}: ok in $((SECONDS - start)) s" >&2
}

step fmt cargo fmt --all -- --check
step clippy cargo clippy "${locked[@]}" --workspace --all-targets -- -D warnings
step build cargo build "${locked[@]}" --workspace
step test-build cargo test "${locked[@]}" --workspace --no-run
step test cargo test "${locked[@]}" --workspace
step counters-clippy cargo clippy "${locked[@]}" -p voxflex-resample --features counters \
    --all-targets -- -D warnings
step counters-test cargo test "${locked[@]}" -p voxflex-resample --features counters \
    --test raster_counters

echo "==> all checks passed in $((SECONDS - total_start)) s" >&2
