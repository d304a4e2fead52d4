#include "texstream/render/cache/ground_pages.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include "texstream/render/cache/texture_cache.hpp"
#include "texstream/render/scene/gpu_structs.hpp"
#include "texstream/render/vulkan/image_barrier.hpp"
#include "texstream/render/vulkan/one_shot.hpp"
#include "texstream/render/vulkan/vk_check.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace texstream::render {

using pages::PageId;

namespace {

// The page of `level` holding (u, v) (page-square units), clamped into the level's grid (ground.frag's page_at).
PageId page_at(uint32_t level, float u, float v) {
  const double n = static_cast<double>(1u << level);
  const auto clampi = [&](float c) {
    return static_cast<uint32_t>(std::clamp(std::floor(static_cast<double>(c) * n), 0.0, n - 1));
  };
  return {level, clampi(u), clampi(v)};
}

}  // namespace

GroundPages::~GroundPages() = default;

Result<std::unique_ptr<GroundPages>> GroundPages::create(const VulkanContext& ctx,
                                                         std::shared_ptr<const pages::PageFile> file,
                                                         const scene::GroundPages& placement,
                                                         const GroundPagesOptions& options) {
  std::unique_ptr<GroundPages> g(new GroundPages());
  g->file_ = std::move(file);
  g->placement_ = placement;
  g->options_ = options;
  const pages::PageGeometry& geo = g->file_->geometry();
  const PagesConfig& cfg = options.config;
  g->policy_.heuristic = cfg.heuristic;
  g->policy_.order = cfg.order;
  g->policy_.noise_scaling = cfg.noise_scaling;
  g->policy_.noise_skipping = cfg.noise_skipping;

  // As many frames as the budget holds, within the device's array layers.
  const uint64_t page_bytes = geo.page_bytes();
  const uint64_t by_budget = static_cast<uint64_t>(cfg.memory_bytes) / page_bytes;
  const uint64_t frames = std::min<uint64_t>(by_budget, ctx.properties().limits.maxImageArrayLayers);
  const uint32_t locked_levels = std::min(static_cast<uint32_t>(cfg.locked_levels), geo.levels);
  const uint64_t locked_pages = pages::PageGeometry::first_slot(locked_levels);
  // The locked levels plus a level's worth of a screen: below that the ground cannot refine at all.
  if (frames < locked_pages + 16) {
    return make_error(ErrorCode::kResourceExhausted,
                      "key 'pages.memory_bytes': " + std::to_string(cfg.memory_bytes) + " bytes hold " +
                          std::to_string(by_budget) + " pages of " + std::to_string(page_bytes) +
                          " bytes (device: " + std::to_string(ctx.properties().limits.maxImageArrayLayers) +
                          " layers at most); at least " + std::to_string(locked_pages + 16) +
                          " are needed (pages.locked_levels = " + std::to_string(cfg.locked_levels) + " locks " +
                          std::to_string(locked_pages) + ")");
  }
  g->cache_ = std::make_unique<pages::PageFrameCache>(geo, static_cast<uint32_t>(frames), locked_levels, cfg.discard);
  g->page_of_frame_.assign(frames, std::nullopt);

  GpuImageInfo ii;
  ii.format = cache_vk_format(geo.format);
  ii.width = ii.height = geo.stored_side();
  ii.layers = static_cast<uint32_t>(frames);
  if (options.reference) {
    // One layer, the whole pyramid as an ordinary mip chain (level l of the file is mip levels - 1 - l).
    const uint64_t side = uint64_t{geo.page_texels} << (geo.levels - 1);
    if (geo.format != TexelFormat::kRgba8 || side > kMaxReferenceSide) {
      return make_error(ErrorCode::kUnsupported, "key 'pages.reference': " + options.file_path.string() + " is a " +
                                                     std::string(to_string(geo.format)) + " square of " +
                                                     std::to_string(side) +
                                                     " texels; the reference reads it whole as RGBA8, at most " +
                                                     std::to_string(kMaxReferenceSide) + " per side");
    }
    ii.width = ii.height = static_cast<uint32_t>(side);
    ii.layers = 1;
    ii.mip_levels = geo.levels;
  }
  ii.usage = VK_IMAGE_USAGE_SAMPLED_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  ii.view_type = VK_IMAGE_VIEW_TYPE_2D_ARRAY;
  auto image = GpuImage::create(ctx, ii);
  if (!image) return image.error();
  g->frames_ = std::move(*image);
  // Sampled from the first frame on (an empty table never reaches a frame): shader-readable at once.
  TS_TRY(run_one_shot(ctx, [&](VkCommandBuffer cmd) {
    image_barrier(cmd, g->frames_.handle(), VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, 0,
                  VK_ACCESS_SHADER_READ_BIT, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT);
  }));

  if (options.reference) TS_TRY(g->load_reference(ctx));

  auto uniforms =
      GpuBuffer::create(ctx, sizeof(gpu::GroundUniforms), VK_BUFFER_USAGE_UNIFORM_BUFFER_BIT, MemoryUse::kHostVisible);
  if (!uniforms) return uniforms.error();
  g->uniforms_ = std::move(*uniforms);
  auto table = GpuBuffer::create(ctx, geo.page_slots() * sizeof(uint32_t), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT,
                                 MemoryUse::kHostVisible);
  if (!table) return table.error();
  g->table_ = std::move(*table);
  std::fill_n(g->table_.as<uint32_t>(), geo.page_slots(), gpu::kNoPageFrame);

  const uint32_t step = static_cast<uint32_t>(cfg.needbuffer_step);
  g->needs_cols_ = (options.viewport_width + step - 1) / step;
  g->needs_rows_ = (options.viewport_height + step - 1) / step;
  auto needs =
      GpuBuffer::create(ctx, g->needs_bytes(), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                        MemoryUse::kHostRead);
  if (!needs) return needs.error();
  g->needs_ = std::move(*needs);
  std::memset(g->needs_.bytes().data(), 0xff, g->needs_bytes());

  auto staging = GpuBuffer::create(ctx, page_bytes * options.staging_pages, VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
                                   MemoryUse::kHostVisible);
  if (!staging) return staging.error();
  g->staging_ = std::move(*staging);
  for (uint32_t i = options.staging_pages; i-- > 0;) g->free_staging_.push_back(i);
  spdlog::info("ground: {}x{} texels in {} levels of {}-texel pages, {} page frames ({:.1f} MB of {:.1f} MB)",
               geo.width, geo.height, geo.levels, geo.page_texels, frames,
               static_cast<double>(frames * page_bytes) / 1e6, static_cast<double>(cfg.memory_bytes) / 1e6);
  return g;
}

