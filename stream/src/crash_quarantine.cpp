#include "texstream/stream/crash_quarantine.hpp"

#include <algorithm>

#include <signal.h>

#include <spdlog/spdlog.h>

namespace texstream::stream {

bool CrashQuarantine::charge_crash(int signal, const ServerBlock& block) {
  // Signals a process raises on itself when its own code fails; SIGKILL (and SIGTERM) come from outside.
  const bool crash = signal == SIGSEGV || signal == SIGBUS || signal == SIGABRT || signal == SIGFPE || signal == SIGILL;
  if (!crash) return false;
  charge_loading(block, "died by signal " + std::to_string(signal));
  return true;
}

void CrashQuarantine::charge_hang(const ServerBlock& block) {
  charge_loading(block, "hung (its heartbeat stalled) and was killed");
}

void CrashQuarantine::charge_loading(const ServerBlock& block, const std::string& how) {
  std::unordered_set<uint32_t> charged;  // two workers on one texture: one crash, one charge
  for (uint32_t i = 0; i < kLoadingWords; ++i) {
    // relaxed: the writer is dead and reaped; its stores are in the page.
    const uint32_t word = block.loading[i].v.load(std::memory_order_relaxed);
    // A dead server's words are as untrusted as its completions: ids outside the table are ignored.
    if (word == 0 || word - 1 >= texture_count_) continue;
    const uint32_t texture = word - 1;
    if (!charged.insert(texture).second || quarantined_.count(texture) != 0) continue;
    const uint32_t n = ++charges_[texture];
    if (n < kQuarantineAfterCrashes) {
      spdlog::warn("texstream-server {} while loading texture {} (crash {} of {} before it is quarantined)", how,
                   texture, n, kQuarantineAfterCrashes);
      continue;
    }
    quarantined_.insert(texture);
    spdlog::warn(
        "texture {} quarantined: texstream-server crashed or hung {} times while loading it (last: {}); "
        "it is not requested again and stays on its colormap",
        texture, n, how);
  }
}

void CrashQuarantine::refuse(TextureId texture, MipLevel mip) {
  if (refused_set_.insert(key(texture, mip)).second) refused_.push_back(key(texture, mip));
}

void CrashQuarantine::fail_refused(MipSink& sink) {
  if (refused_.empty()) return;
  std::vector<uint64_t> refused;
  refused.swap(refused_);
  refused_set_.clear();
  for (uint64_t k : refused) {
    sink.failed(TextureId(static_cast<uint32_t>(k >> 32)), MipLevel(static_cast<uint32_t>(k)),
                CompletionStatus::kCorrupt);
  }
}

std::vector<uint32_t> CrashQuarantine::charged_ids() const {
  std::vector<uint32_t> ids;
  ids.reserve(charges_.size());
  for (const auto& [texture, deaths] : charges_) ids.push_back(texture);
  std::sort(ids.begin(), ids.end());
  return ids;
}

std::vector<uint32_t> CrashQuarantine::quarantined_ids() const {
  std::vector<uint32_t> ids(quarantined_.begin(), quarantined_.end());
  std::sort(ids.begin(), ids.end());
  return ids;
}

}  // namespace texstream::stream
