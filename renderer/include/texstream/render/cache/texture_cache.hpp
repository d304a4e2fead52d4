#pragma once
// The texture cache (seed 000 §3.6): one sparse partially-resident 2D array image (SparseMemory), textures
// placed in square regions by CacheAllocator (one maximum extent per layer, layers in ring order), filled from
// a host-visible staging ring that StreamClient copies validated payloads into (this class is its MipSink).
//
// Residency, per texture and mip: the pages under the texture's region at that level are bound (reference-
// counted: small regions share pages, SparsePageTable) in the frame that first copies into that level, by
// one vkQueueBindSparse for the whole frame; the frame's submission waits on bind_wait() before its copies.
// A mip becomes visible to the shader (TextureGpu: [finest, coarsest] resident) and to the texture state
// machine (a kCommitted event) only after the GPU copy that wrote it has completed; staging space is reused only
// then. So the shader, which clamps every sample to that range, never reads an unbound page.
//
// Budget (cache.memory_bytes): bound pages x page size never exceed it. When a frame's copies need more
// pages than are free, the oldest layer is evicted (seed §3.6's ring order; its textures go back to Initial
// through a kInvalidated event) until they fit. An evicted texture is hidden at once (the table entry is
// host-visible and read by the next submission only); its pages are unbound only after every submission that
// could have sampled them has completed.
//
// The cache does not touch the texture state machine: what it learns (a mip published, rejected or failed, a
// texture evicted) is queued as TextureEvents, in order, and the frame loop hands them over (take_events).
//
// Frame-thread only; every method runs between frames, when no submitted work reads the texture table.
#include <vulkan/vulkan.h>

#include <array>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/render/cache/cache_allocator.hpp"
#include "texstream/render/cache/mip_fades.hpp"
#include "texstream/render/cache/sparse_memory.hpp"
#include "texstream/render/cache/sparse_page_table.hpp"
#include "texstream/render/cache/staging_ring.hpp"
#include "texstream/render/vulkan/gpu_buffer.hpp"
#include "texstream/render/vulkan/zeroed_array.hpp"
#include "texstream/stream/stream_client.hpp"
#include "texstream/stream/texture_states.hpp"

namespace texstream::render {

class VulkanContext;
struct SceneData;

struct TextureCacheOptions {
  TexelFormat format = TexelFormat::kRgba8;  // cache.format; every scene texture must have it
  uint32_t layer_extent = 512;               // cache.layer_extent_px, a power of two
  uint32_t layers = 64;                      // cache.layers
  uint64_t staging_bytes = 32ull << 20;      // host-visible staging ring
  uint64_t memory_bytes = 128ull << 20;      // cache.memory_bytes: GPU memory for bound pages (and mip tail)
  double fade_s = 0;  // stream.fade_ms: a finer level (or a first level) fades in over this long; 0 = at once
};

struct TextureCacheStats {
  uint64_t mips_uploaded = 0;  // copies completed and published
  uint64_t bytes_uploaded = 0;
  uint64_t mips_dropped = 0;            // committed, but the texture was evicted before its copy was recorded or done
  uint64_t evictions = 0;               // textures invalidated by layer recycling or the memory budget
  uint64_t staging_full = 0;            // reserve() answered "no room now"
  uint64_t budget_evicted_layers = 0;   // layers evicted because the pages of a frame's copies did not fit
  uint64_t frames = 0;                  // on_submission_complete calls (one per frame)
  uint64_t budget_exceeded_frames = 0;  // frames that ended with bound pages x page size above the budget (0)
  uint64_t max_bound_bytes = 0;         // most bytes bound at the end of any frame (pages + mip tail)
  uint64_t texture_loads = 0;           // textures placed in a region (first mip or again after an eviction)
  uint64_t texture_reloads = 0;         // of those, textures that had been evicted before (thrashing)
  double create_seconds = 0;            // TextureCache::create (image, table of every texture, first barrier)
};

// What the frame's queue submission must wait for: the sparse binds recorded with its uploads.
struct BindWait {
  VkSemaphore semaphore = VK_NULL_HANDLE;  // timeline
  uint64_t value = 0;                      // 0: nothing to wait for
};

// What the first frames did to the image, for the bind-cost benchmark's replay (cache.json "upload_trace"):
// per frame the page ops of its vkQueueBindSparse and the regions its copies wrote. Whole frames only, up to
// kTraceEntries ops + regions in all, so long runs keep a bounded prefix.
struct UploadTraceFrame {
  std::vector<PageBindOp> binds;
  std::vector<std::array<uint32_t, 6>> copies;  // layer, mip, x, y, width, height (texels)
};
inline constexpr size_t kTraceEntries = size_t{1} << 16;

class TextureCache final : public stream::MipSink {
 public:
  static Result<std::unique_ptr<TextureCache>> create(const VulkanContext& ctx, const TextureCacheOptions& options,
                                                      const SceneData& scene);

  // The texture table entries of `textures` (not resident, City Colormap colour), written the first time a
  // texture is named: by the meshes a frame draws for the first time (SceneGpu::make_resident), or by a commit.
  // The table is allocated for every texture but only the entries in use are written, so creating the cache
  // costs the same for 10^3 and 10^6 textures. Errors: a texture whose format is not cache.format (naming
  // textures.bin and the record).
  Status prepare_textures(std::span<const uint32_t> textures);

