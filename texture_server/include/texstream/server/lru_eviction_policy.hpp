#pragma once
// Least recently used first: a recency list plus an index into it; every operation O(1) except pick_victim,
// which walks past pinned entries from the cold end.
#include <list>
#include <unordered_map>

#include "texstream/server/eviction_policy.hpp"

namespace texstream::server {

class LruEvictionPolicy final : public EvictionPolicy {
 public:
  PolicyNode* on_insert(MipKey key) override;
  void on_access(MipKey key) override;
  void on_erase(MipKey key) override;
  void touch(PolicyNode* node) override;
  void erase(PolicyNode* node) override;
  std::optional<MipKey> pick_victim(const std::function<bool(MipKey)>& evictable) override;

 private:
  using Where = std::unordered_map<MipKey, std::list<MipKey>::iterator, MipKeyHash>;
  // A node is the address of a where_ element (unordered_map never moves its elements).
  static PolicyNode* node_of(Where::value_type& e) { return reinterpret_cast<PolicyNode*>(&e); }
  static Where::value_type& element_of(PolicyNode* n) { return *reinterpret_cast<Where::value_type*>(n); }

  std::list<MipKey> order_;  // front = most recently used
  Where where_;
};

}  // namespace texstream::server
