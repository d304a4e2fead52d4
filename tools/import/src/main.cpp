// texstream-import: a glTF 2.0 / OBJ / Collada / FBX model → a scene folder texstream-render and texstream-server
// read (see scene_builder.hpp and common/scene_format.hpp).
#include <unistd.h>

#include <sys/resource.h>
#include <CLI/CLI.hpp>
#include <cstdio>

#include "model_readers.hpp"
#include "scene_builder.hpp"
#include "texstream/common/progress_bar.hpp"

int main(int argc, char** argv) {
  using namespace texstream;
  import::ImportOptions opt;
  std::filesystem::path input;
  std::vector<double> origin;
  std::string format = "auto", up = "auto";
  CLI::App app{
      "texstream-import: reads a glTF 2.0 (.gltf, .glb), OBJ+MTL or any model Assimp reads (Collada, FBX, ...) and "
      "writes a scene folder for texstream-render: one mesh per (primitive, placement), node transforms and "
      "instancing kept, every image decoded once and baked to a full mip chain in linear light (by default opaque "
      "textures as BC1 and cut-outs as BC3, each texture in its own format; or one format for all), wrap modes and "
      "alpha tests in sampling.bin, the City Colormap from the coarse mip and an orbit camera path. The scene is "
      "written beside --out and renamed into place when complete."};
  app.add_option("file", input, "Model file (.gltf, .glb, .obj, .dae, .fbx, ...)")->required();
  app.add_option("--out", opt.out, "Scene folder to write")->required();
  app.add_option("--origin", origin,
                 "Map position X Y Z (metres; x east, y north, z up) of the file's origin; glTF's y-up is turned "
                 "to z-up first")
      ->expected(3);
  app.add_option("--format", format,
                 "Texel format of the baked textures: auto (each its own: BC1 when opaque, BC3 for alpha-tested "
                 "cut-outs, whose 8-bit alpha keeps their edges), or one for all: bc1 (cut-outs as punch-through), "
                 "bc3 (8-bit alpha, twice the bytes of bc1), rgba8")
      ->check(CLI::IsMember({"auto", "bc1", "bc3", "rgba8"}))
      ->capture_default_str();
  app.add_option("--up", up, "The file's up axis (auto: y, as glTF and most OBJ exporters)")
      ->check(CLI::IsMember({"auto", "y", "z"}))
      ->capture_default_str();
  app.add_option("--max-extent", opt.max_extent,
                 "Largest texture side after baking (px; larger images are scaled down)")
      ->check(CLI::Range(1u, kMaxTextureExtent))
      ->capture_default_str();
  app.add_option("--threads", opt.threads, "Baking threads (default: all cores)")->check(CLI::Range(1u, 1024u));
  app.add_flag("--force", opt.force, "Replace an existing scene folder");
  bool quiet = false;
  app.add_flag("--quiet", quiet, "No progress bar");
  CLI11_PARSE(app, argc, argv);
  if (origin.size() == 3) opt.origin = {origin[0], origin[1], origin[2]};
  if (up != "auto") opt.y_up = up == "y";
  if (format != "auto") opt.format = *texel_format_from_string(format);
  ProgressBar bar("images");
  if (!quiet && ::isatty(STDERR_FILENO))
    opt.progress = [&bar](uint64_t done, uint64_t total) { bar.update(done, total); };

  auto model = import::read_model(input);
  if (!model.ok()) {
    std::fprintf(stderr, "texstream-import: %s\n", model.error().message.c_str());
    return 1;
  }
  std::printf("read %s: %zu primitives, %zu placements, %zu materials, %zu images\n", input.c_str(),
              model->primitives.size(), model->instances.size(), model->materials.size(), model->images.size());
  std::fflush(stdout);
  auto report = import::build_scene(*model, opt);
  if (!report.ok()) {
    std::fprintf(stderr, "texstream-import: %s\n", report.error().message.c_str());
    return 1;
  }
  const import::ImportReport& r = *report;
  rusage ru{};
  ::getrusage(RUSAGE_SELF, &ru);
  std::printf("wrote %s\n", std::filesystem::absolute(opt.out).lexically_normal().c_str());
  std::printf(
      "  meshes     %llu (%llu share another's vertices; %llu turned or scaled by transforms.bin; %llu with "
      "their own transformed copy), %llu triangles\n",
      static_cast<unsigned long long>(r.meshes), static_cast<unsigned long long>(r.shared_meshes),
      static_cast<unsigned long long>(r.transformed_meshes), static_cast<unsigned long long>(r.baked_meshes),
      static_cast<unsigned long long>(r.triangles));
  std::string formats;  // "12 bc1, 3 bc3"
  for (const auto& [f, n] : r.textures_by_format)
    formats += (formats.empty() ? "" : ", ") + std::to_string(n) + " " + std::string(to_string(f));
  std::printf(
      "  textures   %llu: %s (%llu images baked, %llu resized to powers of two, %llu flat base colours, %llu "
      "alpha-tested, %llu repeating), %.1f MB\n",
      static_cast<unsigned long long>(r.textures), formats.c_str(), static_cast<unsigned long long>(r.images_baked),
      static_cast<unsigned long long>(r.resized), static_cast<unsigned long long>(r.flat_textures),
      static_cast<unsigned long long>(r.alpha_tested), static_cast<unsigned long long>(r.repeating),
      static_cast<double>(r.texture_bytes) / 1e6);
  std::printf("  baking     %.2f s, %.1f images/s, peak memory %.0f MB\n", r.bake_seconds,
              r.bake_seconds > 0 ? static_cast<double>(r.images_baked + r.flat_textures) / r.bake_seconds : 0.0,
              static_cast<double>(ru.ru_maxrss) / 1024.0);
  std::printf("  skipped    %zu\n", r.skipped.size());
  for (size_t i = 0; i < r.skipped.size(); ++i) {
    if (i == 20) {
      std::printf("    ... and %zu more\n", r.skipped.size() - 20);
      break;
    }
    std::printf("    %s\n", r.skipped[i].c_str());
  }
  return 0;
}
