#pragma once
// StreamClient's bookkeeping of page requests (RequestKind::kLoadPage, issue 28), without the segment: the page
// files the renderer registered (their headers and indexes, read by the renderer itself), the pages in flight
// and when they were sent. The client asks it whether a page may be requested, whether a completion answers
// a page it asked for, and which requests a dead server or the request timeout ended.
// Single-threaded: the renderer's frame thread (StreamClient's).
#include <cstdint>
#include <memory>
#include <optional>
#include <unordered_map>
#include <vector>

#include "texstream/common/ids.hpp"
#include "texstream/common/page_file.hpp"
#include "texstream/stream/page_sink.hpp"
#include "texstream/stream/server_process.hpp"

namespace texstream::stream {

struct PageRequest {
  uint32_t file = 0;
  pages::PageId page;
  bool operator==(const PageRequest&) const = default;
};

class PageRequests {
 public:
  struct InFlight {
    PageRequest request;
    Generation generation;
    SteadyTime sent_at{};
  };

  // Index = file id. Requests in flight stay (they are answered or time out as before).
  void set_files(std::vector<std::shared_ptr<const pages::PageFile>> files, PageSink* sink) {
    files_ = std::move(files);
    sink_ = sink;
  }
  PageSink* sink() const { return sink_; }
  // The registered file `file`, or nullptr.
  const pages::PageFile* file(uint32_t file) const { return file < files_.size() ? files_[file].get() : nullptr; }

  bool in_flight(PageRequest r) const { return in_flight_.count(key(r)) != 0; }
  size_t in_flight_count() const { return in_flight_.size(); }
  void sent(PageRequest r, Generation generation, SteadyTime at) {
    in_flight_.emplace(key(r), InFlight{r, generation, at});
  }
  // The request a completion claims to answer, or nullptr. `r.page` may be anything (an untrusted record).
  const InFlight* find(PageRequest r) const {
    if (!valid(r.page)) return nullptr;
    const auto it = in_flight_.find(key(r));
    return it == in_flight_.end() ? nullptr : &it->second;
  }
  void erase(PageRequest r) {
    if (valid(r.page)) in_flight_.erase(key(r));
  }
  // Everything in flight, in a deterministic order, forgotten (the server that had them is gone).
  std::vector<PageRequest> take_all();
  // The requests sent more than `timeout` before `now`, in a deterministic order, forgotten.
  std::vector<PageRequest> take_expired(SteadyTime now, std::chrono::milliseconds timeout);

 private:
  // A page file has at most 16 levels (kMaxVirtualExtent / kMinPageTexels = 2^15 pages a side), so the
  // absolute index of a page inside its quadtree fits 32 bits; the file takes the other 32.
  static bool valid(pages::PageId p) { return p.level < 16 && p.x < (1u << p.level) && p.y < (1u << p.level); }
  static uint64_t key(PageRequest r) {
    return (uint64_t{r.file} << 32) |
           (pages::PageGeometry::first_slot(r.page.level) + (uint64_t{r.page.y} << r.page.level) + r.page.x);
  }

  std::vector<std::shared_ptr<const pages::PageFile>> files_;
  PageSink* sink_ = nullptr;
  std::unordered_map<uint64_t, InFlight> in_flight_;
};

}  // namespace texstream::stream
