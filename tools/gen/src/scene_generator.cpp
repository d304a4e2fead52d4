#include "scene_generator.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "bc1_encoder.hpp"
#include "camera_path_builder.hpp"
#include "city_ground.hpp"
#include "city_layout.hpp"
#include "mip_chain.hpp"
#include "rng.hpp"
#include "texstream/common/mesh_index.hpp"
#include "texstream/common/scene_format.hpp"
#include "texture_painter.hpp"

namespace texstream::gen {

namespace fs = std::filesystem;

namespace {

// Textures a worker claims at once: large enough to keep the shared counter cold, small enough to balance.
constexpr uint64_t kChunk = 16;

Status write_whole_file(const fs::path& path, const void* data, size_t bytes) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return make_error(ErrorCode::kIo, path.string() + ": cannot create: " + std::strerror(errno));
  const auto* p = static_cast<const char*>(data);
  size_t left = bytes;
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string err = std::strerror(errno);
      ::close(fd);
      return make_error(ErrorCode::kIo, path.string() + ": write failed: " + err);
    }
    p += n;
    left -= static_cast<size_t>(n);
  }
  if (::close(fd) != 0) return make_error(ErrorCode::kIo, path.string() + ": close failed: " + std::strerror(errno));
  return ok_status();
}

// An empty folder to write into. With `force`, a previous scene there is removed (manifest first, so a crash
// half-way leaves a folder that is recognisably not a complete scene); other files are left alone.
Status prepare_output(const fs::path& out, bool force) {
  std::error_code ec;
  if (fs::exists(out, ec) && !fs::is_directory(out, ec))
    return make_error(ErrorCode::kInvalidArgument, out.string() + ": exists and is not a folder");
  if (fs::exists(out, ec) && !fs::is_empty(out, ec)) {
    if (!force)
      return make_error(ErrorCode::kInvalidArgument,
                        out.string() + ": folder is not empty (pass --force to overwrite a previous scene)");
    const std::string partial_ground = std::string(kGroundPagesFile) + ".partial";
    for (const char* name : {"scene.json", "meshes.bin", "mesh_index.bin", "textures.bin", "colormap.bin",
                             "camera_path.txt", kGroundPagesFile, partial_ground.c_str()}) {
      fs::remove(out / name, ec);
      if (ec) return make_error(ErrorCode::kIo, (out / name).string() + ": cannot remove: " + ec.message());
    }
    fs::remove_all(out / "textures", ec);
    if (ec) return make_error(ErrorCode::kIo, (out / "textures").string() + ": cannot remove: " + ec.message());
  }
  fs::create_directories(out / "textures", ec);
  if (ec) return make_error(ErrorCode::kIo, out.string() + ": cannot create: " + ec.message());
  return ok_status();
}

scene::MeshData build_meshes(const CityLayout& city, const std::array<double, 3>& origin,
                             std::array<double, 3>& bounds_min, std::array<double, 3>& bounds_max) {
  scene::MeshData d;
  d.meshes.reserve(city.surfaces.size());
  d.vertices.reserve(city.surfaces.size() * 4);
  d.indices.reserve(city.surfaces.size() * 6);
  bounds_min.fill(std::numeric_limits<double>::max());
  bounds_max.fill(std::numeric_limits<double>::lowest());
  for (size_t k = 0; k < city.surfaces.size(); ++k) {
    const Surface& s = city.surfaces[k];
    scene::MeshRecord m{};
    for (int a = 0; a < 3; ++a) {
      m.origin[a] = origin[static_cast<size_t>(a)] + s.corner[a];
      m.bounds_min[a] = std::numeric_limits<float>::max();
      m.bounds_max[a] = std::numeric_limits<float>::lowest();
    }
    const float* u = s.edge_u;
    const float* v = s.edge_v;
    float n[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
    const float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (float& c : n) c /= len;
    const uint32_t g = s.grid;
    m.first_vertex = static_cast<uint32_t>(d.vertices.size());
    m.vertex_count = (g + 1) * (g + 1);
    m.first_index = static_cast<uint32_t>(d.indices.size());
    m.index_count = 6 * g * g;
    m.texture_id = static_cast<uint32_t>(k);
    for (uint32_t j = 0; j <= g; ++j)
      for (uint32_t i = 0; i <= g; ++i) {
        const float fs = static_cast<float>(i) / static_cast<float>(g),
                    ft = static_cast<float>(j) / static_cast<float>(g);
        scene::Vertex vx{};
        for (int a = 0; a < 3; ++a) {
          vx.pos[a] = fs * u[a] + ft * v[a];
          vx.normal[a] = n[a];
          m.bounds_min[a] = std::min(m.bounds_min[a], vx.pos[a]);
          m.bounds_max[a] = std::max(m.bounds_max[a], vx.pos[a]);
        }
        vx.uv[0] = fs;
        vx.uv[1] = 1.0f - ft;
        d.vertices.push_back(vx);
      }
    // Counter-clockwise seen from the side the normal points to.
    for (uint32_t j = 0; j < g; ++j)
      for (uint32_t i = 0; i < g; ++i) {
        const uint32_t a = j * (g + 1) + i, b = a + 1, c = a + g + 2, e = a + g + 1;
        for (uint32_t idx : {a, b, c, a, c, e}) d.indices.push_back(idx);
      }
    for (int a = 0; a < 3; ++a) {
      bounds_min[static_cast<size_t>(a)] =
          std::min(bounds_min[static_cast<size_t>(a)], m.origin[a] + static_cast<double>(m.bounds_min[a]));
      bounds_max[static_cast<size_t>(a)] =
          std::max(bounds_max[static_cast<size_t>(a)], m.origin[a] + static_cast<double>(m.bounds_max[a]));
    }
    d.meshes.push_back(m);
  }
  return d;
}

// What one worker thread owns: reusable buffers and its share of the statistics.
struct WorkerState {
  std::vector<uint32_t> chain;
  std::vector<uint8_t> file;
  uint64_t bytes = 0;
};

}  // namespace

