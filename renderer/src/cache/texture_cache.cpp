#include "texstream/render/cache/texture_cache.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>

#include "texstream/protocol/segment_layout.hpp"
#include "texstream/render/cache/cache_geometry.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/scene/scene_data.hpp"
#include "texstream/render/vulkan/one_shot.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

// The shader reads sampling.bin's words as they are (TextureGpu.colour.w).
static_assert(gpu::kSamplingWrapUShift == scene::sampling_flags::kWrapUShift &&
              gpu::kSamplingWrapVShift == scene::sampling_flags::kWrapVShift &&
              gpu::kSamplingWrapMask == scene::sampling_flags::kWrapMask &&
              gpu::kSamplingAlphaTest == scene::sampling_flags::kAlphaTest &&
              gpu::kSamplingCutoffShift == scene::sampling_flags::kCutoffShift &&
              gpu::kWrapRepeat == static_cast<uint32_t>(scene::TextureWrap::kRepeat) &&
              gpu::kWrapMirror == static_cast<uint32_t>(scene::TextureWrap::kMirror));

// The shader's sampler array has a binding per possible plane, and placement.x room for the plane index.
static_assert(gpu::kCachePlanes == kMaxCacheImages && kMaxCacheImages <= (1u << (32 - gpu::kPlacementPlaneShift)));

namespace {

// vkCmdCopyBufferToImage wants bufferOffset a multiple of the texel block size (4 for RGBA8, 8 for BC1) and of
// 4; 16 covers both and keeps rows of a CPU memcpy aligned.
constexpr uint64_t kStagingAlignment = 16;
// BC1 stores 4x4 blocks: a copy whose extent is not whole blocks must end at the mip's edge, so a region side
// below one block at some level cannot be written without touching a neighbour.
constexpr uint32_t kBc1Block = 4;

uint32_t block_size(TexelFormat f) { return is_block_compressed(f) ? kBc1Block : 1; }

}  // namespace

VkFormat cache_vk_format(TexelFormat format) {
  return format == TexelFormat::kBc1   ? VK_FORMAT_BC1_RGBA_SRGB_BLOCK
         : format == TexelFormat::kBc3 ? VK_FORMAT_BC3_SRGB_BLOCK
         : format == TexelFormat::kBc7 ? VK_FORMAT_BC7_SRGB_BLOCK
                                       : VK_FORMAT_R8G8B8A8_SRGB;
}

TextureCache::TextureCache(const TextureCacheOptions& options, const SceneData& scene)
    : options_(options),
      scene_(scene),
      slots_(scene.texture_records().size()),
      ring_(options.staging_bytes),
      residency_(scene.texture_records().size(), 0),
      fades_(options.fade_s) {}

namespace {

// What create() learns of one texel format from the scene's records.
struct FormatTally {
  uint64_t textures = 0;
  uint64_t bytes = 0;                            // level 0 of every texture of the format
  uint32_t largest = 1;                          // max(width, height)
  const scene::TextureRecord* widest = nullptr;  // the largest by area: its pages must fit the budget
};

}  // namespace

