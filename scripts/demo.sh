#!/usr/bin/env bash
# README command (a): the main job. Installs what is missing, builds, generates the default city if it is not
# there yet (its ground as one huge texture in pages), then runs texstream-render, which spawns
# texstream-server, headless on lavapipe over the first seconds of the default camera path; frames (PNG) and
# summary.json land in out/demo/.
# Extra arguments go to texstream-render (e.g. --set render.frames=300).
set -euo pipefail
cd "$(dirname "$0")/.."
t0=$(date +%s)
bash scripts/bootstrap.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target texstream-render texstream-server texstream-gen texstream-config
t1=$(date +%s)
scene=scenes/default
# The city's ground is one huge texture streamed in pages (texstream-gen --ground pages, issue 28); a default
# scene made before that is made again.
if [ ! -f "$scene/scene.json" ] || ! grep -q '"ground"' "$scene/scene.json"; then
  build/bin/texstream-gen --out "$scene" --textures 4000 --seed 1 --force --ground pages
fi
t2=$(date +%s)
out=out/demo
rm -rf "$out"
build/bin/texstream-render --config config/lavapipe.toml --set scene.dir="$scene" --set render.output_dir="$out" "$@"
t3=$(date +%s)
echo "demo: bootstrap+build $((t1 - t0)) s, scene $((t2 - t1)) s, render $((t3 - t2)) s"
echo "demo: frames and summary are in $(pwd)/$out"