TexelFormat texture_format(const GeneratorOptions& opt, uint32_t id) {
  if (!opt.mixed_formats) return opt.format;
  const uint64_t k = hash3(opt.seed, 0x666f726d6174ull, id) % 8;  // stream "format"
  return k < 5 ? TexelFormat::kBc1 : k < 7 ? TexelFormat::kBc3 : TexelFormat::kRgba8;
}

namespace {

// `paint_id`: the surface's index in the layout, which seeds its painting, so that a texture looks the same whether
// the blocks' grounds are meshes or pages (with pages its id is smaller: the grounds are left out).
Status write_texture(const GeneratorOptions& opt, const Surface& s, uint32_t id, uint32_t paint_id, WorkerState& ws,
                     std::vector<uint32_t>& colormap) {
  const TexelFormat format = texture_format(opt, id);
  const uint32_t w = s.width_px, h = s.height_px, levels = full_mip_count(w, h);
  ws.chain.resize(mip_chain_offset(TexelFormat::kRgba8, w, h, levels) / 4);
  paint_texture(opt.seed, paint_id, s, std::span(ws.chain).first(size_t{w} * h));
  build_mip_chain(w, h, ws.chain);
  colormap[id] = ws.chain.back();  // the 1x1 mip: the texture's average colour (seed 000 §3.7)

  const uint64_t total = scene::dds_file_bytes(format, w, h, levels);
  ws.file.resize(total);
  const auto header = scene::make_dds_header(format, w, h, levels);
  std::memcpy(ws.file.data(), header.data(), header.size());
  if (format == TexelFormat::kRgba8) {
    std::memcpy(ws.file.data() + scene::kDdsHeaderBytes, ws.chain.data(), ws.chain.size() * 4);
  } else {
    uint64_t src = 0;
    for (uint32_t l = 0; l < levels; ++l) {
      const Extent2D e = mip_extent(w, h, l);
      const uint64_t at = scene::dds_mip_offset(format, w, h, l);
      const std::span<uint8_t> out(ws.file.data() + at, mip_bytes(format, e));
      if (format == TexelFormat::kBc3) {
        encode_bc3(ws.chain.data() + src, e.width, e.height, out);
      } else {
        encode_bc1(ws.chain.data() + src, e.width, e.height, out);
      }
      src += uint64_t{e.width} * e.height;
    }
  }
  TS_TRY(write_whole_file(scene::texture_path(opt.out, TextureId{id}), ws.file.data(), ws.file.size()));
  ws.bytes += total;
  return ok_status();
}

// `paint_ids[k]`: texture k's index in the layout; empty: k itself.
Status write_textures(const GeneratorOptions& opt, const CityLayout& city, std::span<const uint32_t> paint_ids,
                      std::vector<uint32_t>& colormap, uint64_t& bytes, const ProgressFn& progress) {
  const uint64_t n = city.surfaces.size();
  const unsigned threads =
      std::max(1u, std::min<unsigned>(opt.threads, static_cast<unsigned>((n + kChunk - 1) / kChunk)));
  std::atomic<uint64_t> next{0};
  std::atomic<uint64_t> done{0};
  std::atomic<bool> failed{false};
  std::mutex error_mutex;
  std::optional<Error> first_error;
  std::vector<WorkerState> states(threads);

  const auto work = [&](WorkerState& ws) {
    while (!failed.load(std::memory_order_relaxed)) {
      // relaxed: the counter only hands out disjoint ranges; the results are published by thread join.
      const uint64_t begin = next.fetch_add(kChunk, std::memory_order_relaxed);
      if (begin >= n) return;
      const uint64_t end = std::min(n, begin + kChunk);
      for (uint64_t id = begin; id < end; ++id) {
        const auto tid = static_cast<uint32_t>(id);
        auto st = write_texture(opt, city.surfaces[id], tid, paint_ids.empty() ? tid : paint_ids[id], ws, colormap);
        if (!st.ok()) {
          std::lock_guard lock(error_mutex);
          if (!first_error) first_error = st.error();
          failed.store(true, std::memory_order_relaxed);
          return;
        }
      }
      const uint64_t finished = done.fetch_add(end - begin, std::memory_order_relaxed) + (end - begin);
      if (progress) progress(finished, n);
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work, std::ref(states[t]));
  work(states[0]);
  for (auto& t : pool) t.join();
  if (first_error) return *first_error;
  for (const auto& ws : states) bytes += ws.bytes;
  return ok_status();
}

// The layout without its blocks' grounds (--ground pages) and, per remaining surface, its index in the layout.
CityLayout without_grounds(const CityLayout& city, std::vector<uint32_t>& paint_ids) {
  CityLayout out;
  out.blocks = city.blocks;
  out.block_pitch_m = city.block_pitch_m;
  out.street_width_m = city.street_width_m;
  out.building_count = city.building_count;
  for (size_t k = 0; k < city.surfaces.size(); ++k) {
    if (city.surfaces[k].kind == SurfaceKind::kGround) continue;
    out.surfaces.push_back(city.surfaces[k]);
    paint_ids.push_back(static_cast<uint32_t>(k));
  }
  return out;
}

}  // namespace

TexelFormat ground_format(const GeneratorOptions& opt) {
  return !opt.mixed_formats && opt.format == TexelFormat::kRgba8 ? TexelFormat::kRgba8 : TexelFormat::kBc1;
}

Result<GeneratorStats> generate_scene(const GeneratorOptions& options, const ProgressFn& progress,
                                      const GroundProgressFn& ground_progress) {
  GeneratorOptions opt = options;
  if (opt.texture_count == 0 || opt.texture_count > std::numeric_limits<uint32_t>::max())
    return make_error(ErrorCode::kInvalidArgument,
                      "--textures: must be in 1.." + std::to_string(std::numeric_limits<uint32_t>::max()));
  if (opt.threads == 0) opt.threads = std::max(1u, std::thread::hardware_concurrency());
  for (double c : opt.origin)
    if (!std::isfinite(c) || std::fabs(c) > 1e8)
      return make_error(ErrorCode::kInvalidArgument, "--origin: coordinates must be finite and within 1e8 m");
  const CityLayout layout = generate_layout(opt.seed, opt.texture_count);
  std::optional<GroundPlan> ground;
  std::vector<uint32_t> paint_ids;  // --ground pages: texture k is layout surface paint_ids[k]
  std::optional<CityLayout> without;
  if (opt.ground == GroundMode::kPages) {
    auto plan = plan_ground(layout, opt.ground_texel_m);
    if (!plan.ok()) return plan.error();
    ground = *plan;
    without = without_grounds(layout, paint_ids);
    if (without->surfaces.empty())
      return make_error(ErrorCode::kInvalidArgument,
                        "--ground pages: the city of " + std::to_string(opt.texture_count) +
                            " textures is one block's ground alone, which leaves no mesh (ask for more textures)");
  }
  // What becomes meshes and textures: the whole layout, or the layout without its grounds.
  const CityLayout& city = without ? *without : layout;
  TS_TRY(prepare_output(opt.out, opt.force));

  GeneratorStats stats;
  stats.textures = city.surfaces.size();
  stats.meshes = city.surfaces.size();
  stats.ground_surfaces = layout.surfaces.size() - city.surfaces.size();

  scene::Manifest manifest;
  manifest.name = "texstream-gen city";
  manifest.seed = opt.seed;
  manifest.mesh_count = stats.meshes;
  manifest.texture_count = stats.textures;
  manifest.texture_format = opt.mixed_formats ? std::nullopt : std::optional<TexelFormat>(opt.format);
  manifest.origin = opt.origin;
  {
    const scene::MeshData meshes = build_meshes(city, opt.origin, manifest.bounds_min, manifest.bounds_max);
    if (ground) {  // the scene's extent includes its ground
      const double lo[3] = {ground->west_m(), ground->south_m(), ground->z_m};
      const double hi[3] = {lo[0] + ground->width() * ground->metres_per_texel,
                            lo[1] + ground->height() * ground->metres_per_texel, ground->z_m};
      for (size_t a = 0; a < 3; ++a) {
        manifest.bounds_min[a] = std::min(manifest.bounds_min[a], opt.origin[a] + lo[a]);
        manifest.bounds_max[a] = std::max(manifest.bounds_max[a], opt.origin[a] + hi[a]);
      }
    }
    stats.vertices = meshes.vertices.size();
    stats.triangles = meshes.indices.size() / 3;
    TS_TRY(scene::write_meshes(opt.out, meshes));
    // The broad phase's tree, built once here so that no renderer start pays for it (mesh_index.hpp); after
    // meshes.bin, whose size and time it is stamped with.
    TS_TRY(scene::write_mesh_index(opt.out, scene::build_mesh_index(meshes.meshes).view()));
  }

  std::vector<scene::TextureRecord> table(city.surfaces.size());
  for (size_t k = 0; k < table.size(); ++k) {
    const Surface& s = city.surfaces[k];
    table[k] = {s.width_px, s.height_px, full_mip_count(s.width_px, s.height_px),
                static_cast<uint32_t>(texture_format(opt, static_cast<uint32_t>(k)))};
    stats.side_histogram[floor_log2(s.width_px)]++;
    stats.side_histogram[floor_log2(s.height_px)]++;
    stats.max_side_histogram[floor_log2(std::max(s.width_px, s.height_px))]++;
    if (s.width_px == s.height_px) stats.square_textures++;
  }
  TS_TRY(scene::write_texture_table(opt.out, table));

  const CameraPath path = build_default_camera_path(city, opt.origin.data());
  const std::string path_text =
      "# texstream-gen default fly-through: 4 pauses of 2 s, 4 cuts (seed 000 §4.1)\n" + path.to_text();
  TS_TRY(write_whole_file(opt.out / manifest.camera_path, path_text.data(), path_text.size()));

  // One folder per 4096 textures (scene_format.hpp texture_path), made before the workers start.
  for (uint64_t id = 0; id < stats.textures; id += 4096) {
    std::error_code ec;
    const fs::path dir = scene::texture_path(opt.out, TextureId{static_cast<uint32_t>(id)}).parent_path();
    fs::create_directories(dir, ec);
    if (ec) return make_error(ErrorCode::kIo, dir.string() + ": cannot create: " + ec.message());
  }
  std::vector<uint32_t> colormap(stats.textures);
  TS_TRY(write_textures(opt, city, paint_ids, colormap, stats.texture_bytes, progress));
  if (ground) {
    // The whole layout: each ground is painted as its texture would have been (seeded by its layout index).
    auto baked = bake_city_ground(layout, *ground, opt.seed, ground_format(opt), opt.threads,
                                  opt.out / kGroundPagesFile, ground_progress);
    if (!baked.ok()) return baked.error();
    manifest.ground = scene::GroundPages{
        kGroundPagesFile,
        {opt.origin[0] + ground->west_m(), opt.origin[1] + ground->south_m(), opt.origin[2] + ground->z_m},
        ground->metres_per_texel};
    stats.ground_width = ground->width();
    stats.ground_height = ground->height();
    stats.ground_metres_per_texel = ground->metres_per_texel;
    stats.ground_pages = baked->stored_pages;
    stats.ground_bytes = baked->file_bytes;
    stats.ground_seconds = baked->seconds;
  }
  TS_TRY(scene::write_colormap(opt.out, colormap));
  TS_TRY(scene::write_manifest(opt.out, manifest));  // last: its presence marks a complete scene

  for (const auto& entry : fs::directory_iterator(opt.out)) {
    std::error_code ec;
    if (entry.is_regular_file(ec)) stats.bytes_written += entry.file_size(ec);
  }
  stats.bytes_written += stats.texture_bytes;
  return stats;
}

}  // namespace texstream::gen
