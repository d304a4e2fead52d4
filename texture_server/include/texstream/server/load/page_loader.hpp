#pragma once
// The scene's page files as the dispatcher serves them (RequestKind::kLoadPage, issue 28): one PageReader per
// page file, opened through the server's storage (every tier serves pages as it serves mips: local, http
// origin, disk cache, slow storage), the checks of a page request, and the read of one page into a staging
// slot with its checksum. Page files are numbered; 0 is scene.json's "ground", the only one today.
// Pages do not go into the RAM cache: each request reads its page's exact range once (the renderer keeps the
// pages it has; the disk cache keeps remote ones). Thread-safe after open(): the dispatcher checks and reads
// local pages itself, the workers read the others.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/server/load/load_request.hpp"
#include "texstream/server/load/page_reader.hpp"
#include "texstream/server/load/server_stats.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

class PageLoader {
 public:
  // Opens the page files scene.json names (its header and index read now). A scene without scene.json or
  // without "ground" has none: every page request is then answered kNotFound. A ground whose page file is
  // missing or damaged is an error naming the file; so is a scene.json that cannot be read.
  static Result<std::unique_ptr<PageLoader>> open(const std::filesystem::path& scene_dir, Storage& storage,
                                                  ServerStats& stats);

  uint32_t file_count() const { return static_cast<uint32_t>(readers_.size()); }
  const PageReader& reader(uint32_t file) const { return *readers_.at(file); }

  // kOk when `request` (a page) names a stored page of a known file whose bytes fit a staging slot of
  // `slot_bytes`; otherwise the status to answer it with — kNotFound (no such file; the page outside the
  // quadtree or not stored) or kIoError (larger than a slot) — logged naming the file and the page.
  CompletionStatus check(const LoadRequest& request, uint64_t slot_bytes) const;
  // The page's bytes when they are on this machine and at most `limit` (the dispatcher may read it itself);
  // else 0. `request` passed check().
  uint64_t local_bytes(const LoadRequest& request, uint64_t limit) const;
  // Reads the page into `slot` (`request` passed check(), so it fits): kOk with its size, format, side and
  // checksum, or the failure's status (logged, counted). `local_only`: a page whose bytes would come from a
  // remote or slow origin is kUnfilled, nothing read (the dispatcher hands it to the remote-fetch workers).
  CompletionRecord load(const LoadRequest& request, uint32_t slot_index, std::span<std::byte> slot, bool local_only);

 private:
  PageLoader(std::vector<std::unique_ptr<PageReader>> readers, ServerStats& stats)
      : readers_(std::move(readers)), stats_(stats) {}

  std::vector<std::unique_ptr<PageReader>> readers_;  // by page file index
  ServerStats& stats_;
};

}  // namespace texstream::server
