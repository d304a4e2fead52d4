// texstream-gen: writes a procedural city scene (see scene_generator.hpp and common/scene_format.hpp).
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <thread>

#include "atlas_builder.hpp"
#include "scene_generator.hpp"
#include "texstream/common/progress_bar.hpp"

int main(int argc, char** argv) {
  using namespace texstream;
  namespace fs = std::filesystem;
  gen::GeneratorOptions opt;
  std::string format = "bc1";
  std::vector<double> origin;
  CLI::App app{
      "texstream-gen: writes a procedural city scene (meshes, one DDS texture per mesh with a full mip "
      "chain, City Colormap, default camera path)"};
  app.add_option("--out", opt.out, "Scene folder to write")->required();
  app.add_option("--textures", opt.texture_count, "Number of textures (= meshes), exactly")
      ->required()
      ->check(CLI::Range(uint64_t{1}, uint64_t{0xffffffffu}));
  app.add_option("--seed", opt.seed, "Random seed: the same seed gives byte-identical files")->required();
  app.add_option("--format", format,
                 "Texel format of the textures; mixed: each texture BC1, BC3 or RGBA8 (5:2:1), drawn from the seed")
      ->check(CLI::IsMember({"rgba8", "bc1", "bc3", "mixed"}))
      ->capture_default_str();
  app.add_option("--threads", opt.threads, "Worker threads (default: all cores)")->check(CLI::Range(1u, 1024u));
  app.add_option("--origin", origin,
                 "Map coordinates X Y of the city centre, metres (default: 392000 5820000, "
                 "UTM 33N Berlin)")
      ->expected(2);
  app.add_flag("--force", opt.force, "Write into a non-empty folder, replacing a previous scene there");
  uint32_t atlas_px = 0;
  double atlas_cell_m = 100;
  app.add_option("--atlas", atlas_px,
                 "Pack the textures of nearby, similarly oriented meshes into atlases of at most this many texels a "
                 "side (seed 000 §3.1; 512 as the seed's Berlin (atlas)); 0: one texture per mesh")
      ->check(CLI::Range(0u, 16384u));
  app.add_option("--atlas-cell-m", atlas_cell_m, "With --atlas: grid cell side in metres")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  std::string ground = "meshes";
  app.add_option("--ground", ground,
                 "The blocks' grounds: one textured mesh each (meshes), or the whole city's ground as one huge "
                 "texture in pages, ground.tspages (pages; BC1, or RGBA8 with --format rgba8)")
      ->check(CLI::IsMember({"meshes", "pages"}))
      ->capture_default_str();
  app.add_option("--ground-texel-m", opt.ground_texel_m,
                 "With --ground pages: metres per texel of the ground's finest level, rounded to a whole number of "
                 "texels per 120 m block (default: 0.25, coarser where the image would pass 16384 texels a side)")
      ->check(CLI::PositiveNumber);
  CLI11_PARSE(app, argc, argv);
  opt.ground = ground == "pages" ? gen::GroundMode::kPages : gen::GroundMode::kMeshes;
  if (opt.ground_texel_m != 0 && opt.ground != gen::GroundMode::kPages) {
    std::fprintf(stderr, "texstream-gen: error: --ground-texel-m: only with --ground pages\n");
    return 2;
  }
  if (opt.ground == gen::GroundMode::kPages && atlas_px) {
    std::fprintf(stderr, "texstream-gen: error: --ground pages: not with --atlas (texstream-atlas keeps no ground)\n");
    return 2;
  }
  opt.mixed_formats = format == "mixed";
  if (!opt.mixed_formats) opt.format = *texel_format_from_string(format);
  if (origin.size() == 2) {
    opt.origin[0] = origin[0];
    opt.origin[1] = origin[1];
  }

  const bool show_progress = ::isatty(STDERR_FILENO) || opt.texture_count >= 10000;
  ProgressBar bar;
  gen::ProgressFn progress;
  if (show_progress) progress = [&bar](uint64_t done, uint64_t total) { bar.update(done, total); };
  ProgressBar ground_rows("ground rows"), ground_pages("ground pages");
  gen::GroundProgressFn ground_progress;
  if (show_progress)
    ground_progress = [&](gen::GroundPhase phase, uint64_t done, uint64_t total) {
      (phase == gen::GroundPhase::kPaint ? ground_rows : ground_pages).update(done, total);
    };

  const auto start = std::chrono::steady_clock::now();
  // --atlas: the city is generated beside --out first, then packed into --out (texstream-atlas's engine).
  const fs::path out = opt.out;
  if (atlas_px) {
    std::error_code ec;
    if (fs::exists(out, ec) && !opt.force && !fs::is_empty(out, ec)) {
      std::fprintf(stderr, "texstream-gen: error: %s: exists and is not empty (--force replaces it)\n", out.c_str());
      return 1;
    }
    const fs::path abs = fs::absolute(out).lexically_normal();
    std::string name(1, '.');
    name += abs.filename().string();
    name += ".gen-";
    name += std::to_string(::getpid());
    opt.out = abs.parent_path() / name;
    opt.force = true;
  }
  auto stats = gen::generate_scene(opt, progress, ground_progress);
  if (!stats) {
    std::fprintf(stderr, "texstream-gen: error: %s\n", stats.error().message.c_str());
    return 1;
  }
  if (atlas_px) {
    atlas::AtlasOptions ao;
    ao.in = opt.out;
    ao.out = out;
    ao.atlas_px = atlas_px;
    ao.cell_m = atlas_cell_m;
    ao.threads = opt.threads;
    ao.force = true;
    auto packed = atlas::build_atlases(ao, show_progress ? atlas::AtlasProgress(progress) : atlas::AtlasProgress{});
    std::error_code ec;
    fs::remove_all(opt.out, ec);
    if (!packed) {
      std::fprintf(stderr, "texstream-gen: error: %s\n", packed.error().message.c_str());
      return 1;
    }
    std::printf(
        "atlases: %llu textures -> %llu (%llu atlases of at most %u px holding %llu textures), fill %.1f %%, "
        "texture files %.1f MB -> %.1f MB\n",
        static_cast<unsigned long long>(packed->textures_in), static_cast<unsigned long long>(packed->textures_out),
        static_cast<unsigned long long>(packed->atlases), atlas_px,
        static_cast<unsigned long long>(packed->textures_packed),
        packed->atlas_bytes
            ? 100.0 * static_cast<double>(packed->texel_bytes_in) / static_cast<double>(packed->atlas_bytes)
            : 0.0,
        static_cast<double>(packed->file_bytes_in) / 1e6, static_cast<double>(packed->file_bytes_out) / 1e6);
    opt.out = out;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const unsigned threads = opt.threads != 0 ? opt.threads : std::max(1u, std::thread::hardware_concurrency());

  std::printf("texture extents (per side):\n");
  uint64_t sides = 0;
  for (uint64_t c : stats->side_histogram) sides += c;
  for (size_t k = 0; k < stats->side_histogram.size(); ++k) {
    if (stats->side_histogram[k] == 0) continue;
    const double share = 100.0 * static_cast<double>(stats->side_histogram[k]) / static_cast<double>(sides);
    std::printf("  2^%-2zu %5u  %9llu  %5.1f%%  %.*s\n", k, 1u << k,
                static_cast<unsigned long long>(stats->side_histogram[k]), share, static_cast<int>(share / 2),
                "##################################################");
  }
  std::printf(
      "non-square textures: %.1f%%, average %.1f KB per texture, %.2f triangles per texture\n",
      100.0 * static_cast<double>(stats->textures - stats->square_textures) / static_cast<double>(stats->textures),
      static_cast<double>(stats->texture_bytes) / static_cast<double>(stats->textures) / 1024.0,
      static_cast<double>(stats->triangles) / static_cast<double>(stats->textures));
  std::printf(
      "texstream-gen: %llu textures, %llu meshes, %llu triangles, %.1f MB written to %s in %.2f s "
      "(%.0f textures/s on %u threads, %s)\n",
      static_cast<unsigned long long>(stats->textures), static_cast<unsigned long long>(stats->meshes),
      static_cast<unsigned long long>(stats->triangles), static_cast<double>(stats->bytes_written) / 1e6,
      opt.out.c_str(), seconds, static_cast<double>(stats->textures) / seconds, threads, format.c_str());
  if (stats->ground_width != 0)
    std::printf("ground: %llu block grounds -> %s, %ux%u texels at %.4g m/texel (%s), %llu pages, %.1f MB, %.2f s\n",
                static_cast<unsigned long long>(stats->ground_surfaces), gen::kGroundPagesFile, stats->ground_width,
                stats->ground_height, stats->ground_metres_per_texel,
                std::string(to_string(gen::ground_format(opt))).c_str(),
                static_cast<unsigned long long>(stats->ground_pages), static_cast<double>(stats->ground_bytes) / 1e6,
                stats->ground_seconds);
  return 0;
}
