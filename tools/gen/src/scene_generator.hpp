#pragma once
// texstream-gen's engine: lays out the city, writes meshes, texture table and camera path, paints and writes
// every texture in parallel (DDS, full mip chain), with --ground pages bakes the city's ground into one page file
// (city_ground.hpp), then the City Colormap and, last, the manifest, so that a scene without scene.json is known
// to be incomplete.
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>

#include "city_ground.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::gen {

enum class GroundMode { kMeshes, kPages };
// The page file of --ground pages, in the scene folder.
inline constexpr const char* kGroundPagesFile = "ground.tspages";

struct GeneratorOptions {
  std::filesystem::path out;
  uint64_t texture_count = 0;
  uint64_t seed = 0;
  TexelFormat format = TexelFormat::kBc1;  // seed 000 Table 1: the city data sets are BC1
  // --format mixed: each texture's format drawn from (seed, id), 5/8 BC1, 2/8 BC3, 1/8 RGBA8, as real data mixes
  // them (a scene of several formats for the cache's planes; `format` is then ignored).
  bool mixed_formats = false;
  unsigned threads = 0;  // 0: every core
  // Map coordinates of the city centre at street level: UTM zone 33N, central Berlin (the seed's data set),
  // so that every consumer handles coordinates of 10^5..10^7 m.
  std::array<double, 3> origin{392000.0, 5820000.0, 34.0};
  bool force = false;  // write into a non-empty folder (removing a previous scene there)
  // Where the blocks' grounds go: one textured mesh each (kMeshes), or one huge texture in pages over the whole
  // city (kPages: kGroundPagesFile, scene.json's "ground"; the layout's kGround surfaces are then no meshes).
  GroundMode ground = GroundMode::kMeshes;
  double ground_texel_m = 0;  // kPages: metres per texel of the finest level; 0: city_ground.hpp's default
};

// The texel format of texture `id`.
TexelFormat texture_format(const GeneratorOptions& opt, uint32_t id);
// The texel format of the ground's pages: the scene's when it is BC1 or RGBA8; BC1 for mixed and BC3 scenes (the
// ground is opaque: BC3's alpha block would double its bytes for nothing).
TexelFormat ground_format(const GeneratorOptions& opt);

struct GeneratorStats {
  uint64_t textures = 0;
  uint64_t meshes = 0;
  uint64_t vertices = 0;
  uint64_t triangles = 0;
  uint64_t texture_bytes = 0;  // all DDS files
  uint64_t bytes_written = 0;  // every file of the scene
  uint64_t square_textures = 0;
  std::array<uint64_t, 16> side_histogram{};      // [k]: texture sides (widths and heights) equal to 2^k
  std::array<uint64_t, 16> max_side_histogram{};  // [k]: textures whose larger side is 2^k
  // --ground pages: the blocks' grounds taken out of the meshes, the image and its page file.
  uint64_t ground_surfaces = 0;
  uint32_t ground_width = 0, ground_height = 0;
  double ground_metres_per_texel = 0;
  uint64_t ground_pages = 0;
  uint64_t ground_bytes = 0;
  double ground_seconds = 0;
};

// Called from worker threads (must be thread-safe) with the number of textures finished so far.
using ProgressFn = std::function<void(uint64_t done, uint64_t total)>;

Result<GeneratorStats> generate_scene(const GeneratorOptions& options, const ProgressFn& progress = {},
                                      const GroundProgressFn& ground_progress = {});

}  // namespace texstream::gen
