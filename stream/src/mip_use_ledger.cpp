#include "texstream/stream/mip_use_ledger.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <utility>

#include "texstream/common/texel_format.hpp"

namespace texstream::stream {

namespace {

// Residency is a 32-bit mask per texture, as in the cache (its levels are below 32: a 2^32-texel side).
constexpr uint32_t kMaxLevels = 32;

ResidentLevels levels_of(uint32_t mask, uint32_t mip_count) {
  ResidentLevels l;
  l.mip_count = mip_count;
  if (mask == 0) return l;
  // TextureCache::publish: the shader samples the run of resident levels that ends at the coarsest one.
  const MipRun run = sampled_run(mask);
  l.finest = run.finest;
  l.coarsest = run.coarsest;
  return l;
}

}  // namespace

MipUseLedger::MipUseLedger(TextureTable shapes) : shapes_(std::move(shapes)) {}

void MipUseLedger::leave(Use& u, uint32_t leaving) {
  const TextureShape s = shapes_[u.key];
  for (uint32_t bits = leaving & ~u.displayed; bits != 0; bits &= bits - 1) {
    bytes_wasted_ += mip_bytes(s.format, s.width, s.height, static_cast<uint32_t>(std::countr_zero(bits)));
  }
  u.resident &= ~leaving;
  u.displayed &= ~leaving;
}

void MipUseLedger::leave_and_settle(Use* u, uint32_t leaving) {
  leave(*u, leaving);
  if (u->resident == 0) uses_.erase(u);
}

void MipUseLedger::apply(std::span<const TextureEvent> events) {
  for (const TextureEvent& e : events) {
    const uint32_t t = e.texture.value;
    if (t >= shapes_.size()) continue;
    switch (e.kind) {
      case TextureEvent::Kind::kCommitted: {
        if (e.mip.value >= kMaxLevels) break;
        const uint32_t bit = 1u << e.mip.value;
        Use* u = uses_.find(t);
        if (u == nullptr) u = uses_.insert(Use{t, 0, 0});
        if (u->resident & bit) leave(*u, bit);  // a second copy of the level replaces the first
        u->resident |= bit;
        const TextureShape s = shapes_[t];
        bytes_uploaded_ += mip_bytes(s.format, s.width, s.height, e.mip.value);
        break;
      }
      case TextureEvent::Kind::kInvalidated:
        if (Use* u = uses_.find(t)) leave_and_settle(u, u->resident);
        break;
      case TextureEvent::Kind::kTrimmed:
        if (Use* u = uses_.find(t); u != nullptr && e.mip.value < kMaxLevels) {
          leave_and_settle(u, u->resident & ((1u << e.mip.value) - 1));
        }
        break;
      case TextureEvent::Kind::kFailed:
      case TextureEvent::Kind::kRejected:
      case TextureEvent::Kind::kNoRoom:
        break;  // nothing was uploaded
    }
  }
}

ResidentLevels MipUseLedger::levels(TextureId texture) const {
  if (texture.value >= shapes_.size()) return {};
  const Use* u = uses_.find(texture.value);
  return levels_of(u != nullptr ? u->resident : 0, shapes_[texture.value].mip_count);
}

double MipUseLedger::observe(std::span<const StreamCandidate> list) {
  for (const StreamCandidate& c : list) {
    if (c.texture.value >= shapes_.size() || !std::isfinite(c.desired_mip)) continue;
    Use* u = uses_.find(c.texture.value);
    if (u == nullptr) continue;  // nothing resident
    const ResidentLevels l = levels_of(u->resident, shapes_[c.texture.value].mip_count);
    if (!l.finest) continue;
    const double d = std::clamp(static_cast<double>(c.desired_mip), static_cast<double>(*l.finest),
                                static_cast<double>(*l.coarsest));
    u->displayed |= 1u << static_cast<uint32_t>(std::floor(d));
    u->displayed |= 1u << static_cast<uint32_t>(std::ceil(d));  // the same level unless d is fractional
  }
  return weighted_mip_deficit(list, [this](TextureId t) { return levels(t); });
}

void MipUseLedger::finish() {
  // Every entry has a resident mip; leave() on a copy, as the table is cleared after.
  uses_.for_each([this](const Use& entry) {
    Use u = entry;
    leave(u, u.resident);
  });
  uses_.clear();
}

double MipUseLedger::wasted_fraction() const {
  if (bytes_uploaded_ == 0) return std::numeric_limits<double>::quiet_NaN();
  return static_cast<double>(bytes_wasted_) / static_cast<double>(bytes_uploaded_);
}

}  // namespace texstream::stream