Result<std::unique_ptr<TextureCache>> TextureCache::create(const VulkanContext& ctx, const TextureCacheOptions& options,
                                                           const SceneData& scene) {
  const auto t0 = std::chrono::steady_clock::now();
  if (options.layer_extent != 0 && (options.layer_extent & (options.layer_extent - 1)) != 0) {
    return make_error(ErrorCode::kInvalidArgument,
                      "cache.layer_extent_px = " + std::to_string(options.layer_extent) + " is not a power of two");
  }
  if (options.layers > ctx.properties().limits.maxImageArrayLayers) {
    return make_error(ErrorCode::kInvalidArgument, "cache.layers = " + std::to_string(options.layers) +
                                                       " exceeds the device's maxImageArrayLayers " +
                                                       std::to_string(ctx.properties().limits.maxImageArrayLayers));
  }
  // One pass over the records (mapped): the stream client makes the same pass for its texture table. With
  // cache.format set, textures of another format get no plane and are refused when first named.
  std::array<FormatTally, 8> tally{};
  uint64_t largest_mip = 0;
  for (const scene::TextureRecord& r : scene.texture_records()) {
    const auto f = texel_format_from_raw(r.format);
    if (!f || (options.format && *f != *options.format)) continue;
    FormatTally& t = tally[r.format];
    ++t.textures;
    const uint64_t bytes = mip_bytes(*f, r.width, r.height, 0);
    t.bytes += bytes;
    largest_mip = std::max(largest_mip, bytes);
    t.largest = std::max({t.largest, r.width, r.height});
    if (!t.widest || uint64_t{r.width} * r.height > uint64_t{t.widest->width} * t.widest->height) t.widest = &r;
  }
  std::vector<TexelFormat> formats;
  for (uint32_t raw = 0; raw < tally.size(); ++raw)
    if (tally[raw].textures) formats.push_back(static_cast<TexelFormat>(raw));
  if (formats.empty()) formats.push_back(options.format.value_or(TexelFormat::kRgba8));  // no texture: one plane
  for (TexelFormat f : formats) {
    if (is_block_compressed(f) && !ctx.texture_compression_bc()) {
      return make_error(ErrorCode::kUnsupported, (scene.dir / "textures.bin").string() + " lists " +
                                                     std::to_string(tally[static_cast<uint32_t>(f)].textures) + " " +
                                                     std::string(to_string(f)) + " textures but device '" +
                                                     ctx.device_name() + "' lacks textureCompressionBC");
    }
  }
  TS_ASSERT(formats.size() <= kMaxCacheImages, "%zu texel formats", formats.size());

  // The device's sparse address space is shared by the planes: each is sure of one layer of its largest
  // texture, and the rest goes by the bytes of its textures (docs/design/cache_formats.md).
  const VkPhysicalDeviceLimits& limits = ctx.properties().limits;
  uint64_t floor_sum = 0, weight_sum = 0;
  for (TexelFormat f : formats) {
    const FormatTally& t = tally[static_cast<uint32_t>(f)];
    floor_sum += cache_layer_bytes(f, std::bit_ceil(std::max(t.largest, 4u)));
    weight_sum += t.bytes;
  }
  const uint64_t space = limits.sparseAddressSpaceSize;
  const uint64_t spare = space > floor_sum ? space - floor_sum : 0;

  std::unique_ptr<TextureCache> c(new TextureCache(options, scene));
  c->plane_of_format_.fill(-1);
  std::vector<SparseImageInfo> infos;
  for (TexelFormat f : formats) {
    const FormatTally& t = tally[static_cast<uint32_t>(f)];
    CacheGeometryInputs gi;
    gi.eviction = options.eviction;
    gi.format = f;
    gi.layer_extent = options.layer_extent;
    gi.layers = options.layers;
    gi.memory_bytes = options.memory_bytes;
    gi.largest_texture = t.largest;
    gi.max_image_dimension = limits.maxImageDimension2D;
    gi.max_array_layers = limits.maxImageArrayLayers;
    gi.sparse_address_space =
        formats.size() == 1 ? space
                            : cache_layer_bytes(f, std::bit_ceil(std::max(t.largest, 4u))) +
                                  static_cast<uint64_t>(static_cast<double>(spare) * static_cast<double>(t.bytes) /
                                                        static_cast<double>(std::max<uint64_t>(weight_sum, 1)));
    auto geometry = choose_cache_geometry(gi);
    if (!geometry) return geometry.error();
    if (options.layers == 0 && geometry->layers > 1) {
      // A device with a mip tail per layer (NVIDIA: 64 KiB) pays it for every layer out of the budget: the
      // automatic layer count keeps the tails within a quarter of it (the seed's ring, with many small layers,
      // would otherwise spend the budget on tails; docs/design/cache_budget.md).
      auto tail = SparseMemory::tail_bytes_per_layer(ctx, cache_vk_format(f), geometry->layer_extent,
                                                     floor_log2(geometry->layer_extent) + 1);
      if (!tail) return tail.error();
      const uint64_t share = options.memory_bytes / 4 / formats.size();
      if (*tail > 0 && *tail * geometry->layers > share) {
        geometry->layers = static_cast<uint32_t>(std::max<uint64_t>(share / *tail, 1));
      }
    }
    Plane p;
    p.shape =
        CachePlane{f, block_size(f), geometry->layer_extent, geometry->layers, floor_log2(geometry->layer_extent) + 1};
    if (options.eviction == CacheEviction::kRing) {
      p.ring.emplace(geometry->layer_extent, geometry->layers);
    } else {
      p.tree.emplace(geometry->layer_extent, geometry->layers, block_size(f));
    }
    c->plane_of_format_[static_cast<uint32_t>(f)] = static_cast<int8_t>(c->planes_.size());
    c->planes_.push_back(std::move(p));
    SparseImageInfo info;
    info.format = cache_vk_format(f);
    info.extent = geometry->layer_extent;
    info.mip_levels = floor_log2(geometry->layer_extent) + 1;
    info.layers = geometry->layers;
    info.memory_bytes = options.memory_bytes;
    infos.push_back(info);
  }
  // The staging ring holds the scene's largest mip (the stream client sizes its slots the same way, with
  // protocol.staging_slot_bytes = 0); a mip above the protocol's largest slot can never arrive.
  c->options_.staging_bytes = std::max(c->options_.staging_bytes, std::min(largest_mip, kMaxSlotBytes));
  c->ring_ = StagingRing(c->options_.staging_bytes);
  auto sparse = SparseMemory::create(ctx, infos, options.memory_bytes);
  if (!sparse) return sparse.error();
  c->sparse_ = std::move(*sparse);
  c->pages_ = std::make_unique<SparsePageTable>(c->sparse_->geometries(), c->sparse_->slot_count());
  // A resident texture holds about a page or more: the table starts with room for one per page slot.
  c->residency_ = ResidencyTable(scene.texture_records().size(), c->sparse_->slot_count());
  for (uint32_t i = 0; i < c->planes_.size(); ++i) {
    const CachePlane& shape = c->planes_[i].shape;
    const scene::TextureRecord* widest = tally[static_cast<uint32_t>(shape.format)].widest;
    if (!widest || widest->width > shape.layer_extent || widest->height > shape.layer_extent) continue;
    const bool ring = options.eviction == CacheEviction::kRing;
    const auto [rw, rh] = QuadtreeAllocator::rect_of(widest->width, widest->height, shape.block);
    const PageRect rect{0, 0, 0, ring ? std::max(rw, rh) : rw, ring ? std::max(rw, rh) : rh, shape.block, i};
    uint64_t pages = 0;
    for (uint32_t l = 0; l < shape.mip_levels; ++l)
      pages += SparsePageTable::pages_of_region(c->sparse_->geometry(i), rect, l);
    if (pages > c->sparse_->slot_count()) {
      return make_error(ErrorCode::kInvalidArgument,
                        "cache.memory_bytes = " + std::to_string(options.memory_bytes) + " cannot hold the scene's " +
                            std::to_string(widest->width) + "x" + std::to_string(widest->height) + " " +
                            std::string(to_string(shape.format)) + " texture with all its levels (" +
                            std::to_string(pages) + " pages of " + std::to_string(c->sparse_->page_bytes()) + " bytes" +
                            (c->sparse_->tail_bytes() ? " besides the mip tails" : "") + "); raise it");
    }
  }
  for (uint32_t i = 0; i < c->planes_.size(); ++i) {
    const CachePlane& shape = c->planes_[i].shape;
    const PageGeometry& g = c->sparse_->geometry(i);
    spdlog::info(
        "texture cache: {} plane, {} eviction, sparse {} layers of {}px ({} MiB of address space), {}x{} "
        "texels a page",
        to_string(shape.format), choice_name(options.eviction), shape.layers, shape.layer_extent,
        c->sparse_->image_bytes(i) >> 20, g.granularity_w, g.granularity_h);
  }
  spdlog::info("texture cache: {} KiB pages, {} page slots shared by {} plane(s) ({} MiB budget{})",
               c->sparse_->page_bytes() >> 10, c->sparse_->slot_count(), c->planes_.size(), options.memory_bytes >> 20,
               c->sparse_->tail_bytes() ? fmt::format(", {} KiB mip tails", c->sparse_->tail_bytes() >> 10) : "");

  auto staging =
      GpuBuffer::create(ctx, c->options_.staging_bytes, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::kHostVisible);
  if (!staging) return staging.error();
  c->staging_ = std::move(*staging);

  // By slot, not by texture: the entries of the textures drawn or cached, whatever the scene's texture count.
  c->ctx_ = &ctx;
  TS_TRY(c->grow_table(kInitialTableSlots));

  // Every level of every layer starts in the layout the shader reads; copies move it to TRANSFER_DST and back.
  TS_TRY(run_one_shot(ctx, [&](VkCommandBuffer cmd) {
    std::vector<VkImageMemoryBarrier> barriers;
    for (uint32_t i = 0; i < c->planes_.size(); ++i) {
      VkImageMemoryBarrier b{};
      b.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
      b.srcAccessMask = 0;
      b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
      b.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
      b.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
      b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
      b.image = c->sparse_->image(i);
      b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, c->planes_[i].shape.mip_levels, 0,
                            c->planes_[i].shape.layers};
      barriers.push_back(b);
    }
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0, nullptr,
                         0, nullptr, static_cast<uint32_t>(barriers.size()), barriers.data());
  }));
  c->stats_.create_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return c;
}

