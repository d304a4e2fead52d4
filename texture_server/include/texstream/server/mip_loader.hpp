#pragma once
// Fills one staging slot with one mip: from the RAM cache, or from storage reading exactly that mip
// (seed 000 §3.5: never a whole file to get one mip).
//
// Which file: texture_file_index.hpp (<id>.dds, else .tx / .tif / .exr with the same stem). How it is read:
// - DDS whose encoding matches the texture table (BC1 blocks for a bc1 texture, R8G8B8A8 for rgba8): one
//   pread of the mip's byte range; BC1 reaches the renderer as BC1 blocks, never decoded.
// - Any other DDS encoding for an rgba8 texture, and TIFF / OpenEXR: that one level decoded by OpenImageIO
//   into RGBA8 (oiio_mip_decoder.hpp). A bc1 texture is never encoded here: such a file is kCorrupt.
// The file's extent of the asked mip must equal the texture table's, else kCorrupt. Errors are logged with
// the path. Thread-safe (workers call load() concurrently; the dispatcher calls serve_cached()).
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>

#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment_layout.hpp"
#include "texstream/server/mip_cache.hpp"
#include "texstream/server/open_file_cache.hpp"
#include "texstream/server/request_scheduler.hpp"
#include "texstream/server/server_stats.hpp"
#include "texstream/server/storage.hpp"
#include "texstream/server/texture_file_index.hpp"

namespace texstream::server {

class MipLoader {
 public:
  // `block` gets the segment's load counters (ServerBlock); `stats` the server's detailed statistics.
  MipLoader(std::filesystem::path scene_dir, Storage& storage, MipCache& cache, ServerBlock& block,
            ServerStats& stats);

  // Reads the mip from storage into `slot` (and into the cache when it is admissible). `record` is the
  // texture's entry of the texture table, already validated; `slot` holds at least the mip's bytes.
  // `local_only`: when a read it needs would go to a remote or slow origin (StorageFile::local() is false),
  // nothing is read and the completion is kUnfilled (not logged, not counted as a failure): the server then
  // hands the load to its bounded remote-fetch workers, or answers kUnfilled so the renderer asks again.
  CompletionRecord load(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                        std::span<std::byte> slot, bool local_only = false);
  // Copies a cached mip into `slot`. Returns a kOk record, or a record with status 0 on a cache miss.
  CompletionRecord serve_cached(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                                std::span<std::byte> slot);

 private:
  struct Opened {
    std::filesystem::path path;
    TextureFileEntry entry;
    std::unique_ptr<StorageFile> file;
  };
  // Finds and opens the texture's file (or takes it from files_); on failure returns the error completion in
  // `error`.
  bool open_texture(const LoadRequest& request, Opened& opened, CompletionRecord& error);
  // Reads (or decodes) the mip into `target`; returns kOk or the failure's status (already logged).
  CompletionStatus read_mip(const LoadRequest& request, const scene::TextureRecord& record, Opened& opened,
                            std::span<std::byte> target, bool local_only);
  CompletionRecord fail(const LoadRequest& request, CompletionStatus status, const std::filesystem::path& path,
                        const std::string& why);
  CompletionStatus fail_status(const LoadRequest& request, CompletionStatus status, const std::filesystem::path& path,
                               const std::string& why);
  void count_read(uint64_t bytes);

  std::filesystem::path scene_dir_;
  Storage& storage_;
  MipCache& cache_;
  ServerBlock& block_;
  ServerStats& stats_;
  TextureFileIndex index_;
  OpenFileCache files_;  // files of recent misses, kept open for the texture's next mips
};

// The completion a request gets when it is answered without a payload.
CompletionRecord make_completion(const LoadRequest& request, CompletionStatus status);

}  // namespace texstream::server
