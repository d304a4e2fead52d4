#pragma once
// The texture cache (seed 000 §3.6): sparse partially-resident 2D array images (SparseMemory), textures
// placed in regions of their layers, filled from a host-visible staging ring that StreamClient copies validated
// payloads into (this class is its MipSink). The images' shape comes from the device's limits and the budget
// (cache_geometry.hpp), so that cache.memory_bytes is the cache's only limit (docs/design/cache_budget.md).
//
// Texel formats: one image (a "plane") per texel format the scene has, so every texture stays in its own
// format on the GPU (BC1, BC3, BC7 and RGBA8 side by side, nothing decoded). The planes share one page pool,
// one budget, one use list and one bind call per frame; a texture's table entry names its plane
// (docs/design/cache_formats.md).
//
// Residency, per texture and mip: the pages under the texture's rectangle at that level are bound
// (reference-counted: small regions share pages, SparsePageTable) in the frame that first copies into that
// level, by one vkQueueBindSparse for the whole frame; the frame's submission waits on bind_wait() before its
// copies. A mip becomes visible to the shader (TextureGpu: [finest, coarsest] resident) and to the texture
// state machine (a kCommitted event) only after the GPU copy that wrote it has completed; staging space is
// reused only then. So the shader, which clamps every sample to that range, never reads an unbound page.
//
// Placement and eviction (cache.eviction):
// * lru (default): QuadtreeAllocator packs textures of every size into shared layers; a non-square texture
//   binds about its own bytes. When the pages of a copy do not fit the budget, or no region is free, the
//   texture used longest ago is evicted — never one used in the current cycle (touch()): a view whose working
//   set fits the budget never evicts what it shows. If nothing can go, the copy is dropped (kNoRoom: asked
//   again later) and counted in space_refusals.
// * ring (seed §3.6): CacheAllocator, one texture size per layer, layers in ring order; the oldest layer goes.
// An evicted texture is hidden at once (the table entry is host-visible and read by the next submission only)
// and goes back to Initial through a kInvalidated event; its pages are unbound only after every submission
// that could have sampled them has completed.
//
// The cache does not touch the texture state machine: what it learns (a mip published, rejected or failed, a
// texture evicted) is queued as TextureEvents, in order, and the frame loop hands them over (take_events).
//
// The texture table (gpu::TextureGpu, host-visible) has an entry ("slot", TextureSlots) for each texture drawn in
// the current frame or with residency, not one per scene texture: it starts at kInitialTableSlots and doubles
// into a new buffer when the slots outgrow it (ScenePasses::bind_texture_table points the shaders at it); a slot is
// freed once its texture is neither drawn nor cached (write_slots). docs/design/host_memory.md, item 3.
//
// Frame-thread only; every method runs between frames, when no submitted work reads the texture table.
#include <vulkan/vulkan.h>

#include <array>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/render/cache/cache_allocator.hpp"
#include "texstream/render/cache/mip_fades.hpp"
#include "texstream/render/cache/quadtree_allocator.hpp"
#include "texstream/render/cache/residency_table.hpp"
#include "texstream/render/cache/sparse_memory.hpp"
#include "texstream/render/cache/sparse_page_table.hpp"
#include "texstream/render/cache/staging_ring.hpp"
#include "texstream/render/scene/texture_slots.hpp"
#include "texstream/render/vulkan/gpu_buffer.hpp"
#include "texstream/stream/stream_client.hpp"
#include "texstream/stream/texture_states.hpp"