Status TextureCache::prepare_textures(std::span<const uint32_t> textures) {
  for (uint32_t t : textures) TS_TRY(check_texture(t));
  return ok_status();
}

Status TextureCache::check_texture(uint32_t texture) const {
  const auto records = scene_.texture_records();
  TS_ASSERT(texture < records.size(), "texture %u of %zu", texture, records.size());
  const scene::TextureRecord& r = records[texture];
  // The renderer never decodes: texel blocks go from the file to the image of their format unchanged.
  if (r.format < plane_of_format_.size() && plane_of_format_[r.format] >= 0) return ok_status();
  const auto f = texel_format_from_raw(r.format);
  return make_error(ErrorCode::kInvalidArgument,
                    (options_.format ? "cache.format = " + std::string(to_string(*options_.format)) + " but texture "
                                     : std::string("texture ")) +
                        std::to_string(texture) + " of " + (scene_.dir / "textures.bin").string() + " is " +
                        (f ? std::string(to_string(*f)) : "of unknown format " + std::to_string(r.format)));
}

Status TextureCache::grow_table(uint32_t slots) {
  if (slots <= table_slots_) return ok_status();
  uint32_t n = std::max(table_slots_, kInitialTableSlots);
  while (n < slots) n *= 2;
  auto table = GpuBuffer::create(*ctx_, VkDeviceSize{n} * sizeof(gpu::TextureGpu), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT,
                                 MemoryUse::kHostVisible);
  if (!table) return table.error();
  // Nothing in flight reads the old buffer (every method runs between submissions); the descriptor set is
  // pointed at the new one before the next submission records its passes (RenderStack::submit).
  if (table_slots_ > 0) {
    std::memcpy(table->bytes().data(), table_.bytes().data(), size_t{table_slots_} * sizeof(gpu::TextureGpu));
  }
  table_ = std::move(*table);
  table_slots_ = n;
  return ok_status();
}

Status TextureCache::write_fresh_entries() {
  TS_TRY(grow_table(slots_.high_water()));
  const auto records = scene_.texture_records();
  auto* table = table_.as<gpu::TextureGpu>();
  for (const uint32_t texture : slots_.take_fresh()) {
    const uint32_t slot = slots_.find(texture);
    if (slot == TextureSlots::kNone) continue;  // freed again before its entry was written
    const scene::TextureRecord& r = records[texture];
    gpu::TextureGpu& t = table[slot];
    t = gpu::TextureGpu{};
    t.placement = {0, gpu::kNotResident, 0, r.mip_count};
    t.region = {0, 0, r.width, r.height};
    t.colour = {scene_.colours()[texture], gpu::kNotResident, 0, scene_.sampling_flags(texture)};
    // A ring texture can stay placed after its entry went (all its copies dropped): its next copy goes to that
    // region, which commit() writes only for a texture it places.
    if (const auto region = region_of(TextureId(texture))) {
      t.placement.x = region->layer | plane_of(TextureId(texture)) << gpu::kPlacementPlaneShift;
      t.region.x = region->origin_x;
      t.region.y = region->origin_y;
    }
  }
  return ok_status();
}

Status TextureCache::write_slots() {
  TS_TRY(write_fresh_entries());
  slots_.release_unused([&](uint32_t texture) { return residency_.find(TextureId(texture)) != nullptr; });
  return ok_status();
}

Result<gpu::TextureGpu*> TextureCache::entry(TextureId texture) {
  uint32_t slot = slots_.find(texture.value);
  if (slot == TextureSlots::kNone) {
    slot = slots_.acquire(texture.value);
    TS_TRY(write_fresh_entries());
  }
  return &table_.as<gpu::TextureGpu>()[slot];
}

gpu::TextureGpu* TextureCache::entry_if_slotted(TextureId texture) {
  const uint32_t slot = slots_.find(texture.value);
  return slot == TextureSlots::kNone ? nullptr : &table_.as<gpu::TextureGpu>()[slot];
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
  events_.push_back({stream::TextureEvent::Kind::kRejected, texture, mip});
}

void TextureCache::failed(TextureId texture, MipLevel mip, CompletionStatus status) {
  events_.push_back({stream::TextureEvent::Kind::kFailed, texture, mip, status});
}

