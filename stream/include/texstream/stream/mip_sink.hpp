#pragma once
// Where completed mips go: implemented by the renderer (TextureCache), called only from within
// StreamClient::poll (and restart_server). No Vulkan here: the sink says where a mip's bytes go.
#include <cstddef>
#include <cstdint>
#include <span>

#include "texstream/common/ids.hpp"
#include "texstream/protocol/records.hpp"

namespace texstream::stream {

class MipSink {
 public:
  virtual ~MipSink() = default;
  // Room for `bytes` of (texture, mip), or an empty span for "no room now": the completion then stays
  // pending (its slot still ours) and is offered again first by the next poll. A non-empty span must hold
  // at least `bytes` bytes (a shorter one is a bug of the sink and aborts).
  virtual std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) = 0;
  // `data` (the first `bytes` of the reserved span) holds the mip, checksum verified.
  virtual void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) = 0;
  // The answer for (texture, mip) was refused: a record that failed validation (then `reserved` is
  // empty), or a payload whose checksum did not match (then `reserved` is the span reserve() gave, free
  // again). Nothing is uploaded; the texture state machine counts it and asks again.
  virtual void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) = 0;
  // The request ended without a payload: the server's status, or kCancelled for a request lost with a
  // dead or restarted server. The texture state machine decides whether to ask again.
  virtual void failed(TextureId texture, MipLevel mip, CompletionStatus status) = 0;
};

}  // namespace texstream::stream
