// texstream-atlas: a scene folder -> the same scene with the textures of nearby, similarly oriented meshes
// packed into atlases (seed 000 §3.1). docs/design/atlas.md.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>

#include "atlas_builder.hpp"
#include "texstream/common/progress_bar.hpp"

int main(int argc, char** argv) {
  using namespace texstream;
  atlas::AtlasOptions opt;
  bool quiet = false;
  CLI::App app{
      "texstream-atlas: packs the textures of nearby, similarly oriented meshes of a scene into texture atlases "
      "(seed 000 §3.1: a grid of cells, six orientation groups per cell; each texture at a multiple of its size "
      "so its mip levels are the atlas's), UVs remapped; textures that repeat, are alpha-tested, are not a power "
      "of two or larger than an atlas stay as they are"};
  app.add_option("scene", opt.in, "Scene folder to read")->required()->check(CLI::ExistingDirectory);
  app.add_option("--out", opt.out, "Scene folder to write")->required();
  app.add_option("--atlas-px", opt.atlas_px, "Largest atlas side, texels (a power of two)")
      ->capture_default_str()
      ->check(CLI::Range(4u, 16384u));
  app.add_option("--cell-m", opt.cell_m, "Grid cell side, metres: meshes of one cell share atlases")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", opt.threads, "Worker threads (default: all cores)")->check(CLI::Range(1u, 1024u));
  app.add_flag("--force", opt.force, "Replace a non-empty --out");
  app.add_flag("--quiet", quiet, "No progress bar");
  CLI11_PARSE(app, argc, argv);

  ProgressBar bar("textures");
  atlas::AtlasProgress progress;
  if (!quiet && ::isatty(STDERR_FILENO)) progress = [&bar](uint64_t done, uint64_t total) { bar.update(done, total); };
  auto st = atlas::build_atlases(opt, progress);
  if (!st) {
    std::fprintf(stderr, "texstream-atlas: %s\n", st.error().message.c_str());
    return 1;
  }
  std::printf(
      "texstream-atlas: %llu textures -> %llu (%llu atlases holding %llu textures, %llu kept as they were, %llu "
      "of them not packable); atlas fill %.1f %%; %llu shared vertex ranges copied; texture files %.1f MB -> "
      "%.1f MB; %.2f s\n",
      static_cast<unsigned long long>(st->textures_in), static_cast<unsigned long long>(st->textures_out),
      static_cast<unsigned long long>(st->atlases), static_cast<unsigned long long>(st->textures_packed),
      static_cast<unsigned long long>(st->textures_kept), static_cast<unsigned long long>(st->kept_not_eligible),
      st->atlas_bytes ? 100.0 * static_cast<double>(st->texel_bytes_in) / static_cast<double>(st->atlas_bytes) : 0.0,
      static_cast<unsigned long long>(st->vertex_ranges_copied), static_cast<double>(st->file_bytes_in) / 1e6,
      static_cast<double>(st->file_bytes_out) / 1e6, st->seconds);
  return 0;
}
