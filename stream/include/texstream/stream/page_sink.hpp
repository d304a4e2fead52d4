#pragma once
// Where completed pages of page files go (RequestKind::kLoadPage, issue 28): implemented by the renderer (its
// page cache), called only from within StreamClient::poll (and restart_server), as MipSink is for mips. No
// Vulkan here. `file` is the page file's index in StreamClient::set_page_files (0 = the scene's ground).
#include <cstddef>
#include <cstdint>
#include <span>

#include "texstream/common/page_file.hpp"
#include "texstream/protocol/records.hpp"

namespace texstream::stream {

class PageSink {
 public:
  virtual ~PageSink() = default;
  // Room for `bytes` of the page, or an empty span for "no room now" (completion stays pending, offered again
  // next poll). A non-empty span must hold at least `bytes` (a shorter one is a bug of the sink and aborts).
  virtual std::span<std::byte> reserve_page(uint32_t file, pages::PageId page, uint64_t bytes) = 0;
  // `data` holds the page's bytes exactly as stored in the page file (checksum verified, size = the index
  // entry's bytes).
  virtual void commit_page(uint32_t file, pages::PageId page, std::span<std::byte> data) = 0;
  // The request ended without a payload (server status, a refused record, a checksum mismatch, lost with a
  // dead server). The status is the server's; kIoError for a record the client refused or a payload whose
  // checksum did not match (like a failed read: worth asking again, a bounded number of times); kCancelled
  // for a request lost with a dead or restarted server; kTimedOut for one unanswered past the request
  // timeout. The span reserve_page() gave, if any, is free again.
  virtual void page_failed(uint32_t file, pages::PageId page, CompletionStatus status) = 0;
};

}  // namespace texstream::stream
