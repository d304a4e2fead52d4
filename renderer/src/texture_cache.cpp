#include "texstream/render/texture_cache.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>

#include "texstream/render/gpu_structs.hpp"
#include "texstream/render/one_shot.hpp"
#include "texstream/render/scene_data.hpp"
#include "texstream/render/vk_check.hpp"
#include "texstream/render/vulkan_context.hpp"

namespace texstream::render {

namespace {

// vkCmdCopyBufferToImage wants bufferOffset a multiple of the texel block size (4 for RGBA8, 8 for BC1) and of
// 4; 16 covers both and keeps rows of a CPU memcpy aligned.
constexpr uint64_t kStagingAlignment = 16;
// BC1 stores 4x4 blocks: a copy whose extent is not whole blocks must end at the mip's edge, so a region side
// below one block at some level cannot be written without touching a neighbour.
constexpr uint32_t kBc1Block = 4;

uint32_t block_size(TexelFormat f) { return f == TexelFormat::kBc1 ? kBc1Block : 1; }

}  // namespace

VkFormat cache_vk_format(TexelFormat format) {
  return format == TexelFormat::kBc1 ? VK_FORMAT_BC1_RGBA_SRGB_BLOCK : VK_FORMAT_R8G8B8A8_SRGB;
}

TextureCache::TextureCache(const TextureCacheOptions& options, const SceneData& scene, TextureStates& states)
    : options_(options),
      scene_(scene),
      states_(states),
      ring_(options.staging_bytes),
      allocator_(options.layer_extent, options.layers),
      residency_(scene.textures.size()),
      unplaceable_logged_(scene.textures.size(), false) {}

Result<std::unique_ptr<TextureCache>> TextureCache::create(const VulkanContext& ctx, const TextureCacheOptions& options,
                                                           const SceneData& scene, TextureStates& states) {
  if (options.layer_extent == 0 || (options.layer_extent & (options.layer_extent - 1)) != 0) {
    return make_error(ErrorCode::kInvalidArgument, "cache.layer_extent_px = " + std::to_string(options.layer_extent) +
                                                       " is not a power of two");
  }
  if (options.layers > ctx.properties().limits.maxImageArrayLayers) {
    return make_error(ErrorCode::kInvalidArgument,
                      "cache.layers = " + std::to_string(options.layers) + " exceeds the device's maxImageArrayLayers " +
                          std::to_string(ctx.properties().limits.maxImageArrayLayers));
  }
  // The renderer never decodes: texel blocks go from the file to the image unchanged.
  for (size_t i = 0; i < scene.textures.size(); ++i) {
    if (scene.textures[i].format != static_cast<uint32_t>(options.format)) {
      return make_error(ErrorCode::kInvalidArgument,
                        "cache.format = " + std::string(to_string(options.format)) + " but texture " + std::to_string(i) +
                            " of " + (scene.dir / "textures.bin").string() + " is " +
                            std::string(to_string(texel_format_from_raw(scene.textures[i].format)
                                                      .value_or(TexelFormat::kRgba8))));
    }
  }

  std::unique_ptr<TextureCache> c(new TextureCache(options, scene, states));
  c->mip_levels_ = floor_log2(options.layer_extent) + 1;
  GpuImageInfo info;
  info.format = cache_vk_format(options.format);
  info.width = info.height = options.layer_extent;
  info.mip_levels = c->mip_levels_;
  info.layers = options.layers;
  info.usage = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  info.view_type = VK_IMAGE_VIEW_TYPE_2D_ARRAY;
  auto image = GpuImage::create(ctx, info);
  if (!image) return image.error();
  c->image_ = std::move(*image);

  auto staging = GpuBuffer::create(ctx, options.staging_bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::kHostVisible);
  if (!staging) return staging.error();
  c->staging_ = std::move(*staging);

  const size_t n = std::max<size_t>(scene.textures.size(), 1);
  auto table = GpuBuffer::create(ctx, n * sizeof(gpu::TextureGpu), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT,
                                 MemoryUse::kHostVisible);
  if (!table) return table.error();
  c->table_ = std::move(*table);
  auto* t = c->table_.as<gpu::TextureGpu>();
  std::fill_n(t, n, gpu::TextureGpu{});
  for (size_t i = 0; i < scene.textures.size(); ++i) {
    const auto& r = scene.textures[i];
    t[i].placement = {0, gpu::kNotResident, 0, r.mip_count};
    t[i].region = {0, 0, r.width, r.height};
    t[i].colour = {scene.colormap[i], 0, 0, 0};
  }

  // Every level of every layer starts in the layout the shader reads; copies move it to TRANSFER_DST and back.
  VkImage img = c->image_.handle();
  const uint32_t levels = c->mip_levels_, layers = options.layers;
  TS_TRY(run_one_shot(ctx, [&](VkCommandBuffer cmd) {
    VkImageMemoryBarrier b{};
    b.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
    b.srcAccessMask = 0;
    b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    b.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    b.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    b.image = img;
    b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, levels, 0, layers};
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0, nullptr,
                         0, nullptr, 1, &b);
  }));
  return c;
}