  // ---- MipSink (called from StreamClient::poll) ----
  std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) override;
  void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) override;
  void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) override;
  void failed(TextureId texture, MipLevel mip, CompletionStatus status) override;

  // Binds the pages that the copies committed since the last call need, in one vkQueueBindSparse that also
  // unbinds retired pages, evicting the oldest layers while they do not fit the budget. The submission
  // numbered `serial` carries the copies and must wait on bind_wait(). Errors are the bind's.
  Status prepare_uploads(uint64_t serial);
  // Records the prepared copies into `cmd` (with the layout barriers around them); they complete with the
  // submission numbered `serial`. Calls prepare_uploads(serial) first if the caller did not (an error there is
  // logged and the copies are dropped). Returns the number of copies.
  uint32_t record_uploads(VkCommandBuffer cmd, uint64_t serial);
  BindWait bind_wait() const { return bind_wait_; }
  // Submission `serial` (and every earlier one) has completed: publish what it copied.
  void on_submission_complete(uint64_t serial);
  // Advances the fades (stream.fade_ms) by `dt_s` of path time; call once per frame before drawing it. Levels
  // published before the first call show at once (a preload is no pop-in). docs/design/blend.md.
  void advance_fades(double dt_s);
  // What the texture state machine must hear since the last call, oldest first (TextureStates::apply).
  std::vector<stream::TextureEvent> take_events() { return std::exchange(events_, {}); }

  VkImageView image_view() const { return sparse_->view(); }
  VkBuffer texture_table() const { return table_.handle(); }
  VkDeviceSize texture_table_bytes() const { return table_.size(); }
  uint32_t mip_levels() const { return mip_levels_; }
  uint32_t layer_extent() const { return options_.layer_extent; }
  uint64_t resident_textures() const;
  const TextureCacheStats& stats() const { return stats_; }
  // The allocator's layer numbering (CacheAllocator::layers_assigned): a layer assigned after a mark and freed
  // since means the textures placed after the mark alone outgrew the cache.
  uint64_t layers_assigned() const { return allocator_.layers_assigned(); }
  uint64_t layers_freed() const { return allocator_.layers_freed(); }
  const SparseBindStats& bind_stats() const { return sparse_->stats(); }
  const PageTableStats& page_stats() const { return pages_->stats(); }
  uint64_t page_bytes() const { return sparse_->page_bytes(); }
  uint64_t memory_budget() const { return options_.memory_bytes; }
  // Bytes bound now: pages x page size + the mip tail. Never above memory_budget().
  uint64_t bound_bytes() const { return pages_->bound_pages() * sparse_->page_bytes() + sparse_->tail_bytes(); }
  const PageGeometry& page_geometry() const { return sparse_->geometry(); }
  // cache.json next to summary.json: the statistics above, the bind counts and the budget checks.
  Status write_stats_json(const std::filesystem::path& file) const;

 private:
  struct Residency {
    uint32_t mask = 0;   // bit L: mip L is in the image and published
    uint32_t bound = 0;  // bit L: the pages under the region at mip L hold a reference for this texture
    uint32_t epoch = 0;  // bumped on eviction: copies of an older epoch publish nothing
    bool evicted_before = false;
    CacheRegion region;  // valid while `bound` != 0 (the allocator forgets it when the layer goes)
  };
  struct Copy {
    TextureId texture;
    uint32_t mip;
    StagingRing::Allocation staging;
    uint32_t epoch;
    uint64_t serial;  // submission that carries it (after record_uploads)
  };

  TextureCache(const TextureCacheOptions& options, const SceneData& scene);
  void evict(TextureId texture);
  void evict_all(const std::vector<TextureId>& textures);
  // Takes the page references of copy `c`, evicting oldest layers while the budget is short. False when
  // the copy's own texture was evicted on the way (the copy is then dropped).
  bool bind_pages_for(const Copy& c);
  void publish(TextureId texture);
  Status prepare_texture(uint32_t texture);
  void release_staging(const StagingRing::Allocation& a);

  TextureCacheOptions options_;
  const SceneData& scene_;
  std::vector<stream::TextureEvent> events_;  // for the texture state machine, oldest first (take_events)
  uint32_t mip_levels_ = 1;
  std::unique_ptr<SparseMemory> sparse_;
  std::unique_ptr<SparsePageTable> pages_;
  uint64_t last_serial_ = 0;       // last submission recorded
  uint64_t completed_serial_ = 0;  // last submission known complete
  BindWait bind_wait_;
  GpuBuffer staging_;
  GpuBuffer table_;  // gpu::TextureGpu[texture_count], host-visible
  StagingRing ring_;
  CacheAllocator allocator_;
  ZeroedArray<Residency> residency_;  // per texture; all-zero = not resident (created in O(1), see zeroed_array.hpp)
  uint64_t resident_count_ = 0;       // textures with a non-zero mask
  std::vector<UploadTraceFrame> trace_;
  size_t trace_entries_ = 0;
  bool trace_open_ = false;  // the last prepare_uploads started a trace frame that record_uploads adds to
  std::unordered_map<uint64_t, StagingRing::Allocation> reserved_;  // by buffer offset, until commit/reject
  std::vector<Copy> queued_;                                        // committed, pages not yet bound
  std::vector<Copy> ready_;                                         // pages bound (prepare_uploads), not yet recorded
  uint64_t prepared_serial_ = 0;
  std::deque<Copy> in_flight_;  // recorded, submission not yet complete
  std::vector<bool> unplaceable_logged_;
  std::vector<bool> entry_written_;  // prepare_texture wrote the texture's table entry
  MipFades fades_;
  TextureCacheStats stats_;
};

// VkFormat of the cache image for a texel format (sRGB: the shader filters in linear light).
VkFormat cache_vk_format(TexelFormat format);

}  // namespace texstream::render