namespace texstream::render {

class VulkanContext;
struct SceneData;

struct TextureCacheOptions {
  // cache.format: nullopt (auto) keeps every texture in its own format; a format must be every texture's.
  std::optional<TexelFormat> format;
  CacheEviction eviction = CacheEviction::kLru;  // cache.eviction
  uint32_t layer_extent = 0;                     // cache.layer_extent_px, a power of two; 0: chosen (cache_geometry)
  uint32_t layers = 0;                           // cache.layers; 0: chosen
  uint64_t staging_bytes = 32ull << 20;          // host-visible staging ring
  uint64_t memory_bytes = 128ull << 20;          // cache.memory_bytes: GPU memory for bound pages (and mip tail)
  double fade_s = 0;  // stream.fade_ms: a finer level (or a first level) fades in over this long; 0 = at once
};

struct TextureCacheStats {
  uint64_t mips_uploaded = 0;  // copies completed and published
  uint64_t bytes_uploaded = 0;
  uint64_t mips_dropped = 0;            // committed, but the texture was evicted before its copy was recorded or done
  uint64_t evictions = 0;               // textures invalidated by layer recycling or the memory budget
  uint64_t space_refusals = 0;          // lru: copies dropped because everything evictable was in use this cycle
  uint64_t trimmed_levels = 0;          // lru: levels finer than wanted dropped from textures in use, for room
  uint64_t address_evictions = 0;       // lru: of the evictions, those for address space (no free region)
  uint64_t first_eviction_bytes = 0;    // memory in use (page slots held + mip tail) when the first eviction came
  uint64_t staging_full = 0;            // reserve() answered "no room now"
  uint64_t budget_evicted_layers = 0;   // layers evicted because the pages of a frame's copies did not fit
  uint64_t frames = 0;                  // on_submission_complete calls (one per frame)
  uint64_t budget_exceeded_frames = 0;  // frames that ended with bound pages x page size above the budget (0)
  uint64_t max_bound_bytes = 0;         // most bytes bound at the end of any frame (pages + mip tail)
  uint64_t texture_loads = 0;           // textures placed in a region (first mip or again after an eviction)
  uint64_t texture_reloads = 0;         // of those, textures that had been evicted before (thrashing)
  double create_seconds = 0;            // TextureCache::create (image, texture table, first barrier)
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

// The texture table's first size: 4096 entries of 48 B (192 KiB). A view of the default city draws ~650
// meshes; a larger working set doubles it a few times, once.
inline constexpr uint32_t kInitialTableSlots = 4096;

// One image of the cache: the textures of one texel format.
struct CachePlane {
  TexelFormat format = TexelFormat::kRgba8;
  uint32_t block = 1;  // texel block side: 4 for BC formats
  uint32_t layer_extent = 0;
  uint32_t layers = 0;
  uint32_t mip_levels = 0;
};

class TextureCache final : public stream::MipSink {
 public:
  static Result<std::unique_ptr<TextureCache>> create(const VulkanContext& ctx, const TextureCacheOptions& options,
                                                      const SceneData& scene);

  // Checks that `textures` can be drawn: each has a plane (the meshes a frame draws for the first time,
  // SceneGpu::make_resident; render.preload_all: every texture). Errors: a texture whose format is not
  // cache.format (naming textures.bin and the record) when cache.format is not auto. Their table entries come
  // with their slots (write_slots, commit).
  Status prepare_textures(std::span<const uint32_t> textures);

  // ---- the texture table's slots, once per frame plan (frame_plan.cpp) ----
  // A new frame: the slots its draws take (SceneGpu::write_draws through texture_slots()) are its own.
  void begin_frame() { slots_.begin_frame(); }
  // The textures the shaders look up by slot (SceneGpu::write_draws writes MeshGpu::texture_slot).
  TextureSlots& texture_slots() { return slots_; }
  // After the frame's draws took their slots: writes the entries of textures given a slot (not resident, City
  // Colormap colour), grows the table when they outgrew it, and frees the slots of textures neither drawn in
  // this frame nor with residency. A freed slot may go to another texture at once: every submission has been
  // waited for (RenderStack::submit) and this frame's meshes name only slots it drew. Errors: the new buffer's.
  Status write_slots();

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
  // published before the first call show at once (a preload is no pop-in); an infinite `dt_s` ends every fade
  // (stream.fade_when = still, on a frame whose camera moved). docs/design/blend.md.
  void advance_fades(double dt_s);
  // What the texture state machine must hear since the last call, oldest first (TextureStates::apply).
  std::vector<stream::TextureEvent> take_events() { return std::exchange(events_, {}); }

