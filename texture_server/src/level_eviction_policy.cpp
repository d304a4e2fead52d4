#include "texstream/server/level_eviction_policy.hpp"

#include <algorithm>

namespace texstream::server {

LevelEvictionPolicy::LevelEvictionPolicy(std::function<uint32_t(MipKey)> level_of) : level_of_(std::move(level_of)) {}

void LevelEvictionPolicy::touch(const Where& w) {
  std::list<Node>& list = levels_[w.level];
  w.it->last_used = now_;
  w.it->sequence = ++sequence_;
  list.splice(list.begin(), list, w.it);
}

PolicyNode* LevelEvictionPolicy::on_insert(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) {
    touch(it->second);
    return node_of(*it);
  }
  const uint32_t level = std::min(level_of_(key), kMaxLevels - 1);
  std::list<Node>& list = levels_[level];
  list.push_front(Node{key, now_, ++sequence_});
  return node_of(*where_.emplace(key, Where{level, list.begin()}).first);
}

void LevelEvictionPolicy::touch(PolicyNode* node) { touch(element_of(node).second); }

void LevelEvictionPolicy::erase(PolicyNode* node) {
  WhereMap::value_type& e = element_of(node);
  levels_[e.second.level].erase(e.second.it);
  const MipKey key = e.first;  // a copy: erase() must not read the key of the element it frees
  where_.erase(key);
}

void LevelEvictionPolicy::on_access(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) touch(it->second);
}

void LevelEvictionPolicy::on_erase(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) {
    levels_[it->second.level].erase(it->second.it);
    where_.erase(it);
  }
}

void LevelEvictionPolicy::on_tick(uint64_t now) { now_ = std::max(now_, now); }

std::optional<MipKey> LevelEvictionPolicy::pick_victim(const std::function<bool(MipKey)>& evictable) {
  const Node* best = nullptr;
  uint64_t best_priority = 0;
  for (uint32_t level = 0; level < kMaxLevels; ++level) {
    const std::list<Node>& list = levels_[level];
    // The tail is this level's least recently used entry, the largest f; skip pinned ones.
    for (auto it = list.rbegin(); it != list.rend(); ++it) {
      if (!evictable(it->key)) continue;
      const uint64_t frames = now_ - std::min(now_, it->last_used);
      const uint64_t priority = frames * (uint64_t{level} + 1);  // Eq. 4: p_d = f (l + 1)
      if (!best || priority > best_priority || (priority == best_priority && it->sequence < best->sequence)) {
        best = &*it;
        best_priority = priority;
      }
      break;
    }
  }
  if (!best) return std::nullopt;
  return best->key;
}

}  // namespace texstream::server
