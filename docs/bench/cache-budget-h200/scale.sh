#!/usr/bin/env bash
# Issue 26 scale run on the device: a city of N textures generated there, then (1) texstream-bench cache
# --device gpu --scene-1m (its start-up comparison: the city against itself with 1 K textures, same view) and
# (2) the whole bird's-eye path with config/gpu.toml, sampling both processes' RSS and the GPU's memory.
# Usage (bundle in .gpu/): [ATLAS=512] docs/bench/cache-budget-h200/scale.sh N [skip-bench]
# ATLAS=PX: the atlas variant (texstream-gen --atlas PX, seed 000 §3.1) of the same city.
# THREADS=N: generator threads (16); VALIDATE=1: the path run with the validation layer (VK_ADD_LAYER_PATH set);
# FRAMES=N: only the path's first N frames (0: the whole path). CITY_DIR=D: the city's parent folder (/tmp; a
# tmpfs such as /dev/shm where the disk is too small: 5.7 M textures take 56 GB in 4 KiB blocks).
set -u
cd "$(dirname "$0")/../../.."
R=.gpu/run.sh
n=$1
atlas=${ATLAS:-0}
root=${CITY_DIR:-/tmp}
city=$root/city_$n
tag=$n
[ "$atlas" != 0 ] && city=$root/city_${n}_atlas$atlas && tag=${n}_atlas$atlas
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader
df -h $root | tail -1
if [ ! -f $city/scene.json ]; then
  t0=$(date +%s)
  $R texstream-gen --out $city --textures $n --seed 1 --threads ${THREADS:-16} --atlas $atlas > "$OUT/gen_$tag.log" 2>&1
  echo "gen $tag rc $? $(( $(date +%s) - t0 )) s, $(du -sh $city | cut -f1)"
fi
if [ "${2:-}" != skip-bench ]; then
  t0=$(date +%s)
  $R texstream-bench cache --quick --device gpu --scene-1m $city > "$OUT/cache_bench_$tag.txt" 2>&1
  echo "cache bench rc $? $(( $(date +%s) - t0 )) s"
  grep -E "^(startup|fit|bounds|summary)" "$OUT/cache_bench_$tag.txt"
fi
# The whole path, sampled every 0.5 s: renderer and server RSS (ps), GPU memory used (nvidia-smi).
t0=$(date +%s)
$R texstream-render --config config/gpu.toml --set scene.dir=$city --set render.output_dir=/tmp/o_scale \
   --set render.frames=${FRAMES:-0} --set render.write_every_frames=0 \
   ${VALIDATE:+--set render.validation=true} > "$OUT/render_scale_$tag.log" 2>&1 &
pid=$!
rss_r=0; rss_s=0; gpu=0
while kill -0 $pid 2>/dev/null; do
  r=$(ps -o rss= -C texstream-render | sort -n | tail -1); s=$(ps -o rss= -C texstream-server | sort -n | tail -1)
  g=$(nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits | head -1)
  [ -n "$r" ] && [ "$r" -gt "$rss_r" ] && rss_r=$r
  [ -n "$s" ] && [ "$s" -gt "$rss_s" ] && rss_s=$s
  [ -n "$g" ] && [ "$g" -gt "$gpu" ] && gpu=$g
  sleep 0.5
done
wait $pid; rc=$?
echo "path run rc $rc $(( $(date +%s) - t0 )) s; peak RSS renderer $((rss_r / 1024)) MiB, server $((rss_s / 1024)) MiB; GPU memory used (whole device) $gpu MiB"
python3 - <<'PY'
import json, csv
j = json.load(open("/tmp/o_scale/cache.json"))
s = json.load(open("/tmp/o_scale/summary.json"))
lat = sorted(float(r["latency_ms"]) for r in csv.DictReader(open("/tmp/o_scale/frames.csv")))
t = [float(r["time_s"]) for r in csv.DictReader(open("/tmp/o_scale/frames.csv"))]
p99 = lat[min(len(lat) - 1, int(0.99 * len(lat)))]
dur = max(t) if t else 1
st = s.get("startup_seconds", {})
print("startup s (stages before frame 0):", round(sum(v for k, v in st.items() if not k.startswith("frame0")), 3),
      "frame 0:", round(sum(v for k, v in st.items() if k.startswith("frame0")), 3))
print(f"frames {s['frames']} textures {s['texture_count']} resident {s['textures_resident']} "
      f"latency ms median {s['frame_latency_ms']['median']:.1f} p99 {p99:.1f} max {s['frame_latency_ms']['max']:.1f}; "
      f"{s['mb_streamed']:.1f} MB / {dur:.0f} s = {s['mb_streamed']/dur:.2f} MB/s, {s['mips_streamed']/dur:.0f} mips/s; "
      f"validation {s['validation_errors']} protocol {s['protocol_errors']}")
print(" ".join(f"{k}={j.get(k)}" for k in ["layer_extent", "layers", "addressable_bytes", "max_bound_bytes",
      "evictions", "thrash_rate", "space_refusals", "address_evictions", "budget_exceeded_frames"]))
PY
grep -i "texture cache:" "$OUT/render_scale_$tag.log" | head -1