  uint32_t plane_count() const { return static_cast<uint32_t>(planes_.size()); }
  const CachePlane& plane(uint32_t i) const { return planes_[i].shape; }
  VkImageView image_view(uint32_t plane = 0) const { return sparse_->view(plane); }
  // The table buffer: a new one after the table grew (ScenePasses::bind_texture_table).
  VkBuffer texture_table() const { return table_.handle(); }
  VkDeviceSize texture_table_bytes() const { return table_.size(); }
  uint32_t texture_table_slots() const { return table_slots_; }
  // Slots held now, and at most (the free list is reused first, so the peak is the slots ever handed out).
  uint32_t texture_slots_in_use() const { return slots_.in_use(); }
  uint32_t texture_slots_peak() const { return slots_.high_water(); }
  uint32_t mip_levels(uint32_t plane = 0) const { return planes_[plane].shape.mip_levels; }
  uint32_t layer_extent(uint32_t plane = 0) const { return planes_[plane].shape.layer_extent; }
  uint64_t resident_textures() const;
  const TextureCacheStats& stats() const { return stats_; }
  // The textures of the current cycle (the frame's visibility list, or what a load wants): none of them is
  // evicted until the next call. Textures placed since the last call count as used too.
  void touch(std::span<const stream::StreamCandidate> used);
  // Whether the textures used since a mark alone outgrew the cache: ring, a layer assigned after the mark was
  // freed (layers go in assignment order); lru, a copy was refused for lack of room.
  struct FitMark {
    std::array<uint64_t, kMaxCacheImages> layers_assigned{};  // per plane
    uint64_t space_refusals = 0;
  };
  FitMark fit_mark() const;
  bool outgrown_since(const FitMark& mark) const;
  // Textures the cache refused for good (another texel format, larger than a layer), in the order refused.
  const std::vector<uint32_t>& refused_textures() const { return refused_; }
  uint32_t layers(uint32_t plane = 0) const { return planes_[plane].shape.layers; }
  CacheEviction eviction() const { return options_.eviction; }
  const SparseBindStats& bind_stats() const { return sparse_->stats(); }
  const PageTableStats& page_stats() const { return pages_->stats(); }
  uint64_t page_bytes() const { return sparse_->page_bytes(); }
  uint64_t memory_budget() const { return options_.memory_bytes; }
  // Bytes bound now: pages x page size + the mip tail. Never above memory_budget().
  uint64_t bound_bytes() const { return pages_->bound_pages() * sparse_->page_bytes() + sparse_->tail_bytes(); }
  const PageGeometry& page_geometry(uint32_t plane = 0) const { return sparse_->geometry(plane); }
  // Bytes the images can address with every level (their sizes): what could be bound at most.
  uint64_t addressable_bytes() const { return sparse_->image_bytes(); }
  // Bytes held now: page slots in use (bound, or retired and not yet unbound) + the mip tail.
  uint64_t held_bytes() const;
  // cache.json next to summary.json: the statistics above, the bind counts and the budget checks.
  Status write_stats_json(const std::filesystem::path& file) const;

 private:
  struct Copy {
    TextureId texture;
    uint32_t mip;
    StagingRing::Allocation staging;
    uint64_t epoch;   // the texture's Residency::epoch when committed
    uint64_t serial;  // submission that carries it (after record_uploads)
  };

  struct Plane {
    CachePlane shape;
    std::optional<CacheAllocator> ring;     // cache.eviction = ring
    std::optional<QuadtreeAllocator> tree;  // cache.eviction = lru
  };

