#pragma once
// Least recently used first: a recency list plus an index into it; every operation O(1) except pick_victim,
// which walks past pinned entries from the cold end.
#include <list>
#include <unordered_map>

#include "texstream/server/cache/eviction_policy.hpp"
#include "texstream/server/cache/node_pool.hpp"

namespace texstream::server {

class LruEvictionPolicy final : public EvictionPolicy {
 public:
  LruEvictionPolicy() : order_(PoolAllocator<Node>(pool_)) {}

  PolicyNode* on_insert(MipKey key) override;
  PolicyNode* insert_new(MipKey key) override;
  void on_access(MipKey key) override;
  void on_erase(MipKey key) override;
  void touch(PolicyNode* node) override;
  void erase(PolicyNode* node) override;
  std::optional<MipKey> pick_victim(const std::function<bool(MipKey)>& evictable) override;
  void reserve(size_t entries) override { pool_.reserve(entries); }

 private:
  struct Node;
  using List = std::list<Node, PoolAllocator<Node>>;
  struct Node {
    MipKey key;
    bool indexed;         // entered in where_ (on_insert), not only reachable through its node (insert_new)
    List::iterator self;  // this node's own position (list iterators survive splices)
  };
  // A policy node is the address of the list element itself (list elements never move).
  static PolicyNode* node_of(Node& n) { return reinterpret_cast<PolicyNode*>(&n); }
  static Node& element_of(PolicyNode* n) { return *reinterpret_cast<Node*>(n); }
  PolicyNode* push(MipKey key, bool indexed);

  NodePool pool_;  // the list's nodes (before order_: destroyed after it)
  List order_;     // front = most recently used
  std::unordered_map<MipKey, List::iterator, MipKeyHash> where_;  // keys tracked through on_insert()
};

}  // namespace texstream::server
