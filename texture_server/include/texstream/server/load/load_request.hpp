#pragma once
// One load the renderer asked for, as the dispatcher schedules it and the loader answers it.
#include <cstdint>

#include "texstream/common/ids.hpp"
#include "texstream/server/cache/mip_key.hpp"

namespace texstream::server {

struct LoadRequest {
  TextureId texture;
  MipLevel mip;
  Generation generation;
  float priority = 0;        // larger = sooner; finite (the dispatcher drops NaN)
  uint64_t received_ns = 0;  // steady clock when taken off the ring (latency statistics only)

  MipKey key() const { return MipKey(texture, mip); }
};

}  // namespace texstream::server
