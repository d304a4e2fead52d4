#!/usr/bin/env bash
# README command (b) and CI (.ci/run): installs what is missing, builds everything (Release), runs the whole
# test suite through CTest, then the fault-isolation stage (scripts/ci_sanitizers.sh: an ASan+UBSan build of
# the whole suite, a TSan build of the ring/stream tests, a short chaos run, a short fuzz run).
#   scripts/test.sh [--quick] [ctest arguments...]
#   --quick or TEXSTREAM_QUICK=1: only the Release build and CTest (a developer's run, ~4 min on 2 cores).
# Exit status is non-zero if any stage failed; the last lines name each stage, its time and its outcome.
set -uo pipefail
cd "$(dirname "$0")/.."
quick=${TEXSTREAM_QUICK:-0}
ctest_args=()
for a in "$@"; do
  if [ "$a" = --quick ]; then quick=1; else ctest_args+=("$a"); fi
done
jobs=$(nproc)
t_all=$(date +%s)
results=()
status=0
# stage NAME COMMAND...: runs it, times it; a failure is remembered (and stops the run if fatal=1).
stage() {
  local name="$1"; shift
  local t0; t0=$(date +%s)
  echo "== test.sh: stage '$name' starts ($(( t0 - t_all )) s so far)"
  if "$@"; then
    results+=("$name: ok ($(( $(date +%s) - t0 )) s)")
    return 0
  fi
  results+=("$name: FAILED ($(( $(date +%s) - t0 )) s)")
  echo "== test.sh: stage '$name' FAILED" >&2
  status=1
  return 1
}
report() {
  echo "== test.sh: summary (total $(( $(date +%s) - t_all )) s)"
  for r in "${results[@]}"; do echo "   $r"; done
  if [ "$status" != 0 ]; then echo "test.sh: FAILED" >&2; else echo "test.sh: all stages passed"; fi
  exit "$status"
}

build() {
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null && cmake --build build -j"$jobs"
}

stage bootstrap bash scripts/bootstrap.sh || report
stage release-build build || report  # nothing below is meaningful without it
stage release-ctest ctest --test-dir build --output-on-failure -j"$jobs" "${ctest_args[@]}"
if [ "$quick" = 1 ]; then
  echo "== test.sh: --quick / TEXSTREAM_QUICK=1: sanitizer, chaos and fuzz stages skipped"
else
  stage sanitizers-chaos-fuzz bash scripts/ci_sanitizers.sh
fi
report
