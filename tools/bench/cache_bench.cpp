// texstream-bench cache: the sparse texture cache (issue 6) measured end to end with texstream-render (a child
// process per run, which spawns its texstream-server), plus a raw vkQueueBindSparse microbenchmark in this
// process.
//
//   convergence  static view, lock-step, controller.mode = none, a cache large enough: PSNR of the streamed
//                frame after N frames against the reference frame of the same view rendered with
//                render.preload_all (every mip of every texture loaded before frame 0: fully resident, the
//                hardware's mip choice unconstrained). Printed next to it: the same streamed frame against
//                the streamed view after 3N frames (has streaming settled by frame N?).
//   bounds       the default fly-through with a cache budget far smaller than the visible set, validation on:
//                per-frame budget checks (cache.json), validation errors, the thrash rate.
//   bind cost    seconds per page op of the cache's batched binds (cache.json of the bounds run, which has the
//                most binds) over a bare vkQueueBindSparse replay of the same ops (raw_replay_seconds_per_op); the
//                older raw figure (level-0 pages never written, same batch sizes) is printed next to it.
//   pop-in       seed 000 Fig. 7: a static view refined one mip per frame from the colormap, every frame
//                written; the maximum MSE between consecutive frames with Eq. 8 blending and with direct
//                sampling (stream.colormap_blend).
//   startup      wall time of texstream-render with render.frames = 1 (start to first frame and exit) on a 1 K
//                texture scene and on a 1 M texture scene (--scene-1m DIR, default /work/scale1m; made once by
//                `texstream-gen --out DIR --textures 1000000 --seed 1`: 7.9 GB, ~30 min on 2 cores), same
//                pose; the renderer's start-up stages side by side.
#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb_image.h>
#include <vulkan/vulkan.h>

#include <unistd.h>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "texstream/common/camera_path.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/render/cache/sparse_memory.hpp"
#include "texstream/render/measure/image_metrics.hpp"
#include "texstream/render/vulkan/vulkan_context.hpp"

namespace fs = std::filesystem;

