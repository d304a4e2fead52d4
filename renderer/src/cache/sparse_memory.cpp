#include "texstream/render/cache/sparse_memory.hpp"

#include <algorithm>
#include <chrono>
#include <string>

#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

namespace {

constexpr VkImageUsageFlags kUsage = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;

bool queue_family_can_bind(const VulkanContext& ctx) {
  uint32_t n = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(ctx.physical_device(), &n, nullptr);
  std::vector<VkQueueFamilyProperties> families(n);
  vkGetPhysicalDeviceQueueFamilyProperties(ctx.physical_device(), &n, families.data());
  return ctx.queue_family() < n && (families[ctx.queue_family()].queueFlags & VK_QUEUE_SPARSE_BINDING_BIT);
}

std::string mib(uint64_t bytes) { return std::to_string(bytes >> 20) + " MiB"; }

// The cache image: a square 2D array, sparse and partially resident, sampled and written by copies.
VkImageCreateInfo sparse_image_create_info(VkFormat format, uint32_t extent, uint32_t mip_levels, uint32_t layers) {
  VkImageCreateInfo ici{};
  ici.sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO;
  ici.flags = VK_IMAGE_CREATE_SPARSE_BINDING_BIT | VK_IMAGE_CREATE_SPARSE_RESIDENCY_BIT;
  ici.imageType = VK_IMAGE_TYPE_2D;
  ici.format = format;
  ici.extent = {extent, extent, 1};
  ici.mipLevels = mip_levels;
  ici.arrayLayers = layers;
  ici.samples = VK_SAMPLE_COUNT_1_BIT;
  ici.tiling = VK_IMAGE_TILING_OPTIMAL;
  ici.usage = kUsage;
  ici.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  ici.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  return ici;
}

}  // namespace

SparseMemory::~SparseMemory() = default;

Result<std::unique_ptr<SparseMemory>> SparseMemory::create(const VulkanContext& ctx, const SparseImageInfo& info) {
  return create(ctx, std::span<const SparseImageInfo>(&info, 1), info.memory_bytes);
}

