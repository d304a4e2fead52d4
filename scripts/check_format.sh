#!/usr/bin/env bash
# The tree follows .clang-format: every C++ file of ours, checked without changing it (a CTest test runs this;
# `scripts/check_format.sh --fix` formats in place). shaders/ is left out: shared_structs.h is GLSL as well.
set -euo pipefail
cd "$(dirname "$0")/.."
fmt=$(command -v clang-format-14 || command -v clang-format) || { echo "check_format: clang-format-14 is not installed (scripts/bootstrap.sh installs it)" >&2; exit 1; }
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' ':!:shaders/*')
if [ "${1:-}" = --fix ]; then
  "$fmt" -i "${files[@]}"
else
  "$fmt" --dry-run --Werror "${files[@]}"
  echo "check_format: ${#files[@]} files follow .clang-format"
fi