  TextureCache(const TextureCacheOptions& options, const SceneData& scene);
  // The plane of a texture's format; the texture's entry is prepared (prepare_texture), so it has one.
  uint32_t plane_of(TextureId texture) const;
  void evict(TextureId texture);
  void evict_all(const std::vector<TextureId>& textures);
  std::optional<CacheRegion> region_of(TextureId texture) const;
  // A region for the texture's first mip: ring (recycling layers) or lru (evicting by use). nullopt + kNoRoom
  // event when lru has nothing to evict; an error when the texture can never be placed.
  Result<std::optional<CacheRegion>> place(TextureId texture, uint32_t width, uint32_t height);
  // lru: the texture used longest ago, unless it was used in the current cycle or is `keep`; of `plane` only
  // when given (address space is per plane, memory is shared).
  std::optional<TextureId> lru_victim(TextureId keep, std::optional<uint32_t> plane = std::nullopt) const;
  // ring: evicts the oldest layer of `plane`, else of the plane holding the most layers. False: none left.
  bool evict_oldest_layer(uint32_t plane);
  // lru, when nothing can be evicted: drops the levels of one texture in use that are finer than its wanted
  // level minus one (a texture seen close before and far now). False when no texture has such levels.
  bool trim_one(TextureId keep);
  PageRect page_rect(const CacheRegion& r, uint32_t plane) const;
  void note_eviction();
  // lru: a copy dropped because everything that could make room is in use (kNoRoom: asked again later).
  void refuse_for_room(TextureId texture, MipLevel mip);
  // A texture that can never be placed (another format, larger than a layer): logged and listed once.
  void refuse_for_good(TextureId texture, const std::string& why);
  enum class BindOutcome { kBound, kNoFreePages, kDropped };
  // Takes the page references of copy `c`; with `may_evict`, evicting (lru victims, oldest layers) while the
  // budget is short, else kNoFreePages when the free pages do not hold it. kDropped: the copy's own texture
  // was evicted on the way or no room can be made (the copy is then dropped).
  BindOutcome bind_pages_for(const Copy& c, bool may_evict);
  // A copy the cache lets go of (dropped or done): its staging and its hold on the texture's entry.
  void drop_copy(const Copy& c);
  // Writes the shader's range of resident levels from `mask` (the texture's Residency::mask).
  void publish(TextureId texture, uint32_t mask);
  // Whether the texture has a plane (prepare_textures); the error names the texture and cache.format.
  Status check_texture(uint32_t texture) const;
  // The texture's table entry, given a slot (and the entry written) when it has none. Errors: the table's growth.
  Result<gpu::TextureGpu*> entry(TextureId texture);
  // The entry of a texture that has a slot; nullptr when it has none (nothing to hide or update).
  gpu::TextureGpu* entry_if_slotted(TextureId texture);
  // Writes the entries of the textures given a slot since the last call, the table grown to hold them first.
  Status write_fresh_entries();
  // A table of at least `slots` entries (doubling), the entries so far copied into it.
  Status grow_table(uint32_t slots);
  void release_staging(const StagingRing::Allocation& a);

  TextureCacheOptions options_;
  const SceneData& scene_;
  std::vector<stream::TextureEvent> events_;  // for the texture state machine, oldest first (take_events)
  std::vector<Plane> planes_;                 // image i of sparse_ is plane i
  std::array<int8_t, 8> plane_of_format_{};   // by TexelFormat value; -1: no plane
  std::unique_ptr<SparseMemory> sparse_;
  std::unique_ptr<SparsePageTable> pages_;
  uint64_t last_serial_ = 0;       // last submission recorded
  uint64_t completed_serial_ = 0;  // last submission known complete
  BindWait bind_wait_;
  GpuBuffer staging_;
  const VulkanContext* ctx_ = nullptr;
  GpuBuffer table_;           // gpu::TextureGpu[table_slots_], host-visible, by slot
  uint32_t table_slots_ = 0;  // entries table_ holds (slots_.high_water() or more)
  TextureSlots slots_;        // texture -> slot: textures drawn this frame or with residency
  StagingRing ring_;
  uint32_t use_cycle_ = 1;
  std::vector<uint32_t> trimmable_;  // textures of the last touch() holding levels finer than they want
  // Sparse: entries only for textures resident, placed or with copies on the way (docs/design/host_memory.md).
  ResidencyTable residency_;
  uint64_t resident_count_ = 0;  // textures with a non-zero mask
  std::vector<UploadTraceFrame> trace_;
  size_t trace_entries_ = 0;
  bool trace_open_ = false;  // the last prepare_uploads started a trace frame that record_uploads adds to
  std::unordered_map<uint64_t, StagingRing::Allocation> reserved_;  // by buffer offset, until commit/reject
  std::vector<Copy> queued_;                                        // committed, pages not yet bound
  std::vector<Copy> ready_;                                         // pages bound (prepare_uploads), not yet recorded
  uint64_t prepared_serial_ = 0;
  std::deque<Copy> in_flight_;     // recorded, submission not yet complete
  std::vector<uint32_t> refused_;  // textures that can never be placed, in order (each logged once)
  MipFades fades_;
  TextureCacheStats stats_;
};

// VkFormat of the cache image for a texel format (sRGB: the shader filters in linear light).
VkFormat cache_vk_format(TexelFormat format);

}  // namespace texstream::render
