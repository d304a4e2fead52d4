#pragma once
// Pending loads, best first (DESIGN.md "Texture server": a max-heap by priority across pending requests).
//
// Seed 002 §4.3 keeps the Texture Server's request queue short so that it never works on stale requests;
// here the renderer's pre-queue arrives as one batch per streaming cycle (a generation) and the server drops
// what a newer cycle no longer asks for:
// - Duplicates of (texture, mip) coalesce: the pending entry keeps the larger priority and the newer
//   generation; the request that lost (normally the older one) is handed back to be answered kCancelled,
//   so every request still gets exactly one completion.
// - A request older than the newest generation seen is stale on arrival and is handed back at once.
// - supersede_older_than(g) removes every pending request of a generation < g: a request re-sent in g
//   was coalesced into g above, so what remains older was not asked for again.
// Only the dispatcher thread uses it (not thread-safe). Ties in priority are served first come, first served.
#include <cstdint>
#include <optional>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/server/cache/flat_mip_map.hpp"
#include "texstream/server/cache/mip_key.hpp"
#include "texstream/server/load/load_request.hpp"

namespace texstream::server {

class RequestScheduler {
 public:
  // Queues `request`. Returns the request that must be answered kCancelled because of it, if any: the older
  // of two duplicates, or `request` itself when its generation is older than the newest seen.
  std::optional<LoadRequest> add(const LoadRequest& request);
  // Removes every pending request with generation < `generation`, appending them to `cancelled`.
  void supersede_older_than(Generation generation, std::vector<LoadRequest>& cancelled);
  // The best pending request, without removing it.
  std::optional<LoadRequest> top();
  std::optional<LoadRequest> pop();
  // The key of the heap's top node without checking that it is still pending (a stale node's key is
  // possible): only a hint, e.g. for prefetching what pop() will most likely return next.
  std::optional<MipKey> peek_key_hint() const {
    if (heap_.empty()) return std::nullopt;
    return heap_.front().key;
  }

  // True if a load of `key` is pending (queued, not yet popped).
  bool contains(MipKey key) const { return pending_.find(key) != nullptr; }
  size_t size() const { return pending_.size(); }
  bool empty() const { return pending_.empty(); }
  Generation newest_generation() const { return newest_; }

 private:
  struct Pending {
    LoadRequest request;
    uint64_t sequence;  // arrival order: FIFO among equal priorities
    // Unique across the scheduler's life (drawn from next_sequence_), renewed when the priority is raised:
    // a heap node whose version differs is stale. Per-entry counters starting at 0 let a node left behind by
    // a removed entry pass for the node of a later request for the same mip, serving it at the old priority.
    uint64_t version;
  };
  struct HeapNode {
    float priority;
    uint64_t sequence;
    MipKey key;
    uint64_t version;
  };
  struct NodeLess {
    bool operator()(const HeapNode& a, const HeapNode& b) const {
      if (a.priority != b.priority) return a.priority < b.priority;
      return a.sequence > b.sequence;
    }
  };

  void push_node(const Pending& p);
  // Pops stale nodes off the heap; the top node's pending entry (valid until the next change), or nullptr.
  const Pending* drop_stale_top();
  void compact_heap();

  FlatMipMap<Pending> pending_;  // (flat_mip_map.hpp: no allocation per request)
  // Lazy deletion: nodes of removed or re-prioritised entries stay until they reach the top or the heap is
  // rebuilt (when stale nodes outnumber live ones), so every operation stays O(log n) amortised.
  std::vector<HeapNode> heap_;
  uint64_t next_sequence_ = 0;
  Generation newest_{0};
  Generation superseded_through_{0};  // supersede_older_than() has run for this generation
};

}  // namespace texstream::server