std::span<std::byte> TextureCache::reserve(TextureId, MipLevel, uint64_t bytes) {
  auto a = ring_.allocate(bytes, kStagingAlignment);
  if (!a) {
    ++stats_.staging_full;
    return {};  // the client holds the completion and offers it again next frame
  }
  reserved_.emplace(a->offset, *a);
  return staging_.bytes().subspan(a->offset, bytes);
}

void TextureCache::release_staging(const StagingRing::Allocation& a) { ring_.release(a.id); }

void TextureCache::reject(TextureId texture, MipLevel mip, std::span<std::byte> reserved) {
  if (!reserved.empty()) {
    const auto offset = static_cast<uint64_t>(reserved.data() - staging_.bytes().data());
    auto it = reserved_.find(offset);
    TS_ASSERT(it != reserved_.end(), "reject of a span this sink did not reserve");
    release_staging(it->second);
    reserved_.erase(it);
  }
  states_.on_rejected(texture, mip);
}

void TextureCache::failed(TextureId texture, MipLevel mip, CompletionStatus status) {
  states_.on_failed(texture, mip, status);
}

void TextureCache::evict(TextureId texture) {
  Residency& r = residency_[texture.value];
  r.mask = 0;
  ++r.epoch;
  ++stats_.evictions;
  table_.as<gpu::TextureGpu>()[texture.value].placement.y = gpu::kNotResident;
  // Copies not yet recorded would write into a region that now belongs to another texture: drop them.
  std::erase_if(queued_, [&](const Copy& c) {
    if (c.texture != texture) return false;
    release_staging(c.staging);
    ++stats_.mips_dropped;
    return true;
  });
  states_.invalidate(texture);
}

void TextureCache::commit(TextureId texture, MipLevel mip, std::span<std::byte> data) {
  const auto offset = static_cast<uint64_t>(data.data() - staging_.bytes().data());
  auto it = reserved_.find(offset);
  TS_ASSERT(it != reserved_.end(), "commit of a span this sink did not reserve");
  const StagingRing::Allocation alloc = it->second;
  reserved_.erase(it);

  // StreamClient checked the payload against the texture table; these are our own invariants.
  TS_ASSERT(texture.value < scene_.textures.size(), "commit of unknown texture %u", texture.value);
  const scene::TextureRecord& rec = scene_.textures[texture.value];
  TS_ASSERT(mip.value < rec.mip_count && data.size() == mip_bytes(options_.format, rec.width, rec.height, mip.value),
            "commit of texture %u mip %u with %zu bytes", texture.value, mip.value, data.size());

  auto region = allocator_.find(texture);
  if (!region) {
    std::vector<TextureId> evicted;
    // BC1 regions are at least one block wide so that the 4x4 level (one block) has a region of its own.
    const uint32_t w = std::max(rec.width, block_size(options_.format));
    auto placed = allocator_.allocate(texture, w, rec.height, evicted);
    for (TextureId e : evicted) evict(e);
    if (!placed) {
      if (!unplaceable_logged_[texture.value]) {
        spdlog::warn("texture cache: {}", placed.error().message);
        unplaceable_logged_[texture.value] = true;
      }
      release_staging(alloc);
      // Not the file's fault, but it can never be shown: kNotFound marks it broken, so it is not asked again.
      states_.on_failed(texture, mip, CompletionStatus::kNotFound);
      return;
    }
    region = *placed;
    auto& t = table_.as<gpu::TextureGpu>()[texture.value];
    t.placement.x = region->layer;
    t.region.x = region->origin_x;
    t.region.y = region->origin_y;
  }
  if ((region->extent >> mip.value) < block_size(options_.format)) {
    // A BC1 level smaller than a block in a shared layer: writing it would overwrite a neighbour's texels.
    release_staging(alloc);
    states_.on_rejected(texture, mip);
    return;
  }
  queued_.push_back(Copy{texture, mip.value, alloc, residency_[texture.value].epoch, 0});
}