Result<std::unique_ptr<SparseMemory>> SparseMemory::create(const VulkanContext& ctx,
                                                           std::span<const SparseImageInfo> images,
                                                           uint64_t memory_bytes) {
  TS_ASSERT(!images.empty() && images.size() <= kMaxCacheImages, "%zu sparse cache images", images.size());
  VkPhysicalDeviceFeatures features{};
  vkGetPhysicalDeviceFeatures(ctx.physical_device(), &features);
  if (!features.sparseBinding || !features.sparseResidencyImage2D) {
    return make_error(ErrorCode::kUnsupported, "device '" + ctx.device_name() +
                                                   "' lacks sparseBinding / sparseResidencyImage2D (the texture cache "
                                                   "is a sparse partially-resident image)");
  }
  if (!queue_family_can_bind(ctx)) {
    return make_error(ErrorCode::kUnsupported, "the renderer's queue family has no VK_QUEUE_SPARSE_BINDING_BIT");
  }
  std::unique_ptr<SparseMemory> m(new SparseMemory());
  m->device_ = ctx.device();
  m->queue_ = ctx.queue();
  m->memory_bytes_ = memory_bytes;
  uint32_t type_bits = ~0u;
  for (const SparseImageInfo& in : images) {
    SparseImageInfo info = in;
    info.memory_bytes = memory_bytes;
    auto image = m->create_image(ctx, info);
    if (!image) return image.error();
    Image& im = m->images_.emplace_back(std::move(*image));
    if (m->page_bytes_ != 0 && im.page_bytes != m->page_bytes_) {
      return make_error(ErrorCode::kUnsupported,
                        "the device's sparse pages are " + std::to_string(m->page_bytes_) + " bytes for VkFormat " +
                            std::to_string(images[0].format) + " but " + std::to_string(im.page_bytes) +
                            " for VkFormat " + std::to_string(info.format) +
                            ": one cache cannot hold both; set cache.format to one texel format");
    }
    m->page_bytes_ = im.page_bytes;
    type_bits &= im.memory_type_bits;
    m->image_bytes_ += im.image_bytes;
    m->tail_bytes_ += im.tail_bytes;
  }
  const VkDeviceSize space = ctx.properties().limits.sparseAddressSpaceSize;
  if (m->image_bytes_ > space) {
    return make_error(ErrorCode::kInvalidArgument, "cache.layers x cache.layer_extent_px need " + mib(m->image_bytes_) +
                                                       " of sparse address space; the device has " + mib(space));
  }
  auto type = ctx.find_memory_type(type_bits, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (!type) {
    return make_error(ErrorCode::kUnsupported,
                      "the sparse cache images of the scene's texel formats share no "
                      "device-local memory type; set cache.format to one texel format");
  }
  m->memory_type_ = *type;

  // The texture cache checks that its largest texture fits (TextureCache::create); here only that the budget
  // leaves pages after the mip tails, which are paid first.
  if (memory_bytes < m->tail_bytes_ + m->page_bytes_) {
    return make_error(ErrorCode::kInvalidArgument, "cache.memory_bytes = " + std::to_string(memory_bytes) +
                                                       " does not cover the mip tail of the cache image (" +
                                                       std::to_string(m->tail_bytes_) + " bytes) and one page");
  }
  const uint64_t pages = (memory_bytes - m->tail_bytes_) / m->page_bytes_;
  m->slot_count_ = static_cast<uint32_t>(std::min<uint64_t>(pages, UINT32_MAX));
  m->pages_per_block_ = static_cast<uint32_t>(std::max<uint64_t>(kBlockBytes / m->page_bytes_, 1));
  m->blocks_.resize((m->slot_count_ + m->pages_per_block_ - 1) / m->pages_per_block_);

  VkSemaphoreTypeCreateInfo sti{};
  sti.sType = VK_STRUCTURE_TYPE_SEMAPHORE_TYPE_CREATE_INFO;
  sti.semaphoreType = VK_SEMAPHORE_TYPE_TIMELINE;
  VkSemaphoreCreateInfo sci{};
  sci.sType = VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO;
  sci.pNext = &sti;
  VkSemaphore sem = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateSemaphore(m->device_, &sci, nullptr, &sem));
  m->semaphore_ = UniqueSemaphore(m->device_, sem);

  for (Image& im : m->images_) {
    if (im.tail_bytes > 0) TS_TRY(m->bind_tail(im));
    VkImageViewCreateInfo vci{};
    vci.sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO;
    vci.image = im.image.get();
    vci.viewType = VK_IMAGE_VIEW_TYPE_2D_ARRAY;
    vci.format = im.info.format;
    vci.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, im.info.mip_levels, 0, im.info.layers};
    VkImageView view = VK_NULL_HANDLE;
    TS_VK_TRY(vkCreateImageView(m->device_, &vci, nullptr, &view));
    im.view = UniqueImageView(m->device_, view);
  }
  return m;
}