namespace texstream::bench {
namespace {

struct Image {
  int w = 0, h = 0;
  std::vector<uint8_t> rgb;
};

bool load_png(const fs::path& file, Image& out) {
  int n = 0;
  unsigned char* p = stbi_load(file.string().c_str(), &out.w, &out.h, &n, 3);
  if (!p) return false;
  out.rgb.assign(p, p + static_cast<size_t>(out.w) * out.h * 3);
  stbi_image_free(p);
  return true;
}

// Mean squared error over RGB in 0..255 units (the seed's Fig. 7 scale).
double mse(const Image& a, const Image& b) {
  if (a.w != b.w || a.h != b.h || a.rgb.empty()) return -1;
  double s = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) {
    const double d = static_cast<double>(a.rgb[i]) - static_cast<double>(b.rgb[i]);
    s += d * d;
  }
  return s / static_cast<double>(a.rgb.size());
}

// PSNR in dB: the renderer's, capped at 100 dB for identical frames (MSE 0).
double psnr(double m) { return render::psnr_db(m); }

struct Ctx {
  fs::path bin;
  fs::path profile;
  fs::path work;
  std::string device_substring;
};

int run_cmd(const std::string& cmd, bool quiet = true) {
  const std::string full = quiet ? cmd + " > /dev/null 2>&1" : cmd;
  const int rc = std::system(full.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

// `src` with its meshes unchanged but only its first `textures` textures: mesh m uses texture
// (its own id mod `textures`). The same city and, from the same pose, the same view; only the texture count
// differs. Texture files are shared through a symlink to src/textures.
Status derive_texture_subset(const fs::path& src, const fs::path& dst, uint32_t textures) {
  auto manifest = scene::read_manifest(src);
  if (!manifest) return manifest.error();
  auto meshes = scene::read_meshes(src);
  if (!meshes) return meshes.error();
  auto table = scene::read_texture_table(src);
  if (!table) return table.error();
  auto colours = scene::read_colormap(src, table->size());
  if (!colours) return colours.error();
  if (table->size() < textures)
    return make_error(ErrorCode::kInvalidArgument,
                      src.string() + ": fewer than " + std::to_string(textures) + " textures");
  std::error_code ec;
  fs::remove_all(dst, ec);
  fs::create_directories(dst, ec);
  if (ec) return make_error(ErrorCode::kIo, dst.string() + ": " + ec.message());
  for (auto& m : meshes->meshes) m.texture_id %= textures;
  table->resize(textures);
  colours->resize(textures);
  manifest->texture_count = textures;
  TS_TRY(scene::write_meshes(dst, *meshes));
  TS_TRY(scene::write_texture_table(dst, *table));
  TS_TRY(scene::write_colormap(dst, *colours));
  TS_TRY(scene::write_manifest(dst, *manifest));
  fs::copy_file(src / manifest->camera_path, dst / manifest->camera_path, fs::copy_options::overwrite_existing, ec);
  if (!ec) fs::create_directory_symlink(fs::absolute(src / "textures"), dst / "textures", ec);
  if (ec) return make_error(ErrorCode::kIo, dst.string() + ": " + ec.message());
  return ok_status();
}

// One texstream-render run; returns its exit code and wall seconds.
int render(const Ctx& c, const fs::path& scene, const fs::path& out, const std::vector<std::string>& sets,
           double* seconds = nullptr) {
  std::error_code ec;
  fs::remove_all(out, ec);
  std::string cmd = (c.bin / "texstream-render").string() + " --config " + c.profile.string() +
                    " --set scene.dir=" + scene.string() + " --set render.output_dir=" + out.string();
  for (const auto& s : sets) cmd += " --set " + s;
  cmd += " > " + (out.string() + ".log") + " 2>&1";
  Stopwatch sw;
  const int rc = run_cmd(cmd, false);
  if (seconds) *seconds = sw.seconds();
  if (rc != 0) std::fprintf(stderr, "cache bench: texstream-render failed (%d), see %s.log\n", rc, out.c_str());
  return rc;
}

// The file's JSON object, or an empty object (value() then gives each default) when it is missing or bad.
nlohmann::json read_json(const fs::path& f) {
  std::ifstream in(f);
  if (!in) return nlohmann::json::object();
  try {
    nlohmann::json j = nlohmann::json::parse(in);
    return j.is_object() ? j : nlohmann::json::object();
  } catch (...) {
    return nlohmann::json::object();
  }
}

// A one-pose path: the static views of the convergence and pop-in runs.
fs::path static_path(const Ctx& c, const fs::path& scene_path_file, const std::string& name) {
  auto path = CameraPath::load(scene_path_file);
  const fs::path out = c.work / name;
  if (!path || path->keys().empty()) return {};
  const CameraPose p = path->keys().front().pose;
  std::ofstream f(out);
  char line[256];
  std::snprintf(line, sizeof line, "0 %.6f %.6f %.6f %.6f %.6f\n1000 %.6f %.6f %.6f %.6f %.6f\n", p.position[0],
                p.position[1], p.position[2], p.yaw_deg, p.pitch_deg, p.position[0], p.position[1], p.position[2],
                p.yaw_deg, p.pitch_deg);
  f << line;
  return out;
}

fs::path frame_file(const fs::path& out, uint64_t i) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%05llu.png", static_cast<unsigned long long>(i));
  return out / "frames" / name;
}

// Bytes of mip tail the cache's sparse image needs on this device for `layers` layers of 512² RGBA8 (0 on
// lavapipe, which has none; 64 KiB per layer on the H100): paid from cache.memory_bytes before any page.
uint64_t mip_tail_bytes(const Ctx& c, uint32_t layers) {
  using namespace texstream::render;
  VulkanContextOptions vo;
  vo.device_substring = c.device_substring;
  auto ctx = VulkanContext::create(vo);
  if (!ctx) return 0;
  SparseImageInfo info;
  info.format = VK_FORMAT_R8G8B8A8_SRGB;
  info.extent = 512;
  info.mip_levels = 10;
  info.layers = layers;
  info.memory_bytes = 1ull << 30;
  auto sm = SparseMemory::create(**ctx, info);
  return sm ? (*sm)->tail_bytes() : 0;
}

// The bare bind microbenchmark: the same sparse image geometry as the cache, a memory block, and for each
// batch size of the cache's run one vkQueueBindSparse of that many pages (binds and unbinds alternating, as
// the cache's batches mix them), built beforehand so only the call is timed.
double raw_bind_seconds_per_op(const Ctx& c, const std::vector<uint32_t>& sizes, uint32_t format_is_bc1) {
  using namespace texstream::render;
  VulkanContextOptions vo;
  vo.device_substring = c.device_substring;
  vo.need_bc = format_is_bc1 != 0;
  auto ctx = VulkanContext::create(vo);
  if (!ctx) {
    std::fprintf(stderr, "cache bench: %s\n", ctx.error().message.c_str());
    return -1;
  }
  SparseImageInfo info;
  info.format = format_is_bc1 ? VK_FORMAT_BC1_RGBA_SRGB_BLOCK : VK_FORMAT_R8G8B8A8_SRGB;
  info.extent = 512;
  info.mip_levels = 10;
  info.layers = 64;
  info.memory_bytes = 64ull << 20;
  auto sm = SparseMemory::create(**ctx, info);
  if (!sm) {
    std::fprintf(stderr, "cache bench: %s\n", sm.error().message.c_str());
    return -1;
  }
  const PageGeometry& g = (*sm)->geometry();
  // One memory block of 256 pages, directly: the op arrays point into it.
  VkMemoryRequirements req{};
  vkGetImageMemoryRequirements((*ctx)->device(), (*sm)->image(), &req);
  auto type = (*ctx)->find_memory_type(req.memoryTypeBits, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (!type) return -1;
  const uint32_t pages = 256;
  VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, nullptr, pages * req.alignment, *type};
  VkDeviceMemory mem = VK_NULL_HANDLE;
  if (vkAllocateMemory((*ctx)->device(), &ai, nullptr, &mem) != VK_SUCCESS) return -1;
  // Page locations: level 0 pages of the layers, up to 256 distinct ones.
  const uint32_t per_layer = (512 / g.granularity_w) * (512 / g.granularity_h);
  auto op = [&](uint32_t i, bool bind) {
    VkSparseImageMemoryBind b{};
    const uint32_t layer = (i / per_layer) % 64, p = i % per_layer, cols = 512 / g.granularity_w;
    b.subresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, layer};
    b.offset = {static_cast<int32_t>((p % cols) * g.granularity_w), static_cast<int32_t>((p / cols) * g.granularity_h),
                0};
    b.extent = {g.granularity_w, g.granularity_h, 1};
    if (bind) {
      b.memory = mem;
      b.memoryOffset = (i % pages) * req.alignment;
    }
    return b;
  };
  // The same call shape as SparseMemory::submit: one VkBindSparseInfo signalling a timeline semaphore, then a
  // wait for it (lavapipe returns from the call before it binds).
  VkSemaphoreTypeCreateInfo sti{VK_STRUCTURE_TYPE_SEMAPHORE_TYPE_CREATE_INFO, nullptr, VK_SEMAPHORE_TYPE_TIMELINE, 0};
  VkSemaphoreCreateInfo sci{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO, &sti, 0};
  VkSemaphore sem = VK_NULL_HANDLE;
  if (vkCreateSemaphore((*ctx)->device(), &sci, nullptr, &sem) != VK_SUCCESS) return -1;
  uint64_t value = 0;
  double total = 0;
  uint64_t ops = 0;
  for (uint32_t n : sizes) {
    n = std::min(n, pages);
    std::vector<VkSparseImageMemoryBind> binds, unbinds;
    for (uint32_t i = 0; i < n; ++i) {
      binds.push_back(op(i, true));
      unbinds.push_back(op(i, false));
    }
    for (auto* v : {&binds, &unbinds}) {
      VkSparseImageMemoryBindInfo ib{(*sm)->image(), n, v->data()};
      VkBindSparseInfo bi{};
      bi.sType = VK_STRUCTURE_TYPE_BIND_SPARSE_INFO;
      bi.imageBindCount = 1;
      bi.pImageBinds = &ib;
      ++value;
      VkTimelineSemaphoreSubmitInfo ts{};
      ts.sType = VK_STRUCTURE_TYPE_TIMELINE_SEMAPHORE_SUBMIT_INFO;
      ts.signalSemaphoreValueCount = 1;
      ts.pSignalSemaphoreValues = &value;
      bi.pNext = &ts;
      bi.signalSemaphoreCount = 1;
      bi.pSignalSemaphores = &sem;
      VkSemaphoreWaitInfo wi{VK_STRUCTURE_TYPE_SEMAPHORE_WAIT_INFO, nullptr, 0, 1, &sem, &value};
      Stopwatch sw;
      if (vkQueueBindSparse((*ctx)->queue(), 1, &bi, VK_NULL_HANDLE) != VK_SUCCESS) return -1;
      if (vkWaitSemaphores((*ctx)->device(), &wi, UINT64_MAX) != VK_SUCCESS) return -1;
      total += sw.seconds();
      ops += n;
    }
  }
  vkQueueWaitIdle((*ctx)->queue());
  vkDestroySemaphore((*ctx)->device(), sem, nullptr);
  sm->reset();
  vkFreeMemory((*ctx)->device(), mem, nullptr);
  return ops ? total / static_cast<double>(ops) : -1;
}

// The replay microbenchmark: the cache run's own first frames (cache.json "upload_trace": the same pages,
// levels, layers and memory slots, call by call) on an identical sparse image, each call one bare
// vkQueueBindSparse built beforehand, timed from the call to the semaphore wait like SparseMemory::submit.
// After each frame's call, untimed, the frame's copies write the same regions the cache's uploads wrote:
// what a bind or unbind costs depends on what was written under the page (lavapipe maps host memory; a page
// whose mapping was touched costs more to replace), so replaying the binds alone, or writing whole pages,
// measures a different operation (both were tried: 2x cheaper and 3x dearer than the cache's binds).
struct ReplayResult {
  double seconds_per_op = -1;       // bare vkQueueBindSparse
  double ours_seconds_per_op = -1;  // SparseMemory::submit (the cache's path) on the same ops, interleaved
  uint64_t ops = 0;
  size_t calls = 0;
};

ReplayResult raw_replay_seconds_per_op(const Ctx& c, const nlohmann::json& cache_json) {
  using namespace texstream::render;
  ReplayResult out;
  const auto& si = cache_json.value("sparse_image", nlohmann::json::object());
  const auto& trace = cache_json.value("upload_trace", nlohmann::json::array());
  if (si.empty() || trace.empty()) return out;
  SparseImageInfo info;
  info.format = static_cast<VkFormat>(si.value("vk_format", 0));
  info.extent = si.value("extent", 0u);
  info.mip_levels = si.value("mip_levels", 0u);
  info.layers = si.value("layers", 0u);
  info.memory_bytes = si.value("memory_bytes", uint64_t{0});
  const uint32_t per_block = si.value("pages_per_block", 0u);
  if (info.extent == 0 || info.mip_levels == 0 || info.layers == 0 || per_block == 0) return out;
  VulkanContextOptions vo;
  vo.device_substring = c.device_substring;
  vo.need_bc = info.format == VK_FORMAT_BC1_RGBA_SRGB_BLOCK || info.format == VK_FORMAT_BC3_SRGB_BLOCK;
  auto ctx = VulkanContext::create(vo);
  if (!ctx) {
    std::fprintf(stderr, "cache bench: %s\n", ctx.error().message.c_str());
    return out;
  }
  auto sm = SparseMemory::create(**ctx, info);    // the image only: its memory blocks stay unallocated
  auto ours = SparseMemory::create(**ctx, info);  // a second image, bound through SparseMemory::submit
  if (!sm || !ours) {
    std::fprintf(stderr, "cache bench: %s\n", (!sm ? sm : ours).error().message.c_str());
    return out;
  }
  VkDevice dev = (*ctx)->device();
  VkQueue queue = (*ctx)->queue();
  const PageGeometry& g = (*sm)->geometry();
  const uint64_t page = (*sm)->page_bytes();
  VkMemoryRequirements req{};
  vkGetImageMemoryRequirements(dev, (*sm)->image(), &req);
  auto type = (*ctx)->find_memory_type(req.memoryTypeBits, 0, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT);
  if (!type) return out;
  // The same blocks as SparseMemory (kBlockBytes each), all allocated before any timing.
  std::vector<VkDeviceMemory> blocks((*sm)->slot_count() / per_block + 1, VK_NULL_HANDLE);
  for (auto& b : blocks) {
    VkMemoryAllocateInfo ai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, nullptr, uint64_t{per_block} * page, *type};
    if (vkAllocateMemory(dev, &ai, nullptr, &b) != VK_SUCCESS) return out;
  }
  // Copies: a zero staging buffer for the largest region, a command pool, the whole image in TRANSFER_DST.
  uint64_t largest = 4;
  for (const auto& frame : trace)
    for (const auto& cp : frame.value("copies", nlohmann::json::array()))
      if (cp.is_array() && cp.size() == 6)
        largest = std::max(largest, cp[4].get<uint64_t>() * cp[5].get<uint64_t>() * 4);
  VkBufferCreateInfo bci{};
  bci.sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO;
  bci.size = largest;
  bci.usage = VK_BUFFER_USAGE_TRANSFER_SRC_BIT;
  VkBuffer staging = VK_NULL_HANDLE;
  if (vkCreateBuffer(dev, &bci, nullptr, &staging) != VK_SUCCESS) return out;
  VkMemoryRequirements breq{};
  vkGetBufferMemoryRequirements(dev, staging, &breq);
  auto htype = (*ctx)->find_memory_type(breq.memoryTypeBits, VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT, 0);
  if (!htype) return out;
  VkMemoryAllocateInfo hai{VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO, nullptr, breq.size, *htype};
  VkDeviceMemory staging_mem = VK_NULL_HANDLE;
  if (vkAllocateMemory(dev, &hai, nullptr, &staging_mem) != VK_SUCCESS) return out;
  vkBindBufferMemory(dev, staging, staging_mem, 0);
  VkCommandPoolCreateInfo pci{};
  pci.sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO;
  pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
  pci.queueFamilyIndex = (*ctx)->queue_family();
  VkCommandPool pool = VK_NULL_HANDLE;
  if (vkCreateCommandPool(dev, &pci, nullptr, &pool) != VK_SUCCESS) return out;
  VkCommandBufferAllocateInfo cai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO, nullptr, pool,
                                  VK_COMMAND_BUFFER_LEVEL_PRIMARY, 1};
  VkCommandBuffer cmd = VK_NULL_HANDLE;
  if (vkAllocateCommandBuffers(dev, &cai, &cmd) != VK_SUCCESS) return out;
  VkSemaphoreTypeCreateInfo sti{VK_STRUCTURE_TYPE_SEMAPHORE_TYPE_CREATE_INFO, nullptr, VK_SEMAPHORE_TYPE_TIMELINE, 0};
  VkSemaphoreCreateInfo sci{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO, &sti, 0};
  VkSemaphore sem = VK_NULL_HANDLE;
  if (vkCreateSemaphore(dev, &sci, nullptr, &sem) != VK_SUCCESS) return out;
  uint64_t value = 0;
  // Runs `record` in a command buffer that waits for the last bind; returns false on an API failure.
  auto run = [&](auto&& record) {
    vkResetCommandBuffer(cmd, 0);
    VkCommandBufferBeginInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO;
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    vkBeginCommandBuffer(cmd, &bi);
    record();
    vkEndCommandBuffer(cmd);
    const VkPipelineStageFlags stage = VK_PIPELINE_STAGE_ALL_COMMANDS_BIT;
    VkTimelineSemaphoreSubmitInfo ts{};
    ts.sType = VK_STRUCTURE_TYPE_TIMELINE_SEMAPHORE_SUBMIT_INFO;
    ts.waitSemaphoreValueCount = 1;
    ts.pWaitSemaphoreValues = &value;
    VkSubmitInfo s{VK_STRUCTURE_TYPE_SUBMIT_INFO, &ts, 1, &sem, &stage, 1, &cmd, 0, nullptr};
    return vkQueueSubmit(queue, 1, &s, VK_NULL_HANDLE) == VK_SUCCESS && vkQueueWaitIdle(queue) == VK_SUCCESS;
  };
  const bool ok = run([&] {
    VkImageMemoryBarrier b{};
    b.sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER;
    b.dstAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
    b.oldLayout = VK_IMAGE_LAYOUT_UNDEFINED;
    b.newLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
    b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
    b.subresourceRange = {VK_IMAGE_ASPECT_COLOR_BIT, 0, info.mip_levels, 0, info.layers};
    for (VkImage image : {(*sm)->image(), (*ours)->image()}) {
      b.image = image;
      vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, nullptr, 0,
                           nullptr, 1, &b);
    }
  });
  double total = 0;
  bool raw_first = true;  // alternates frame by frame, so neither path always runs on a warmer cache
  // The frame's copies into both images (untimed).
  auto write_both = [&](const std::vector<VkBufferImageCopy>& writes) {
    return writes.empty() || run([&] {
             for (VkImage image : {(*sm)->image(), (*ours)->image()})
               vkCmdCopyBufferToImage(cmd, staging, image, VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                                      static_cast<uint32_t>(writes.size()), writes.data());
           });
  };
  for (const auto& frame : trace) {
    if (!ok) break;
    std::vector<VkSparseImageMemoryBind> binds;
    std::vector<PageBindOp> our_ops;
    std::vector<VkBufferImageCopy> writes;
    for (const auto& cp : frame.value("copies", nlohmann::json::array())) {
      if (!cp.is_array() || cp.size() != 6) continue;
      std::array<uint32_t, 6> v{};
      for (size_t k = 0; k < 6; ++k) v[k] = cp[k].get<uint32_t>();
      if (v[0] >= info.layers || v[1] >= info.mip_levels) continue;
      VkBufferImageCopy w{};
      w.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, v[1], v[0], 1};
      w.imageOffset = {static_cast<int32_t>(v[2]), static_cast<int32_t>(v[3]), 0};
      w.imageExtent = {v[4], v[5], 1};
      writes.push_back(w);
    }
    for (const auto& op : frame.value("binds", nlohmann::json::array())) {
      if (!op.is_array() || op.size() != 5) continue;
      const auto layer = op[0].get<uint32_t>(), mip = op[1].get<uint32_t>(), x = op[2].get<uint32_t>(),
                 y = op[3].get<uint32_t>();
      const auto slot = op[4].get<int64_t>();
      if (layer >= info.layers || mip >= info.mip_levels) continue;
      if (slot >= 0 && static_cast<uint64_t>(slot) >= (*ours)->slot_count()) continue;
      our_ops.push_back(
          PageBindOp{PageLocation{layer, mip, x, y}, slot >= 0, slot >= 0 ? static_cast<uint32_t>(slot) : 0u});
      const uint32_t level = std::max(info.extent >> mip, 1u);
      VkSparseImageMemoryBind b{};
      b.subresource = {VK_IMAGE_ASPECT_COLOR_BIT, mip, layer};
      b.offset = {static_cast<int32_t>(x * g.granularity_w), static_cast<int32_t>(y * g.granularity_h), 0};
      b.extent = {std::min(g.granularity_w, level - x * g.granularity_w),
                  std::min(g.granularity_h, level - y * g.granularity_h), 1};
      if (slot >= 0) {
        const auto s = static_cast<uint64_t>(slot);
        if (s / per_block >= blocks.size()) continue;
        b.memory = blocks[s / per_block];
        b.memoryOffset = (s % per_block) * page;
      }
      binds.push_back(b);
    }
    if (binds.empty()) {
      if (!write_both(writes)) break;
      continue;
    }
    if (!raw_first && !(*ours)->submit(our_ops).ok()) break;
    VkSparseImageMemoryBindInfo ib{(*sm)->image(), static_cast<uint32_t>(binds.size()), binds.data()};
    VkBindSparseInfo bi{};
    bi.sType = VK_STRUCTURE_TYPE_BIND_SPARSE_INFO;
    bi.imageBindCount = 1;
    bi.pImageBinds = &ib;
    const uint64_t next = value + 1;
    VkTimelineSemaphoreSubmitInfo ts{};
    ts.sType = VK_STRUCTURE_TYPE_TIMELINE_SEMAPHORE_SUBMIT_INFO;
    ts.signalSemaphoreValueCount = 1;
    ts.pSignalSemaphoreValues = &next;
    bi.pNext = &ts;
    bi.signalSemaphoreCount = 1;
    bi.pSignalSemaphores = &sem;
    VkSemaphoreWaitInfo wi{VK_STRUCTURE_TYPE_SEMAPHORE_WAIT_INFO, nullptr, 0, 1, &sem, &next};
    Stopwatch sw;
    if (vkQueueBindSparse(queue, 1, &bi, VK_NULL_HANDLE) != VK_SUCCESS) break;
    if (vkWaitSemaphores(dev, &wi, UINT64_MAX) != VK_SUCCESS) break;
    total += sw.seconds();
    value = next;
    out.ops += binds.size();
    ++out.calls;
    if (raw_first && !(*ours)->submit(our_ops).ok()) break;
    raw_first = !raw_first;
    if (!write_both(writes)) break;
  }
  vkQueueWaitIdle(queue);
  vkDestroySemaphore(dev, sem, nullptr);
  vkDestroyCommandPool(dev, pool, nullptr);
  vkDestroyBuffer(dev, staging, nullptr);
  vkFreeMemory(dev, staging_mem, nullptr);
  if (out.ops > 0) out.seconds_per_op = total / static_cast<double>(out.ops);
  if ((*ours)->stats().ops > 0)
    out.ours_seconds_per_op = (*ours)->stats().seconds / static_cast<double>((*ours)->stats().ops);
  ours->reset();
  sm->reset();  // the image before the memory bound to it
  for (auto b : blocks) vkFreeMemory(dev, b, nullptr);
  return out;
}

