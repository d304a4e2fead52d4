#include "texstream/server/cache/lru_eviction_policy.hpp"

namespace texstream::server {

PolicyNode* LruEvictionPolicy::on_insert(MipKey key) {
  // One hash lookup for both cases (find + emplace was two).
  const auto [it, fresh] = where_.try_emplace(key);
  if (!fresh) {
    order_.splice(order_.begin(), order_, it->second);
    return node_of(*it->second);
  }
  PolicyNode* node = push(key, /*indexed=*/true);
  it->second = order_.begin();
  return node;
}

PolicyNode* LruEvictionPolicy::insert_new(MipKey key) { return push(key, /*indexed=*/false); }

PolicyNode* LruEvictionPolicy::push(MipKey key, bool indexed) {
  order_.push_front(Node{key, indexed, {}});
  order_.front().self = order_.begin();
  return node_of(order_.front());
}

void LruEvictionPolicy::touch(PolicyNode* node) { order_.splice(order_.begin(), order_, element_of(node).self); }

void LruEvictionPolicy::erase(PolicyNode* node) {
  Node& n = element_of(node);
  const MipKey key = n.key;  // copies: the list erase below frees the node
  const bool indexed = n.indexed;
  order_.erase(n.self);
  if (indexed) where_.erase(key);
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
    if (!evictable || evictable(it->key)) return it->key;
  }
  return std::nullopt;
}

}  // namespace texstream::server