void TextureCache::evict(TextureId texture) {
  note_eviction();
  residency_.mark_evicted(texture);
  ++stats_.evictions;
  // Without a slot the texture is drawn from a fresh entry, which is not resident, when it gets one.
  if (gpu::TextureGpu* t = entry_if_slotted(texture)) {
    const uint32_t before = t->placement.y;
    t->placement.y = gpu::kNotResident;
    fades_.on_publish(slots_.find(texture.value), *t, before);  // no fade survives an eviction
  }
  Plane& p = planes_[plane_of(texture)];
  if (p.tree) p.tree->free(texture);
  // No entry: a ring texture placed whose copies were all dropped; nothing resident, bound or on its way.
  Residency* r = residency_.find(texture);
  if (!r) {
    events_.push_back({stream::TextureEvent::Kind::kInvalidated, texture});
    return;
  }
  if (r->mask != 0) --resident_count_;
  r->mask = 0;
  r->epoch = residency_.new_epoch();
  // Its pages: the submissions up to last_serial_ may still sample them, so they are unbound after those.
  for (uint32_t mip = 0; r->bound != 0; ++mip) {
    if (!(r->bound & (1u << mip))) continue;
    r->bound &= ~(1u << mip);
    pages_->release(page_rect(r->region, plane_of(texture)), mip, last_serial_);
  }
  residency_.lru_unlink(*r);
  // Copies not yet recorded would write into a region that now belongs to another texture: drop them.
  auto drop = [&](const Copy& c) {
    if (c.texture != texture) return false;
    release_staging(c.staging);
    --r->copies;
    ++stats_.mips_dropped;
    return true;
  };
  std::erase_if(queued_, drop);
  std::erase_if(ready_, drop);
  residency_.release_if_idle(*r);
  events_.push_back({stream::TextureEvent::Kind::kInvalidated, texture});
}

void TextureCache::drop_copy(const Copy& c) {
  release_staging(c.staging);
  Residency* r = residency_.find(c.texture);
  TS_ASSERT(r != nullptr && r->copies > 0, "copy of texture %u without its residency", c.texture.value);
  --r->copies;
  residency_.release_if_idle(*r);
}

uint32_t TextureCache::plane_of(TextureId texture) const {
  const uint32_t raw = scene_.texture_records()[texture.value].format;
  TS_ASSERT(raw < plane_of_format_.size() && plane_of_format_[raw] >= 0, "texture %u has no cache plane",
            texture.value);
  return static_cast<uint32_t>(plane_of_format_[raw]);
}

std::optional<CacheRegion> TextureCache::region_of(TextureId texture) const {
  const Plane& p = planes_[plane_of(texture)];
  return p.ring ? p.ring->find(texture) : p.tree->find(texture);
}

PageRect TextureCache::page_rect(const CacheRegion& r, uint32_t plane) const {
  return PageRect{r.layer, r.origin_x, r.origin_y, r.width, r.height, planes_[plane].shape.block, plane};
}

void TextureCache::refuse_for_good(TextureId texture, const std::string& why) {
  // Such a texture is marked broken (kFailed), so only copies already on their way come back: a short search.
  if (std::find(refused_.begin(), refused_.end(), texture.value) != refused_.end()) return;
  spdlog::warn("texture cache: {}", why);
  refused_.push_back(texture.value);
}

void TextureCache::refuse_for_room(TextureId texture, MipLevel mip) {
  ++stats_.space_refusals;
  events_.push_back({stream::TextureEvent::Kind::kNoRoom, texture, mip});
}

void TextureCache::note_eviction() {
  if (stats_.evictions == 0) stats_.first_eviction_bytes = held_bytes();
}

uint64_t TextureCache::held_bytes() const {
  return uint64_t{pages_->slot_count() - pages_->free_slots()} * sparse_->page_bytes() + sparse_->tail_bytes();
}

Result<std::optional<CacheRegion>> TextureCache::place(TextureId texture, uint32_t width, uint32_t height) {
  const uint32_t plane = plane_of(texture);
  Plane& p = planes_[plane];
  if (p.ring) {
    std::vector<TextureId> evicted;
    // BC regions are at least one block wide so that the 4x4 level (one block) has a region of its own.
    auto placed = p.ring->allocate(texture, std::max(width, p.shape.block), height, evicted);
    evict_all(evicted);
    if (!placed) return placed.error();
    return std::optional<CacheRegion>(*placed);
  }
  if (!p.tree->fits(width, height)) {
    return make_error(ErrorCode::kInvalidArgument,
                      "texture " + std::to_string(texture.value) + " (" + std::to_string(width) + "x" +
                          std::to_string(height) + ") does not fit a cache layer of " +
                          std::to_string(p.shape.layer_extent) + " px (cache.layer_extent_px)");
  }
  for (;;) {
    if (auto r = p.tree->allocate(texture, width, height)) {
      Residency& res = residency_.get(texture);
      res.used_cycle = use_cycle_;
      residency_.lru_append(res);
      return std::optional<CacheRegion>(*r);
    }
    // No free square large enough: the plane's address space, not the memory, is short. Free by use, as for
    // memory, among the textures of this plane.
    const std::optional<TextureId> victim = lru_victim(texture, plane);
    if (!victim) return std::optional<CacheRegion>();
    ++stats_.address_evictions;
    evict(*victim);
  }
}

std::optional<TextureId> TextureCache::lru_victim(TextureId keep, std::optional<uint32_t> plane) const {
  // The list is in order of last use, so once a texture was used this cycle, every later one was.
  std::optional<TextureId> victim;
  residency_.walk_lru([&](const Residency& r) {
    if (r.used_cycle == use_cycle_) return false;
    if (r.texture() != keep && (!plane || plane_of(r.texture()) == *plane)) {
      victim = r.texture();
      return false;
    }
    return true;
  });
  return victim;
}

