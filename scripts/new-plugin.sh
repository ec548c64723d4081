#!/usr/bin/env bash
# Creates a new deformation plugin from the template: copies plugins/template
# to plugins/<name>, shaders/template to shaders/<name> and the template's
# integration test to tests/tests/<name_>_plugin.rs, renames the crate
# (voxflex-<name>), the library (libvoxflex_<name_>.so), the plugin name
# ("<name>") and the Rust types (Template… → <Name>…), and adds the crate to
# the workspace's members. docs/PLUGINS.md says what to change next.
#
#   scripts/new-plugin.sh my-model
#
# <name>: lower-case letters and digits, words joined by single hyphens,
# starting with a letter (the plugin name a scene writes: plugin = "<name>").
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."

usage() {
    echo "usage: scripts/new-plugin.sh NAME   (e.g. my-model: lower-case words joined by -)" >&2
    exit 2
}
[[ $# -eq 1 ]] || usage
name=$1
if [[ ! $name =~ ^[a-z][a-z0-9]*(-[a-z0-9]+)*$ ]]; then
    echo "error: plugin name \`$name\` is not lower-case words joined by single hyphens (e.g. my-model)" >&2
    exit 1
fi
if [[ $name == template ]]; then
    echo "error: \`template\` is the template itself; choose another name" >&2
    exit 1
fi
snake=${name//-/_}
camel=""
IFS=- read -ra words <<<"$name"
for w in "${words[@]}"; do
    camel+="${w^}"
done

for src in plugins/template shaders/template tests/tests/template_plugin.rs Cargo.toml; do
    [[ -e $src ]] || {
        echo "error: $src is missing; run this from a voxflex checkout" >&2
        exit 1
    }
done
for dst in "plugins/$name" "shaders/$name" "tests/tests/${snake}_plugin.rs"; do
    if [[ -e $dst ]]; then
        echo "error: $dst already exists; choose another name or remove it" >&2
        exit 1
    fi
done
if grep -q "\"plugins/$name\"" Cargo.toml; then
    echo "error: Cargo.toml already lists plugins/$name" >&2
    exit 1
fi

# The renames, most specific first. Prose that mentions "the template"
# stays: it still says where the code came from.
rename() {
    sed -e "s/voxflex-template/voxflex-$name/g" \
        -e "s/voxflex_template/voxflex_$snake/g" \
        -e "s#plugins/template#plugins/$name#g" \
        -e "s#shaders/template#shaders/$name#g" \
        -e "s/template_plugin/${snake}_plugin/g" \
        -e "s/\"template\"/\"$name\"/g" \
        -e "s#\"template/#\"$name/#g" \
        -e "s/\"template /\"$name /g" \
        -e "s/Template/$camel/g" \
        "$1"
}

mkdir -p "plugins/$name" "shaders/$name"
# Source files only: a target/ or editor files inside the template are not copied.
while IFS= read -r -d '' f; do
    rel=${f#plugins/template/}
    mkdir -p "plugins/$name/$(dirname "$rel")"
    rename "$f" >"plugins/$name/$rel"
done < <(find plugins/template -type f \( -name '*.rs' -o -name '*.toml' -o -name '*.md' \) -not -path '*/target/*' -print0)
for f in shaders/template/*.wgsl; do
    rename "$f" >"shaders/$name/$(basename "$f")"
done
rename tests/tests/template_plugin.rs >"tests/tests/${snake}_plugin.rs"

# Workspace membership: after the template's line, in `members` and in
# `default-members` (so `cargo build` builds the new plugin too).
sed -i "s#^\(\s*\)\"plugins/template\",\$#&\n\1\"plugins/$name\",#" Cargo.toml
count=$(grep -c "\"plugins/$name\"" Cargo.toml || true)
if [[ $count -ne 2 ]]; then
    echo "error: could not add plugins/$name to Cargo.toml's members and default-members; add it by hand" >&2
    exit 1
fi

# The shader coverage guard (runtime/wgsl-check) names the module that
# validates each shaders/ folder: the new folder's owner is the new crate.
owners=runtime/wgsl-check/src/coverage.rs
sed -i "s#^\(\s*\)(\"template\", \"plugins/template/src\"),\$#&\n\1(\"$name\", \"plugins/$name/src\"),#" "$owners"
if ! grep -q "(\"$name\", \"plugins/$name/src\")" "$owners"; then
    echo "error: could not add shaders/$name to SHADER_OWNERS in $owners; add it by hand" >&2
    exit 1
fi

cat <<MSG
created plugin \`$name\`:
  plugins/$name/            crate voxflex-$name → libvoxflex_$snake.so, types ${camel}Field, ${camel}Params
  shaders/$name/            its WGSL
  tests/tests/${snake}_plugin.rs   its integration test
  Cargo.toml                plugins/$name added to members and default-members
  $owners   shaders/$name owned by plugins/$name/src (naga validation)
next: change the STEP comments' code (docs/PLUGINS.md), then
  cargo build && cargo test -p voxflex-$name && cargo test -p voxflex-integration-tests --test ${snake}_plugin
MSG