uint32_t TextureCache::record_uploads(VkCommandBuffer cmd, uint64_t serial) {
  if (queued_.empty()) return 0;
  VkImageMemoryBarrier b{};
  b.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.image = image_.handle();
  b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, mip_levels_, 0, options_.layers};
  // Earlier frames' fragment shaders read the image; the copies must wait for them (write-after-read).
  b.srcAccessMask = VK_ACCESS_SHADER_READ_BIT;
  b.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.oldLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
  b.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0,
                       nullptr, 1, &b);

  std::vector<VkBufferImageCopy> regions;
  regions.reserve(queued_.size());
  const uint32_t block = block_size(options_.format);
  for (Copy& c : queued_) {
    const scene::TextureRecord& rec = scene_.textures[c.texture.value];
    const auto region = allocator_.find(c.texture);
    TS_ASSERT(region.has_value(), "queued copy of texture %u without a region", c.texture.value);
    const Extent2D e = mip_extent(rec.width, rec.height, c.mip);
    VkBufferImageCopy r{};
    r.bufferOffset = c.staging.offset;
    r.bufferRowLength = 0;  // tightly packed, as the DDS stores it
    r.bufferImageHeight = 0;
    r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, c.mip, region->layer, 1};
    r.imageOffset = {static_cast<int32_t>(region->origin_x >> c.mip), static_cast<int32_t>(region->origin_y >> c.mip), 0};
    // BC1: whole blocks (the payload holds them: mip_bytes rounds up), inside the region by the check in commit.
    r.imageExtent = {(e.width + block - 1) / block * block, (e.height + block - 1) / block * block, 1};
    regions.push_back(r);
    c.serial = serial;
    in_flight_.push_back(c);
  }
  vkCmdCopyBufferToImage(cmd, staging_.handle(), image_.handle(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                         static_cast<uint32_t>(regions.size()), regions.data());

  b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
  b.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  b.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0, nullptr, 0,
                       nullptr, 1, &b);
  const auto n = static_cast<uint32_t>(queued_.size());
  queued_.clear();
  return n;
}

void TextureCache::publish(TextureId texture) {
  const uint32_t mask = residency_[texture.value].mask;
  auto& t = table_.as<gpu::TextureGpu>()[texture.value];
  if (mask == 0) {
    t.placement.y = gpu::kNotResident;
    return;
  }
  // The shader samples a contiguous range [finest, coarsest]: the run of resident levels that ends at the
  // coarsest one (Algorithm 1 refines one level at a time, so normally every resident level is in it).
  const uint32_t coarsest = 31u - static_cast<uint32_t>(std::countl_zero(mask));
  uint32_t finest = coarsest;
  while (finest > 0 && (mask & (1u << (finest - 1)))) --finest;
  t.placement.y = finest;
  t.placement.z = coarsest;
}

void TextureCache::on_submission_complete(uint64_t serial) {
  while (!in_flight_.empty() && in_flight_.front().serial <= serial) {
    const Copy c = in_flight_.front();
    in_flight_.pop_front();
    release_staging(c.staging);
    Residency& r = residency_[c.texture.value];
    if (r.epoch != c.epoch) {  // evicted while the copy was on its way: it wrote into a region no one samples
      ++stats_.mips_dropped;
      continue;
    }
    r.mask |= 1u << c.mip;
    publish(c.texture);
    ++stats_.mips_uploaded;
    stats_.bytes_uploaded += c.staging.size;
    states_.on_committed(c.texture, MipLevel(c.mip));
  }
}

uint64_t TextureCache::resident_textures() const {
  uint64_t n = 0;
  for (const auto& r : residency_) n += r.mask != 0;
  return n;
}

}  // namespace texstream::render