bool TextureCache::evict_oldest_layer(uint32_t plane) {
  // The copy's own plane first; else the pages must come from another plane's layers.
  uint32_t order[kMaxCacheImages];
  uint32_t n = 0;
  order[n++] = plane;
  for (uint32_t i = 0; i < planes_.size(); ++i)
    if (i != plane) order[n++] = i;
  for (uint32_t k = 0; k < n; ++k) {
    std::vector<TextureId> evicted;
    if (!planes_[order[k]].ring->evict_oldest(evicted)) continue;
    evict_all(evicted);
    return true;
  }
  return false;
}

void TextureCache::touch(std::span<const stream::StreamCandidate> used) {
  ++use_cycle_;
  trimmable_.clear();
  if (options_.eviction != CacheEviction::kLru) return;
  for (const stream::StreamCandidate& c : used) {
    if (c.texture.value >= scene_.texture_records().size()) continue;
    // A texture without an entry holds nothing to keep or trim, and place() stamps the cycle when it comes.
    Residency* r = residency_.find(c.texture);
    if (!r) continue;
    r->used_cycle = use_cycle_;
    // NaN or below 0: wants the finest level; nothing to trim.
    r->wanted = c.desired_mip >= 1.0f ? static_cast<uint8_t>(std::min(c.desired_mip, 31.0f)) : 0;
    if (r->wanted >= 2 && (r->mask & ((1u << (r->wanted - 1)) - 1)) != 0) trimmable_.push_back(c.texture.value);
    if (r->listed()) {  // to the back: most recently used
      residency_.lru_unlink(*r);
      residency_.lru_append(*r);
    }
  }
}

bool TextureCache::trim_one(TextureId keep) {
  while (!trimmable_.empty()) {
    const uint32_t t = trimmable_.back();
    trimmable_.pop_back();
    // Used this cycle, so lru_victim() spares it; were it evicted, no entry and nothing to trim.
    Residency* found = residency_.find(TextureId(t));
    if (!found || t == keep.value || found->wanted < 2) continue;
    Residency& r = *found;
    // One level of margin below the wanted one, so a view that moves a little does not reload what it drops;
    // the coarsest resident level always stays (a BC1 texture's coarsest levels may be below its wanted one).
    const uint32_t coarsest = 1u << (31 - std::countl_zero(r.mask | 1u));
    const uint32_t surplus = r.mask & ((1u << (r.wanted - 1)) - 1) & ~coarsest;
    if (surplus == 0) continue;
    // A copy of this texture not yet recorded would need its pages as they are: leave it alone.
    const auto busy = [&](const Copy& c) { return c.texture.value == t; };
    if (std::any_of(queued_.begin(), queued_.end(), busy) || std::any_of(ready_.begin(), ready_.end(), busy) ||
        std::any_of(in_flight_.begin(), in_flight_.end(), busy))
      continue;
    for (uint32_t bits = surplus; bits != 0; bits &= bits - 1) {
      const auto mip = static_cast<uint32_t>(std::countr_zero(bits));
      // The submissions up to last_serial_ may still sample these levels: their pages retire at it.
      pages_->release(page_rect(r.region, plane_of(TextureId(t))), mip, last_serial_);
      r.bound &= ~(1u << mip);
      ++stats_.trimmed_levels;
    }
    r.mask &= ~surplus;
    publish(TextureId(t), r.mask);  // the shader's range starts at the first level kept
    events_.push_back({stream::TextureEvent::Kind::kTrimmed, TextureId(t),
                       MipLevel(static_cast<uint32_t>(std::countr_zero(r.mask)))});
    return true;
  }
  return false;
}

TextureCache::FitMark TextureCache::fit_mark() const {
  FitMark m;
  for (uint32_t i = 0; i < planes_.size(); ++i)
    if (planes_[i].ring) m.layers_assigned[i] = planes_[i].ring->layers_assigned();
  m.space_refusals = stats_.space_refusals;
  return m;
}

bool TextureCache::outgrown_since(const FitMark& mark) const {
  if (options_.eviction == CacheEviction::kRing) {
    for (uint32_t i = 0; i < planes_.size(); ++i)
      if (planes_[i].ring->layers_freed() > mark.layers_assigned[i]) return true;
    return false;
  }
  return stats_.space_refusals > mark.space_refusals;
}

void TextureCache::evict_all(const std::vector<TextureId>& textures) {
  for (TextureId e : textures) evict(e);
}

