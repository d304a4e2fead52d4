#pragma once
// Seed 002 Eq. 4, the level-aware discard priority: p_d = f · (l + 1), where f is the number of frames since
// the tile was last used and l its quadtree level counting the root as zero. The entry with the largest p_d
// goes first, so among entries unused for equally long the finer levels (large l: big, cheap to lose for a
// while since a coarser level still draws) go before the coarse ones every texture needs first (seed 000
// §3.5 loads coarsest first). Here a "frame" is the server's clock: the renderer's streaming-cycle
// generation (on_tick); a mip's level l = mip_count - 1 - mip (the 1x1 mip is the root). Ties (e.g. f = 0 for
// everything used in the current cycle) go least recently used first.
//
// One LRU list per level; within a level the tail has the largest f, so a victim is the best of ≤ 32 tails:
// O(levels) per pick, O(1) otherwise. Called under the cache's lock (no locking of its own).
#include <array>
#include <cstdint>
#include <functional>
#include <list>
#include <unordered_map>
#include <utility>

#include "texstream/server/cache/eviction_policy.hpp"
#include "texstream/server/cache/node_pool.hpp"

namespace texstream::server {

class LevelEvictionPolicy final : public EvictionPolicy {
 public:
  static constexpr uint32_t kMaxLevels = 32;
  // `level_of(key)`: the mip's quadtree level l (0 = the coarsest, 1x1 mip). Values ≥ kMaxLevels are clamped.
  explicit LevelEvictionPolicy(std::function<uint32_t(MipKey)> level_of);

  PolicyNode* on_insert(MipKey key) override;
  PolicyNode* insert_new(MipKey key) override;
  void on_access(MipKey key) override;
  void on_erase(MipKey key) override;
  void touch(PolicyNode* node) override;
  void erase(PolicyNode* node) override;
  void on_tick(uint64_t now) override;
  std::optional<MipKey> pick_victim(const std::function<bool(MipKey)>& evictable) override;
  void reserve(size_t entries) override { pool_.reserve(entries); }

 private:
  struct Node;
  using List = std::list<Node, PoolAllocator<Node>>;
  struct Node {
    MipKey key;
    uint64_t last_used;  // clock value of the last use (f = now - last_used)
    uint64_t sequence;   // global use order: the tie break
    uint32_t level;
    bool indexed;         // entered in where_ (on_insert), not only reachable through its node (insert_new)
    List::iterator self;  // this node's own position (list iterators survive splices)
  };
  using WhereMap = std::unordered_map<MipKey, List::iterator, MipKeyHash>;
  template <size_t... I>
  static std::array<List, kMaxLevels> make_levels(NodePool& pool, std::index_sequence<I...>) {
    return {((void)I, List(PoolAllocator<Node>(pool)))...};
  }
  PolicyNode* push(MipKey key, bool indexed);
  // A policy node is the address of the list element itself (list elements never move), so a hit's touch
  // goes straight to it: no hop through where_'s hash node, which was one more cache miss per hit.
  static PolicyNode* node_of(Node& n) { return reinterpret_cast<PolicyNode*>(&n); }
  static Node& element_of(PolicyNode* n) { return *reinterpret_cast<Node*>(n); }
  void touch(Node& n);

  std::function<uint32_t(MipKey)> level_of_;
  NodePool pool_;                        // the lists' nodes (before levels_: destroyed after them)
  std::array<List, kMaxLevels> levels_;  // front = most recently used
  WhereMap where_;
  uint64_t now_ = 0;
  uint64_t sequence_ = 0;
};

}  // namespace texstream::server
