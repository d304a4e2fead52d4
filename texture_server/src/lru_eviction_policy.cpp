#include "texstream/server/lru_eviction_policy.hpp"

namespace texstream::server {

void LruEvictionPolicy::on_insert(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) {
    order_.splice(order_.begin(), order_, it->second);
    return;
  }
  order_.push_front(key);
  where_.emplace(key, order_.begin());
}

void LruEvictionPolicy::on_access(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) order_.splice(order_.begin(), order_, it->second);
}

void LruEvictionPolicy::on_erase(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) {
    order_.erase(it->second);
    where_.erase(it);
  }
}

std::optional<MipKey> LruEvictionPolicy::pick_victim(const std::function<bool(MipKey)>& evictable) {
  for (auto it = order_.rbegin(); it != order_.rend(); ++it) {
    if (evictable(*it)) return *it;
  }
  return std::nullopt;
}

}  // namespace texstream::server
