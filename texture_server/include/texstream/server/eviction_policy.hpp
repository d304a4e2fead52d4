#pragma once
// Which cached mip goes first when the RAM cache is over budget. The cache owns the entries and the byte
// accounting; a policy only orders keys. LRU is the default (seed 002 §4.4 uses LRU for the in-memory cache);
// a later issue can plug in the discard priority p_d = f(l + 1) of seed 002 Eq. 4 behind the same interface.
// Called only with the cache's lock held, so implementations need no locking of their own.
#include <functional>
#include <optional>

#include "texstream/server/mip_key.hpp"

namespace texstream::server {

class EvictionPolicy {
 public:
  virtual ~EvictionPolicy() = default;
  virtual void on_insert(MipKey key) = 0;
  virtual void on_access(MipKey key) = 0;
  virtual void on_erase(MipKey key) = 0;
  // The key to evict first among those for which `evictable` is true (pinned entries are not), or nullopt.
  virtual std::optional<MipKey> pick_victim(const std::function<bool(MipKey)>& evictable) = 0;
};

}  // namespace texstream::server
