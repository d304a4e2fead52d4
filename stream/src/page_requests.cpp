#include "texstream/stream/page_requests.hpp"

#include <algorithm>

namespace texstream::stream {

namespace {
// A deterministic order for the sink: by the map's keys (file, then the page's absolute index).
std::vector<PageRequest> in_key_order(std::vector<std::pair<uint64_t, PageRequest>>& entries) {
  std::sort(entries.begin(), entries.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<PageRequest> out;
  out.reserve(entries.size());
  for (const auto& e : entries) out.push_back(e.second);
  return out;
}
}  // namespace

std::vector<PageRequest> PageRequests::take_all() {
  std::vector<std::pair<uint64_t, PageRequest>> entries;
  entries.reserve(in_flight_.size());
  for (const auto& [k, f] : in_flight_) entries.emplace_back(k, f.request);
  in_flight_.clear();
  return in_key_order(entries);
}

std::vector<PageRequest> PageRequests::take_expired(SteadyTime now, std::chrono::milliseconds timeout) {
  std::vector<std::pair<uint64_t, PageRequest>> entries;
  for (const auto& [k, f] : in_flight_)
    if (now - f.sent_at > timeout) entries.emplace_back(k, f.request);
  for (const auto& e : entries) in_flight_.erase(e.first);
  return in_key_order(entries);
}

}  // namespace texstream::stream
