#pragma once
// Named kill points for texstream-chaos (issue 9): the server SIGKILLs itself at a chosen protocol step, so
// recovery is tested at the worst instants, not only at random ones.
//
// Armed through the environment, which the renderer passes on to the servers it spawns:
//   TEXSTREAM_FAULT=<point>[@N][,<point>[@N]...]   die the N-th time (default 1st) this process passes <point>
//   TEXSTREAM_FAULT_ARM=<file>                     a watcher thread polls <file> every kPollInterval; when it
//                                                  appears it is claimed (renamed away) and the point named in
//                                                  it is armed: the next pass of that point dies. texstream-chaos
//                                                  writes it at random instants; every server of a run shares it,
//                                                  and each kill is taken by exactly one of them.
// Points: slot_write (halfway through copying a payload into a staging slot), before_completion (payload and
// checksum in the slot, completion not pushed), after_ring_push (completion record published, the renderer
// not yet woken, statistics not yet counted), eviction (a RAM-cache victim picked, not yet erased),
// mid_ring_push (inside the completion ring's push: half of the record copied, the position not published).
//
// Cost when neither variable is set: one relaxed atomic load per pass after the first (which reads the
// environment once). Thread-safe: workers and the main loop pass points concurrently.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string_view>

#include "texstream/common/result.hpp"

namespace texstream::server {

enum class FaultPoint : uint8_t {
  kSlotWrite = 0,
  kBeforeCompletion = 1,
  kAfterRingPush = 2,
  kEviction = 3,
  kMidRingPush = 4,
};
inline constexpr uint32_t kFaultPointCount = 5;

// True when TEXSTREAM_FAULT or TEXSTREAM_FAULT_ARM is set: the server then hooks the completion ring's push
// (kMidRingPush); otherwise the ring runs without the hook's call.
bool fault_injection_enabled();

const char* to_string(FaultPoint point);
std::optional<FaultPoint> fault_point_from_string(std::string_view name);

// Passes `point`: SIGKILLs this process if the point is armed (see above). Never returns then.
void fault_point(FaultPoint point);

// memcpy with FaultPoint::kSlotWrite passed halfway: a kill there leaves a half-written slot behind.
void copy_into_slot(void* dst, const void* src, size_t bytes);

// The parsed TEXSTREAM_FAULT value: per point, the pass that dies (0: never). Errors name the variable and
// the bad entry. Exposed for tests; fault_point() reads the environment itself.
struct FaultPlan {
  uint64_t die_on_pass[kFaultPointCount] = {};
};
Result<FaultPlan> parse_fault_plan(std::string_view text);

}  // namespace texstream::server
