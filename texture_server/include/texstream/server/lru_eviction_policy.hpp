#pragma once
// Least recently used first: a recency list plus an index into it; every operation O(1) except pick_victim,
// which walks past pinned entries from the cold end.
#include <list>
#include <unordered_map>

#include "texstream/server/eviction_policy.hpp"

namespace texstream::server {

class LruEvictionPolicy final : public EvictionPolicy {
 public:
  void on_insert(MipKey key) override;
  void on_access(MipKey key) override;
  void on_erase(MipKey key) override;
  std::optional<MipKey> pick_victim(const std::function<bool(MipKey)>& evictable) override;

 private:
  std::list<MipKey> order_;  // front = most recently used
  std::unordered_map<MipKey, std::list<MipKey>::iterator, MipKeyHash> where_;
};

}  // namespace texstream::server
