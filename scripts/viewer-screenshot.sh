#!/usr/bin/env bash
# Runs the viewer under a virtual X server (Debian's `xvfb`), saves the
# window as a PNG after N frames and checks the PNG is not blank: the
# desktop viewer's smoke test for CI, and how docs/VIEWER.md's screenshot
# is made.
#
#   scripts/viewer-screenshot.sh [OUT.png] [INPUT] [FRAMES] [VIEWER ARGS...]
#
# OUT.png defaults to target/viewer-screenshot.png, INPUT (a scene or a
# volume file; "" for none) to the built-in head phantom, FRAMES to 10;
# further arguments go to the viewer. Builds the viewer and the plugins
# (debug) first. docs/figures/viewer.png is
#
#   scripts/viewer-screenshot.sh docs/figures/viewer.png "" 10 --seed-roi 10,-5,15
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

out=${1:-target/viewer-screenshot.png}
input=${2:-}
frames=${3:-10}
extra=("${@:4}")

command -v xvfb-run >/dev/null || {
    echo "error: xvfb-run not found; install Debian's xvfb (apt-get install xvfb)" >&2
    exit 1
}
cargo build -p voxflex-viewer -p voxflex-raycast -p voxflex-chainmail -p voxflex-affine \
    -p voxflex-corotational-fem -p voxflex-mass-spring
rm -f "$out"
# shellcheck disable=SC2086  # $input is empty or one path
xvfb-run -a -s "-screen 0 1400x900x24" \
    target/debug/voxflex-viewer $input --screenshot "$out" --exit-after-frames "$frames" "${extra[@]}"
[[ -s $out ]] || {
    echo "error: $out was not written" >&2
    exit 1
}
target/debug/voxflex-viewer --check-png "$out"
