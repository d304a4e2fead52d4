#!/usr/bin/env bash
# Installs everything texstream needs on Debian 12 (bookworm), as root, idempotently:
# only missing packages are installed, and the backports suite is added once.
# Mesa lavapipe comes from bookworm-backports because Debian 12's Mesa 22.3 has no sparse residency
# (Mesa >= 24 has sparseBinding, sparseResidencyImage2D and shaderResourceResidency).
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config git ca-certificates
  libvulkan-dev vulkan-tools vulkan-validationlayers glslang-dev glslang-tools spirv-tools
  libglfw3-dev libglm-dev
  libopenimageio-dev openimageio-tools
  libboost-dev
  libtomlplusplus-dev libcli11-dev libspdlog-dev libfmt-dev nlohmann-json3-dev
  libtbb-dev libxxhash-dev libcurl4-openssl-dev libstb-dev liburing-dev
  libassimp-dev libtinygltf-dev libsquish-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  xvfb xauth
  nginx python3-matplotlib
  clang libclang-rt-14-dev clang-format-14
)
BACKPORTS_PACKAGES=(mesa-vulkan-drivers)

if [ "$(id -u)" -ne 0 ]; then
  SUDO=sudo
else
  SUDO=
fi

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

# Mesa from backports: installed and at major version >= 24?
need_mesa=1
if v=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null); then
  major=${v%%.*}; major=${major#*:}
  if [ -n "$major" ] && [ "$major" -ge 24 ] 2>/dev/null; then need_mesa=0; fi
fi

if [ ${#missing[@]} -eq 0 ] && [ $need_mesa -eq 0 ]; then
  echo "bootstrap: all dependencies present"
  exit 0
fi

export DEBIAN_FRONTEND=noninteractive
if [ $need_mesa -eq 1 ]; then
  if ! grep -rqs "bookworm-backports" /etc/apt/sources.list /etc/apt/sources.list.d/; then
    echo "bootstrap: adding bookworm-backports"
    echo "deb http://deb.debian.org/debian bookworm-backports main" | $SUDO tee /etc/apt/sources.list.d/texstream-backports.list >/dev/null
  fi
fi
echo "bootstrap: installing ${missing[*]:-} ${need_mesa:+(mesa from backports)}"
$SUDO apt-get update -q
if [ ${#missing[@]} -gt 0 ]; then
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi
if [ $need_mesa -eq 1 ]; then
  $SUDO apt-get install -y -q --no-install-recommends -t bookworm-backports "${BACKPORTS_PACKAGES[@]}"
fi
echo "bootstrap: done"
