#pragma once
// Where the stream client hands pages of a huge texture (issue 28), as MipSink does mips.
#include <cstddef>
#include <cstdint>
#include <span>

#include "texstream/common/page_file.hpp"
#include "texstream/protocol/records.hpp"

namespace texstream::stream {

class PageSink {
 public:
  virtual ~PageSink() = default;
  // Room for `bytes` of the page, or an empty span for "no room now" (completion stays pending, offered again next
  // poll).
  virtual std::span<std::byte> reserve_page(uint32_t file, pages::PageId page, uint64_t bytes) = 0;
  // `data` holds the page's bytes exactly as stored in the page file (checksum verified, size = the index entry's
  // bytes).
  virtual void commit_page(uint32_t file, pages::PageId page, std::span<std::byte> data) = 0;
  // The request ended without a payload (server status, a refused record, a checksum mismatch, lost with a dead
  // server).
  virtual void page_failed(uint32_t file, pages::PageId page, CompletionStatus status) = 0;
};

}  // namespace texstream::stream
