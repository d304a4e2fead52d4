#include "texstream/server/request_scheduler.hpp"

#include <algorithm>

namespace texstream::server {

void RequestScheduler::push_node(const Pending& p) {
  heap_.push_back({p.request.priority, p.sequence, p.request.key(), p.version});
  std::push_heap(heap_.begin(), heap_.end(), NodeLess{});
}

std::optional<LoadRequest> RequestScheduler::add(const LoadRequest& request) {
  if (request.generation < newest_) return request;  // stale on arrival: a newer cycle has already asked
  newest_ = request.generation;
  const MipKey key = request.key();
  auto it = pending_.find(key);
  if (it == pending_.end()) {
    const uint64_t sequence = next_sequence_++;
    Pending p{request, sequence, sequence};
    pending_.emplace(key, p);
    push_node(p);
    compact_heap();
    return std::nullopt;
  }
  // Coalesce. The pending entry lives on with the newer generation and the larger priority; the request it
  // replaces is the one answered kCancelled (its generation is what the renderer will see echoed).
  Pending& p = it->second;
  const LoadRequest superseded = p.request;
  const bool raise = request.priority > p.request.priority;
  p.request.generation = request.generation;
  if (raise) {
    p.request.priority = request.priority;
    p.version = next_sequence_++;
    push_node(p);
    compact_heap();
  }
  return superseded;
}

void RequestScheduler::supersede_older_than(Generation generation, std::vector<LoadRequest>& cancelled) {
  // add() refuses generations older than the newest seen, so after a pass for `generation` nothing older can
  // be pending: the dispatcher calls this after every batch it drains, and the scan is O(pending).
  if (generation <= superseded_through_) return;
  superseded_through_ = generation;
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (it->second.request.generation < generation) {
      cancelled.push_back(it->second.request);
      it = pending_.erase(it);
    } else {
      ++it;
    }
  }
  compact_heap();
}

void RequestScheduler::drop_stale_top() {
  while (!heap_.empty()) {
    const HeapNode& n = heap_.front();
    auto it = pending_.find(n.key);
    if (it != pending_.end() && it->second.version == n.version) return;
    std::pop_heap(heap_.begin(), heap_.end(), NodeLess{});
    heap_.pop_back();
  }
}

std::optional<LoadRequest> RequestScheduler::top() {
  drop_stale_top();
  if (heap_.empty()) return std::nullopt;
  return pending_.at(heap_.front().key).request;
}

std::optional<LoadRequest> RequestScheduler::pop() {
  drop_stale_top();
  if (heap_.empty()) return std::nullopt;
  const MipKey key = heap_.front().key;
  std::pop_heap(heap_.begin(), heap_.end(), NodeLess{});
  heap_.pop_back();
  auto it = pending_.find(key);
  const LoadRequest out = it->second.request;
  pending_.erase(it);
  return out;
}

void RequestScheduler::compact_heap() {
  // Rebuild when stale nodes outnumber live ones (plus slack so small queues never rebuild): the heap then
  // stays within about twice the live entries.
  if (heap_.size() <= 2 * pending_.size() + 64) return;
  heap_.clear();
  for (const auto& [key, p] : pending_) heap_.push_back({p.request.priority, p.sequence, key, p.version});
  std::make_heap(heap_.begin(), heap_.end(), NodeLess{});
}

}  // namespace texstream::server
