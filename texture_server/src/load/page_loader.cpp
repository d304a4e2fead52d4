#include "texstream/server/load/page_loader.hpp"

#include <spdlog/spdlog.h>

#include <string>

#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/checksum.hpp"
#include "texstream/server/load/mip_loader.hpp"

namespace texstream::server {

namespace {

std::string page_name(const LoadRequest& r) {
  return "page file " + std::to_string(r.texture.value) + " level " + std::to_string(r.mip.value) + " page " +
         std::to_string(r.x) + "," + std::to_string(r.y);
}

}  // namespace

Result<std::unique_ptr<PageLoader>> PageLoader::open(const std::filesystem::path& scene_dir, Storage& storage,
                                                     ServerStats& stats) {
  std::vector<std::unique_ptr<PageReader>> readers;
  Result<scene::Manifest> manifest = scene::read_manifest(scene_dir);
  // A folder with only the texture table (a bare origin's fetched table, a test's scene) has no page files.
  if (!manifest.ok() && manifest.error().code != ErrorCode::kNotFound) return manifest.error();
  if (manifest.ok() && manifest->ground) {
    // As the storage names it: the scene folder's path, relative to the origin's root for a remote origin.
    const std::string path = (scene_dir / manifest->ground->pages).string();
    Result<std::unique_ptr<PageReader>> ground = PageReader::open(storage, path);
    if (!ground.ok()) {
      return make_error(ground.error().code,
                        "scene.json's ground: page file '" + path + "': " + ground.error().message);
    }
    const pages::PageGeometry& g = (*ground)->file().geometry();
    spdlog::info("ground pages: '{}', {}x{} {}, {} levels of {}-texel pages (+{} border), {} pages stored", path,
                 g.width, g.height, to_string(g.format), g.levels, g.page_texels, g.border_texels,
                 (*ground)->file().stored_pages());
    readers.push_back(std::move(ground).value());
  }
  return std::unique_ptr<PageLoader>(new PageLoader(std::move(readers), stats));
}

CompletionStatus PageLoader::check(const LoadRequest& request, uint64_t slot_bytes) const {
  if (request.texture.value >= readers_.size()) {
    spdlog::warn("{}: not found: the scene has {} page file(s)", page_name(request), readers_.size());
    return CompletionStatus::kNotFound;
  }
  const pages::PageFile& file = readers_[request.texture.value]->file();
  const std::optional<pages::PageIndexEntry> entry = file.entry(request.page_id());
  if (!entry) {
    const bool inside = request.mip.value < file.geometry().levels && request.x < (1u << request.mip.value) &&
                        request.y < (1u << request.mip.value);
    spdlog::warn("{} ({}): not found: {}", page_name(request), readers_[request.texture.value]->path(),
                 inside ? "not stored (outside the image)"
                        : "outside the quadtree of " + std::to_string(file.geometry().levels) + " levels");
    return CompletionStatus::kNotFound;
  }
  if (entry->bytes > slot_bytes) {
    spdlog::warn("{} ({}): {} bytes do not fit a staging slot of {} bytes", page_name(request),
                 readers_[request.texture.value]->path(), entry->bytes, slot_bytes);
    return CompletionStatus::kIoError;
  }
  return CompletionStatus::kOk;
}

uint64_t PageLoader::local_bytes(const LoadRequest& request, uint64_t limit) const {
  const PageReader& reader = *readers_[request.texture.value];
  const std::optional<pages::PageIndexEntry> entry = reader.file().entry(request.page_id());
  if (!entry || entry->bytes > limit || !reader.local(request.page_id())) return 0;
  return entry->bytes;
}

CompletionRecord PageLoader::load(const LoadRequest& request, uint32_t slot_index, std::span<std::byte> slot,
                                  bool local_only) {
  PageReader& reader = *readers_[request.texture.value];
  if (local_only && !reader.local(request.page_id())) return make_completion(request, CompletionStatus::kUnfilled);
  // Straight into the slot (the server owns it until the completion): one exact read, no copy.
  const Result<uint64_t> got = reader.read(request.page_id(), slot);
  if (!got.ok()) {
    // kCorrupt: the file ended inside the page; anything else as a mip's failed read.
    const CompletionStatus status =
        got.error().code == ErrorCode::kCorrupt ? CompletionStatus::kCorrupt : read_failure_status(got.error().code);
    spdlog::warn("{}: {}: {}", page_name(request), to_string(status), got.error().message);
    stats_.add(status == CompletionStatus::kNotFound  ? stats_.not_found
               : status == CompletionStatus::kCorrupt ? stats_.corrupt
                                                      : stats_.io_errors,
               1);
    return make_completion(request, status);
  }
  const pages::PageGeometry& g = reader.file().geometry();
  CompletionRecord c = make_completion(request, CompletionStatus::kOk);
  c.slot = slot_index;
  c.byte_size = *got;
  c.format = static_cast<uint32_t>(g.format);
  c.width = g.stored_side();
  c.height = g.stored_side();
  c.checksum = payload_checksum(slot.data(), *got);
  stats_.add(stats_.page_bytes_read, *got);
  return c;
}

}  // namespace texstream::server
