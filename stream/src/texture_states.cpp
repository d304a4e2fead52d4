#include "texstream/stream/texture_states.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <utility>

#include "texstream/common/contract.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::stream {

const char* to_string(TexturePhase phase) {
  switch (phase) {
    case TexturePhase::kInitial:
      return "initial";
    case TexturePhase::kActive:
      return "active";
    case TexturePhase::kFinal:
      return "final";
  }
  return "?";
}

uint32_t initial_mip_level(const TextureShape& shape) {
  // Seed 000 Algorithm 1: "Set the initial mipmap level to load. We use the 4x4 mipmap."
  constexpr uint32_t kInitialExtentLog2 = 2;  // 4 texels
  const uint32_t top = floor_log2(std::max(shape.width, shape.height));
  const uint32_t level = top >= kInitialExtentLog2 ? top - kInitialExtentLog2 : 0;
  return shape.mip_count == 0 ? 0 : std::min(level, shape.mip_count - 1);
}

TextureStates::TextureStates(TextureTable shapes, uint32_t levels_in_flight)
    : shapes_(std::move(shapes)), levels_in_flight_(std::max<uint32_t>(levels_in_flight, 1)) {
  for (const TextureShape& shape : shapes_) {
    if (shape.mip_count == 0) ++broken_from_start_;
  }
}

uint32_t TextureStates::frontier(const State& s) {
  const uint32_t covered = s.resident | s.pending;
  return covered == 0 ? kNone : sampled_run(covered).finest;
}

TexturePhase TextureStates::phase_of(const State& s) {
  const uint32_t f = frontier(s);
  if (f == kNone) return TexturePhase::kInitial;
  return f == 0 ? TexturePhase::kFinal : TexturePhase::kActive;
}

std::optional<uint32_t> TextureStates::next_mip(const State& s, uint32_t texture, float desired, float bias) const {
  if (s.broken) return std::nullopt;
  // levels_in_flight = 1: "one request per texture in flight" (Algorithm 1).
  if (static_cast<uint32_t>(std::popcount(s.pending)) >= levels_in_flight_) return std::nullopt;
  const uint32_t f = frontier(s);
  if (f == kNone) {
    // Initial. The shape is read only here and for a request's size: a texture that streams nothing this
    // cycle (most of the list, most frames) touches no record of the table.
    const TextureShape shape = shapes_[texture];
    if (shape.mip_count == 0) return std::nullopt;  // broken from start
    return initial_mip_level(shape);
  }
  // Algorithm 1: `if texture.mipLevelSampled + b < texture.mipLevel` → load mipLevel - 1, with mipLevel the
  // frontier (what is displayed once the pending levels arrive). Written so that a NaN from the GPU metadata
  // refines nothing; frontier 0 is Final.
  if (f == 0) return std::nullopt;
  if (desired + bias < static_cast<float>(f)) return f - 1u;
  return std::nullopt;
}

TextureStates::Entry* TextureStates::pending_entry(TextureId texture, MipLevel mip) {
  if (!contains(texture) || mip.value >= 32) return nullptr;
  Entry* e = states_.find(texture.value);
  if (e == nullptr || !(e->state.pending & (1u << mip.value))) return nullptr;
  return e;
}

void TextureStates::settle(Entry* e) {
  if (e->state.is_default()) states_.erase(e);
}