void TextureCache::commit(TextureId texture, MipLevel mip, std::span<std::byte> data) {
  const auto offset = static_cast<uint64_t>(data.data() - staging_.bytes().data());
  auto it = reserved_.find(offset);
  TS_ASSERT(it != reserved_.end(), "commit of a span this sink did not reserve");
  const StagingRing::Allocation alloc = it->second;
  reserved_.erase(it);

  // StreamClient checked the payload against the texture table; these are our own invariants.
  TS_ASSERT(texture.value < scene_.texture_records().size(), "commit of unknown texture %u", texture.value);
  if (auto checked = check_texture(texture.value); !checked) {
    // Streamed before any mesh of it was drawn (render.preload_all) and of another format: never shown.
    refuse_for_good(texture, checked.error().message);
    release_staging(alloc);
    events_.push_back({stream::TextureEvent::Kind::kFailed, texture, mip, CompletionStatus::kNotFound});
    return;
  }
  // A texture with residency has a slot (write_slots keeps it): given here, before place() makes the entry.
  if (auto slotted = entry(texture); !slotted) {
    spdlog::error("texture cache: texture {}: {}", texture.value, slotted.error().message);
    release_staging(alloc);
    events_.push_back({stream::TextureEvent::Kind::kRejected, texture, mip});  // asked again later
    return;
  }
  const scene::TextureRecord& rec = scene_.texture_records()[texture.value];
  const CachePlane& plane = planes_[plane_of(texture)].shape;
  TS_ASSERT(mip.value < rec.mip_count && data.size() == mip_bytes(plane.format, rec.width, rec.height, mip.value),
            "commit of texture %u mip %u with %zu bytes", texture.value, mip.value, data.size());

  auto region = region_of(texture);
  if (!region) {
    auto placed = place(texture, rec.width, rec.height);
    if (placed && !*placed) {  // lru: everything that could go is in use this cycle
      release_staging(alloc);
      refuse_for_room(texture, mip);
      return;
    }
    if (!placed) {
      refuse_for_good(texture, placed.error().message);
      release_staging(alloc);
      // Not the file's fault, but it can never be shown: kNotFound marks it broken, so it is not asked again.
      events_.push_back({stream::TextureEvent::Kind::kFailed, texture, mip, CompletionStatus::kNotFound});
      return;
    }
    region = **placed;
    ++stats_.texture_loads;
    if (residency_.evicted_before(texture)) ++stats_.texture_reloads;
    gpu::TextureGpu* t = entry_if_slotted(texture);  // given above; place() hands out no slot
    TS_ASSERT(t != nullptr, "texture %u placed without a slot", texture.value);
    t->placement.x = region->layer | plane_of(texture) << gpu::kPlacementPlaneShift;
    t->region.x = region->origin_x;
    t->region.y = region->origin_y;
  }
  if ((region->extent >> mip.value) < plane.block) {
    // A BC level smaller than a block in a shared layer: writing it would overwrite a neighbour's texels.
    release_staging(alloc);
    events_.push_back({stream::TextureEvent::Kind::kRejected, texture, mip});
    return;
  }
  Residency& r = residency_.get(texture);
  ++r.copies;
  queued_.push_back(Copy{texture, mip.value, alloc, r.epoch, 0});
}

TextureCache::BindOutcome TextureCache::bind_pages_for(const Copy& c, bool may_evict) {
  // `c` holds the entry (Residency::copies), so it stays through evictions, this texture's included.
  Residency& r = *residency_.find(c.texture);
  if (r.epoch != c.epoch) return BindOutcome::kDropped;
  if (r.bound & (1u << c.mip)) return BindOutcome::kBound;
  while (true) {
    const auto region = region_of(c.texture);
    if (!region || r.epoch != c.epoch) return BindOutcome::kDropped;  // evicted while making room
    if (pages_->acquire(page_rect(*region, plane_of(c.texture)), c.mip)) {
      TS_ASSERT(r.bound == 0 || (r.region.layer == region->layer && r.region.index == region->index),
                "texture %u bound in two regions", c.texture.value);
      r.region = *region;
      r.bound |= 1u << c.mip;
      return BindOutcome::kBound;
    }
    if (!may_evict) return BindOutcome::kNoFreePages;
    // The evicted pages retire at last_serial_, which has completed by now in the renderer's
    // one-frame-in-flight loop, so reclaim() frees their slots at once.
    if (options_.eviction == CacheEviction::kRing) {
      // Seed §3.6: when the cache is full, the oldest layer goes.
      if (!evict_oldest_layer(plane_of(c.texture))) return BindOutcome::kDropped;
      ++stats_.budget_evicted_layers;
    } else {
      const std::optional<TextureId> victim = lru_victim(c.texture);
      if (!victim && trim_one(c.texture)) {
        pages_->reclaim(completed_serial_);
        continue;
      }
      if (!victim) {
        refuse_for_room(c.texture, MipLevel(c.mip));
        return BindOutcome::kDropped;
      }
      evict(*victim);
    }
    pages_->reclaim(completed_serial_);
  }
}

Status TextureCache::prepare_uploads(uint64_t serial) {
  TS_ASSERT(serial > last_serial_, "submission serials must increase (%llu after %llu)", (unsigned long long)serial,
            (unsigned long long)last_serial_);
  prepared_serial_ = serial;
  bind_wait_ = BindWait{};
  pages_->reclaim(completed_serial_);
  // lru: the copies that fit the free pages first, then the rest with evictions, so that nothing is evicted
  // while free pages could hold a copy of this frame (docs/design/cache_budget.md, "fill before evicting");
  // the seed's ring evicts in commit order (§3.6). An eviction drops copies of evicted textures from ready_
  // (evict()); those still in `work` or `short_of_pages` are recognised by their epoch.
  std::vector<Copy> work = std::move(queued_);
  queued_.clear();
  const bool fill_first = options_.eviction != CacheEviction::kRing;
  std::vector<Copy> short_of_pages;
  for (const Copy& c : work) {
    switch (bind_pages_for(c, !fill_first)) {
      case BindOutcome::kBound:
        ready_.push_back(c);
        break;
      case BindOutcome::kNoFreePages:
        short_of_pages.push_back(c);
        break;
      case BindOutcome::kDropped:
        drop_copy(c);
        ++stats_.mips_dropped;
        break;
    }
  }
  for (const Copy& c : short_of_pages) {
    if (bind_pages_for(c, true) == BindOutcome::kBound) {
      ready_.push_back(c);
    } else {
      drop_copy(c);
      ++stats_.mips_dropped;
    }
  }
  const std::vector<PageBindOp> batch = pages_->take_batch();
  // Copies come at most one per ready mip: counting them now keeps the trace frame whole.
  trace_open_ = trace_entries_ + batch.size() + ready_.size() <= kTraceEntries && (!batch.empty() || !ready_.empty());
  if (trace_open_) {
    // The first plane's binds only: the replay has one image (cache.json "sparse_image").
    UploadTraceFrame f;
    for (const PageBindOp& op : batch)
      if (op.page.image == 0) f.binds.push_back(op);
    trace_.push_back(std::move(f));
    trace_entries_ += batch.size() + ready_.size();
  }
  if (!batch.empty()) {
    TS_TRY(sparse_->submit(batch));
    bind_wait_ = BindWait{sparse_->semaphore(), sparse_->signal_value()};
  }
  return ok_status();
}

