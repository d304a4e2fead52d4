#include "texstream/server/support/fault_point.hpp"

#include <signal.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <thread>

#include <spdlog/spdlog.h>

namespace texstream::server {

namespace {

constexpr std::array<const char*, kFaultPointCount> kNames = {"slot_write", "before_completion", "after_ring_push",
                                                              "eviction", "mid_ring_push"};
// How often the watcher looks for TEXSTREAM_FAULT_ARM's file: far below the chaos tool's kill intervals
// (>= 50 ms between events), far above a cost anyone would notice (one failed rename per poll).
constexpr auto kPollInterval = std::chrono::milliseconds(2);
constexpr int kNotArmed = -1;

struct FaultState {
  FaultPlan plan;
  std::array<std::atomic<uint64_t>, kFaultPointCount> passes{};
  std::atomic<int> armed{kNotArmed};  // a point named by the arm file, taken by its next pass
};

[[noreturn]] void die_at(FaultPoint point) {
  // write(2), not spdlog: other threads may hold its locks, and nothing may stand between here and the kill.
  char line[96];
  const int n = std::snprintf(line, sizeof line, "texstream-server: fault point '%s' reached: SIGKILL (pid %d)\n",
                              to_string(point), static_cast<int>(::getpid()));
  if (n > 0) (void)!::write(2, line, static_cast<size_t>(n));
  ::kill(::getpid(), SIGKILL);
  std::abort();  // not reached: SIGKILL cannot be caught
}

void watch_arm_file(FaultState* state, std::string file) {
  const std::string claimed = file + ".taken-" + std::to_string(::getpid());
  for (;;) {
    std::this_thread::sleep_for(kPollInterval);
    // rename() is atomic: of several servers (an old one still dying, its replacement), one takes the kill.
    if (std::rename(file.c_str(), claimed.c_str()) != 0) continue;
    std::string name;
    {
      std::ifstream in(claimed);
      std::getline(in, name);
    }
    std::remove(claimed.c_str());
    if (const std::optional<FaultPoint> p = fault_point_from_string(name)) {
      state->armed.store(static_cast<int>(*p), std::memory_order_relaxed);  // relaxed: a lone flag, no data
    } else {
      spdlog::error(
          "{} named fault point '{}', not one of slot_write, before_completion, after_ring_push, "
          "eviction, mid_ring_push: ignored",
          file, name);
    }
  }
}

// Reads the environment once. nullptr: no fault armed in this process (the common case).
FaultState* load_state() {
  const char* plan_text = std::getenv("TEXSTREAM_FAULT");
  const char* arm_file = std::getenv("TEXSTREAM_FAULT_ARM");
  const bool has_plan = plan_text != nullptr && *plan_text != '\0';
  const bool has_arm = arm_file != nullptr && *arm_file != '\0';
  if (!has_plan && !has_arm) return nullptr;
  auto* state = new FaultState();  // lives as long as the process (the watcher thread uses it)
  if (has_plan) {
    Result<FaultPlan> plan = parse_fault_plan(plan_text);
    if (plan.ok()) {
      state->plan = *plan;
    } else {
      spdlog::error("{}: fault points off", plan.error().message);
    }
  }
  if (has_arm) std::thread(watch_arm_file, state, std::string(arm_file)).detach();
  spdlog::warn("fault injection on: TEXSTREAM_FAULT='{}' TEXSTREAM_FAULT_ARM='{}'", has_plan ? plan_text : "",
               has_arm ? arm_file : "");
  return state;
}

}  // namespace

const char* to_string(FaultPoint point) {
  const auto i = static_cast<uint32_t>(point);
  return i < kFaultPointCount ? kNames[i] : "?";
}

std::optional<FaultPoint> fault_point_from_string(std::string_view name) {
  for (uint32_t i = 0; i < kFaultPointCount; ++i)
    if (name == kNames[i]) return static_cast<FaultPoint>(i);
  return std::nullopt;
}

Result<FaultPlan> parse_fault_plan(std::string_view text) {
  FaultPlan plan;
  for (;;) {
    const size_t comma = text.find(',');
    const std::string_view entry = text.substr(0, comma);
    const size_t at = entry.find('@');
    const std::optional<FaultPoint> p = fault_point_from_string(entry.substr(0, at));
    uint64_t pass = 1;
    bool ok = p.has_value();  // an empty entry ("a,,b", a trailing comma) is no point either
    if (ok && at != std::string_view::npos) {
      const std::string digits(entry.substr(at + 1));
      char* end = nullptr;
      pass = digits.empty() || digits[0] == '-' ? 0 : std::strtoull(digits.c_str(), &end, 10);
      ok = pass > 0 && end != nullptr && *end == '\0';
    }
    if (!ok) {
      return make_error(ErrorCode::kInvalidArgument,
                        "TEXSTREAM_FAULT entry '" + std::string(entry) +
                            "': expected <point>[@N] with N >= 1 and <point> one of slot_write, before_completion, "
                            "after_ring_push, eviction, mid_ring_push");
    }
    plan.die_on_pass[static_cast<uint32_t>(*p)] = pass;
    if (comma == std::string_view::npos) return plan;
    text = text.substr(comma + 1);
  }
}

void fault_point(FaultPoint point) {
  static FaultState* const state = load_state();  // thread-safe one-time initialisation
  if (state == nullptr) return;
  const auto i = static_cast<uint32_t>(point);
  // relaxed: each counter only needs to count; exactly one pass sees the N-th value.
  const uint64_t die_on = state->plan.die_on_pass[i];
  if (die_on != 0 && state->passes[i].fetch_add(1, std::memory_order_relaxed) + 1 == die_on) die_at(point);
  int armed = static_cast<int>(i);
  if (state->armed.load(std::memory_order_relaxed) == armed &&
      state->armed.compare_exchange_strong(armed, kNotArmed, std::memory_order_relaxed)) {
    die_at(point);
  }
}

bool fault_injection_enabled() {
  static const bool enabled =
      std::getenv("TEXSTREAM_FAULT") != nullptr || std::getenv("TEXSTREAM_FAULT_ARM") != nullptr;
  return enabled;
}

void copy_into_slot(void* dst, const void* src, size_t bytes) {
  if (bytes == 0) {  // memcpy's pointers must be valid even for 0 bytes; an empty payload's may be null
    fault_point(FaultPoint::kSlotWrite);
    return;
  }
  const size_t half = bytes / 2;
  std::memcpy(dst, src, half);
  fault_point(FaultPoint::kSlotWrite);
  std::memcpy(static_cast<std::byte*>(dst) + half, static_cast<const std::byte*>(src) + half, bytes - half);
}

}  // namespace texstream::server
