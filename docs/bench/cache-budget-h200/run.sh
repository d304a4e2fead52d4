#!/usr/bin/env bash
# Issue 26 on the device: a 300 K-texture city (generated there), config/gpu.toml (1 GiB), 1920x1080, the
# scene's bird's-eye path. Runs: NAME:FRAMES:SETS... (FRAMES 0 = whole path). Prints each run's cache.json
# figures and frame latencies. Usage (on the device, with the bundle in .gpu/): docs/bench/cache-budget-h200/run.sh RUN...
set -u
cd "$(dirname "$0")/../../.."
R=.gpu/run.sh
nvidia-smi --query-gpu=name --format=csv,noheader
if [ ! -f /tmp/city/scene.json ]; then
  t0=$(date +%s)
  $R texstream-gen --out /tmp/city --textures 300000 --seed 1 --threads 16 > "$OUT/gen.log" 2>&1
  echo "gen rc $? $(( $(date +%s) - t0 )) s"
fi
for run in "$@"; do
  IFS=: read -r name frames sets <<< "$run"
  t0=$(date +%s)
  args=()
  for s in $sets; do args+=(--set "$s"); done
  $R texstream-render --config config/gpu.toml --set scene.dir=/tmp/city --set render.output_dir=/tmp/o_$name \
     --set render.frames=$frames --set render.write_every_frames=0 "${args[@]}" > "$OUT/render_$name.log" 2>&1
  echo "== $name ($sets) rc $? $(( $(date +%s) - t0 )) s"
  python3 - "$name" <<'PY'
import json,sys
n=sys.argv[1]
j=json.load(open(f"/tmp/o_{n}/cache.json"))
keys=["eviction","layer_extent","layers","addressable_bytes","memory_budget_bytes","max_bound_bytes","evictions",
      "texture_loads","texture_reloads","thrash_rate","layers_recycled","budget_evicted_layers","address_evictions",
      "space_refusals","fill_at_first_eviction","mips_uploaded","bytes_uploaded","budget_exceeded_frames"]
print(" ".join(f"{k}={j.get(k)}" for k in keys))
s=json.load(open(f"/tmp/o_{n}/summary.json"))
print(" ".join(f"{k}={s.get(k)}" for k in ["frames","textures_resident","texture_count","validation_errors","protocol_errors"]), "latency_ms", s.get("frame_latency_ms"))
PY
  grep -i "texture cache:" "$OUT/render_$name.log" | head -2
done
