#!/usr/bin/env bash
# Issue 9's CI job: an ASan+UBSan build of the whole test suite, a TSan build of the ring / stream tests, a
# short chaos run (>= 20 SIGKILLs) and a short libFuzzer run per target. Meant for .ci/run (the lead wires it
# in); each step prints its duration. Budget: ~25 minutes on 2 cores with warm build dirs... see the report.
#   scripts/ci_sanitizers.sh [--skip-asan] [--skip-tsan] [--skip-chaos] [--skip-fuzz] [--fuzz-seconds N]
# Build dirs: build-asan, build-tsan, build-fuzz (clang), build (Release, for the chaos run).
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc)
fuzz_seconds=30
skip_asan=0 skip_tsan=0 skip_chaos=0 skip_fuzz=0
while [ $# -gt 0 ]; do
  case "$1" in
    --skip-asan) skip_asan=1 ;;
    --skip-tsan) skip_tsan=1 ;;
    --skip-chaos) skip_chaos=1 ;;
    --skip-fuzz) skip_fuzz=1 ;;
    --fuzz-seconds) fuzz_seconds="$2"; shift ;;
    *) echo "ci_sanitizers: unknown argument $1" >&2; exit 2 ;;
  esac
  shift
done
t_all=$(date +%s)
step() { echo "== ci_sanitizers: $* ($(( $(date +%s) - t_all )) s so far)"; }
failed=()

# Sanitizer runtime options: fail on the first report, keep going on leaks of the Vulkan driver (lavapipe
# leaks at exit by design), and let TSan/ASan coexist with posix_spawn'd servers.
export ASAN_OPTIONS=detect_leaks=0:abort_on_error=1:detect_stack_use_after_return=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1

if [ "$skip_asan" = 0 ]; then
  step "ASan+UBSan: whole test suite"
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTEXSTREAM_SANITIZE=address,undefined >/dev/null
  cmake --build build-asan -j"$jobs"
  ctest --test-dir build-asan --output-on-failure -j"$jobs" || failed+=(asan)
fi

if [ "$skip_tsan" = 0 ]; then
  step "TSan: ring and stream tests"
  cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTEXSTREAM_SANITIZE=thread >/dev/null
  cmake --build build-tsan -j"$jobs" --target protocol_unit_tests protocol_segment_tests server_ring_stress_test \
    stream_integration_tests stream_unit_tests chaos_recovery_tests texstream-server
  # The hostile-server test races on purpose (it plays another process scribbling on shared memory): not here.
  ctest --test-dir build-tsan --output-on-failure -j"$jobs" \
    -R '^(SpscRing|ProtocolSegment|Segment|RingStress|StreamClient|ServerProcess|ServerCommand|StreamRealServer|ChaosRecovery|TextureStates)' \
    || failed+=(tsan)
fi

if [ "$skip_chaos" = 0 ]; then
  step "chaos: texstream-chaos --quick (>= 20 SIGKILLs)"
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
  cmake --build build -j"$jobs" --target texstream-chaos texstream-render texstream-server texstream-gen
  build/bin/texstream-chaos --quick --kills 20 || failed+=(chaos)
fi

if [ "$skip_fuzz" = 0 ]; then
  step "fuzz: ${fuzz_seconds} s per target"
  if ! command -v clang++-14 >/dev/null; then
    echo "ci_sanitizers: clang++-14 missing (scripts/bootstrap.sh installs clang-14 and libclang-rt-14-dev)" >&2
    failed+=(fuzz)
  else
    CC=clang-14 CXX=clang++-14 cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTEXSTREAM_FUZZ=ON \
      -DTEXSTREAM_BUILD_TESTS=ON -DCMAKE_CXX_FLAGS="-fsanitize=fuzzer-no-link,address,undefined" >/dev/null
    cmake --build build-fuzz -j"$jobs" --target fuzz_dds_reader fuzz_completion fuzz_stream_client fuzz_config
    for f in fuzz_dds_reader fuzz_completion fuzz_stream_client fuzz_config; do
      corpus=build-fuzz/corpus/$f
      mkdir -p "$corpus"
      seeds=tests/fuzz/seeds/$f
      [ -d "$seeds" ] && cp -n "$seeds"/* "$corpus"/ 2>/dev/null || true
      echo "-- $f"
      build-fuzz/bin/$f -max_total_time="$fuzz_seconds" -print_final_stats=1 -artifact_prefix=build-fuzz/"$f"- \
        "$corpus" 2>&1 | tail -n 12 || failed+=("fuzz:$f")
    done
  fi
fi

step "done"
echo "ci_sanitizers: total $(( $(date +%s) - t_all )) s"
if [ ${#failed[@]} -gt 0 ]; then
  echo "ci_sanitizers: FAILED: ${failed[*]}" >&2
  exit 1
fi
