// texstream-bench pages: the page heuristics of seed 004 §4 (and seed 002 Eq. 3) measured as the thesis did —
// lock-step over camera motions like its fly-through (holds, a very fast turn that stops at once, slow turns,
// translations, a slow pitch), a fixed number of pages loaded per frame (5 and 10), and every frame compared with
// its reference frame (all pages it needs resident) by RMSE, SSIM and the screen-weighted WSSIM.
//   1. a page file: --file (RGBA8), else texstream-tile's painted ground baked here (RGBA8, 32-texel pages, 3 cm);
//   2. every page read once through the server's PageReader over the local storage tier, the origin's bytes
//      counted: page_read_amp = bytes read ÷ bytes of the pages;
//   3. seams: every frame of the path drawn through pages with all resident against the same frame drawn from an
//      ordinary mipmapped texture (the baked pyramid), largest channel difference (baked file only);
//   4. per configuration and budget: the frames drawn through a bounded page cache (the coarsest three levels
//      locked and loaded, with the first view's pages, as the thesis's runs started), the heuristic choosing
//      the pages of each frame from its needbuffer (the LookAhead camera's too where named).
// The frames are drawn on the CPU through the page table the way the page shader samples (pages_view.hpp).
// --quick: a 4096² ground, 320x180, a third of the path's frames; default 16384², 640x360, the whole path.
// Last line, all at 5 pages per frame: summary: heuristics=N best=NAME (highest mean SSIM)
//   best_vs_random_ssim = (1 - SSIM Random) / (1 - SSIM best), lookahead_gain = the same of HotSpot+NoiseValue
//   over it with the LookAhead camera, extern_uniformity = level spread Intern / Extern (> 1: Extern refines more
//   uniformly), seams_max_abs_diff (0-255: the larger of the CPU's and the GPU's, step 3b), page_read_amp.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <squish.h>

#include "bench_registry.hpp"
#include "page_baker.hpp"
#include "pages_gpu.hpp"
#include "pages_view.hpp"
#include "texstream/render/measure/image_metrics.hpp"
#include "texstream/server/load/page_reader.hpp"
#include "texstream/server/storage/counting_storage.hpp"
#include "texstream/server/storage/posix_storage.hpp"
#include "texstream/stream/page_policy.hpp"