CycleResult TextureStates::run_cycle(std::span<const StreamCandidate> candidates, uint64_t load_bytes, float bias,
                                     const Sender& send, size_t max_requests) {
  CycleResult out;
  // Candidates (indices) sent a level in the pass before: only they can take another one in the next pass.
  std::vector<uint32_t>& sent_in_pass = pass_scratch_[0];
  std::vector<uint32_t>& next_pass = pass_scratch_[1];
  sent_in_pass.clear();
  sent_textures_.clear();
  enum class Visit : uint8_t { kNothing, kSent, kStop };
  auto visit = [&](const StreamCandidate& c, uint32_t pass) {
    Entry* e = states_.find(c.texture.value);  // valid until the insert below: send() cannot reach the table
    State s = e != nullptr ? e->state : State{};
    const std::optional<uint32_t> mip = next_mip(s, c.texture.value, c.desired_mip, bias);
    if (!mip) return Visit::kNothing;
    // Algorithm 1: "Stop streaming textures when the adaptive load size is reached" — tested before each
    // load, so the mip that first pushes the batch over s is still loaded.
    if (out.bytes > load_bytes) {
      out.stopped_by_load_size = true;
      return Visit::kStop;
    }
    if (out.sent.size() >= max_requests) {
      out.stopped_by_count = true;
      return Visit::kStop;
    }
    const TextureShape shape = shapes_[c.texture.value];
    // Pass k's level costs about 4^k times the first one's: its priority at the server is weight / 4^k.
    const float priority = std::ldexp(c.weight, -2 * static_cast<int>(pass));
    const MipRequest request{c.texture, MipLevel(*mip), priority,
                             mip_bytes(shape.format, shape.width, shape.height, *mip)};
    const SendResult r = send(request);
    if (r == SendResult::kStop) {
      out.stopped_by_sender = true;
      return Visit::kStop;
    }
    if (r == SendResult::kSkip) return Visit::kNothing;
    // Below 32: initial_mip_level or frontier - 1. Initial → Active; "Set to Final state as the highest
    // resolution mipmap will be streamed" when the level is mipLevelMin (the base level 0).
    s.pending |= 1u << *mip;
    if (e != nullptr) {
      e->state = s;
    } else {
      states_.insert(Entry{c.texture.value, s});
    }
    out.bytes += request.bytes;
    out.sent.push_back(request);
    return Visit::kSent;
  };
  // A texture listed twice (meshes sharing it) takes one level in the first pass, at its heaviest entry's
  // weight; with one level in flight its state already refuses the second.
  for (uint32_t i = 0; i < candidates.size(); ++i) {
    const StreamCandidate& c = candidates[i];
    if (!contains(c.texture)) {
      ++out.unknown_textures;
      continue;
    }
    if (levels_in_flight_ > 1 && sent_textures_.count(c.texture.value)) continue;
    const Visit v = visit(c, 0);
    if (v == Visit::kStop) return out;
    if (v == Visit::kSent && levels_in_flight_ > 1) {
      sent_in_pass.push_back(i);
      sent_textures_.insert(c.texture.value);
    }
  }
  for (uint32_t pass = 1; pass < levels_in_flight_ && !sent_in_pass.empty(); ++pass) {
    next_pass.clear();
    for (const uint32_t i : sent_in_pass) {
      const Visit v = visit(candidates[i], pass);
      if (v == Visit::kStop) return out;
      if (v == Visit::kSent) next_pass.push_back(i);
    }
    sent_in_pass.swap(next_pass);
  }
  return out;
}

bool TextureStates::on_committed(TextureId texture, MipLevel mip) {
  Entry* e = pending_entry(texture, mip);
  if (e == nullptr) return false;
  State& s = e->state;
  s.pending &= ~(1u << mip.value);
  s.resident |= 1u << mip.value;
  s.failures = 0;
  return true;
}

bool TextureStates::on_failed(TextureId texture, MipLevel mip, CompletionStatus status) {
  Entry* e = pending_entry(texture, mip);
  if (e == nullptr) return false;
  State& s = e->state;
  // The level is no longer pending: the frontier is back before it (Initial when nothing else is resident or
  // pending; a base level that failed leaves the texture Active), and the next cycle asks for it again.
  s.pending &= ~(1u << mip.value);
  switch (status) {
    case CompletionStatus::kNotFound:
    case CompletionStatus::kCorrupt:
      s.broken = true;  // the file is missing or does not match its header: asking again cannot help
      break;
    case CompletionStatus::kIoError:
      if (++s.failures >= kMaxCountedFailures) s.broken = true;
      break;
    case CompletionStatus::kOk:  // a kOk that the caller reports as failed: treat as a rejected payload
      if (++s.failures >= kMaxCountedFailures) s.broken = true;
      break;
    case CompletionStatus::kUnfilled:
    case CompletionStatus::kCancelled:
    case CompletionStatus::kTimedOut:
      break;  // not the texture's fault: the next cycle asks again
  }
  settle(e);
  return true;
}