// Whether the Khronos validation layer can be enabled on this machine (the GPU machine of the device tool has
// none: the bounds run there goes without, and says so).
bool validation_layer_installed() {
  uint32_t n = 0;
  if (vkEnumerateInstanceLayerProperties(&n, nullptr) != VK_SUCCESS) return false;
  std::vector<VkLayerProperties> layers(n);
  if (vkEnumerateInstanceLayerProperties(&n, layers.data()) != VK_SUCCESS) return false;
  return std::any_of(layers.begin(), layers.end(), [](const VkLayerProperties& l) {
    return std::string_view(l.layerName) == "VK_LAYER_KHRONOS_validation";
  });
}

struct CacheArgs {
  bool quick = false;
  std::string device = "lavapipe";
  std::string scene_1m = "/work/scale1m";
  bool keep = false;
};

int run_cache(const CacheArgs& args) {
  const bool quick = args.quick;
  const std::string device = args.device;
  if (device != "lavapipe" && device != "gpu") {
    std::fprintf(stderr, "cache bench: --device must be lavapipe or gpu\n");
    return 2;
  }
  Ctx c;
  c.bin = self_dir();
  // TEXSTREAM_CONFIG_DIR overrides the build-time path (a bundle run on another machine: scripts/make_gpu_bundle.sh).
  const char* config_dir = std::getenv("TEXSTREAM_CONFIG_DIR");
  c.profile = fs::path(config_dir && *config_dir ? config_dir : TEXSTREAM_CACHE_BENCH_CONFIG_DIR) / (device + ".toml");
  c.device_substring = device == "lavapipe" ? "llvmpipe" : "";
  c.work = fs::temp_directory_path() / ("texstream_cache_bench_" + std::to_string(getpid()));
  fs::create_directories(c.work);
  const std::string ws = std::to_string(quick ? 320 : 640), hs = std::to_string(quick ? 180 : 360);
  const std::vector<std::string> common = {"render.lockstep=true", "controller.mode=none", "render.width_px=" + ws,
                                           "render.height_px=" + hs, "server.log_level=warn"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> v = common;
    v.insert(v.end(), extra.begin(), extra.end());
    return v;
  };

  // Scenes: an RGBA8 city for the image runs (lossless: PSNR measures the cache, not BC1), a BC1 one of
  // 1 K textures for the startup comparison with the 1 M scene (BC1).
  const fs::path scene = c.work / "city_rgba8";
  const fs::path scene1k = c.work / "city_bc1_1k";
  const uint32_t textures = quick ? 1000 : 4000;
  if (run_cmd((c.bin / "texstream-gen").string() + " --out " + scene.string() + " --textures " +
              std::to_string(textures) + " --seed 1 --format rgba8 --force") != 0 ||
      run_cmd((c.bin / "texstream-gen").string() + " --out " + scene1k.string() +
              " --textures 1000 --seed 1 --format bc1 --force") != 0) {
    std::fprintf(stderr, "cache bench: texstream-gen failed\n");
    return 1;
  }
  const fs::path still = static_path(c, scene / "camera_path.txt", "still.txt");

  // ---- convergence ----
  const uint64_t n_conv = quick ? 16 : 24;
  // Large enough for render.preload_all to hold every mip of every texture of the 4000-texture scene (512 MiB
  // was not, on the H100); the image's layers are chosen from the device (lavapipe: 1.8 GiB of address).
  const auto big = std::vector<std::string>{"cache.memory_bytes=" + std::to_string(1536ull << 20),
                                            "render.camera_path=" + still.string(), "render.write_every_frames=0"};
  auto conv_sets = with(big);
  conv_sets.push_back("render.frames=" + std::to_string(n_conv));
  auto settled_sets = with(big);
  settled_sets.push_back("render.frames=" + std::to_string(3 * n_conv));
  auto ref_sets = with(big);
  ref_sets.push_back("render.frames=1");
  ref_sets.push_back("render.preload_all=true");
  const fs::path conv_out = c.work / "converge", settled_out = c.work / "settled", ref_out = c.work / "reference";
  double converged_psnr = 0, settled_psnr = 0;
  Image a, b, r;
  if (render(c, scene, conv_out, conv_sets) == 0 && render(c, scene, ref_out, ref_sets) == 0 &&
      load_png(frame_file(conv_out, n_conv - 1), a) && load_png(frame_file(ref_out, 0), r)) {
    converged_psnr = psnr(mse(a, r));
  }
  if (render(c, scene, settled_out, settled_sets) == 0 && load_png(frame_file(settled_out, 3 * n_conv - 1), b) &&
      !a.rgb.empty()) {
    settled_psnr = psnr(mse(a, b));
  }
  const auto conv_sum = read_json(conv_out / "summary.json");
  std::printf(
      "convergence: streamed frame %llu vs the preload_all reference frame (every mip of every texture "
      "resident) of the same static view: PSNR %.2f dB (%s of %s textures resident when streamed)\n",
      static_cast<unsigned long long>(n_conv - 1), converged_psnr,
      conv_sum.value("textures_resident", nlohmann::json(0)).dump().c_str(),
      conv_sum.value("texture_count", nlohmann::json(0)).dump().c_str());
  std::printf("convergence: streamed frame %llu vs streamed frame %llu of the same run settings: PSNR %.2f dB\n",
              static_cast<unsigned long long>(n_conv - 1), static_cast<unsigned long long>(3 * n_conv - 1),
              settled_psnr);

  // Bytes the cache can address over its budget, the smallest over every run here (issue 26: >= 1).
  double addressable_vs_budget = 1e30;
  auto note_addressable = [&](const nlohmann::json& cj) {
    const double budget_bytes = cj.value("memory_budget_bytes", 0.0);
    const double v = budget_bytes > 0 ? cj.value("addressable_bytes", 0.0) / budget_bytes : 0.0;
    addressable_vs_budget = std::min(addressable_vs_budget, v);
  };
  note_addressable(read_json(conv_out / "cache.json"));

  // ---- fit: a view whose working set fits the budget must never evict (issue 26) ----
  // The still view's working set is what the converged run held (nothing evicted there: the budget is the
  // whole scene's); the budget here is 1/8 above it. lru must evict nothing; the seed's ring is shown beside.
  const uint64_t working_set = read_json(conv_out / "cache.json").value("max_bound_bytes", uint64_t{0});
  const uint64_t fit_budget = std::max<uint64_t>(working_set + working_set / 8, 2ull << 20);
  uint64_t fit_evictions = ~0ull;
  for (const char* mode : {"lru", "ring"}) {
    const fs::path out = c.work / (std::string("fit_") + mode);
    auto sets = with({"cache.memory_bytes=" + std::to_string(fit_budget), std::string("cache.eviction=") + mode,
                      "render.camera_path=" + still.string(), "render.write_every_frames=0",
                      "render.frames=" + std::to_string(3 * n_conv)});
    const int rc = render(c, scene, out, sets);
    const auto fj = read_json(out / "cache.json");
    note_addressable(fj);
    const uint64_t ev = rc == 0 ? fj.value("evictions", ~0ull) : ~0ull;
    if (std::string(mode) == "lru") fit_evictions = ev;
    std::printf(
        "fit: still view, working set %llu B, budget %llu B, cache.eviction=%s: %llu evictions, thrash rate %.3f, "
        "%llu layers of %llu px, exit %d\n",
        (unsigned long long)working_set, (unsigned long long)fit_budget, mode, (unsigned long long)ev,
        fj.value("thrash_rate", 0.0), (unsigned long long)fj.value("layers", 0ull),
        (unsigned long long)fj.value("layer_extent", 0ull), rc);
  }

  // ---- bounds (thrash) ----
  // 64 pages (4 MiB) beyond the device's mip tail: far below the view's working set.
  const uint64_t tail = mip_tail_bytes(c, 64);
  const uint64_t budget = (4ull << 20) + tail;
  if (tail > 0)
    std::printf("bounds: this device's mip tail for 64 layers: %llu B (added to the budget)\n",
                (unsigned long long)tail);
  const fs::path thrash_out = c.work / "thrash";
  const bool validate = validation_layer_installed();
  if (!validate) std::printf("bounds: VK_LAYER_KHRONOS_validation is not installed here: run without validation\n");
  auto thrash_sets = with({"cache.memory_bytes=" + std::to_string(budget),
                           std::string("render.validation=") + (validate ? "true" : "false"),
                           "render.frames=" + std::to_string(quick ? 60 : 200), "render.write_every_frames=0"});
  const int thrash_rc = render(c, scene, thrash_out, thrash_sets);
  const auto tj = read_json(thrash_out / "cache.json");
  const auto ts = read_json(thrash_out / "summary.json");
  const uint64_t exceeded = tj.value("budget_exceeded_frames", uint64_t{999999});
  const uint64_t max_bound = tj.value("max_bound_bytes", uint64_t{0});
  const uint64_t validation = ts.value("validation_errors", uint64_t{999999});
  std::printf(
      "bounds: budget %llu B, max bound %llu B over %llu frames, budget_exceeded_frames=%llu, allocated %llu B, "
      "validation errors %llu, exit %d\n",
      (unsigned long long)budget, (unsigned long long)max_bound, (unsigned long long)tj.value("frames", 0ull),
      (unsigned long long)exceeded, (unsigned long long)tj.value("allocated_bytes", 0ull),
      (unsigned long long)validation, thrash_rc);
  std::printf(
      "bounds: thrash rate %.3f (%llu of %llu texture loads were reloads after eviction), %llu layers "
      "evicted for the budget, %llu pages bound, %llu unbound, %llu shared acquisitions\n",
      tj.value("thrash_rate", 0.0), (unsigned long long)tj.value("texture_reloads", 0ull),
      (unsigned long long)tj.value("texture_loads", 0ull), (unsigned long long)tj.value("budget_evicted_layers", 0ull),
      (unsigned long long)tj.value("pages_bound", 0ull), (unsigned long long)tj.value("pages_unbound", 0ull),
      (unsigned long long)tj.value("pages_shared", 0ull));
  note_addressable(tj);
  const double fill_at_first_eviction = tj.value("fill_at_first_eviction", 0.0);
  std::printf(
      "bounds: memory in use at the first eviction %llu B = %.3f of the budget; %llu evictions for address space, "
      "%llu levels finer than wanted dropped from textures in view, %llu copies refused (all in use); %llu layers "
      "of %llu px, %llu B addressable\n",
      (unsigned long long)tj.value("first_eviction_bytes", 0ull), fill_at_first_eviction,
      (unsigned long long)tj.value("address_evictions", 0ull), (unsigned long long)tj.value("trimmed_levels", 0ull),
      (unsigned long long)tj.value("space_refusals", 0ull), (unsigned long long)tj.value("layers", 0ull),
      (unsigned long long)tj.value("layer_extent", 0ull), (unsigned long long)tj.value("addressable_bytes", 0ull));
  {
    // The seed's ring at the same budget, same path: its thrash rate beside lru's.
    const fs::path ring_out = c.work / "thrash_ring";
    auto ring_sets = thrash_sets;
    ring_sets.push_back("cache.eviction=ring");
    ring_sets.push_back("render.validation=false");
    const int ring_rc = render(c, scene, ring_out, ring_sets);
    const auto rj = read_json(ring_out / "cache.json");
    std::printf(
        "bounds: cache.eviction=ring at the same budget: thrash rate %.3f (%llu of %llu loads), %llu evictions, "
        "memory in use at the first eviction %.3f of the budget, exit %d\n",
        rj.value("thrash_rate", 0.0), (unsigned long long)rj.value("texture_reloads", 0ull),
        (unsigned long long)rj.value("texture_loads", 0ull), (unsigned long long)rj.value("evictions", 0ull),
        rj.value("fill_at_first_eviction", 0.0), ring_rc);
  }

  // ---- bind cost: the thrash run again without the validation layer (it checks every bind) ----
  const fs::path bind_out = c.work / "bindcost";
  auto bind_sets = thrash_sets;
  bind_sets.push_back("render.validation=false");
  render(c, scene, bind_out, bind_sets);
  const auto bj = read_json(bind_out / "cache.json");
  std::vector<uint32_t> sizes = bj.value("bind_ops_per_call", std::vector<uint32_t>{});
  const double ours = bj.value("bind_ops", 0ull) ? bj.value("bind_seconds", 0.0) / bj.value("bind_ops", 1.0) : -1;
  const double ours_call =
      bj.value("bind_ops", 0ull) ? bj.value("bind_call_seconds", 0.0) / bj.value("bind_ops", 1.0) : -1;
  const double raw_sizes = sizes.empty() ? -1 : raw_bind_seconds_per_op(c, sizes, 0);
  const ReplayResult replay = raw_replay_seconds_per_op(c, bj);
  const double ratio = replay.ours_seconds_per_op > 0 && replay.seconds_per_op > 0
                           ? replay.ours_seconds_per_op / replay.seconds_per_op
                           : -1;
  const double ratio_in_run = ours > 0 && replay.seconds_per_op > 0 ? ours / replay.seconds_per_op : -1;
  std::printf("bind cost: ours %.2f us/page over %zu calls (%llu ops; the calls and waits alone %.2f us/page)\n",
              ours * 1e6, sizes.size(), (unsigned long long)bj.value("bind_ops", 0ull), ours_call * 1e6);
  std::printf(
      "bind cost: replay of the run's first %zu calls (%llu ops, the run's copies written between calls), "
      "interleaved: SparseMemory::submit %.2f us/page, bare vkQueueBindSparse %.2f us/page: ratio %.3f\n",
      replay.calls, (unsigned long long)replay.ops, replay.ours_seconds_per_op * 1e6, replay.seconds_per_op * 1e6,
      ratio);
  std::printf(
      "bind cost: the renderer's own figure over the replay's bare one (other process, other moment on a "
      "shared machine): %.3f\n",
      ratio_in_run);
  std::printf(
      "bind cost: raw level-0 pages never written, same batch sizes %.2f us/page (ratio against it %.3f; "
      "not the same operation: see raw_replay_seconds_per_op)\n",
      raw_sizes * 1e6, ours > 0 && raw_sizes > 0 ? ours / raw_sizes : -1.0);

  // ---- pop-in (seed 000 Fig. 7) ----
  const uint64_t n_pop = quick ? 12 : 16;
  double popin[2] = {0, 0};
  for (int blend = 0; blend < 2; ++blend) {
    const fs::path out = c.work / (blend ? "popin_blend" : "popin_direct");
    auto sets = with(big);
    sets.push_back("render.frames=" + std::to_string(n_pop));
    sets.push_back("render.write_every_frames=1");
    sets.push_back(std::string("stream.colormap_blend=") + (blend ? "true" : "false"));
    if (render(c, scene, out, sets) != 0) continue;
    Image prev, cur;
    std::printf("pop-in %s: MSE frame i-1 -> i:", blend ? "blend " : "direct");
    for (uint64_t i = 0; i < n_pop; ++i) {
      if (!load_png(frame_file(out, i), cur)) break;
      if (i > 0) std::printf(" %.1f", mse(prev, cur));
      if (i > 0) popin[blend] = std::max(popin[blend], mse(prev, cur));
      prev = std::move(cur);
      cur = Image{};
    }
    std::printf("\n");
  }
  std::printf("pop-in: max MSE between consecutive frames over %llu frames: direct %.2f, Eq. 8 blend %.2f (%.1f %%)\n",
              (unsigned long long)n_pop, popin[0], popin[1],
              popin[0] > 0 ? 100.0 * (popin[1] - popin[0]) / popin[0] : 0.0);

  // ---- startup: 1 K vs 1 M textures, same view ----
  // Two comparisons, both from the 1 M scene's first keyframe. (a) Same view: the 1 M city with only 1 K
  // textures (derive_texture_subset: every mesh, the same picture's geometry) against itself with its 1 M
  // textures; only the texture count differs, which is what start-up must not depend on (seed 000 §3.5-3.6:
  // no preprocessing of textures). This is startup_ratio_1m_vs_1k. (b) Two cities: a generated 1 K-texture
  // city against the 1 M one; from the same pose the big city shows far more meshes, so (b) also counts
  // geometry the view really draws. Each scene gets one untimed warm-up run (page cache, the renderer's
  // first build of mesh_index.bin where the scene lacks it), then the fastest of kStartupRuns timed runs.
  constexpr int kStartupRuns = 3;
  const fs::path scale1m = args.scene_1m;
  double startup_ratio = -1;
  if (fs::exists(scale1m / "scene.json")) {
    const fs::path pose = static_path(c, scale1m / "camera_path.txt", "startup_pose.txt");
    auto sets = with({"render.frames=1", "render.camera_path=" + pose.string(), "render.write_every_frames=0"});
    const fs::path same_view_1k = c.work / "scale1m_1k_textures";
    if (Status st = derive_texture_subset(scale1m, same_view_1k, 1000); !st) {
      std::fprintf(stderr, "cache bench: %s\n", st.error().message.c_str());
      return 1;
    }
    const std::array<std::pair<const char*, fs::path>, 3> scenes{
        {{"1m", scale1m}, {"1m_geometry_1k_textures", same_view_1k}, {"1k_city", scene1k}}};
    std::array<double, 3> best{1e30, 1e30, 1e30};
    bool ok = true;
    for (int run = -1; run < kStartupRuns && ok; ++run) {
      for (size_t k = 0; k < scenes.size() && ok; ++k) {
        double t = 0;
        ok = render(c, scenes[k].second, c.work / (std::string("startup_") + scenes[k].first), sets, &t) == 0;
        if (run >= 0) best[k] = std::min(best[k], t);
      }
    }
    if (ok && best[1] > 0) startup_ratio = best[0] / best[1];
    std::printf(
        "startup (a) same view: start to first frame (process wall time, frames = 1, fastest of %d): "
        "1 M city with 1 K textures %.3f s, with its 1 M textures %.3f s, ratio %.2f\n",
        kStartupRuns, best[1], best[0], startup_ratio);
    std::printf(
        "startup (b) two cities, same pose: 1 K-texture city %.3f s, 1 M-texture city %.3f s, ratio %.2f "
        "(the 1 M city shows far more meshes from that pose)\n",
        best[2], best[0], best[2] > 0 ? best[0] / best[2] : -1.0);
    // Stage by stage (the renderer's summary.json of the last timed run): which stages grow.
    std::array<nlohmann::json, 3> st;
    std::array<double, 3> first{};
    for (size_t k = 0; k < scenes.size(); ++k) {
      const auto sj = read_json(c.work / (std::string("startup_") + scenes[k].first) / "summary.json");
      st[k] = sj.value("startup_seconds", nlohmann::json::object());
      first[k] = sj.value("frame_latency_ms", nlohmann::json::object()).value("max", 0.0) / 1000.0;
    }
    std::printf("startup: %-20s %12s %12s %12s\n", "stage", "1M geo 1K tx", "1M (s)", "1K city (s)");
    for (const char* stage : {"scene_load", "vulkan", "texture_cache", "scene_gpu_upload", "passes_and_shaders",
                              "broad_phase_tree", "stream_client"}) {
      std::printf("startup: %-20s %12.4f %12.4f %12.4f\n", stage, st[1].value(stage, 0.0), st[0].value(stage, 0.0),
                  st[2].value(stage, 0.0));
    }
    std::printf("startup: %-20s %12.4f %12.4f %12.4f\n", "first_frame", first[1], first[0], first[2]);
  } else {
    std::printf("startup: %s not found: skipped (make it with: texstream-gen --out %s --textures 1000000 --seed 1)\n",
                scale1m.c_str(), scale1m.c_str());
  }

  if (!args.keep) {
    std::error_code ec;
    fs::remove_all(c.work, ec);
  } else {
    std::printf("outputs kept in %s\n", c.work.c_str());
  }
  Summary()
      .add("converged_psnr_db", converged_psnr)
      .add("budget_exceeded_frames", static_cast<double>(exceeded))
      .add("bind_cost_ratio", ratio)
      .add("popin_mse_direct", popin[0])
      .add("popin_mse_blend", popin[1])
      .add("startup_ratio_1m_vs_1k", startup_ratio)
      .add("fit_evictions", static_cast<double>(fit_evictions))
      .add("fill_at_first_eviction", fill_at_first_eviction)
      .add("addressable_vs_budget", addressable_vs_budget)
      .print();
  return converged_psnr >= 45 && exceeded == 0 && validation == 0 && thrash_rc == 0 ? 0 : 1;
}

}  // namespace

std::function<int()> define_cache(CLI::App& app) {
  auto a = std::make_shared<CacheArgs>();
  app.add_flag("--quick", a->quick, "the short run");
  app.add_option("--device", a->device, "lavapipe or gpu: the profile in config/");
  app.add_option("--scene-1m", a->scene_1m, "the 1M-texture scene of the start-up phase (skipped if absent)");
  app.add_flag("--keep", a->keep, "keep the work folder");
  return [a] { return run_cache(*a); };
}

TEXSTREAM_BENCH_COMMAND(cache, "sparse texture cache: convergence, budget, bind cost, pop-in, startup", define_cache);

}  // namespace texstream::bench