namespace texstream::bench {
namespace {
namespace fs = std::filesystem;
using pages::PageId;

struct PagesBenchOptions {
  bool quick = false;
  fs::path file;
  fs::path out;
  uint32_t ground = 0;  // baked ground side; 0: 4096 quick, 16384 full
  uint32_t page = 32;
  double metres_per_texel = 0.03;
  uint32_t width = 0, height = 0;
  std::string gpu_device = "llvmpipe";  // the GPU seams run's render.device; "none" skips it
};

// Camera motions in the spirit of seed 004 §4.2.1 (its motions 1-15): holds, a very fast turn that stops after
// one frame, slow turns, translations forward and sideways, a fast turn then a stop, a slow pitch.
std::vector<GroundPose> camera_path(const pages::PageGeometry& g, double metres_per_texel, bool quick) {
  const double w_m = g.width * metres_per_texel, h_m = g.height * metres_per_texel;
  GroundPose p{w_m / 2, h_m * 0.12, 6.0, std::numbers::pi / 2, -15.0 * std::numbers::pi / 180};
  std::vector<GroundPose> path{p};
  const double deg = std::numbers::pi / 180;
  auto seg = [&](int frames, double turn_deg, double pitch_deg, double forward_m, double right_m) {
    if (quick) frames = std::max(1, (frames + 2) / 3);
    for (int i = 0; i < frames; ++i) {
      p.yaw += turn_deg * deg;
      p.pitch += pitch_deg * deg;
      p.x += forward_m * std::cos(p.yaw) + right_m * std::sin(p.yaw);
      p.y += forward_m * std::sin(p.yaw) - right_m * std::cos(p.yaw);
      path.push_back(p);
    }
  };
  seg(9, 0, 0, 0, 0);
  seg(1, 45, 0, 0, 0);  // very fast, then stopped
  seg(9, 0, 0, 0, 0);
  seg(24, -1.5, 0, 0, 0);  // slow turn right
  seg(30, 0, 0, 0.4, 0);   // forward
  seg(15, 0, 0, 0, 0.3);   // sideways
  seg(5, -12, 0, 0, 0);    // fast turn right ...
  seg(9, 0, 0, 0, 0);      // ... and a stop
  seg(15, 0, -0.4, 0, 0);  // slow pitch down
  seg(24, 0, 0, 0.8, 0);   // forward, faster
  seg(15, 3, 0, 0, 0);     // turn left
  return path;
}

struct Config {
  std::string name;
  pages::PagePolicyOptions policy;
  // 0: none; 1: seed 004's LookAhead camera (this frame's motion once more); 2: the same, but held at the
  // current view when the turn changed abruptly (the thesis's own remedy for a fast turn that stops, §4.2.4.1).
  int lookahead = 0;
  pages::DiscardRule discard = pages::DiscardRule::kLru;
};

std::vector<Config> configs() {
  using H = pages::PageHeuristic;
  using O = pages::AncestorOrder;
  auto make = [](std::string name, H h, bool noise = false, O order = O::kNeededOnly, bool skipping = false,
                 int lookahead = 0, pages::DiscardRule d = pages::DiscardRule::kLru) {
    Config c;
    c.name = std::move(name);
    c.policy.heuristic = h;
    c.policy.noise_scaling = noise;
    c.policy.order = order;
    c.policy.noise_skipping = skipping;
    c.lookahead = lookahead;
    c.discard = d;
    return c;
  };
  return {make("Random", H::kRandom),
          make("PixelSum", H::kPixelSum),
          make("Distance", H::kDistance),
          make("WeightedPixel", H::kWeightedPixel),
          make("HotSpot", H::kHotSpot),
          make("TexelRatio(p_r)", H::kTexelRatio),
          make("PixelSum+NoiseValue", H::kPixelSum, true),
          make("HotSpot+NoiseValue", H::kHotSpot, true),
          make("HotSpot+NoiseValue+LookAhead", H::kHotSpot, true, O::kNeededOnly, false, 1),
          make("HotSpot+NoiseValue+LookAhead(held)", H::kHotSpot, true, O::kNeededOnly, false, 2),
          make("HotSpot+NoiseValue+LookAhead,p_d", H::kHotSpot, true, O::kNeededOnly, false, 1,
               pages::DiscardRule::kSeed002P_d),
          make("PixelSum,Intern", H::kPixelSum, false, O::kIntern),
          make("PixelSum,Extern", H::kPixelSum, false, O::kExtern),
          make("PixelSum,Extern+NoiseValueSkipping", H::kPixelSum, false, O::kExtern, true)};
}

struct Frame {
  std::vector<GroundSample> samples;
  std::vector<pages::PageNeedSample> needs, lookahead, lookahead_held;
  std::vector<uint32_t> reference;
  std::vector<float> reference_luma;
  pages::HotSpot hotspot;
};

struct Curve {
  std::vector<double> rmse, ssim, wssim, spread;
  uint64_t evictions = 0;
  double mean(const std::vector<double>& v) const {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0 : s / static_cast<double>(v.size());
  }
};

render::RgbaView view_of(const std::vector<uint32_t>& rgba, uint32_t w, uint32_t h) {
  return {std::as_bytes(std::span(rgba)), w, h};
}

int run_pages_bench(const PagesBenchOptions& o) {
  const uint32_t width = o.width ? o.width : (o.quick ? 320 : 640);
  const uint32_t height = o.height ? o.height : (o.quick ? 180 : 360);
  const fs::path out = o.out.empty() ? fs::temp_directory_path() / "texstream_pages_bench" : o.out;
  fs::create_directories(out);
  const double metres_per_texel = o.metres_per_texel;

  // 1. The page file.
  fs::path file = o.file;
  std::vector<tile::LevelImage> pyramid;
  std::unique_ptr<tile::PageSource> ground;
  tile::BakeOptions bake;
  if (file.empty()) {
    const uint32_t side = o.ground ? o.ground : (o.quick ? 4096 : 16384);
    ground = tile::make_painted_ground(side, side, metres_per_texel, 1);
    bake.format = TexelFormat::kRgba8;
    bake.page_texels = o.page;
    bake.border_texels = 4;
    file = out / "ground.tspages";
    auto st = tile::bake_pages(*ground, bake, file);
    if (!st.ok()) {
      std::fprintf(stderr, "pages bench: %s\n", st.error().message.c_str());
      return 1;
    }
    std::printf("baked %ux%u into %s: %u levels, %llu pages, %.2f s\n", side, side, file.c_str(), st->geometry.levels,
                static_cast<unsigned long long>(st->stored_pages), st->seconds);
    auto levels = tile::build_pyramid(*ground, st->geometry);
    if (!levels.ok()) return 1;
    pyramid = std::move(levels.value());
  }

  // 2. Every page through the server's reader, the origin's bytes counted.
  server::PosixStorage posix;
  server::CountingStorage origin(posix);
  auto reader = server::PageReader::open(origin, file.string());
  if (!reader.ok()) {
    std::fprintf(stderr, "pages bench: %s\n", reader.error().message.c_str());
    return 1;
  }
  const pages::PageFile& pf = reader.value()->file();
  const pages::PageGeometry& g = pf.geometry();
  if (g.format != TexelFormat::kRgba8) {
    std::fprintf(stderr, "pages bench: %s is %s; the bench draws RGBA8 pages (texstream-tile --format rgba8)\n",
                 file.c_str(), std::string(to_string(g.format)).c_str());
    return 1;
  }
  std::vector<std::vector<uint32_t>> texels(g.page_slots());
  for (uint64_t s = 0; s < g.page_slots(); ++s) {
    const PageId p = g.page_of_slot(s);
    if (!pf.stored(p)) continue;
    texels[s].resize(g.page_bytes() / 4);
    auto got = reader.value()->read(p, std::as_writable_bytes(std::span(texels[s])));
    if (!got.ok()) {
      std::fprintf(stderr, "pages bench: %s\n", got.error().message.c_str());
      return 1;
    }
  }
  const double read_amp = static_cast<double>(origin.bytes()) / static_cast<double>(pf.stored_pages() * g.page_bytes());
  const PageTexels page_texels = [&](PageId p) { return texels[g.slot(p)].data(); };
  std::printf("mean NoiseValue per level (coarsest first):");
  for (uint32_t l = 0; l < g.levels; ++l) {
    double sum = 0, n = 0;
    for (uint64_t s = pages::PageGeometry::first_slot(l); s < pages::PageGeometry::first_slot(l + 1); ++s)
      if (pf.stored(g.page_of_slot(s))) sum += static_cast<double>(pf.noise(g.page_of_slot(s))), n += 1;
    std::printf(" %.2f", n > 0 ? sum / n : 0.0);
  }
  std::printf("\n");

  // 3. The path, its needbuffers and reference frames; seams against the ordinary mipmapped texture.
  GroundView view;
  view.width = width;
  view.height = height;
  view.metres_per_texel = metres_per_texel;
  const auto path = camera_path(g, metres_per_texel, o.quick);
  pages::PageTable all(g);
  for (uint64_t s = 0; s < g.page_slots(); ++s)
    if (pf.stored(g.page_of_slot(s))) all.set(g.page_of_slot(s), static_cast<uint32_t>(s));
  std::vector<Frame> frames(path.size());
  double seams = pyramid.empty() ? std::nan("") : 0.0;
  size_t max_needed = 0;
  const uint32_t need_step = 2;  // the needbuffer at half the frame's resolution in x and y
  for (size_t f = 0; f < path.size(); ++f) {
    Frame& fr = frames[f];
    fr.samples = cast_ground(view, path[f], g, 1);
    fr.needs = needbuffer(view, path[f], g, need_step);
    const GroundPose& prev = path[f ? f - 1 : 0];
    GroundPose ahead = path[f];  // seed 004 §4.2.4.1: this frame's motion once more
    ahead.x += path[f].x - prev.x, ahead.y += path[f].y - prev.y, ahead.z += path[f].z - prev.z;
    ahead.yaw += path[f].yaw - prev.yaw, ahead.pitch += path[f].pitch - prev.pitch;
    fr.lookahead = needbuffer(view, ahead, g, need_step);
    // The turn's change since the last frame: above 5° per frame the motion is not extrapolated.
    const GroundPose& prev2 = path[f > 1 ? f - 2 : 0];
    const double turn_change = std::fabs((path[f].yaw - prev.yaw) - (prev.yaw - prev2.yaw)) +
                               std::fabs((path[f].pitch - prev.pitch) - (prev.pitch - prev2.pitch));
    fr.lookahead_held = turn_change > 5 * std::numbers::pi / 180 ? fr.needs : fr.lookahead;
    // hotspot_from_turn takes a turn to the right and down as positive; yaw grows to the left, pitch upwards.
    fr.hotspot = pages::hotspot_from_turn(static_cast<float>(prev.yaw - path[f].yaw),
                                          static_cast<float>(prev.pitch - path[f].pitch), 0.01f);
    draw_pages(fr.samples, g, all, page_texels, fr.reference);
    fr.reference_luma = render::luma(view_of(fr.reference, width, height));
    std::set<uint64_t> distinct;
    for (const auto& n : fr.needs) distinct.insert(g.slot(n.page));
    max_needed = std::max(max_needed, distinct.size());
    if (!pyramid.empty()) {
      std::vector<uint32_t> ordinary;
      draw_reference(
          fr.samples, g, [&](uint32_t level, int64_t x, int64_t y) { return pyramid[level].at(x, y, g.wrap); },
          ordinary);
      for (size_t i = 0; i < ordinary.size(); ++i)
        for (int c = 0; c < 4; ++c)
          seams = std::max(
              seams, std::fabs(double((ordinary[i] >> (8 * c)) & 0xff) - double((fr.reference[i] >> (8 * c)) & 0xff)));
    }
  }

  // 3b. The same check on the GPU: texstream-render's page path against its one-texture reference (pages_gpu.hpp).
  double cpu_seams = seams;
  if (o.gpu_device != "none") {
    const GpuSeams gs = gpu_seams(out / "gpu_seams", o.gpu_device, o.quick);
    if (gs.ran) {
      std::printf("seams on the GPU (%s): %llu frames, max |pages - one mipmapped texture| = %.0f; on the CPU: %.0f\n",
                  gs.device.c_str(), static_cast<unsigned long long>(gs.frames), gs.max_abs_diff, cpu_seams);
      seams = std::isnan(seams) ? gs.max_abs_diff : std::max(seams, gs.max_abs_diff);
    } else {
      std::printf("seams on the GPU: not measured (%s); on the CPU: %.0f\n", gs.why.c_str(), cpu_seams);
    }
  }

  // 4. Each configuration at each budget, lock-step.
  const uint32_t locked_levels = std::min(3u, g.levels);
  const uint64_t locked_pages = [&] {
    uint64_t n = 0;
    for (uint64_t s = 0; s < pages::PageGeometry::first_slot(locked_levels); ++s) n += pf.stored(g.page_of_slot(s));
    return n;
  }();
  // Room for the locked levels and about two views' pages: the cache must choose what to discard on the path.
  const auto cache_frames = static_cast<uint32_t>(locked_pages + 2 * max_needed);
  const std::vector<Config> cfgs = configs();
  const std::array<uint32_t, 2> budgets{5, 10};
  std::vector<std::array<Curve, 2>> curves(cfgs.size());
  std::ofstream csv(out / "pages_frames.csv");
  csv << "config,budget,frame,rmse,ssim,wssim,level_spread\n";
  std::printf(
      "page file %s: %ux%u, %u levels of %u+2x%u texels, %llu pages; %zu frames %ux%u; cache %u frames "
      "(%llu locked); needbuffer 1/%u per axis\n",
      file.c_str(), g.width, g.height, g.levels, g.page_texels, g.border_texels,
      static_cast<unsigned long long>(pf.stored_pages()), path.size(), width, height, cache_frames,
      static_cast<unsigned long long>(locked_pages), need_step);
  // One lock-step run per configuration and budget, independent of each other: spread over the cores.
  auto run_one = [&](size_t ci, size_t bi) {
    const Config& cfg = cfgs[ci];
    std::vector<uint32_t> rgba;
    std::vector<float> shown;
    pages::PageFrameCache cache(g, cache_frames, locked_levels, cfg.discard);
    for (uint64_t s = 0; s < pages::PageGeometry::first_slot(locked_levels); ++s)
      if (pf.stored(g.page_of_slot(s))) (void)cache.insert(g.page_of_slot(s), 0);
    for (const auto& n : frames[0].needs) (void)cache.insert(n.page, 0);  // the first view's pages
    Curve& cv = curves[ci][bi];
    for (size_t f = 0; f < frames.size(); ++f) {
      const Frame& fr = frames[f];
      const uint64_t now = f + 1;
      draw_pages(fr.samples, g, cache.table(), page_texels, rgba, &shown);
      const double mse = render::mse_rgb(view_of(rgba, width, height), view_of(fr.reference, width, height));
      // The frame is at least one SSIM window in each direction (checked before the runs).
      const auto map =
          render::ssim_map(render::luma(view_of(rgba, width, height)), fr.reference_luma, width, height).value();
      double ssim = 0;
      for (double v : map) ssim += v;
      ssim /= static_cast<double>(map.size());
      // ExternMipMapOrder's aim (seed 004 §4.3): every spot still short of its level shown at the same level,
      // not some sharp and some blurred: the spread of the shown level over the pixels still short of theirs.
      double sum = 0, sum_sq = 0, n = 0;
      for (size_t i = 0; i < fr.samples.size(); ++i) {
        if (!fr.samples[i].hit || shown[i] < 0) continue;
        const double level = static_cast<double>(shown[i]);
        if (level >= std::ceil(fr.samples[i].level)) continue;
        sum += level, sum_sq += level * level, n += 1;
      }
      cv.rmse.push_back(std::sqrt(mse));
      cv.ssim.push_back(ssim);
      cv.wssim.push_back(render::wssim(map, width, height));
      cv.spread.push_back(n > 0 ? std::sqrt(std::max(0.0, sum_sq / n - (sum / n) * (sum / n))) : 0.0);
      // Pages this frame used stay; then this frame's choice arrives for the next one.
      for (const auto& nd : fr.needs)
        if (auto a = cache.table().available(nd.page)) cache.touch(*a, now);
      std::vector<pages::PageNeedSample> needs = fr.needs;
      if (cfg.lookahead) {
        const auto& ahead = cfg.lookahead == 1 ? fr.lookahead : fr.lookahead_held;
        needs.insert(needs.end(), ahead.begin(), ahead.end());
      }
      for (const auto& c : pages::choose_pages(needs, pf, cache.table(), {}, cfg.policy, fr.hotspot, now, budgets[bi]))
        (void)cache.insert(c.page, now);
    }
    cv.evictions = cache.evictions();
  };
  if (width < render::kSsimWindow || height < render::kSsimWindow) {
    std::fprintf(stderr, "pages bench: %ux%u is smaller than one SSIM window\n", width, height);
    return 1;
  }
  {
    std::atomic<size_t> next{0};
    const size_t runs = cfgs.size() * budgets.size();
    auto work = [&] {
      for (size_t k = next++; k < runs; k = next++) run_one(k / budgets.size(), k % budgets.size());
    };
    std::vector<std::thread> pool;
    for (unsigned t = 1; t < std::max(1u, std::thread::hardware_concurrency()); ++t) pool.emplace_back(work);
    work();
    for (auto& t : pool) t.join();
  }
  for (size_t ci = 0; ci < cfgs.size(); ++ci)
    for (size_t bi = 0; bi < budgets.size(); ++bi) {
      const Curve& cv = curves[ci][bi];
      for (size_t f = 0; f < cv.ssim.size(); ++f)
        csv << cfgs[ci].name << ',' << budgets[bi] << ',' << f << ',' << cv.rmse[f] << ',' << cv.ssim[f] << ','
            << cv.wssim[f] << ',' << cv.spread[f] << '\n';
    }

  for (size_t bi = 0; bi < budgets.size(); ++bi) {
    std::printf(
        "\n%u pages per frame:\n| configuration | RMSE | SSIM | WSSIM | lowest SSIM | level spread | evictions |\n"
        "|---|---:|---:|---:|---:|---:|---:|\n",
        budgets[bi]);
    for (size_t ci = 0; ci < cfgs.size(); ++ci) {
      const Curve& c = curves[ci][bi];
      std::printf("| %s | %.3f | %.4f | %.4f | %.4f | %.3f | %llu |\n", cfgs[ci].name.c_str(), c.mean(c.rmse),
                  c.mean(c.ssim), c.mean(c.wssim), *std::min_element(c.ssim.begin(), c.ssim.end()), c.mean(c.spread),
                  static_cast<unsigned long long>(c.evictions));
    }
  }
  auto index_of = [&](const std::string& name) {
    for (size_t i = 0; i < cfgs.size(); ++i)
      if (cfgs[i].name == name) return i;
    return size_t{0};
  };
  auto best_index = [&] {
    size_t b = 0;
    for (size_t ci = 1; ci < cfgs.size(); ++ci)
      if (curves[ci][0].mean(curves[ci][0].ssim) > curves[b][0].mean(curves[b][0].ssim)) b = ci;
    return b;
  };
  // 5. Seed 002 §5 (Fig. 12): the error under limited bandwidth, uncompressed pages against compressed ones (BC1
  // here, 8:1; the seed's VQ and JPEG), its own policy (p_r, progressive; p_d discard) and our best. The link is a
  // byte budget per frame at 30 frames per second (a token bucket in the path's time: the lock-step equivalent of
  // the slow-storage emulation's bandwidth cap); MSE per colour component over the textured pixels only, against
  // the uncompressed reference frame, as the seed measured.
  std::vector<std::vector<uint32_t>> bc1_texels;
  if (ground) {
    bake.format = TexelFormat::kBc1;
    const fs::path bc1_file = out / "ground_bc1.tspages";
    auto st = tile::bake_pages(*ground, bake, bc1_file);
    auto bc1 = st.ok() ? server::PageReader::open(posix, bc1_file.string())
                       : Result<std::unique_ptr<server::PageReader>>(st.error());
    if (!bc1.ok()) {
      std::fprintf(stderr, "pages bench: %s\n", bc1.error().message.c_str());
      return 1;
    }
    const uint32_t side = g.stored_side();
    std::vector<std::byte> blocks(bc1.value()->file().geometry().page_bytes());
    bc1_texels.resize(g.page_slots());
    for (uint64_t s = 0; s < g.page_slots(); ++s) {
      const PageId p = g.page_of_slot(s);
      if (!pf.stored(p)) continue;
      if (auto got = bc1.value()->read(p, blocks); !got.ok()) {
        std::fprintf(stderr, "pages bench: %s\n", got.error().message.c_str());
        return 1;
      }
      bc1_texels[s].resize(uint64_t{side} * side);
      squish::DecompressImage(reinterpret_cast<squish::u8*>(bc1_texels[s].data()), static_cast<int>(side),
                              static_cast<int>(side), blocks.data(), squish::kDxt1);
    }
  }
  struct Link {
    const char* name;
    double bytes_per_s;
  };
  const std::vector<Link> links =
      o.quick
          ? std::vector<Link>{{"ISDN 16 KB/s", 16e3}, {"T1 193 KB/s", 193e3}, {"1 MB/s", 1e6}}
          : std::vector<Link>{
                {"ISDN 16 KB/s", 16e3}, {"64 KB/s", 64e3}, {"T1 193 KB/s", 193e3}, {"1 MB/s", 1e6}, {"8 MB/s", 8e6}};
  struct Flow {
    std::string policy;
    bool bc1;
    double mse = 0;
    uint64_t pages = 0;
  };
  std::vector<Flow> flows;
  std::ofstream bw_csv(out / "pages_bandwidth.csv");
  bw_csv << "link_bytes_per_s,pages,policy,frame,mse\n";
  for (const Link& link : links)
    for (const bool bc1 : {false, true}) {
      if (bc1 && bc1_texels.empty()) continue;
      for (const std::string& name : {std::string("TexelRatio(p_r)"), cfgs[best_index()].name}) {
        Config cfg = cfgs[index_of(name)];
        if (name == "TexelRatio(p_r)") cfg.discard = pages::DiscardRule::kSeed002P_d;
        const std::vector<std::vector<uint32_t>>& store = bc1 ? bc1_texels : texels;
        const PageTexels fetch = [&](PageId p) { return store[g.slot(p)].data(); };
        const double page_bytes = static_cast<double>(
            mip_bytes(bc1 ? TexelFormat::kBc1 : TexelFormat::kRgba8, Extent2D{g.stored_side(), g.stored_side()}));
        pages::PageFrameCache cache(g, cache_frames, locked_levels, cfg.discard);
        for (uint64_t s = 0; s < pages::PageGeometry::first_slot(locked_levels); ++s)
          if (pf.stored(g.page_of_slot(s))) (void)cache.insert(g.page_of_slot(s), 0);
        Flow flow{name, bc1};
        double bucket = 0, total = 0;
        std::vector<uint32_t> rgba;
        for (size_t f = 0; f < frames.size(); ++f) {
          const Frame& fr = frames[f];
          const uint64_t now = f + 1;
          draw_pages(fr.samples, g, cache.table(), fetch, rgba);
          double err = 0, n = 0;
          for (size_t i = 0; i < rgba.size(); ++i) {
            if (!fr.samples[i].hit) continue;
            for (int c = 0; c < 3; ++c) {
              const double d = double((rgba[i] >> (8 * c)) & 0xff) - double((fr.reference[i] >> (8 * c)) & 0xff);
              err += d * d;
              n += 1;
            }
          }
          const double mse = n > 0 ? err / n : 0.0;
          total += mse;
          bw_csv << link.bytes_per_s << ',' << (bc1 ? "bc1" : "rgba8") << ',' << name << ',' << f << ',' << mse << '\n';
          for (const auto& nd : fr.needs)
            if (auto a = cache.table().available(nd.page)) cache.touch(*a, now);
          bucket = std::min(bucket + link.bytes_per_s / 30.0, 30 * page_bytes);  // at most a second's burst
          std::vector<pages::PageNeedSample> needs = fr.needs;
          if (cfg.lookahead) {
            const auto& ahead = cfg.lookahead == 1 ? fr.lookahead : fr.lookahead_held;
            needs.insert(needs.end(), ahead.begin(), ahead.end());
          }
          const auto budget = static_cast<size_t>(bucket / page_bytes);
          for (const auto& c : pages::choose_pages(needs, pf, cache.table(), {}, cfg.policy, fr.hotspot, now, budget)) {
            (void)cache.insert(c.page, now);
            bucket -= page_bytes;
            ++flow.pages;
          }
        }
        flow.mse = total / static_cast<double>(frames.size());
        flows.push_back(flow);
      }
    }
  std::printf(
      "\nseed 002 Fig. 12: mean MSE per colour component over textured pixels against the uncompressed reference, "
      "30 frames/s\n| link | pages | %s | %s |\n|---|---|---:|---:|\n",
      "TexelRatio(p_r), p_d", cfgs[best_index()].name.c_str());
  for (size_t k = 0; k + 1 < flows.size(); k += 2) {
    const Link& link = links[k / (bc1_texels.empty() ? 2 : 4)];
    std::printf("| %s | %s | %.2f (%llu pages) | %.2f (%llu pages) |\n", link.name, flows[k].bc1 ? "bc1" : "rgba8",
                flows[k].mse, static_cast<unsigned long long>(flows[k].pages), flows[k + 1].mse,
                static_cast<unsigned long long>(flows[k + 1].pages));
  }

  const size_t best = best_index();
  auto ssim_of = [&](const std::string& name) {
    const Curve& c = curves[index_of(name)][0];
    return c.mean(c.ssim);
  };
  auto spread_of = [&](const std::string& name) {
    const Curve& c = curves[index_of(name)][0];
    return c.mean(c.spread);
  };
  // SSIM near 1 hides the differences: ratios are of 1 - SSIM, the structural error (> 1: the second is better).
  auto dissimilarity_ratio = [](double ssim_a, double ssim_b) { return (1 - ssim_a) / std::max(1 - ssim_b, 1e-12); };
  std::printf("\nframes: %s\n", (out / "pages_frames.csv").c_str());
  std::printf(
      "\nsummary: heuristics=%zu best=%s best_vs_random_ssim=%.4g lookahead_gain=%.4g extern_uniformity=%.4g "
      "seams_max_abs_diff=%.4g page_read_amp=%.4g\n",
      cfgs.size(), cfgs[best].name.c_str(), dissimilarity_ratio(ssim_of("Random"), ssim_of(cfgs[best].name)),
      dissimilarity_ratio(ssim_of("HotSpot+NoiseValue"), ssim_of("HotSpot+NoiseValue+LookAhead")),
      spread_of("PixelSum,Intern") / std::max(spread_of("PixelSum,Extern"), 1e-9), seams, read_amp);
  return 0;
}

std::function<int()> define_pages(CLI::App& app) {
  auto o = std::make_shared<PagesBenchOptions>();
  app.add_flag("--quick", o->quick, "the short run: 4096² ground, 320x180, a third of the path");
  app.add_option("--gpu-device", o->gpu_device,
                 "render.device of the GPU seams run (a substring of the Vulkan device name; none: skip it)");
  app.add_option("--file", o->file, "an RGBA8 page file to use instead of baking the painted ground")
      ->check(CLI::ExistingFile);
  app.add_option("--ground", o->ground, "side of the painted ground to bake (default 4096 quick, 16384 full)")
      ->check(CLI::Range(64u, 65536u));
  app.add_option("--page", o->page, "page side of the baked ground, texels")->capture_default_str();
  app.add_option("--metres-per-texel", o->metres_per_texel, "ground resolution of the baked ground")
      ->capture_default_str();
  app.add_option("--width", o->width, "frame width (default 320 quick, 640 full)")->check(CLI::Range(16u, 8192u));
  app.add_option("--height", o->height, "frame height (default 180 quick, 360 full)")->check(CLI::Range(16u, 8192u));
  app.add_option("--out", o->out, "working folder (the baked file, pages_frames.csv)");
  return [o] { return run_pages_bench(*o); };
}

}  // namespace

TEXSTREAM_BENCH_COMMAND(pages, "page heuristics of a huge texture (seeds 002, 004): RMSE/SSIM/WSSIM per budget",
                        define_pages);

}  // namespace texstream::bench
