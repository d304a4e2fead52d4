#!/usr/bin/env bash
# Packs texstream binaries and the shared libraries they need (all but glibc's) into .gpu/, to be carried to
# the GPU machine of the device tool, which has no network and none of our packages. Build first:
#   cmake -S . -B build-gpu -G Ninja -DTEXSTREAM_BUILD_TESTS=OFF -DTEXSTREAM_BENCH_COMMANDS="visibility;cache"
#   ninja -C build-gpu texstream-bench texstream-gen texstream-render texstream-server
# On the device:  .gpu/run.sh texstream-bench visibility --device gpu
set -euo pipefail
cd "$(dirname "$0")/.."
src=${1:-build-gpu}
rm -rf .gpu && mkdir -p .gpu/bin .gpu/lib
for b in texstream-bench texstream-gen texstream-render texstream-server; do
  [ -x "$src/bin/$b" ] && cp "$src/bin/$b" .gpu/bin/
done
for b in .gpu/bin/*; do
  ldd "$b" | awk '/=> \//{print $3}' | while read -r lib; do
    case "$(basename "$lib")" in
      libc.so.*|libm.so.*|libpthread.so.*|libdl.so.*|librt.so.*|ld-linux*) ;;  # glibc: the device's own
      *) cp -nL "$lib" .gpu/lib/ ;;
    esac
  done
done
cat > .gpu/run.sh <<'RUN'
#!/usr/bin/env bash
# Runs a bundled texstream binary with the bundled libraries, the repo's shaders/config, and NVIDIA's ICD.
here=$(cd "$(dirname "$0")" && pwd)
export LD_LIBRARY_PATH="$here/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
export TEXSTREAM_SHADER_DIR="$here/../shaders" TEXSTREAM_CONFIG_DIR="$here/../config"
if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
export XDG_CACHE_HOME=${XDG_CACHE_HOME:-/tmp/texstream-cache}
exe=$1; shift
exec "$here/bin/$exe" "$@"
RUN
chmod +x .gpu/run.sh
du -sh .gpu
