#!/usr/bin/env bash
# The path bench's GPU workloads (issue 25), run on the device machine from the bundle of make_gpu_bundle.sh.
# A device call ends after at most 600 s, and the 300 K city's three pairs take longer, so the runs go to the
# background and later calls wait for them and collect what is done; the machine stays held while calls follow
# each other. On the device, from the repository root:
#
#   scripts/gpu_path_runs.sh start default city300k-720p   # launches them one after another, returns at once
#   scripts/gpu_path_runs.sh wait 540                      # waits up to 540 s, prints progress, then collects
#
# (both in the first call: `start ... && ... wait 540`; then `wait 540` calls until `done` is printed.)
# Workloads (docs/bench/path-gpu-h200-paced/README.md): default (4000 textures, 640x360, 24 s, ours, baseline
# and resident_blend), city300k-720p and city300k-1080p (300 000 textures, 14 s, ours and baseline); each 3
# pairs. Collecting packs report.md, results.json and raw/*.csv of every finished workload into $OUT/<name>.tgz
# (the device tool brings $OUT back).
set -uo pipefail
cd "$(dirname "$0")/.."
R="$PWD/.gpu/run.sh"
self="$PWD/scripts/gpu_path_runs.sh"
state=/tmp/gpu_path_runs
mkdir -p "$state"

run_one() {
  case "$1" in
    default)
      [ -f /tmp/scene/scene.json ] || $R texstream-gen --out /tmp/scene --textures 4000 --seed 1 --force
      $R texstream-bench path --scene /tmp/scene --config config/gpu.toml --size 640x360 --until 24 \
        --only ours,baseline,resident_blend --repeat 3 --out "$state/default" ;;
    city300k-720p | city300k-1080p)
      [ -f /tmp/city/scene.json ] || $R texstream-gen --out /tmp/city --textures 300000 --seed 1 --threads "$(nproc)"
      local size=1280x720
      [ "$1" = city300k-1080p ] && size=1920x1080
      $R texstream-bench path --scene /tmp/city --config config/gpu.toml --size "$size" --until 14 \
        --only ours,baseline --repeat 3 --out "$state/$1" ;;
    *)
      echo "unknown workload '$1' (default, city300k-720p, city300k-1080p)" >&2
      return 2 ;;
  esac
}

collect() {
  [ -n "${OUT:-}" ] || return 0
  for d in "$state"/*/; do
    local name
    name=$(basename "$d")
    [ -f "$d/report.md" ] || continue
    (cd "$state" && tar czf "$OUT/$name.tgz" "$name/report.md" "$name/results.json" "$name"/raw/*.csv 2>/dev/null)
    ls -la "$OUT/$name.tgz"
  done
}

case "${1:-}" in
  start)
    shift
    [ $# -gt 0 ] || { echo "start: name at least one workload" >&2; exit 2; }
    nvidia-smi -L 2>/dev/null | head -1
    if [ -f "$state/started" ]; then
      echo "already started: $(cat "$state/started")"
    else
      echo "$*" > "$state/started"
      # Detached from the call: it goes on while later calls wait for it.
      setsid bash -c "
        t0=\$(date +%s)
        for w in $*; do
          '$self' one \"\$w\" > '$state/'\"\$w\".log 2>&1
          echo \"\$w rc \$? \$(( \$(date +%s) - t0 )) s\" >> '$state/status'
        done
        touch '$state/done'" < /dev/null > /dev/null 2>&1 &
      echo "started: $*"
    fi ;;
  one)
    run_one "$2" ;;
  wait)
    limit=${2:-540}
    for _ in $(seq 1 $((limit / 5))); do
      [ -f "$state/done" ] && break
      sleep 5
    done
    cat "$state/status" 2>/dev/null
    [ -f "$state/done" ] && echo done
    for f in "$state"/*.log; do
      [ -f "$f" ] && { echo "== $(basename "$f")"; tail -n 2 "$f"; }
    done
    collect ;;
  *)
    sed -n 2,13p "$0"
    exit 2 ;;
esac
