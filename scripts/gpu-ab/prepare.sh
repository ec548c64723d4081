#!/usr/bin/env bash
# Builds what a GPU A/B of ChainMail needs, here, into target/gpu-ab/ (small
# enough to carry to a GPU machine, ~45 MB stripped): for the revision
# BEFORE (default 2e3cbaf, the last build whose ChainMail read back every
# iteration) and for this working tree, the ChainMail bench binary, the
# CLI and the chainmail and raycast plugins. Then run, on the GPU machine,
# scripts/gpu-ab/run.sh (docs/BENCHMARKS.md, "ChainMail").
#
#   scripts/gpu-ab/prepare.sh [BEFORE]
set -euo pipefail
before=${1:-2e3cbaf}
root=$(git rev-parse --show-toplevel)
out=$root/target/gpu-ab
rm -rf "$out" && mkdir -p "$out/before" "$out/after"

build() { # <checkout> <target dir> <destination>
  (cd "$1" && CARGO_TARGET_DIR=$2 cargo build --release -q -p voxflex-cli -p voxflex-chainmail -p voxflex-raycast \
    && CARGO_TARGET_DIR=$2 cargo bench -q -p voxflex-chainmail --bench chainmail --no-run 2>&1 | tail -1)
  local bench
  bench=$(ls -t "$2"/release/deps/chainmail-* | grep -v '\.d$' | head -1)
  strip -o "$3/chainmail-bench" "$bench"
  strip -o "$3/voxflex" "$2/release/voxflex"
  for p in chainmail raycast; do strip -o "$3/libvoxflex_$p.so" "$2/release/libvoxflex_$p.so"; done
}

worktree=$(mktemp -d)
git -C "$root" worktree add -q --detach "$worktree" "$before"
trap 'git -C "$root" worktree remove --force "$worktree"' EXIT
build "$worktree" "$root/target/gpu-ab-before-build" "$out/before"
build "$root" "$root/target" "$out/after"
cp "$root/scripts/gpu-ab/run.sh" "$out/"
du -sh "$out"
echo "carry target/gpu-ab and run: bash target/gpu-ab/run.sh"