Result<SparseMemory::Image> SparseMemory::create_image(const VulkanContext& ctx, const SparseImageInfo& info) {
  // The cache format must be sparse-residency capable, with its own page shape.
  uint32_t nprops = 0;
  vkGetPhysicalDeviceSparseImageFormatProperties(ctx.physical_device(), info.format, VK_IMAGE_TYPE_2D,
                                                 VK_SAMPLE_COUNT_1_BIT, kUsage, VK_IMAGE_TILING_OPTIMAL, &nprops,
                                                 nullptr);
  if (nprops == 0) {
    return make_error(ErrorCode::kUnsupported,
                      "cache.format: VkFormat " + std::to_string(info.format) + " has no sparse residency support");
  }
  Image im;
  im.info = info;
  const VkImageCreateInfo ici = sparse_image_create_info(info.format, info.extent, info.mip_levels, info.layers);
  VkImage image = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateImage(device_, &ici, nullptr, &image));
  im.image = UniqueImage(device_, image);

  VkMemoryRequirements req{};
  vkGetImageMemoryRequirements(device_, image, &req);
  im.page_bytes = req.alignment;  // the sparse block size (64 KiB on lavapipe and most GPUs)
  im.image_bytes = req.size;
  im.memory_type_bits = req.memoryTypeBits;
  const VkDeviceSize space = ctx.properties().limits.sparseAddressSpaceSize;
  if (req.size > space) {
    return make_error(ErrorCode::kInvalidArgument, "cache.layers = " + std::to_string(info.layers) +
                                                       " x cache.layer_extent_px = " + std::to_string(info.extent) +
                                                       " needs " + mib(req.size) +
                                                       " of sparse address space; the device has " + mib(space));
  }
  uint32_t nreq = 0;
  vkGetImageSparseMemoryRequirements(device_, image, &nreq, nullptr);
  im.reqs.resize(nreq);
  vkGetImageSparseMemoryRequirements(device_, image, &nreq, im.reqs.data());
  const VkSparseImageMemoryRequirements* colour = nullptr;
  for (const auto& r : im.reqs)
    if (r.formatProperties.aspectMask & VK_IMAGE_ASPECT_COLOR_BIT) colour = &r;
  if (!colour) return make_error(ErrorCode::kUnsupported, "sparse cache image has no colour-aspect requirements");
  // imageGranularity is "in texels or compressed texel blocks" (spec): lavapipe gives BC1 128x64, which is
  // blocks (128 x 64 blocks x 8 bytes = one 64 KiB page), NVIDIA gives 512x256 texels. Decide by the page
  // size, and keep texels (VkSparseImageMemoryBind offsets and extents are texels).
  VkExtent3D g = colour->formatProperties.imageGranularity;
  const bool bc1 = info.format == VK_FORMAT_BC1_RGBA_SRGB_BLOCK || info.format == VK_FORMAT_BC1_RGBA_UNORM_BLOCK;
  const bool bc3 = info.format == VK_FORMAT_BC3_SRGB_BLOCK || info.format == VK_FORMAT_BC3_UNORM_BLOCK ||
                   info.format == VK_FORMAT_BC7_SRGB_BLOCK || info.format == VK_FORMAT_BC7_UNORM_BLOCK;  // 16 B blocks
  const uint64_t block_bytes = bc1 ? 8 : bc3 ? 16 : 4, block_side = bc1 || bc3 ? 4 : 1;
  if (block_side > 1 && uint64_t{g.width} * g.height * block_bytes == im.page_bytes) {
    g.width *= block_side;
    g.height *= block_side;
  }
  if (uint64_t{g.width} * g.height * block_bytes / (block_side * block_side) != im.page_bytes) {
    return make_error(ErrorCode::kUnsupported, "sparse page of " + std::to_string(im.page_bytes) +
                                                   " bytes does not match its " + std::to_string(g.width) + "x" +
                                                   std::to_string(g.height) + " granularity");
  }
  im.geometry = PageGeometry{info.extent, info.mip_levels, info.layers,
                             g.width,     g.height,        std::min(colour->imageMipTailFirstLod, info.mip_levels)};
  for (const auto& r : im.reqs) {
    if (r.imageMipTailFirstLod >= info.mip_levels && !(r.formatProperties.aspectMask & VK_IMAGE_ASPECT_METADATA_BIT))
      continue;
    const bool single = (r.formatProperties.flags & VK_SPARSE_IMAGE_FORMAT_SINGLE_MIPTAIL_BIT) ||
                        (r.formatProperties.aspectMask & VK_IMAGE_ASPECT_METADATA_BIT);
    im.tail_bytes += single ? r.imageMipTailSize : r.imageMipTailSize * info.layers;
  }
  return im;
}

std::vector<PageGeometry> SparseMemory::geometries() const {
  std::vector<PageGeometry> out;
  for (const Image& im : images_) out.push_back(im.geometry);
  return out;
}

Result<uint64_t> SparseMemory::tail_bytes_per_layer(const VulkanContext& ctx, VkFormat format, uint32_t extent,
                                                    uint32_t mip_levels) {
  const VkImageCreateInfo ici = sparse_image_create_info(format, extent, mip_levels, 1);
  VkImage image = VK_NULL_HANDLE;
  TS_VK_TRY(vkCreateImage(ctx.device(), &ici, nullptr, &image));
  UniqueImage owner(ctx.device(), image);
  uint32_t n = 0;
  vkGetImageSparseMemoryRequirements(ctx.device(), image, &n, nullptr);
  std::vector<VkSparseImageMemoryRequirements> reqs(n);
  vkGetImageSparseMemoryRequirements(ctx.device(), image, &n, reqs.data());
  uint64_t bytes = 0;
  for (const auto& r : reqs) {
    const bool metadata = r.formatProperties.aspectMask & VK_IMAGE_ASPECT_METADATA_BIT;
    const bool single = (r.formatProperties.flags & VK_SPARSE_IMAGE_FORMAT_SINGLE_MIPTAIL_BIT) || metadata;
    if (r.imageMipTailFirstLod < mip_levels && !single) bytes += r.imageMipTailSize;
  }
  return bytes;
}

