#include "texstream/server/dispatch/request_scheduler.hpp"

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
  Pending* found = pending_.find(key);
  if (found == nullptr) {
    const uint64_t sequence = next_sequence_++;
    const Pending p{request, sequence, sequence};
    pending_.insert(key, p);
    push_node(p);
    compact_heap();
    return std::nullopt;
  }
  // Coalesce. The pending entry lives on with the newer generation and the larger priority; the request it
  // replaces is the one answered kCancelled (its generation is what the renderer will see echoed).
  Pending& p = *found;
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
  pending_.erase_if_not([generation](MipKey, const Pending& p) { return !(p.request.generation < generation); },
                        [&cancelled](const Pending& p) { cancelled.push_back(p.request); });
  compact_heap();
}

const RequestScheduler::Pending* RequestScheduler::drop_stale_top() {
  while (!heap_.empty()) {
    const HeapNode& n = heap_.front();
    const Pending* p = pending_.find(n.key);
    if (p != nullptr && p->version == n.version) return p;
    std::pop_heap(heap_.begin(), heap_.end(), NodeLess{});
    heap_.pop_back();
  }
  return nullptr;
}

std::optional<LoadRequest> RequestScheduler::top() {
  const Pending* p = drop_stale_top();
  if (p == nullptr) return std::nullopt;
  return p->request;
}

std::optional<LoadRequest> RequestScheduler::pop() {
  const Pending* p = drop_stale_top();
  if (p == nullptr) return std::nullopt;
  const LoadRequest out = p->request;
  std::pop_heap(heap_.begin(), heap_.end(), NodeLess{});
  heap_.pop_back();
  pending_.erase(out.key());
  return out;
}

void RequestScheduler::compact_heap() {
  // Rebuild when stale nodes outnumber live ones (plus slack so small queues never rebuild): the heap then
  // stays within about twice the live entries.
  if (heap_.size() <= 2 * pending_.size() + 64) return;
  heap_.clear();
  pending_.for_each([this](MipKey key, const Pending& p) {
    heap_.push_back({p.request.priority, p.sequence, key, p.version});
  });
  std::make_heap(heap_.begin(), heap_.end(), NodeLess{});
}

}  // namespace texstream::server
