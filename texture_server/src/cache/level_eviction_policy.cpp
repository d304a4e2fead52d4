#include "texstream/server/cache/level_eviction_policy.hpp"

#include <algorithm>
#include <array>

namespace texstream::server {

LevelEvictionPolicy::LevelEvictionPolicy(std::function<uint32_t(MipKey)> level_of)
    : level_of_(std::move(level_of)), levels_(make_levels(pool_, std::make_index_sequence<kMaxLevels>{})) {}

void LevelEvictionPolicy::touch(Node& n) {
  List& list = levels_[n.level];
  n.last_used = now_;
  n.sequence = ++sequence_;
  list.splice(list.begin(), list, n.self);
}

PolicyNode* LevelEvictionPolicy::on_insert(MipKey key) {
  // One hash lookup for both cases (a find, then an emplace, was two: perf of a miss's cache inserts).
  const auto [where, fresh] = where_.try_emplace(key);
  if (!fresh) {
    touch(*where->second);
    return node_of(*where->second);
  }
  PolicyNode* node = push(key, /*indexed=*/true);
  where->second = element_of(node).self;
  return node;
}

PolicyNode* LevelEvictionPolicy::insert_new(MipKey key) { return push(key, /*indexed=*/false); }

PolicyNode* LevelEvictionPolicy::push(MipKey key, bool indexed) {
  const uint32_t level = std::min(level_of_(key), kMaxLevels - 1);
  List& list = levels_[level];
  list.push_front(Node{key, now_, ++sequence_, level, indexed, {}});
  list.front().self = list.begin();
  return node_of(list.front());
}

void LevelEvictionPolicy::touch(PolicyNode* node) { touch(element_of(node)); }

void LevelEvictionPolicy::erase(PolicyNode* node) {
  Node& n = element_of(node);
  const MipKey key = n.key;  // copies: the list erase below frees the node
  const bool indexed = n.indexed;
  levels_[n.level].erase(n.self);
  if (indexed) where_.erase(key);
}

void LevelEvictionPolicy::on_access(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) touch(*it->second);
}

void LevelEvictionPolicy::on_erase(MipKey key) {
  if (auto it = where_.find(key); it != where_.end()) {
    levels_[it->second->level].erase(it->second);
    where_.erase(it);
  }
}

void LevelEvictionPolicy::on_tick(uint64_t now) { now_ = std::max(now_, now); }

std::optional<MipKey> LevelEvictionPolicy::pick_victim(const std::function<bool(MipKey)>& evictable) {
  // Each level's candidate is its least recently used entry that nobody holds (the tail, the largest f, unless
  // pinned); the victim is the candidate with the largest p_d. Only the winner is asked whether it is pinned:
  // asking every level's tail (a hash lookup each) was most of an eviction (perf of misses into a full
  // cache). A pinned winner gives way to the next entry of its level and the candidates are compared again,
  // which picks the same victim as asking every tail first.
  std::array<List::const_reverse_iterator, kMaxLevels> at;
  for (uint32_t level = 0; level < kMaxLevels; ++level) at[level] = levels_[level].crbegin();
  for (;;) {
    const Node* best = nullptr;
    uint32_t best_level = 0;
    uint64_t best_priority = 0;
    for (uint32_t level = 0; level < kMaxLevels; ++level) {
      if (at[level] == levels_[level].crend()) continue;
      const Node& n = *at[level];
      const uint64_t frames = now_ - std::min(now_, n.last_used);
      const uint64_t priority = frames * (uint64_t{level} + 1);  // Eq. 4: p_d = f (l + 1)
      if (!best || priority > best_priority || (priority == best_priority && n.sequence < best->sequence)) {
        best = &n;
        best_level = level;
        best_priority = priority;
      }
    }
    if (!best) return std::nullopt;
    if (!evictable || evictable(best->key)) return best->key;
    ++at[best_level];
  }
}

}  // namespace texstream::server
