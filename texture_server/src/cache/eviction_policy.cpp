#include "texstream/server/cache/eviction_policy.hpp"

#include "texstream/common/contract.hpp"
#include "texstream/server/cache/level_eviction_policy.hpp"
#include "texstream/server/cache/lru_eviction_policy.hpp"

namespace texstream::server {

std::unique_ptr<EvictionPolicy> make_eviction_policy(RamCachePolicy policy, std::function<uint32_t(MipKey)> level_of) {
  switch (policy) {
    case RamCachePolicy::kLru:
      return std::make_unique<LruEvictionPolicy>();
    case RamCachePolicy::kLevel:
      return std::make_unique<LevelEvictionPolicy>(std::move(level_of));
  }
  TS_UNREACHABLE("server.cache_policy %d is outside its table", static_cast<int>(policy));
}

Result<std::unique_ptr<EvictionPolicy>> make_eviction_policy(const std::string& name,
                                                             std::function<uint32_t(MipKey)> level_of) {
  Result<RamCachePolicy> policy = parse_choice<RamCachePolicy>("server.cache_policy", name);
  if (!policy.ok()) return policy.error();
  return make_eviction_policy(*policy, std::move(level_of));
}

}  // namespace texstream::server
