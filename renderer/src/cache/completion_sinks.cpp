#include "texstream/render/cache/completion_sinks.hpp"

#include <algorithm>

namespace texstream::render {

std::span<std::byte> LoadTimeSink::reserve(TextureId texture, MipLevel mip, uint64_t bytes) {
  if (taken_ > 0 && Clock::now() >= deadline_) {
    limited_ = true;
    return {};
  }
  auto span = inner_.reserve(texture, mip, bytes);
  if (!span.empty())
    ++taken_;
  else
    no_room_ = true;
  return span;
}

void OrderedCommitSink::flush() {
  std::sort(pending_.begin(), pending_.end(), [](const Pending& a, const Pending& b) {
    return a.texture != b.texture ? a.texture < b.texture : a.mip < b.mip;
  });
  for (const Pending& p : pending_) inner_.commit(p.texture, p.mip, p.data);
  pending_.clear();
}

}  // namespace texstream::render
