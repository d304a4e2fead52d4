#pragma once
// The scene's ground as one huge texture in pages (issue 28; seed 004 §3, seed 002 §4), on the GPU:
// - the page cache: a 2D array image, one bordered page per layer ("frame"), as many as pages.memory_bytes
//   holds (never more), the coarsest pages.locked_levels levels never evicted, the rest by pages.discard;
// - the frame table the shader walks up from the wanted page to its nearest resident ancestor (one uint per
//   quadtree slot, host-visible, rewritten only where a page comes or goes);
// - the needbuffer: every pages.needbuffer_step-th pixel of the ground writes where it hits the texture, the
//   level it wants and its distance (ground.frag); read back after the frame and aggregated per page by
//   choose_pages (stream/page_policy.hpp) with pages.heuristic and pages.order;
// - the uploads: pages arrive through the stream client (this class is its PageSink) into a host-visible
//   staging buffer and are copied into their frames at the start of the next submission, before any draw, so
//   a table entry never names a frame whose copy has not been recorded ahead of it.
// Frame-thread only, between submissions (RenderStack waits for each one).
#include <vulkan/vulkan.h>

#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include "texstream/common/config.hpp"
#include "texstream/common/page_file.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/render/vulkan/gpu_buffer.hpp"
#include "texstream/render/vulkan/gpu_image.hpp"
#include "texstream/stream/page_policy.hpp"
#include "texstream/stream/page_sink.hpp"

namespace texstream::render {

class VulkanContext;

struct GroundPagesOptions {
  PagesConfig config;
  uint32_t viewport_width = 960;  // the needbuffer covers the viewport at 1 / config.needbuffer_step per axis
  uint32_t viewport_height = 540;
  uint32_t staging_pages = 64;  // pages that can wait for their copy at once (reserve_page says "no room" beyond)
  // pages.reference: the whole texture as one ordinary mipmapped image read from `file_path` (RGBA8, at most
  // kMaxReferenceSide per side), nothing streamed: the reference the page path is compared with (seams).
  bool reference = false;
  std::filesystem::path file_path;
};

struct GroundPagesStats {
  uint64_t pages_requested = 0;
  uint64_t pages_uploaded = 0;   // copies recorded into frames
  uint64_t pages_failed = 0;     // answered without a page (or refused by the client)
  uint64_t pages_cancelled = 0;  // superseded by a newer cycle before the server started them (asked again if wanted)
  uint64_t pages_refused = 0;    // arrived, but every frame was locked or used this frame: dropped
  uint64_t evictions = 0;
  uint64_t needs_last_frame = 0;  // needbuffer texels that saw the ground in the last read-back
};

class GroundPages : public stream::PageSink {
 public:
  // `file`: the page file's header and index (PageFile::open of <scene>/<ground.pages>); its file id on the
  // segment is 0. Errors name pages.memory_bytes when not even the locked levels fit.
  static Result<std::unique_ptr<GroundPages>> create(const VulkanContext& ctx,
                                                     std::shared_ptr<const pages::PageFile> file,
                                                     const scene::GroundPages& placement,
                                                     const GroundPagesOptions& options);
  ~GroundPages() override;
  GroundPages(const GroundPages&) = delete;
  GroundPages& operator=(const GroundPages&) = delete;

  static constexpr uint32_t kFileId = 0;
  static constexpr uint32_t kMaxReferenceSide = 8192;
  bool reference() const { return options_.reference; }

  // Descriptor set 1's resources (shared_structs.h kGroundBinding*).
  VkImageView frames_view() const { return frames_.view(); }
  VkBuffer uniforms() const { return uniforms_.handle(); }
  VkBuffer table() const { return table_.handle(); }
  VkBuffer needs() const { return needs_.handle(); }
  VkDeviceSize needs_bytes() const;

  // Before a frame is recorded: the ground's corner relative to `camera` (map coordinates, computed in double)
  // and whether this frame writes the needbuffer.
  void write_uniforms(const std::array<double, 3>& camera, bool write_needs);
  bool writes_needs() const { return write_needs_; }
  // Into the submission's command buffer, before the passes: the copies of the pages that arrived.
  void record_uploads(VkCommandBuffer cmd);
  // Before the main pass of a frame that writes the needbuffer: fill it with "no ground" (NaN levels).
  void record_needs_clear(VkCommandBuffer cmd) const;
  // After the submission completed: staging space reused; when it drew the passes with write_needs, the
  // needbuffer is read back (plan() uses it).
  void on_submission_complete(bool drew);

  // After a frame that wrote the needbuffer completed: marks the pages it sampled used in frame `now` and
  // returns the pages to request, best first, at most pages.per_frame (minus those still in flight), or every
  // page the needbuffer wants with `everything` (reference frames: render.load_wanted_before_drawing).
  std::vector<pages::PageCandidate> plan(uint64_t now, pages::HotSpot hotspot, bool everything = false);
  bool staging_full() const { return free_staging_.empty(); }
  // Every stored page neither resident nor pending, coarsest first (render.preload_all).
  std::vector<pages::PageCandidate> missing_pages() const;
  // The stream client took the request (or did not): the page is pending until answered.
  void on_requested(pages::PageId page);

  // stream::PageSink
  std::span<std::byte> reserve_page(uint32_t file, pages::PageId page, uint64_t bytes) override;
  void commit_page(uint32_t file, pages::PageId page, std::span<std::byte> data) override;
  void page_failed(uint32_t file, pages::PageId page, CompletionStatus status) override;

  const pages::PageFile& file() const { return *file_; }
  const pages::PageFrameCache& frames() const { return *cache_; }
  const GroundPagesStats& stats() const { return stats_; }
  size_t pending() const { return pending_.size(); }
  // The last read-back's needbuffer as the policy sees it (tests).
  const std::vector<pages::PageNeedSample>& last_needs() const { return needs_seen_; }

 private:
  GroundPages() = default;
  void read_needs();
  Status load_reference(const VulkanContext& ctx);

  struct Upload {
    uint32_t staging;  // slot of the staging buffer
    uint32_t frame;
    pages::PageId page;
  };

  std::shared_ptr<const pages::PageFile> file_;
  scene::GroundPages placement_;
  GroundPagesOptions options_;
  pages::PagePolicyOptions policy_;
  std::unique_ptr<pages::PageFrameCache> cache_;
  std::vector<std::optional<pages::PageId>> page_of_frame_;  // what the GPU table says each frame holds
  GpuImage frames_;
  bool frames_initialised_ = false;
  GpuBuffer uniforms_;
  GpuBuffer table_;
  GpuBuffer needs_;
  GpuBuffer staging_;
  std::vector<uint32_t> free_staging_;
  std::vector<uint32_t> staging_in_use_;  // copies recorded, waiting for the submission to complete
  std::optional<std::pair<pages::PageId, uint32_t>> reserved_;  // reserve_page's slot until its commit
  std::vector<Upload> uploads_;
  std::vector<pages::PageId> pending_;
  std::vector<pages::PageNeedSample> needs_seen_;
  uint32_t needs_cols_ = 0, needs_rows_ = 0;
  bool write_needs_ = false;
  uint64_t now_ = 0;
  GroundPagesStats stats_;
};

}  // namespace texstream::render
