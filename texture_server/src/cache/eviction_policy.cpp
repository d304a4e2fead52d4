#include "texstream/server/cache/eviction_policy.hpp"

#include "texstream/server/cache/level_eviction_policy.hpp"
#include "texstream/server/cache/lru_eviction_policy.hpp"

namespace texstream::server {

Result<std::unique_ptr<EvictionPolicy>> make_eviction_policy(const std::string& name,
                                                             std::function<uint32_t(MipKey)> level_of) {
  if (name == "lru") return std::unique_ptr<EvictionPolicy>(new LruEvictionPolicy());
  if (name == "level") return std::unique_ptr<EvictionPolicy>(new LevelEvictionPolicy(std::move(level_of)));
  return make_error(ErrorCode::kInvalidArgument, "server.cache_policy must be lru or level, not '" + name + "'");
}

}  // namespace texstream::server
