#!/usr/bin/env bash
# On a GPU machine, after scripts/gpu-ab/prepare.sh: ChainMail with the
# block lists built on the device (after) against the build that read back
# every iteration (before), interleaved A B A B — the papers' 126³ test
# (`-- gpu`, three runs each) and the chainmail-head scene at 1.56 mm on
# backend = "gpu" (model, map and resample stage times from metrics.json).
set -u
ab=target/gpu-ab
chmod +x "$ab"/*/voxflex "$ab"/*/chainmail-bench
command -v nvidia-smi >/dev/null && nvidia-smi -L
for round in 1 2; do
  for v in before after; do
    echo "== papers' test, $v, round $round"
    timeout 300 "$ab/$v/chainmail-bench" gpu 2>&1 | grep -E "adapter|GPU"
  done
done
sed 's/^dims = .*/dims = [128, 154, 141]/; s/^backend = .*/backend = "gpu"/' \
  configs/chainmail-head.toml > /tmp/gpu-ab-head.toml
for round in 1 2; do
  for v in before after; do
    echo "== chainmail-head at 1.56 mm, $v, round $round"
    rm -rf out/chainmail-head
    VOXFLEX_PLUGIN_PATH=$ab/$v timeout 300 "$ab/$v/voxflex" run /tmp/gpu-ab-head.toml > /tmp/gpu-ab.log 2>&1 \
      || { tail -3 /tmp/gpu-ab.log; continue; }
    python3 - <<'PY'
import json
m = json.load(open("out/chainmail-head/metrics.json"))
s, n = m["stages"], m["stages"]["model"]["notes"]
print(m["backend"], f"model {s['model']['wall_ms']:.1f} ms, map {s['map']['wall_ms']:.1f}, "
      f"resample {s['resample']['wall_ms']:.1f}; propagation {n['propagation_iterations']:.0f}, "
      f"sweeps {n['relaxation_sweeps']:.0f}, slowest frame {n['ms_per_frame_max']:.1f} ms")
PY
  done
done
