#pragma once
// The texture cache (seed 000 §3.6; non-sparse for now): one 2D array image with a full mip chain, placed by
// CacheAllocator, filled from a host-visible staging ring that StreamClient copies validated payloads into
// (this class is its MipSink). A mip becomes visible to the shader (TextureGpu) and to the texture state
// machine (on_committed) only after the GPU copy that wrote it has completed; staging space is reused only
// then. Frame-thread only; every method runs between frames, when no submitted work reads the texture table.
#include <vulkan/vulkan.h>

#include <cstdint>
#include <deque>
#include <memory>
#include <unordered_map>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/protocol/texel_format.hpp"
#include "texstream/render/cache_allocator.hpp"
#include "texstream/render/gpu_buffer.hpp"
#include "texstream/render/gpu_image.hpp"
#include "texstream/render/staging_ring.hpp"
#include "texstream/render/stream_client.hpp"
#include "texstream/render/texture_states.hpp"

namespace texstream::render {

class VulkanContext;
struct SceneData;

struct TextureCacheOptions {
  TexelFormat format = TexelFormat::kRgba8;  // cache.format; every scene texture must have it
  uint32_t layer_extent = 512;               // cache.layer_extent_px, a power of two
  uint32_t layers = 64;                      // cache.layers
  uint64_t staging_bytes = 32ull << 20;      // host-visible staging ring
};

struct TextureCacheStats {
  uint64_t mips_uploaded = 0;     // copies completed and published
  uint64_t bytes_uploaded = 0;
  uint64_t mips_dropped = 0;      // committed, but the texture was evicted before its copy was recorded or done
  uint64_t evictions = 0;         // textures invalidated by layer recycling
  uint64_t staging_full = 0;      // reserve() answered "no room now"
};

class TextureCache final : public MipSink {
 public:
  static Result<std::unique_ptr<TextureCache>> create(const VulkanContext& ctx, const TextureCacheOptions& options,
                                                      const SceneData& scene, TextureStates& states);

  // ---- MipSink (called from StreamClient::poll) ----
  std::span<std::byte> reserve(TextureId texture, MipLevel mip, uint64_t bytes) override;
  void commit(TextureId texture, MipLevel mip, std::span<std::byte> data) override;
  void reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) override;
  void failed(TextureId texture, MipLevel mip, CompletionStatus status) override;

  // Records the copies committed since the last call into `cmd` (with the layout barriers around them);
  // they complete with the submission numbered `serial`. Returns the number of copies.
  uint32_t record_uploads(VkCommandBuffer cmd, uint64_t serial);
  // Submission `serial` (and every earlier one) has completed: publish what it copied.
  void on_submission_complete(uint64_t serial);

  VkImageView image_view() const { return image_.view(); }
  VkBuffer texture_table() const { return table_.handle(); }
  VkDeviceSize texture_table_bytes() const { return table_.size(); }
  uint32_t mip_levels() const { return mip_levels_; }
  uint32_t layer_extent() const { return options_.layer_extent; }
  uint64_t resident_textures() const;
  const TextureCacheStats& stats() const { return stats_; }

 private:
  struct Residency {
    uint32_t mask = 0;   // bit L: mip L is in the image and published
    uint32_t epoch = 0;  // bumped on eviction: copies of an older epoch publish nothing
  };
  struct Copy {
    TextureId texture;
    uint32_t mip;
    StagingRing::Allocation staging;
    uint32_t epoch;
    uint64_t serial;  // submission that carries it (after record_uploads)
  };

  TextureCache(const TextureCacheOptions& options, const SceneData& scene, TextureStates& states);
  void evict(TextureId texture);
  void publish(TextureId texture);
  void release_staging(const StagingRing::Allocation& a);

  TextureCacheOptions options_;
  const SceneData& scene_;
  TextureStates& states_;
  uint32_t mip_levels_ = 1;
  GpuImage image_;
  GpuBuffer staging_;
  GpuBuffer table_;  // gpu::TextureGpu[texture_count], host-visible
  StagingRing ring_;
  CacheAllocator allocator_;
  std::vector<Residency> residency_;
  std::unordered_map<uint64_t, StagingRing::Allocation> reserved_;  // by buffer offset, until commit/reject
  std::vector<Copy> queued_;        // committed, not yet recorded
  std::deque<Copy> in_flight_;      // recorded, submission not yet complete
  std::vector<bool> unplaceable_logged_;
  TextureCacheStats stats_;
};

// VkFormat of the cache image for a texel format (sRGB: the shader filters in linear light).
VkFormat cache_vk_format(TexelFormat format);

}  // namespace texstream::render
