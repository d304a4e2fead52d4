#include "texstream/server/lru_eviction_policy.hpp"

namespace texstream::server {

PolicyNode* LruEvictionPolicy::on_insert(MipKey key) {
  // One hash lookup for both cases (find + emplace was two).
  const auto [it, fresh] = where_.try_emplace(key);
  if (!fresh) {
    order_.splice(order_.begin(), order_, it->second);
    return node_of(*it);
  }
  order_.push_front(key);
  it->second = order_.begin();
  return node_of(*it);
}

void LruEvictionPolicy::touch(PolicyNode* node) {
  order_.splice(order_.begin(), order_, element_of(node).second);
}

void LruEvictionPolicy::erase(PolicyNode* node) {
  Where::value_type& e = element_of(node);
  order_.erase(e.second);
  const MipKey key = e.first;  // a copy: erase() must not read the key of the element it frees
  where_.erase(key);
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
