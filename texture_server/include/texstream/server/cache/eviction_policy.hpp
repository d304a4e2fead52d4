#pragma once
// Which cached mip goes first when the RAM cache is over budget. The cache owns the entries and the byte
// accounting; a policy only orders keys. LRU is the default (seed 002 §4.4 uses LRU for the in-memory cache);
// LevelEvictionPolicy is the discard priority p_d = f(l + 1) of seed 002 Eq. 4 (server.cache_policy).
// Called only with the cache's lock held, so implementations need no locking of their own.
//
// Handles: on_insert() returns the policy's own node for the key (stable until the key is erased), which the
// cache keeps in its entry, so that a hit touches the policy without a second hash lookup (touch()).
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "texstream/common/config.hpp"
#include "texstream/common/result.hpp"

#include "texstream/server/cache/mip_key.hpp"

namespace texstream::server {

// Opaque: what a policy's on_insert() returns; only that policy looks inside.
struct PolicyNode;

class EvictionPolicy {
 public:
  virtual ~EvictionPolicy() = default;
  // Starts tracking `key` (or touches it if tracked) and returns its node.
  virtual PolicyNode* on_insert(MipKey key) = 0;
  // Starts tracking `key`, which the caller guarantees is not tracked yet (the cache looks in its own index
  // first), and returns its node; the node API (touch(), erase()) is then the only way to reach it: such a
  // key is not entered in the policy's own key index, which on_access() / on_erase() by key use. Saves a hash
  // insert on every cache insert and a hash erase on every eviction (texstream-bench server, misses: the
  // level policy's index insert was ~9 % of the dispatcher's time, cache misses on its buckets and nodes).
  virtual PolicyNode* insert_new(MipKey key) { return on_insert(key); }
  virtual void on_access(MipKey key) = 0;
  virtual void on_erase(MipKey key) = 0;
  // on_access() / on_erase() through the node on_insert() returned for the key (no lookup).
  virtual void touch(PolicyNode* node) = 0;
  virtual void erase(PolicyNode* node) = 0;
  // The key to evict first among those for which `evictable` is true (pinned entries are not), or nullopt.
  // An empty `evictable`: every key is (the cache has no pin out), and none is asked about.
  virtual std::optional<MipKey> pick_victim(const std::function<bool(MipKey)>& evictable) = 0;
  // The clock advanced to `now` (the server's streaming-cycle generation: the "frames" of Eq. 4). Policies
  // that order by recency alone ignore it.
  virtual void on_tick(uint64_t now) { (void)now; }
  // About `entries` keys will be tracked: allocate what can be allocated up front (the cache calls this once,
  // at construction, so that inserts while misses fill it do not grow tables).
  virtual void reserve(size_t entries) { (void)entries; }
};

// server.cache_policy: lru or level (which needs each key's quadtree level, see level_eviction_policy.hpp).
std::unique_ptr<EvictionPolicy> make_eviction_policy(RamCachePolicy policy, std::function<uint32_t(MipKey)> level_of);
// The same from its name (benches and tests). Errors: kInvalidArgument naming the key and the allowed values.
Result<std::unique_ptr<EvictionPolicy>> make_eviction_policy(const std::string& name,
                                                             std::function<uint32_t(MipKey)> level_of);

}  // namespace texstream::server