Status SparseMemory::bind_tail(Image& im) {
  VkMemoryAllocateInfo ai{};
  ai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
  ai.allocationSize = im.tail_bytes;
  ai.memoryTypeIndex = memory_type_;
  VkDeviceMemory mem = VK_NULL_HANDLE;
  TS_VK_TRY(vkAllocateMemory(device_, &ai, nullptr, &mem));
  im.tail_memory = UniqueMemory(device_, mem);
  allocated_bytes_ += im.tail_bytes;
  std::vector<VkSparseMemoryBind> binds;
  VkDeviceSize offset = 0;
  for (const auto& r : im.reqs) {
    const bool metadata = r.formatProperties.aspectMask & VK_IMAGE_ASPECT_METADATA_BIT;
    if (r.imageMipTailFirstLod >= im.info.mip_levels && !metadata) continue;
    const bool single = (r.formatProperties.flags & VK_SPARSE_IMAGE_FORMAT_SINGLE_MIPTAIL_BIT) || metadata;
    const uint32_t count = single ? 1 : im.info.layers;
    for (uint32_t layer = 0; layer < count; ++layer) {
      VkSparseMemoryBind b{};
      b.resourceOffset = r.imageMipTailOffset + layer * r.imageMipTailStride;
      b.size = r.imageMipTailSize;
      b.memory = mem;
      b.memoryOffset = offset;
      b.flags = metadata ? VK_SPARSE_MEMORY_BIND_METADATA_BIT : 0;
      offset += r.imageMipTailSize;
      binds.push_back(b);
    }
  }
  VkSparseImageOpaqueMemoryBindInfo opaque{im.image.get(), static_cast<uint32_t>(binds.size()), binds.data()};
  VkBindSparseInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_BIND_SPARSE_INFO;
  bi.imageOpaqueBindCount = 1;
  bi.pImageOpaqueBinds = &opaque;
  VkTimelineSemaphoreSubmitInfo ts{};
  ts.sType = VK_STRUCTURE_TYPE_TIMELINE_SEMAPHORE_SUBMIT_INFO;
  const uint64_t value = ++signal_value_;
  ts.signalSemaphoreValueCount = 1;
  ts.pSignalSemaphoreValues = &value;
  VkSemaphore sem = semaphore_.get();
  bi.pNext = &ts;
  bi.signalSemaphoreCount = 1;
  bi.pSignalSemaphores = &sem;
  TS_VK_TRY(vkQueueBindSparse(queue_, 1, &bi, VK_NULL_HANDLE));
  // Once at start-up: the cache's first layout transition must not race the tail binding.
  TS_VK_TRY(vkQueueWaitIdle(queue_));
  return ok_status();
}

Result<VkDeviceMemory> SparseMemory::block_of(uint32_t slot) {
  const uint32_t b = slot / pages_per_block_;
  TS_ASSERT(b < blocks_.size(), "slot %u outside the %u slots", slot, slot_count_);
  if (!blocks_[b]) {
    // The last block holds only the slots left, so the blocks never add up to more than the budget.
    const uint64_t slots = std::min<uint64_t>(pages_per_block_, slot_count_ - b * pages_per_block_);
    VkMemoryAllocateInfo ai{};
    ai.sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO;
    ai.allocationSize = slots * page_bytes_;
    ai.memoryTypeIndex = memory_type_;
    VkDeviceMemory mem = VK_NULL_HANDLE;
    TS_VK_TRY(vkAllocateMemory(device_, &ai, nullptr, &mem));
    blocks_[b] = UniqueMemory(device_, mem);
    allocated_bytes_ += ai.allocationSize;
    TS_ASSERT(allocated_bytes_ <= memory_bytes_, "sparse cache memory %llu above the budget %llu",
              (unsigned long long)allocated_bytes_, (unsigned long long)memory_bytes_);
  }
  return blocks_[b].get();
}

