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
  const uint32_t coarsest = 31u - static_cast<uint32_t>(std::countl_zero(mask));
  uint32_t finest = coarsest;
  while (finest > 0 && (mask & (1u << (finest - 1)))) --finest;
  l.finest = finest;
  l.coarsest = coarsest;
  return l;
}

}  // namespace

MipUseLedger::MipUseLedger(TextureTable shapes) : shapes_(std::move(shapes)), uses_(shapes_.size()) {}

void MipUseLedger::leave(uint32_t texture, uint32_t leaving) {
  Use& u = uses_[texture];
  const TextureShape& s = shapes_[texture];
  for (uint32_t bits = leaving & ~u.displayed; bits != 0; bits &= bits - 1) {
    bytes_wasted_ += mip_bytes(s.format, s.width, s.height, static_cast<uint32_t>(std::countr_zero(bits)));
  }
  u.resident &= ~leaving;
  u.displayed &= ~leaving;
}

void MipUseLedger::apply(std::span<const TextureEvent> events) {
  for (const TextureEvent& e : events) {
    const uint32_t t = e.texture.value;
    if (t >= uses_.size()) continue;
    switch (e.kind) {
      case TextureEvent::Kind::kCommitted: {
        if (e.mip.value >= kMaxLevels) break;
        const uint32_t bit = 1u << e.mip.value;
        if (uses_[t].resident & bit) leave(t, bit);  // a second copy of the level replaces the first
        uses_[t].resident |= bit;
        const TextureShape& s = shapes_[t];
        bytes_uploaded_ += mip_bytes(s.format, s.width, s.height, e.mip.value);
        break;
      }
      case TextureEvent::Kind::kInvalidated:
        leave(t, uses_[t].resident);
        break;
      case TextureEvent::Kind::kTrimmed:
        if (e.mip.value < kMaxLevels) leave(t, uses_[t].resident & ((1u << e.mip.value) - 1));
        break;
      case TextureEvent::Kind::kFailed:
      case TextureEvent::Kind::kRejected:
      case TextureEvent::Kind::kNoRoom:
        break;  // nothing was uploaded
    }
  }
}

ResidentLevels MipUseLedger::levels(TextureId texture) const {
  if (texture.value >= uses_.size()) return {};
  return levels_of(uses_[texture.value].resident, shapes_[texture.value].mip_count);
}

double MipUseLedger::observe(std::span<const StreamCandidate> list) {
  for (const StreamCandidate& c : list) {
    if (c.texture.value >= uses_.size() || !std::isfinite(c.desired_mip)) continue;
    Use& u = uses_[c.texture.value];
    const ResidentLevels l = levels_of(u.resident, shapes_[c.texture.value].mip_count);
    if (!l.finest) continue;
    const double d = std::clamp(static_cast<double>(c.desired_mip), static_cast<double>(*l.finest),
                                static_cast<double>(*l.coarsest));
    u.displayed |= 1u << static_cast<uint32_t>(std::floor(d));
    u.displayed |= 1u << static_cast<uint32_t>(std::ceil(d));  // the same level unless d is fractional
  }
  return weighted_mip_deficit(list, [this](TextureId t) { return levels(t); });
}

void MipUseLedger::finish() {
  for (uint32_t t = 0; t < uses_.size(); ++t) {
    if (uses_[t].resident) leave(t, uses_[t].resident);
  }
}

double MipUseLedger::wasted_fraction() const {
  if (bytes_uploaded_ == 0) return std::numeric_limits<double>::quiet_NaN();
  return static_cast<double>(bytes_wasted_) / static_cast<double>(bytes_uploaded_);
}

}  // namespace texstream::stream