uint32_t TextureCache::record_uploads(VkCommandBuffer cmd, uint64_t serial) {
  if (prepared_serial_ != serial) {
    if (auto st = prepare_uploads(serial); !st.ok()) {
      spdlog::error("texture cache: {}", st.error().message);
      for (const Copy& c : ready_) {
        drop_copy(c);
        events_.push_back({stream::TextureEvent::Kind::kRejected, c.texture, MipLevel(c.mip)});
      }
      ready_.clear();
    }
  }
  last_serial_ = serial;
  if (ready_.empty()) return 0;
  // Per plane: the copies into its image, between two layout barriers of the planes that get copies.
  std::vector<std::vector<VkBufferImageCopy>> regions(planes_.size());
  for (Copy& c : ready_) {
    const scene::TextureRecord& rec = scene_.texture_records()[c.texture.value];
    const uint32_t plane = plane_of(c.texture);
    const uint32_t block = planes_[plane].shape.block;
    const auto region = region_of(c.texture);
    TS_ASSERT(region.has_value(), "queued copy of texture %u without a region", c.texture.value);
    const Extent2D e = mip_extent(rec.width, rec.height, c.mip);
    VkBufferImageCopy r{};
    r.bufferOffset = c.staging.offset;
    r.bufferRowLength = 0;  // tightly packed, as the DDS stores it
    r.bufferImageHeight = 0;
    r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, c.mip, region->layer, 1};
    r.imageOffset = {static_cast<int32_t>(region->origin_x >> c.mip), static_cast<int32_t>(region->origin_y >> c.mip),
                     0};
    // BC: whole blocks (the payload holds them: mip_bytes rounds up), inside the region by the check in commit.
    r.imageExtent = {(e.width + block - 1) / block * block, (e.height + block - 1) / block * block, 1};
    regions[plane].push_back(r);
    if (trace_open_ && plane == 0) {
      trace_.back().copies.push_back({region->layer, c.mip, static_cast<uint32_t>(r.imageOffset.x),
                                      static_cast<uint32_t>(r.imageOffset.y), r.imageExtent.width,
                                      r.imageExtent.height});
    }
    c.serial = serial;
    in_flight_.push_back(c);
  }
  std::vector<VkImageMemoryBarrier> barriers;
  for (uint32_t i = 0; i < planes_.size(); ++i) {
    if (regions[i].empty()) continue;
    VkImageMemoryBarrier b{};
    b.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
    b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    b.image = sparse_->image(i);
    b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, planes_[i].shape.mip_levels, 0, planes_[i].shape.layers};
    // Earlier frames' fragment shaders read the image; the copies must wait for them (write-after-read).
    b.srcAccessMask = VK_ACCESS_SHADER_READ_BIT;
    b.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.oldLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
    b.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    barriers.push_back(b);
  }
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0,
                       nullptr, static_cast<uint32_t>(barriers.size()), barriers.data());
  for (uint32_t i = 0; i < planes_.size(); ++i) {
    if (regions[i].empty()) continue;
    vkCmdCopyBufferToImage(cmd, staging_.handle(), sparse_->image(i), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                           static_cast<uint32_t>(regions[i].size()), regions[i].data());
  }
  for (VkImageMemoryBarrier& b : barriers) {
    b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.dstAccessMask = VK_ACCESS_SHADER_READ_BIT;
    b.oldLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.newLayout = VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL;
  }
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 0, nullptr, 0,
                       nullptr, static_cast<uint32_t>(barriers.size()), barriers.data());
  const auto n = static_cast<uint32_t>(ready_.size());
  ready_.clear();
  trace_open_ = false;
  return n;
}

void TextureCache::publish(TextureId texture, uint32_t mask) {
  // The texture has residency (a copy or a trim publishes), so it has a slot (write_slots keeps it).
  const uint32_t slot = slots_.find(texture.value);
  TS_ASSERT(slot != TextureSlots::kNone, "texture %u published without a slot", texture.value);
  gpu::TextureGpu& t = table_.as<gpu::TextureGpu>()[slot];
  const uint32_t before = t.placement.y;
  if (mask == 0) {
    t.placement.y = gpu::kNotResident;
    fades_.on_publish(slot, t, before);
    return;
  }
  // The shader samples a contiguous range [finest, coarsest]: the run of resident levels that ends at the
  // coarsest one (levels that arrive ahead of a coarser one wait for it: docs/design/pipelined_levels.md).
  const MipRun run = sampled_run(mask);
  t.placement.y = run.finest;
  t.placement.z = run.coarsest;
  fades_.on_publish(slot, t, before);
}

void TextureCache::advance_fades(double dt_s) {
  fades_.advance(dt_s, std::span(table_.as<gpu::TextureGpu>(), table_slots_));
}

void TextureCache::on_submission_complete(uint64_t serial) {
  completed_serial_ = std::max(completed_serial_, serial);
  // The budget check of every frame (issue 6: bound pages x page size <= cache.memory_bytes).
  ++stats_.frames;
  const uint64_t bound = bound_bytes();
  stats_.max_bound_bytes = std::max(stats_.max_bound_bytes, bound);
  if (bound > options_.memory_bytes) ++stats_.budget_exceeded_frames;
  while (!in_flight_.empty() && in_flight_.front().serial <= serial) {
    const Copy c = in_flight_.front();
    in_flight_.pop_front();
    Residency& r = *residency_.find(c.texture);  // held by `c` until drop_copy
    if (r.epoch != c.epoch) {  // evicted while the copy was on its way: it wrote into a region no one samples
      drop_copy(c);
      ++stats_.mips_dropped;
      continue;
    }
    if (r.mask == 0) ++resident_count_;
    r.mask |= 1u << c.mip;
    publish(c.texture, r.mask);
    drop_copy(c);
    ++stats_.mips_uploaded;
    stats_.bytes_uploaded += c.staging.size;
    events_.push_back({stream::TextureEvent::Kind::kCommitted, c.texture, MipLevel(c.mip)});
  }
}

