#!/usr/bin/env bash
# Packs texstream binaries and the shared libraries they need (all but glibc's) into .gpu/, to be carried to
# the GPU machine of the device tool, which has no network and none of our packages. Build first:
#   cmake -S . -B build-gpu -G Ninja -DTEXSTREAM_BUILD_TESTS=OFF -DTEXSTREAM_BENCH_COMMANDS="visibility;cache"
#   ninja -C build-gpu texstream-bench texstream-gen texstream-render texstream-server
# On the device:  .gpu/run.sh texstream-bench visibility --device gpu
set -euo pipefail
cd "$(dirname "$0")/.."
src=${1:-build-gpu}
# The binaries to pack (the server links OpenImageIO and its ~350 MB of dependencies: leave it out when the
# benchmark does not spawn it; the device tool carries at most 64 MiB).
bins=${BINS:-texstream-bench texstream-gen texstream-render texstream-server}
rm -rf .gpu && mkdir -p .gpu/bin .gpu/lib
for b in $bins; do
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
# Shaders and profiles: the bundle's own copies if packed (they must match the binaries), else the repo's.
if [ -d "$here/shaders" ]; then export TEXSTREAM_SHADER_DIR="$here/shaders"; else export TEXSTREAM_SHADER_DIR="$here/../shaders"; fi
if [ -d "$here/config" ]; then export TEXSTREAM_CONFIG_DIR="$here/config"; else export TEXSTREAM_CONFIG_DIR="$here/../config"; fi
# NVIDIA's Vulkan driver (libGLX_nvidia) and its glvnd dependencies live outside the default search path there.
if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  export LD_LIBRARY_PATH="$LD_LIBRARY_PATH:/usr/local/nvidia/lib64:/usr/local/nvidia/lib"
fi
export XDG_CACHE_HOME=${XDG_CACHE_HOME:-/tmp/texstream-cache}
exe=$1; shift
exec "$here/bin/$exe" "$@"
RUN
chmod +x .gpu/run.sh
# glvnd, which NVIDIA's Vulkan driver loads and the device image lacks.
for l in libGLX.so.0 libGLdispatch.so.0 libEGL.so.1 libOpenGL.so.0 libGL.so.1; do
  f=$(ldconfig -p | awk -v n="$l" '$1==n{print $NF; exit}')
  [ -n "$f" ] && cp -nL "$f" .gpu/lib/
done
du -sh .gpu
