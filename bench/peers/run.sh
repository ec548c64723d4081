#!/usr/bin/env bash
# voxflex side by side with its peers: makes bench/peers/.venv with the
# pinned peers (requirements.txt) when missing or stale, then runs peers.py.
#   bench/peers/run.sh --quick                 # seconds: checks the harness
#   bench/peers/run.sh --repeat 5              # full sizes (quiet machine!)
#   bench/peers/run.sh --jobs resample,roi     # a subset
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
python="${PYTHON:-python3.11}"
command -v "$python" >/dev/null || python=python3
if [[ ! -x "$venv/bin/python" || "$here/requirements.txt" -nt "$venv/.installed" ]]; then
  echo "+ creating $venv with $("$python" --version) and requirements.txt" >&2
  "$python" -m venv "$venv"
  "$venv/bin/pip" install --quiet --upgrade pip
  "$venv/bin/pip" install --quiet -r "$here/requirements.txt"
  touch "$venv/.installed"
fi
# VTK: render off screen through EGL (no X server needed); warp: CPU only.
export VTK_DEFAULT_OPENGL_WINDOW="${VTK_DEFAULT_OPENGL_WINDOW:-vtkEGLRenderWindow}"
export CUDA_VISIBLE_DEVICES="${CUDA_VISIBLE_DEVICES-}"
cd "$here"
exec "$venv/bin/python" "$here/peers.py" "$@"