Status SparseMemory::submit(std::span<const PageBindOp> ops) {
  if (ops.empty()) return ok_status();
  // Memory blocks first: a block is allocated once per run, not per bind, so it is not part of the bind cost.
  for (const PageBindOp& op : ops) {
    if (!op.bind) continue;
    auto mem = block_of(op.slot);
    if (!mem) return mem.error();
  }
  const auto t0 = std::chrono::steady_clock::now();
  scratch_.clear();
  scratch_.reserve(ops.size());
  // One VkSparseImageMemoryBindInfo per image, in the batch's order (SparsePageTable sorts by image first).
  std::vector<std::pair<uint32_t, size_t>> runs;  // image, first op of its run
  for (const PageBindOp& op : ops) {
    TS_ASSERT(op.page.image < images_.size(), "bind of image %u of %zu", op.page.image, images_.size());
    const Image& im = images_[op.page.image];
    const uint32_t gw = im.geometry.granularity_w, gh = im.geometry.granularity_h;
    const uint32_t level = std::max(im.info.extent >> op.page.mip, 1u);
    VkSparseImageMemoryBind b{};
    b.subresource = {VK_IMAGE_ASPECT_COLOR_BIT, op.page.mip, op.page.layer};
    b.offset = {static_cast<int32_t>(op.page.x * gw), static_cast<int32_t>(op.page.y * gh), 0};
    // Whole pages, except at the level's right and bottom edge (which is how levels below one page are bound).
    b.extent = {std::min(gw, level - op.page.x * gw), std::min(gh, level - op.page.y * gh), 1};
    if (op.bind) {
      b.memory = blocks_[op.slot / pages_per_block_].get();
      b.memoryOffset = static_cast<VkDeviceSize>(op.slot % pages_per_block_) * page_bytes_;
    }
    if (runs.empty() || runs.back().first != op.page.image) runs.emplace_back(op.page.image, scratch_.size());
    scratch_.push_back(b);
  }
  std::vector<VkSparseImageMemoryBindInfo> image_binds;
  for (size_t i = 0; i < runs.size(); ++i) {
    const size_t end = i + 1 < runs.size() ? runs[i + 1].second : scratch_.size();
    image_binds.push_back({images_[runs[i].first].image.get(), static_cast<uint32_t>(end - runs[i].second),
                           scratch_.data() + runs[i].second});
  }
  VkBindSparseInfo bi{};
  bi.sType = VK_STRUCTURE_TYPE_BIND_SPARSE_INFO;
  bi.imageBindCount = static_cast<uint32_t>(image_binds.size());
  bi.pImageBinds = image_binds.data();
  const uint64_t value = signal_value_ + 1;
  VkTimelineSemaphoreSubmitInfo ts{};
  ts.sType = VK_STRUCTURE_TYPE_TIMELINE_SEMAPHORE_SUBMIT_INFO;
  ts.signalSemaphoreValueCount = 1;
  ts.pSignalSemaphoreValues = &value;
  VkSemaphore sem = semaphore_.get();
  bi.pNext = &ts;
  bi.signalSemaphoreCount = 1;
  bi.pSignalSemaphores = &sem;
  const auto t_call = std::chrono::steady_clock::now();
  TS_VK_TRY(vkQueueBindSparse(queue_, 1, &bi, VK_NULL_HANDLE));
  signal_value_ = value;
  // Wait for the binds here: the frame's submission would wait for them anyway (its copies need the pages),
  // and lavapipe returns from vkQueueBindSparse before binding, so only this makes the measured bind cost the
  // real one. No GPU work is pending on this queue at this point (one frame in flight, already complete).
  VkSemaphoreWaitInfo wi{};
  wi.sType = VK_STRUCTURE_TYPE_SEMAPHORE_WAIT_INFO;
  wi.semaphoreCount = 1;
  wi.pSemaphores = &sem;
  wi.pValues = &value;
  TS_VK_TRY(vkWaitSemaphores(device_, &wi, UINT64_MAX));
  const auto t_end = std::chrono::steady_clock::now();
  stats_.seconds += std::chrono::duration<double>(t_end - t0).count();
  stats_.call_seconds += std::chrono::duration<double>(t_end - t_call).count();
  ++stats_.calls;
  stats_.ops += ops.size();
  stats_.max_ops_per_call = std::max<uint64_t>(stats_.max_ops_per_call, ops.size());
  stats_.ops_per_call.push_back(static_cast<uint32_t>(ops.size()));
  return ok_status();
}

}  // namespace texstream::render
