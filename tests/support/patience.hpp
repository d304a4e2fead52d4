#pragma once
// Wall-clock bounds in tests. A test asserts behaviour, not speed (texstream-bench measures speed): a bound
// says "promptly" or "it did not hang", with a margin that holds on a busy machine. Header-only; included as
// "../support/patience.hpp". Why these numbers: docs/design/test_time_bounds.md.
#include <chrono>

namespace texstream::test {

// How much slower than a quiet Release run a test may find itself: ASan+UBSan (~3x) at 3x CPU
// oversubscription (the README's test command at load 5 on 2 cores). A bound of promptly(x) = 10 x.
inline constexpr int kBusyMachineFactor = 10;

// `quiet`: what the behaviour needs on a quiet machine (a design figure, e.g. "death is told within 100 ms").
template <class Rep, class Period>
constexpr auto promptly(std::chrono::duration<Rep, Period> quiet) {
  return quiet * kBusyMachineFactor;
}

// How long a test waits for something that must happen before it calls it a hang. Waiting costs nothing
// when the thing happens; only a broken build waits this long.
inline constexpr std::chrono::seconds kHangAfter{60};

}  // namespace texstream::test
