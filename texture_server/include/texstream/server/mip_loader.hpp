#pragma once
// Fills one staging slot with one mip: from the RAM cache, or from storage by reading exactly the mip's byte
// range of the texture's DDS (seed 000 §3.5: never a whole file to get one mip). Checks the DDS header
// against the scene's texture table first. Produces the completion record; errors are logged with the path.
// Thread-safe (workers call it concurrently; the dispatcher calls serve_cached()).
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>

#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/records.hpp"
#include "texstream/protocol/segment_layout.hpp"
#include "texstream/server/mip_cache.hpp"
#include "texstream/server/request_scheduler.hpp"
#include "texstream/server/storage.hpp"

namespace texstream::server {

class MipLoader {
 public:
  // `stats` is where the load counters go (the segment's ServerBlock; a plain one in tests).
  MipLoader(std::filesystem::path scene_dir, Storage& storage, MipCache& cache, ServerBlock& stats);

  // Reads the mip from storage into `slot` (and into the cache when it is admissible). `record` is the
  // texture's entry of the texture table, already validated; `slot` holds at least the mip's bytes.
  CompletionRecord load(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                        std::span<std::byte> slot);
  // Copies a cached mip into `slot`. Returns a kOk record, or a record with status 0 on a cache miss.
  CompletionRecord serve_cached(const LoadRequest& request, const scene::TextureRecord& record, uint32_t slot_index,
                                std::span<std::byte> slot);

 private:
  CompletionRecord fail(const LoadRequest& request, CompletionStatus status, const std::filesystem::path& path,
                        const std::string& why);

  std::filesystem::path scene_dir_;
  Storage& storage_;
  MipCache& cache_;
  ServerBlock& stats_;
};

// The completion a request gets when it is answered without a payload.
CompletionRecord make_completion(const LoadRequest& request, CompletionStatus status);

}  // namespace texstream::server
