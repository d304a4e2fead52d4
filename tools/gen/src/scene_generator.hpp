#pragma once
// texstream-gen's engine: lays out the city, writes meshes, texture table and camera path, paints and writes
// every texture in parallel (DDS, full mip chain), then the City Colormap and, last, the manifest, so that a
// scene without scene.json is known to be incomplete.
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::gen {

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
};

// The texel format of texture `id`.
TexelFormat texture_format(const GeneratorOptions& opt, uint32_t id);

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
};

// Called from worker threads (must be thread-safe) with the number of textures finished so far.
using ProgressFn = std::function<void(uint64_t done, uint64_t total)>;

Result<GeneratorStats> generate_scene(const GeneratorOptions& options, const ProgressFn& progress = {});

}  // namespace texstream::gen