uint64_t TextureCache::resident_textures() const {
  // Counted as masks change, not by a pass over every texture: the frame loop asks every frame, and a scene
  // can have millions of textures.
  return resident_count_;
}

}  // namespace texstream::render

namespace texstream::render {

Status TextureCache::write_stats_json(const std::filesystem::path& file) const {
  const SparseBindStats& b = sparse_->stats();
  const PageTableStats& p = pages_->stats();
  const PageGeometry& g = sparse_->geometry();
  nlohmann::json j;
  j["memory_budget_bytes"] = options_.memory_bytes;
  j["page_bytes"] = sparse_->page_bytes();
  j["page_texels"] = {g.granularity_w, g.granularity_h};
  j["mip_tail_first_level"] = g.tail_first_level;
  j["mip_tail_bytes"] = sparse_->tail_bytes();
  j["page_slots"] = sparse_->slot_count();
  j["allocated_bytes"] = sparse_->allocated_bytes();
  j["image_virtual_bytes"] = sparse_->image_bytes();
  j["create_seconds"] = stats_.create_seconds;
  // The texture table by slot (docs/design/host_memory.md, item 3): its entries, bytes, the slots held at most
  // and the slots freed for reuse.
  j["texture_table_slots"] = table_slots_;
  j["texture_table_bytes"] = table_.size();
  j["texture_slots_peak"] = slots_.high_water();
  j["texture_slots_released"] = slots_.released();
  j["frames"] = stats_.frames;
  j["budget_exceeded_frames"] = stats_.budget_exceeded_frames;
  j["max_bound_bytes"] = stats_.max_bound_bytes;
  j["bound_bytes"] = bound_bytes();
  j["mips_uploaded"] = stats_.mips_uploaded;
  j["bytes_uploaded"] = stats_.bytes_uploaded;
  j["mips_dropped"] = stats_.mips_dropped;
  j["evictions"] = stats_.evictions;
  j["budget_evicted_layers"] = stats_.budget_evicted_layers;
  uint64_t recycled = 0;
  for (const Plane& plane : planes_) recycled += plane.ring ? plane.ring->layers_recycled() : 0;
  j["layers_recycled"] = recycled;
  j["eviction"] = std::string(choice_name(options_.eviction));
  // The first plane's shape (the bind-cost benchmark's replay reads these); every plane's in "planes".
  j["layer_extent"] = planes_[0].shape.layer_extent;
  j["layers"] = planes_[0].shape.layers;
  nlohmann::json planes = nlohmann::json::array();
  for (uint32_t i = 0; i < planes_.size(); ++i) {
    const CachePlane& shape = planes_[i].shape;
    planes.push_back({{"format", std::string(to_string(shape.format))},
                      {"layer_extent", shape.layer_extent},
                      {"layers", shape.layers},
                      {"mip_levels", shape.mip_levels},
                      {"page_texels", {sparse_->geometry(i).granularity_w, sparse_->geometry(i).granularity_h}},
                      {"virtual_bytes", sparse_->image_bytes(i)}});
  }
  j["planes"] = std::move(planes);
  j["addressable_bytes"] = addressable_bytes();
  j["space_refusals"] = stats_.space_refusals;
  j["trimmed_levels"] = stats_.trimmed_levels;
  j["address_evictions"] = stats_.address_evictions;
  j["first_eviction_bytes"] = stats_.first_eviction_bytes;
  j["fill_at_first_eviction"] =
      stats_.evictions ? static_cast<double>(stats_.first_eviction_bytes) / static_cast<double>(options_.memory_bytes)
                       : 0.0;
  j["texture_loads"] = stats_.texture_loads;
  j["texture_reloads"] = stats_.texture_reloads;
  j["thrash_rate"] = stats_.texture_loads
                         ? static_cast<double>(stats_.texture_reloads) / static_cast<double>(stats_.texture_loads)
                         : 0.0;
  j["bind_calls"] = b.calls;
  j["bind_ops"] = b.ops;
  j["bind_seconds"] = b.seconds;
  j["bind_max_ops_per_call"] = b.max_ops_per_call;
  j["bind_ops_per_call"] = b.ops_per_call;
  j["bind_call_seconds"] = b.call_seconds;
  // The image the binds went to and the first frames' bind ops ([layer, mip, x, y, slot], slot -1 = unbind) and
  // copy regions, for the bind-cost benchmark's replay.
  const SparseImageInfo& si = sparse_->info();
  j["sparse_image"] = {{"vk_format", static_cast<int64_t>(si.format)},
                       {"extent", si.extent},
                       {"mip_levels", si.mip_levels},
                       {"layers", si.layers},
                       {"memory_bytes", si.memory_bytes},
                       {"pages_per_block", sparse_->pages_per_block()}};
  nlohmann::json trace = nlohmann::json::array();
  for (const UploadTraceFrame& f : trace_) {
    nlohmann::json binds = nlohmann::json::array(), copies = nlohmann::json::array();
    for (const PageBindOp& op : f.binds)
      binds.push_back({op.page.layer, op.page.mip, op.page.x, op.page.y, op.bind ? static_cast<int64_t>(op.slot) : -1});
    for (const auto& c : f.copies) {
      nlohmann::json row = nlohmann::json::array();
      for (uint32_t v : c) row.push_back(static_cast<int64_t>(v));  // signed: GCC 12 misreads the unsigned path
      copies.push_back(std::move(row));
    }
    trace.push_back({{"binds", std::move(binds)}, {"copies", std::move(copies)}});
  }
  j["upload_trace"] = std::move(trace);
  j["pages_bound"] = p.pages_bound;
  j["pages_unbound"] = p.pages_unbound;
  j["pages_shared"] = p.pages_shared;
  j["pages_revived"] = p.pages_revived;
  std::ofstream out(file);
  out << j.dump(1) << "\n";
  if (!out) return make_error(ErrorCode::kIo, "cannot write " + file.string());
  return ok_status();
}

}  // namespace texstream::render