Status GroundPages::load_reference(const VulkanContext& ctx) {
  const pages::PageGeometry& geo = file_->geometry();
  std::ifstream in(options_.file_path, std::ios::binary);
  if (!in) return make_error(ErrorCode::kNotFound, options_.file_path.string() + ": cannot open (pages.reference)");
  const uint32_t side = geo.stored_side(), P = geo.page_texels, B = geo.border_texels;
  uint64_t total = 0;
  for (uint32_t l = 0; l < geo.levels; ++l) total += (uint64_t{P} << l) * (uint64_t{P} << l) * 4;
  auto staging = GpuBuffer::create(ctx, total, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, MemoryUse::kHostVisible);
  if (!staging) return staging.error();
  std::vector<uint32_t> page(size_t{side} * side);
  std::vector<VkBufferImageCopy> copies;
  uint64_t offset = 0;
  for (uint32_t l = 0; l < geo.levels; ++l) {
    const uint64_t n = uint64_t{P} << l;
    auto* level = reinterpret_cast<uint32_t*>(staging->bytes().data() + offset);
    std::fill_n(level, n * n, 0xff806040u);  // where no page is stored: ground.frag's background
    for (uint32_t y = 0; y < (1u << l); ++y) {
      for (uint32_t x = 0; x < (1u << l); ++x) {
        const auto e = file_->entry({l, x, y});
        if (!e) continue;
        in.seekg(static_cast<std::streamoff>(e->offset));
        if (e->bytes != page.size() * 4 ||
            !in.read(reinterpret_cast<char*>(page.data()), static_cast<std::streamsize>(e->bytes))) {
          return make_error(ErrorCode::kCorrupt, options_.file_path.string() + ": page " + std::to_string(l) + "/" +
                                                     std::to_string(x) + "/" + std::to_string(y) + " unreadable");
        }
        for (uint32_t r = 0; r < P; ++r)
          std::copy_n(&page[size_t{r + B} * side + B], P, &level[(uint64_t{y} * P + r) * n + uint64_t{x} * P]);
      }
    }
    VkBufferImageCopy c{};
    c.bufferOffset = offset;
    c.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, geo.levels - 1 - l, 0, 1};
    c.imageExtent = {static_cast<uint32_t>(n), static_cast<uint32_t>(n), 1};
    copies.push_back(c);
    offset += n * n * 4;
  }
  return run_one_shot(ctx, [&](VkCommandBuffer cmd) {
    image_barrier(cmd, frames_.handle(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                  VK_ACCESS_SHADER_READ_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT,
                  VK_PIPELINE_STAGE_TRANSFER_BIT);
    vkCmdCopyBufferToImage(cmd, staging->handle(), frames_.handle(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                           static_cast<uint32_t>(copies.size()), copies.data());
    image_barrier(cmd, frames_.handle(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL,
                  VK_ACCESS_TRANSFER_WRITE_BIT, VK_ACCESS_SHADER_READ_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT,
                  VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT);
  });
}

VkDeviceSize GroundPages::needs_bytes() const {
  return VkDeviceSize{needs_cols_} * needs_rows_ * sizeof(gpu::PageNeedGpu);
}

void GroundPages::write_uniforms(const std::array<double, 3>& camera, bool write_needs) {
  const pages::PageGeometry& geo = file_->geometry();
  auto* u = uniforms_.as<gpu::GroundUniforms>();
  u->corner = {static_cast<float>(placement_.origin[0] - camera[0]),
               static_cast<float>(placement_.origin[1] - camera[1]),
               static_cast<float>(placement_.origin[2] - camera[2]), static_cast<float>(placement_.metres_per_texel)};
  u->image = {geo.width, geo.height, geo.levels, geo.page_texels};
  u->page = {geo.border_texels, geo.stored_side(), static_cast<uint32_t>(options_.config.needbuffer_step), needs_cols_};
  u->flags = {needs_rows_, write_needs ? 1u : 0u, 0, 0};
  write_needs_ = write_needs;
}

void GroundPages::record_needs_clear(VkCommandBuffer cmd) const {
  if (!write_needs_) return;
  vkCmdFillBuffer(cmd, needs_.handle(), 0, VK_WHOLE_SIZE, 0xffffffffu);  // NaN levels: no ground
  VkMemoryBarrier b{};
  b.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
  b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT, 0, 1, &b, 0, nullptr,
                       0, nullptr);
}

void GroundPages::record_uploads(VkCommandBuffer cmd) {
  if (uploads_.empty()) return;
  const pages::PageGeometry& geo = file_->geometry();
  image_barrier(cmd, frames_.handle(), VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                VK_ACCESS_SHADER_READ_BIT, VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT,
                VK_PIPELINE_STAGE_TRANSFER_BIT);
  std::vector<VkBufferImageCopy> copies;
  copies.reserve(uploads_.size());
  for (const Upload& u : uploads_) {
    VkBufferImageCopy c{};
    c.bufferOffset = VkDeviceSize{u.staging} * geo.page_bytes();
    c.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, u.frame, 1};
    c.imageExtent = {geo.stored_side(), geo.stored_side(), 1};
    copies.push_back(c);
    staging_in_use_.push_back(u.staging);
  }
  vkCmdCopyBufferToImage(cmd, staging_.handle(), frames_.handle(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                         static_cast<uint32_t>(copies.size()), copies.data());
  image_barrier(cmd, frames_.handle(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_SHADER_READ_ONLY_OPTIMAL,
                VK_ACCESS_TRANSFER_WRITE_BIT, VK_ACCESS_SHADER_READ_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT,
                VK_PIPELINE_STAGE_FRAGMENT_SHADER_BIT);
  stats_.pages_uploaded += uploads_.size();
  uploads_.clear();
}

void GroundPages::on_submission_complete(bool drew) {
  free_staging_.insert(free_staging_.end(), staging_in_use_.begin(), staging_in_use_.end());
  staging_in_use_.clear();
  if (drew && write_needs_) read_needs();
}

void GroundPages::read_needs() {
  const pages::PageGeometry& geo = file_->geometry();
  const auto* n = needs_.as<const gpu::PageNeedGpu>();
  const uint32_t step = static_cast<uint32_t>(options_.config.needbuffer_step);
  needs_seen_.clear();
  uint64_t seen = 0;
  for (uint32_t r = 0; r < needs_rows_; ++r) {
    for (uint32_t c = 0; c < needs_cols_; ++c) {
      const gpu::PageNeedGpu& s = n[size_t{r} * needs_cols_ + c];
      // Untrusted like any GPU output: NaN (no ground there) and anything outside the square are skipped.
      if (!(s.level >= 0.0f) || !(s.u >= 0.0f && s.u <= 1.0f) || !(s.v >= 0.0f && s.v <= 1.0f)) continue;
      ++seen;
      const float level = std::min(s.level, static_cast<float>(geo.levels - 1));
      const float sx = 2.0f * (static_cast<float>(c * step) + 0.5f) / static_cast<float>(options_.viewport_width) - 1;
      const float sy = 2.0f * (static_cast<float>(r * step) + 0.5f) / static_cast<float>(options_.viewport_height) - 1;
      const auto lo = static_cast<uint32_t>(std::floor(level));
      const auto hi = std::min(static_cast<uint32_t>(std::ceil(level)), geo.levels - 1);
      for (uint32_t l = lo; l <= hi; ++l) needs_seen_.push_back({page_at(l, s.u, s.v), sx, sy, s.distance, level});
    }
  }
  stats_.needs_last_frame = seen;
}

std::vector<pages::PageCandidate> GroundPages::plan(uint64_t now, pages::HotSpot hotspot, bool everything) {
  now_ = now;
  if (options_.reference) return {};  // everything is there
  // What the last frame sampled (the wanted pages or the ancestors standing in) is not evicted now.
  const pages::PageTable& table = cache_->table();
  for (const pages::PageNeedSample& s : needs_seen_) {
    if (const auto shown = table.available(s.page)) cache_->touch(*shown, now);
  }
  const size_t budget =
      everything ? std::numeric_limits<size_t>::max() / 2 : static_cast<size_t>(options_.config.per_frame);
  if (pending_.size() >= budget) return {};
  return pages::choose_pages(needs_seen_, *file_, table, pending_, policy_, hotspot, now, budget - pending_.size());
}

std::vector<pages::PageCandidate> GroundPages::missing_pages() const {
  const pages::PageGeometry& geo = file_->geometry();
  std::vector<pages::PageCandidate> out;
  for (uint64_t s = 0; s < geo.page_slots(); ++s) {
    const PageId p = geo.page_of_slot(s);
    if (!file_->stored(p) || cache_->table().resident(p) ||
        std::find(pending_.begin(), pending_.end(), p) != pending_.end())
      continue;
    out.push_back({p, static_cast<double>(geo.page_slots() - s)});
  }
  return out;
}

void GroundPages::on_requested(PageId page) {
  pending_.push_back(page);
  ++stats_.pages_requested;
}

std::span<std::byte> GroundPages::reserve_page(uint32_t file, PageId page, uint64_t bytes) {
  const uint64_t page_bytes = file_->geometry().page_bytes();
  if (file != kFileId || bytes > page_bytes || free_staging_.empty()) return {};
  const uint32_t slot = free_staging_.back();
  free_staging_.pop_back();
  reserved_ = std::pair{page, slot};
  return staging_.bytes().subspan(size_t{slot} * page_bytes, bytes);
}

void GroundPages::commit_page(uint32_t file, PageId page, std::span<std::byte> data) {
  std::erase(pending_, page);
  if (!reserved_ || file != kFileId || !(reserved_->first == page)) {
    spdlog::error("ground: page {}/{}/{} committed without its reservation: dropped", page.level, page.x, page.y);
    return;
  }
  const uint32_t slot = reserved_->second;
  reserved_.reset();
  const pages::PageGeometry& geo = file_->geometry();
  // A stored page's bytes are the file's: exactly one bordered page in the file's format (the client checked
  // the size against the index); anything else is not copied.
  if (data.size() != geo.page_bytes()) {
    free_staging_.push_back(slot);
    ++stats_.pages_failed;
    return;
  }
  const uint64_t evictions_before = cache_->evictions();
  const auto frame = cache_->insert(page, now_);
  if (!frame) {
    free_staging_.push_back(slot);
    ++stats_.pages_refused;
    return;
  }
  stats_.evictions += cache_->evictions() - evictions_before;
  auto* t = table_.as<uint32_t>();
  if (const auto& old = page_of_frame_[*frame]; old && !(*old == page)) t[geo.slot(*old)] = gpu::kNoPageFrame;
  page_of_frame_[*frame] = page;
  t[geo.slot(page)] = *frame;
  uploads_.push_back({slot, *frame, page});
}

void GroundPages::page_failed(uint32_t file, PageId page, CompletionStatus status) {
  std::erase(pending_, page);
  if (reserved_ && reserved_->first == page) {  // the span reserve_page() gave is free again
    free_staging_.push_back(reserved_->second);
    reserved_.reset();
  }
  // Superseded by a newer cycle before the server started it (or lost with a restarted server): asked again by a
  // later frame if still wanted.
  if (status == CompletionStatus::kCancelled) {
    ++stats_.pages_cancelled;
    return;
  }
  ++stats_.pages_failed;
  if (file != kFileId) return;
  spdlog::warn("ground: page {}/{}/{} failed: {}", page.level, page.x, page.y, to_string(status));
}

}  // namespace texstream::render