bool TextureStates::on_rejected(TextureId texture, MipLevel mip) {
  Entry* e = pending_entry(texture, mip);
  if (e == nullptr) return false;
  e->state.pending &= ~(1u << mip.value);
  if (++e->state.failures >= kMaxCountedFailures) e->state.broken = true;
  return true;
}

bool TextureStates::on_no_room(TextureId texture, MipLevel mip) {
  Entry* e = pending_entry(texture, mip);
  if (e == nullptr) return false;
  e->state.pending &= ~(1u << mip.value);
  settle(e);
  return true;
}

void TextureStates::on_trimmed(TextureId texture, MipLevel finest) {
  if (!contains(texture)) return;
  Entry* e = states_.find(texture.value);
  if (e == nullptr) return;  // nothing resident
  State& s = e->state;
  // A level the texture does not have, or one not resident, would leave it resident at nothing (the cache
  // always keeps one level).
  if (finest.value >= shapes_[texture.value].mip_count || finest.value >= 32 || !(s.resident & (1u << finest.value)))
    return;
  s.resident &= ~((1u << finest.value) - 1u);  // the levels finer than `finest` are gone
}

void TextureStates::invalidate(TextureId texture) {
  if (!contains(texture)) return;
  Entry* e = states_.find(texture.value);
  if (e == nullptr) return;  // already Initial with nothing resident or pending
  State& s = e->state;
  s.resident = 0;
  s.pending = 0;
  settle(e);  // gone unless broken or with counted failures
}

TextureStateView TextureStates::view(TextureId texture) const {
  TS_ASSERT(contains(texture), "texture %u outside the table of %zu", texture.value, shapes_.size());
  const Entry* e = states_.find(texture.value);
  const State s = e != nullptr ? e->state : State{};
  TextureStateView v{phase_of(s),
                     std::nullopt,
                     std::nullopt,
                     static_cast<uint32_t>(std::popcount(s.pending)),
                     s.broken || shapes_[texture.value].mip_count == 0,
                     s.failures};
  if (s.resident != 0) v.resident = sampled_run(s.resident).finest;
  if (s.pending != 0) v.pending = static_cast<uint32_t>(std::countr_zero(s.pending));
  return v;
}

TextureStateCounts TextureStates::counts() const {
  TextureStateCounts c;
  states_.for_each([&c](const Entry& e) {
    const State& s = e.state;
    if (s.broken) {
      ++c.broken;
      return;
    }
    if (s.pending != 0) ++c.pending;
    switch (phase_of(s)) {
      case TexturePhase::kInitial:
        ++c.initial;
        break;
      case TexturePhase::kActive:
        ++c.active;
        break;
      case TexturePhase::kFinal:
        ++c.final;
        break;
    }
  });
  // Textures without an entry: Initial, or broken when their shape has no mips (those never get one).
  c.broken += broken_from_start_;
  c.initial += shapes_.size() - states_.size() - broken_from_start_;
  return c;
}

void TextureStates::apply(std::span<const TextureEvent> events) {
  for (const TextureEvent& e : events) {
    switch (e.kind) {
      case TextureEvent::Kind::kCommitted:
        on_committed(e.texture, e.mip);
        break;
      case TextureEvent::Kind::kFailed:
        on_failed(e.texture, e.mip, e.status);
        break;
      case TextureEvent::Kind::kRejected:
        on_rejected(e.texture, e.mip);
        break;
      case TextureEvent::Kind::kInvalidated:
        invalidate(e.texture);
        break;
      case TextureEvent::Kind::kNoRoom:
        on_no_room(e.texture, e.mip);
        break;
      case TextureEvent::Kind::kTrimmed:
        on_trimmed(e.texture, e.mip);
        break;
    }
  }
}

}  // namespace texstream::stream
