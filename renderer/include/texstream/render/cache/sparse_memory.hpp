#pragma once
// The Vulkan side of the sparse cache images (seed 000 §3.6): the partially-resident 2D array images (one per
// texel format of the scene), the device memory behind their pages, and the binds.
//
// * Every image's pages come out of one pool of slots and are bound by one vkQueueBindSparse per batch, so
//   several formats share one budget and one wait (docs/design/cache_formats.md). The images must agree on
//   the page size and have a memory type in common (they do on lavapipe and NVIDIA); create() says so if not.
//
// * The image has VK_IMAGE_CREATE_SPARSE_BINDING_BIT | SPARSE_RESIDENCY_BIT; its page size and the page shape
//   (imageGranularity) of the cache format are queried from the device, never assumed. The whole image must
//   fit the device's sparse address space (lavapipe: 2 GiB).
// * Memory: `memory_bytes` (cache.memory_bytes) is the most this object ever allocates. A mip tail, if the
//   device has one (lavapipe has none), is bound for good at start-up and paid first; the rest is cut into
//   one-page slots carved from a few large VkDeviceMemory blocks (kBlockBytes each), allocated the first time
//   a slot in them is bound and kept until destruction: never one allocation per page.
// * submit() turns one batch of SparsePageTable ops into exactly one vkQueueBindSparse that signals the next
//   value of a timeline semaphore; the frame's submission waits on that value before its copies (a sparse
//   bind is not ordered with command buffers of the same queue otherwise).
// Frame-thread only.
#include <vulkan/vulkan.h>

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/render/cache/sparse_page_table.hpp"
#include "texstream/render/vulkan/vk_handle.hpp"

namespace texstream::render {

class VulkanContext;

struct SparseImageInfo {
  VkFormat format = VK_FORMAT_R8G8B8A8_SRGB;
  uint32_t extent = 512;  // layer side at mip 0 (cache.layer_extent_px)
  uint32_t mip_levels = 10;
  uint32_t layers = 64;       // cache.layers
  uint64_t memory_bytes = 0;  // cache.memory_bytes: the GPU memory budget of the pages (and mip tails)
};

struct SparseBindStats {
  uint64_t calls = 0;       // vkQueueBindSparse calls
  uint64_t ops = 0;         // page binds + unbinds submitted
  double seconds = 0;       // building the bind arrays + the calls (and the waits for them)
  double call_seconds = 0;  // of which the calls and waits alone
  uint64_t max_ops_per_call = 0;
  std::vector<uint32_t> ops_per_call;  // one entry per call (the bind-cost benchmark replays these sizes)
};

class SparseMemory {
 public:
  // Bytes of one memory block: 16 MiB = 256 pages of 64 KiB, so a 1 GiB budget is 64 allocations at most
  // (well under maxMemoryAllocationCount, which is 4096 on many devices).
  static constexpr uint64_t kBlockBytes = 16ull << 20;

  // One image; info.memory_bytes is the budget.
  static Result<std::unique_ptr<SparseMemory>> create(const VulkanContext& ctx, const SparseImageInfo& info);
  // Several images (at most kMaxCacheImages) over one budget of `memory_bytes`; PageLocation::image indexes them.
  static Result<std::unique_ptr<SparseMemory>> create(const VulkanContext& ctx, std::span<const SparseImageInfo> images,
                                                      uint64_t memory_bytes);
  // Bytes of mip tail each layer of such an image costs on this device (0: none, or one tail for the whole
  // image), from a one-layer image that is never bound: the cache keeps the tail a small part of its budget.
  static Result<uint64_t> tail_bytes_per_layer(const VulkanContext& ctx, VkFormat format, uint32_t extent,
                                               uint32_t mip_levels);
  ~SparseMemory();
  SparseMemory(const SparseMemory&) = delete;
  SparseMemory& operator=(const SparseMemory&) = delete;

  uint32_t image_count() const { return static_cast<uint32_t>(images_.size()); }
  VkImage image(uint32_t i = 0) const { return images_[i].image.get(); }
  VkImageView view(uint32_t i = 0) const { return images_[i].view.get(); }
  const PageGeometry& geometry(uint32_t i = 0) const { return images_[i].geometry; }
  std::vector<PageGeometry> geometries() const;
  const SparseImageInfo& info(uint32_t i = 0) const { return images_[i].info; }
  uint64_t image_bytes(uint32_t i) const { return images_[i].image_bytes; }  // one image's virtual size
  uint64_t page_bytes() const { return page_bytes_; }
  uint32_t slot_count() const { return slot_count_; }
  uint64_t tail_bytes() const { return tail_bytes_; }            // every image's mip tail
  uint64_t allocated_bytes() const { return allocated_bytes_; }  // device memory allocated so far (<= budget)
  uint64_t image_bytes() const { return image_bytes_; }          // the images' virtual size, all together
  uint64_t memory_bytes() const { return memory_bytes_; }
  uint32_t pages_per_block() const { return pages_per_block_; }

  // One vkQueueBindSparse for the whole batch (nothing when it is empty). On success the semaphore reaches
  // signal_value() once the binds have executed.
  Status submit(std::span<const PageBindOp> ops);
  VkSemaphore semaphore() const { return semaphore_.get(); }
  uint64_t signal_value() const { return signal_value_; }
  const SparseBindStats& stats() const { return stats_; }

 private:
  // One image of the set. Members are destroyed in reverse order: view, image, then the tail's memory.
  struct Image {
    SparseImageInfo info;
    PageGeometry geometry;
    uint64_t image_bytes = 0;
    uint64_t tail_bytes = 0;
    uint64_t page_bytes = 0;
    uint32_t memory_type_bits = 0;
    std::vector<VkSparseImageMemoryRequirements> reqs;
    UniqueMemory tail_memory;
    UniqueImage image;
    UniqueImageView view;
  };

  SparseMemory() = default;
  Result<Image> create_image(const VulkanContext& ctx, const SparseImageInfo& info);
  Result<VkDeviceMemory> block_of(uint32_t slot);
  Status bind_tail(Image& image);

  VkDevice device_ = VK_NULL_HANDLE;
  VkQueue queue_ = VK_NULL_HANDLE;
  uint64_t memory_bytes_ = 0;
  uint64_t page_bytes_ = 0;
  uint32_t slot_count_ = 0;
  uint32_t pages_per_block_ = 0;
  uint32_t memory_type_ = 0;
  uint64_t tail_bytes_ = 0;
  uint64_t allocated_bytes_ = 0;
  uint64_t image_bytes_ = 0;
  uint64_t signal_value_ = 0;
  std::vector<UniqueMemory> blocks_;  // index = slot / pages_per_block_; null until first used
  UniqueSemaphore semaphore_;
  // Destroyed before the memory blocks (members are destroyed in reverse order).
  std::vector<Image> images_;
  std::vector<VkSparseImageMemoryBind> scratch_;
  SparseBindStats stats_;
};

}  // namespace texstream::render
