#include "texstream/stream/texture_states.hpp"

#include <algorithm>
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

TextureStates::TextureStates(TextureTable shapes) : shapes_(std::move(shapes)) {
  for (const TextureShape& shape : shapes_) {
    if (shape.mip_count == 0) ++broken_from_start_;
  }
}

std::optional<uint32_t> TextureStates::next_mip(const State& s, uint32_t texture, float desired, float bias) const {
  if (s.broken || s.pending != kNone) return std::nullopt;  // one request per texture in flight
  switch (s.phase) {
    case TexturePhase::kFinal:
      return std::nullopt;
    case TexturePhase::kInitial: {
      // The shape is read only here and for a request's size: a texture that streams nothing this cycle
      // (most of the list, most frames) touches no record of the table.
      const TextureShape shape = shapes_[texture];
      if (shape.mip_count == 0) return std::nullopt;  // broken from start
      return initial_mip_level(shape);
    }
    case TexturePhase::kActive:
      // Algorithm 1: `if texture.mipLevelSampled + b < texture.mipLevel` → load mipLevel - 1. Written so
      // that a NaN from the GPU metadata refines nothing. resident is set in Active with nothing pending
      // (roll_back returns a texture with nothing resident to Initial), and resident > 0 (0 is Final).
      if (s.resident == kNone || s.resident == 0) return std::nullopt;
      if (desired + bias < static_cast<float>(s.resident)) return s.resident - 1u;
      return std::nullopt;
  }
  return std::nullopt;
}

void TextureStates::roll_back(State& s) {
  s.pending = kNone;
  // Nothing displayed: the texture is as if never loaded (the Initial request failed, or the base mip of a
  // tiny texture whose initial level is 0). Otherwise it stays Active and refines again from `resident`.
  s.phase =
      s.resident == kNone ? TexturePhase::kInitial : (s.resident == 0 ? TexturePhase::kFinal : TexturePhase::kActive);
}

TextureStates::Entry* TextureStates::pending_entry(TextureId texture, MipLevel mip) {
  if (!contains(texture)) return nullptr;
  Entry* e = states_.find(texture.value);
  if (e == nullptr || e->state.pending == kNone || e->state.pending != mip.value) return nullptr;
  return e;
}

void TextureStates::settle(Entry* e) {
  if (e->state.is_default()) states_.erase(e);
}

CycleResult TextureStates::run_cycle(std::span<const StreamCandidate> candidates, uint64_t load_bytes, float bias,
                                     const Sender& send, size_t max_requests) {
  CycleResult out;
  for (const StreamCandidate& c : candidates) {
    if (!contains(c.texture)) {
      ++out.unknown_textures;
      continue;
    }
    Entry* e = states_.find(c.texture.value);  // valid until the insert below: send() cannot reach the table
    State s = e != nullptr ? e->state : State{};
    const std::optional<uint32_t> mip = next_mip(s, c.texture.value, c.desired_mip, bias);
    if (!mip) continue;
    // Algorithm 1: "Stop streaming textures when the adaptive load size is reached" — tested before each
    // load, so the mip that first pushes the batch over s is still loaded.
    if (out.bytes > load_bytes) {
      out.stopped_by_load_size = true;
      break;
    }
    if (out.sent.size() >= max_requests) {
      out.stopped_by_count = true;
      break;
    }
    const TextureShape shape = shapes_[c.texture.value];
    const MipRequest request{c.texture, MipLevel(*mip), c.weight,
                             mip_bytes(shape.format, shape.width, shape.height, *mip)};
    const SendResult r = send(request);
    if (r == SendResult::kStop) {
      out.stopped_by_sender = true;
      break;
    }
    if (r == SendResult::kSkip) continue;
    s.pending = static_cast<uint8_t>(*mip);  // below 32 (kNone): initial_mip_level or resident - 1
    // Initial → Active; "Set to Final state as the highest resolution mipmap will be streamed" when the
    // level is mipLevelMin (the base level 0), also straight from Initial for a texture smaller than 4x4.
    s.phase = *mip == 0 ? TexturePhase::kFinal : TexturePhase::kActive;
    if (e != nullptr) {
      e->state = s;
    } else {
      states_.insert(Entry{c.texture.value, s});
    }
    out.bytes += request.bytes;
    out.sent.push_back(request);
  }
  return out;
}

bool TextureStates::on_committed(TextureId texture, MipLevel mip) {
  Entry* e = pending_entry(texture, mip);
  if (e == nullptr) return false;
  State& s = e->state;
  s.pending = kNone;
  s.resident = static_cast<uint8_t>(mip.value);  // the pending level's value
  s.failures = 0;
  s.phase = mip.value == 0 ? TexturePhase::kFinal : TexturePhase::kActive;
  return true;
}

bool TextureStates::on_failed(TextureId texture, MipLevel mip, CompletionStatus status) {
  Entry* e = pending_entry(texture, mip);
  if (e == nullptr) return false;
  State& s = e->state;
  roll_back(s);
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
  roll_back(e->state);
  if (++e->state.failures >= kMaxCountedFailures) e->state.broken = true;
  return true;
}

bool TextureStates::on_no_room(TextureId texture, MipLevel mip) {
  Entry* e = pending_entry(texture, mip);
  if (e == nullptr) return false;
  roll_back(e->state);
  settle(e);
  return true;
}

void TextureStates::on_trimmed(TextureId texture, MipLevel finest) {
  if (!contains(texture)) return;
  Entry* e = states_.find(texture.value);
  if (e == nullptr) return;  // nothing resident
  State& s = e->state;
  // A level the texture does not have would leave it resident at nothing (the cache always keeps one level).
  if (s.resident == kNone || s.resident >= finest.value || finest.value >= shapes_[texture.value].mip_count ||
      finest.value >= kNone)
    return;
  s.resident = static_cast<uint8_t>(finest.value);
  if (s.pending == kNone) s.phase = finest.value == 0 ? TexturePhase::kFinal : TexturePhase::kActive;
}

void TextureStates::invalidate(TextureId texture) {
  if (!contains(texture)) return;
  Entry* e = states_.find(texture.value);
  if (e == nullptr) return;  // already Initial with nothing resident or pending
  State& s = e->state;
  s.phase = TexturePhase::kInitial;
  s.resident = kNone;
  s.pending = kNone;
  settle(e);  // gone unless broken or with counted failures
}

TextureStateView TextureStates::view(TextureId texture) const {
  TS_ASSERT(contains(texture), "texture %u outside the table of %zu", texture.value, shapes_.size());
  const Entry* e = states_.find(texture.value);
  const State s = e != nullptr ? e->state : State{};
  TextureStateView v{s.phase, std::nullopt, std::nullopt, s.broken || shapes_[texture.value].mip_count == 0,
                     s.failures};
  if (s.resident != kNone) v.resident = s.resident;
  if (s.pending != kNone) v.pending = s.pending;
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
    if (s.pending != kNone) ++c.pending;
    switch (s.phase) {
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
