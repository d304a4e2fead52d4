// texstream-tile: one huge texture -> a page file (common/page_file.hpp; docs/design/pages.md).
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <map>

#include "page_baker.hpp"
#include "texstream/common/progress_bar.hpp"

int main(int argc, char** argv) {
  using namespace texstream;
  tile::BakeOptions opt;
  std::filesystem::path in, out;
  std::string format = "bc1", wrap = "clamp";
  uint32_t paint = 0;
  double metres_per_texel = 0.25;
  uint64_t seed = 1;
  bool quiet = false;
  CLI::App app{
      "texstream-tile: cuts one huge texture into a quadtree of uniform pages with borders (seeds 002 §3.1 and 004 "
      "§3.1): every level, pages outside the image not stored, each page's NoiseValue in the index; one file, one "
      "exact byte range per page"};
  auto* in_opt =
      app.add_option("--in", in, "Image file to bake (PNG, JPEG, TGA, BMP, PSD, HDR, PNM)")->check(CLI::ExistingFile);
  app.add_option("--paint", paint, "Instead of --in: paint an orthophoto-like ground of PAINT x PAINT texels")
      ->excludes(in_opt)
      ->check(CLI::Range(1u, pages::kMaxVirtualExtent));
  app.add_option("--metres-per-texel", metres_per_texel, "Ground resolution of --paint")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--seed", seed, "Seed of --paint")->capture_default_str();
  app.add_option("--out", out, "Page file to write")->required();
  app.add_option("--format", format, "Texel format of the pages")
      ->capture_default_str()
      ->check(CLI::IsMember({"bc1", "bc3", "rgba8"}));
  app.add_option("--page", opt.page_texels, "Page side in texels without the border (a power of two)")
      ->capture_default_str();
  app.add_option("--border", opt.border_texels, "Border texels on each side (a multiple of 4 for bc1, bc3)")
      ->capture_default_str();
  app.add_option("--wrap", wrap, "What the borders hold beyond the image: clamp (its edge), repeat (wrap around)")
      ->capture_default_str()
      ->check(CLI::IsMember({"clamp", "repeat"}));
  app.add_option("--threads", opt.threads, "Worker threads (default: all cores)")->check(CLI::Range(1u, 1024u));
  app.add_flag("--quiet", quiet, "No progress bar");
  CLI11_PARSE(app, argc, argv);
  if (in.empty() && paint == 0) {
    std::fprintf(stderr, "texstream-tile: give --in IMAGE or --paint SIZE\n");
    return 2;
  }
  opt.format = *texel_format_from_string(format);
  opt.wrap = wrap == "repeat" ? pages::PageWrap::kRepeat : pages::PageWrap::kClamp;

  std::unique_ptr<tile::PageSource> source;
  if (!in.empty()) {
    auto src = tile::open_image_source(in);
    if (!src.ok()) {
      std::fprintf(stderr, "texstream-tile: %s\n", src.error().message.c_str());
      return 1;
    }
    source = std::move(src.value());
  } else {
    source = tile::make_painted_ground(paint, paint, metres_per_texel, seed);
  }
  ProgressBar bar("pages");
  tile::BakeProgress progress;
  if (!quiet) progress = [&bar](uint64_t done, uint64_t total) { bar.update(done, total); };
  auto st = tile::bake_pages(*source, opt, out, progress);
  if (!st.ok()) {
    std::fprintf(stderr, "texstream-tile: %s\n", st.error().message.c_str());
    return 1;
  }
  const pages::PageGeometry& g = st->geometry;
  std::printf(
      "texstream-tile: %ux%u %s -> %s: %u levels of %u-texel pages (+%u border), %llu pages stored of %llu in the "
      "quadtree, %.1f MB, mean NoiseValue %.2f, %.2f s (%.0f Mtexel/s), peak level memory %.0f MB\n",
      g.width, g.height, std::string(to_string(g.format)).c_str(), out.c_str(), g.levels, g.page_texels,
      g.border_texels, static_cast<unsigned long long>(st->stored_pages),
      static_cast<unsigned long long>(g.page_slots()), static_cast<double>(st->file_bytes) / 1e6, st->mean_noise,
      st->seconds, static_cast<double>(g.width) * g.height / 1e6 / st->seconds,
      static_cast<double>(st->peak_level_bytes) / 1e6);
  return 0;
}
