// texstream-bench import: texstream-import on a glTF with many textures, and what reaches the GPU of it.
//   1. writes a glTF of N quads, each with its own material and its own PNG image (distinct texels, so nothing
//      is baked twice), in a grid on the ground;
//   2. runs texstream-import on it as a user would (a child process): wall time, textures per second and the
//      child's peak resident memory (wait4's ru_maxrss);
//   3. renders the imported scene with render.preload_all (every mip of every texture streamed through the real
//      server into the cache) and compares the bytes the cache uploaded with the mip bytes of the DDS files on
//      disk: 1.0 when every mip reaches the GPU in its own format, undecoded.
// --quick: 10,000 textures of 64 x 64 (within 60 s on 2 cores); default: 10,000 of 256 x 256. --format picks
// the importer's texel format (bc1, bc3, rgba8, or auto: these opaque images come out BC1 either way).
// Last line: summary: textures=N import_s=T textures_per_s=R peak_rss_mb=M upload_vs_disk=U
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "bench_registry.hpp"
#include "bench_util.hpp"
#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"

namespace texstream::bench {
namespace {
namespace fs = std::filesystem;

struct ImportBenchOptions {
  bool quick = false;
  uint32_t textures = 10000;
  uint32_t size = 0;  // 0: 64 with --quick, else 256
  fs::path out;
  unsigned threads = 0;
  std::string format = "bc1";  // texstream-import --format
};

// A small hash: distinct texels per image.
uint32_t mix(uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352dU;
  x ^= x >> 15;
  x *= 0x846ca68bU;
  return x ^ (x >> 16);
}

void write_model(const fs::path& dir, uint32_t n, uint32_t size) {
  fs::create_directories(dir / "images");
  const uint32_t side = static_cast<uint32_t>(std::ceil(std::sqrt(static_cast<double>(n))));
  std::vector<uint8_t> px(size_t{size} * size * 4);
  nlohmann::json images = nlohmann::json::array(), textures = nlohmann::json::array(),
                 materials = nlohmann::json::array(), meshes = nlohmann::json::array(), nodes = nlohmann::json::array();
  for (uint32_t t = 0; t < n; ++t) {
    const uint32_t h = mix(t + 1);
    for (uint32_t y = 0; y < size; ++y)
      for (uint32_t x = 0; x < size; ++x) {
        uint8_t* p = &px[(size_t{y} * size + x) * 4];
        const bool cell = ((x / 8) + (y / 8) + (h & 1)) % 2 == 0;
        p[0] = static_cast<uint8_t>((h >> 8) + x * 255 / size);
        p[1] = static_cast<uint8_t>((h >> 16) + y * 255 / size);
        p[2] = static_cast<uint8_t>(cell ? h >> 24 : 255 - (h >> 24));
        p[3] = 255;
      }
    char name[32];
    std::snprintf(name, sizeof name, "images/t%05u.png", t);
    stbi_write_png((dir / name).c_str(), static_cast<int>(size), static_cast<int>(size), 4, px.data(),
                   static_cast<int>(size * 4));
    images.push_back({{"uri", name}});
    textures.push_back({{"source", t}});
    materials.push_back({{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", t}}}}}});
    nlohmann::json prim = {{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}}, {"indices", 2}, {"material", t}};
    meshes.push_back({{"primitives", nlohmann::json::array({prim})}});
    nodes.push_back({{"mesh", t}, {"translation", {12.0 * (t % side), 0.0, -12.0 * (t / side)}}});
  }
  // One 10 m quad on the ground (y up), shared by every mesh's primitive.
  const float pos[12] = {-5, 0, 5, 5, 0, 5, 5, 0, -5, -5, 0, -5};
  const float uv[8] = {0, 1, 1, 1, 1, 0, 0, 0};
  const uint16_t idx[6] = {0, 1, 2, 0, 2, 3};
  std::ofstream bin(dir / "model.bin", std::ios::binary);
  bin.write(reinterpret_cast<const char*>(pos), sizeof pos);
  bin.write(reinterpret_cast<const char*>(uv), sizeof uv);
  bin.write(reinterpret_cast<const char*>(idx), sizeof idx);
  bin.close();
  nlohmann::json scene_nodes = nlohmann::json::array();
  for (uint32_t t = 0; t < n; ++t) scene_nodes.push_back(t);
  const nlohmann::json gltf = {
      {"asset", {{"version", "2.0"}, {"generator", "texstream-bench import"}}},
      {"scene", 0},
      {"scenes", {{{"nodes", scene_nodes}}}},
      {"nodes", nodes},
      {"meshes", meshes},
      {"materials", materials},
      {"textures", textures},
      {"images", images},
      {"buffers", {{{"uri", "model.bin"}, {"byteLength", sizeof pos + sizeof uv + sizeof idx}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", sizeof pos}},
        {{"buffer", 0}, {"byteOffset", sizeof pos}, {"byteLength", sizeof uv}},
        {{"buffer", 0}, {"byteOffset", sizeof pos + sizeof uv}, {"byteLength", sizeof idx}}}},
      {"accessors",
       {{{"bufferView", 0},
         {"componentType", 5126},
         {"count", 4},
         {"type", "VEC3"},
         {"min", {-5, 0, -5}},
         {"max", {5, 0, 5}}},
        {{"bufferView", 1}, {"componentType", 5126}, {"count", 4}, {"type", "VEC2"}},
        {{"bufferView", 2}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}}};
  std::ofstream(dir / "model.gltf") << gltf.dump();
}

// Runs `argv` as a child; its exit status and peak resident memory (KiB).
std::pair<int, long> run_child(const std::vector<std::string>& args, const fs::path& log) {
  std::fflush(stdout);  // the child must not inherit (and write out again) what we have buffered
  const pid_t pid = ::fork();
  if (pid == 0) {
    std::FILE* f = std::freopen(log.c_str(), "w", stdout);
    (void)f;
    ::dup2(STDOUT_FILENO, STDERR_FILENO);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    std::_Exit(127);
  }
  int status = 0;
  rusage ru{};
  ::wait4(pid, &status, 0, &ru);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status), ru.ru_maxrss};
}

fs::path bin_dir() { return fs::canonical("/proc/self/exe").parent_path(); }

int run_import_bench(const ImportBenchOptions& o) {
  const uint32_t size = o.size ? o.size : (o.quick ? 64 : 256);
  const fs::path root =
      o.out.empty() ? fs::temp_directory_path() / ("texstream_bench_import_" + std::to_string(::getpid())) : o.out;
  fs::remove_all(root);
  fs::create_directories(root);
  std::printf("import bench: %u textures of %ux%u (PNG) to %s, folder %s\n", o.textures, size, size, o.format.c_str(),
              root.c_str());
  std::fflush(stdout);
  const auto w0 = std::chrono::steady_clock::now();
  write_model(root / "model", o.textures, size);
  const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
  std::printf("  wrote the glTF and its images in %.1f s\n", write_s);

  std::vector<std::string> args = {(bin_dir() / "texstream-import").string(),
                                   (root / "model" / "model.gltf").string(),
                                   "--out",
                                   (root / "scene").string(),
                                   "--quiet",
                                   "--format",
                                   o.format};
  if (o.threads) args.insert(args.end(), {"--threads", std::to_string(o.threads)});
  const auto t0 = std::chrono::steady_clock::now();
  const auto [rc, rss_kib] = run_child(args, root / "import.log");
  const double import_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (rc != 0) {
    std::fprintf(stderr, "texstream-import failed (%d): see %s\n", rc, (root / "import.log").c_str());
    return 1;
  }
  std::ifstream log(root / "import.log");
  for (std::string line; std::getline(log, line);) std::printf("  | %s\n", line.c_str());

  // Every mip of every texture through the real server into the cache.
  uint64_t disk_bytes = 0;
  const auto table = scene::read_texture_table(root / "scene");
  if (!table.ok()) return std::fprintf(stderr, "%s\n", table.error().message.c_str()), 1;
  for (const auto& r : *table)
    disk_bytes += mip_chain_offset(static_cast<TexelFormat>(r.format), r.width, r.height, r.mip_count);
  const std::vector<std::string> render = {
      (bin_dir() / "texstream-render").string(),
      "--set",
      "scene.dir=" + (root / "scene").string(),
      "--set",
      "render.preload_all=true",
      "--set",
      "render.frames=2",
      "--set",
      "render.width_px=320",
      "--set",
      "render.height_px=180",
      "--set",
      "cache.memory_bytes=" + std::to_string(std::max<uint64_t>(disk_bytes * 3, 64ull << 20)),
      "--set",
      "render.output_dir=" + (root / "out").string()};
  const auto [rrc, rrss] = run_child(render, root / "render.log");
  (void)rrss;
  double uploaded = 0;
  if (rrc == 0) {
    std::ifstream sj(root / "out" / "summary.json");
    const auto s = nlohmann::json::parse(sj, nullptr, false);
    if (!s.is_discarded()) uploaded = s.value("mb_streamed", 0.0) * 1e6;
  } else {
    std::fprintf(stderr, "texstream-render failed (%d): see %s\n", rrc, (root / "render.log").c_str());
  }
  const double ratio = disk_bytes ? uploaded / static_cast<double>(disk_bytes) : std::nan("");
  std::printf(
      "  import %.2f s (%.0f textures/s on %u cores), peak memory %.0f MB; preload uploaded %.1f MB of %.1f MB "
      "of mips on disk\n",
      import_s, o.textures / import_s, std::thread::hardware_concurrency(), rss_kib / 1024.0, uploaded / 1e6,
      disk_bytes / 1e6);
  if (rc == 0 && rrc == 0 && o.out.empty()) fs::remove_all(root);
  Summary()
      .add("textures", o.textures)
      .add("import_s", import_s)
      .add("textures_per_s", o.textures / import_s)
      .add("peak_rss_mb", rss_kib / 1024.0)
      .add("upload_vs_disk", ratio)
      .print();
  return rrc == 0 ? 0 : 1;
}

std::function<int()> define_import(CLI::App& app) {
  auto o = std::make_shared<ImportBenchOptions>();
  app.add_flag("--quick", o->quick, "10,000 textures of 64 x 64 (within 60 s here)");
  app.add_option("--textures", o->textures, "Textures (each its own image and material)")
      ->check(CLI::Range(1u, 1000000u));
  app.add_option("--size", o->size, "Image side in pixels (default 64 with --quick, else 256)")
      ->check(CLI::Range(1u, 16384u));
  app.add_option("--out", o->out, "Keep the model, scene and logs here (default: a temp folder, removed)");
  app.add_option("--threads", o->threads, "texstream-import --threads (default: all cores)");
  app.add_option("--format", o->format, "texstream-import --format")
      ->check(CLI::IsMember({"bc1", "bc3", "rgba8", "auto"}))
      ->capture_default_str();
  return [o] { return run_import_bench(*o); };
}

}  // namespace

TEXSTREAM_BENCH_COMMAND(import, "texstream-import on a 10 K-texture glTF: time, peak memory, bytes to the GPU",
                        define_import);

}  // namespace texstream::bench
