#pragma once
// A read model → a scene folder (common/scene_format.hpp): one mesh per (primitive, placement); a placement that
// moves, turns and scales its primitive uniformly shares the primitive's vertices and indices with every other
// such placement (the scene format's instancing, its rotation and scale in transforms.bin), one that mirrors,
// shears or scales it unevenly gets its own transformed copy; one texture per
// (image, base colour, wrap modes, alpha mode), each image decoded once and each texture in its own texel format;
// written to a temporary folder beside the destination and renamed into place, so a failed import leaves no
// half-written scene.
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "import_model.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::import {

struct ImportOptions {
  std::filesystem::path out;
  std::array<double, 3> origin{0, 0, 0};  // map position (x east, y north, z up, metres) of the file's origin
  std::optional<bool> y_up;               // overrides the model's own convention
  std::optional<TexelFormat> format;      // one for every texture; nullopt (auto): texel_format_for each texture
  uint32_t max_extent = 8192;
  unsigned threads = 0;  // 0: every core
  bool force = false;    // replace an existing scene folder
  std::function<void(uint64_t done, uint64_t total)> progress;
};

struct ImportReport {
  uint64_t meshes = 0;
  uint64_t shared_meshes = 0;       // placements drawn from another mesh's vertices
  uint64_t transformed_meshes = 0;  // placements with a rotation or uniform scale in transforms.bin
  uint64_t baked_meshes = 0;        // placements whose mirror, shear or non-uniform scale was applied to a copy
  uint64_t triangles = 0;
  uint64_t textures = 0;
  uint64_t images_baked = 0;   // decoded and encoded (each once)
  uint64_t flat_textures = 0;  // 1x1 base-colour textures (no image, or an image that failed)
  uint64_t alpha_tested = 0;
  uint64_t repeating = 0;      // textures with a repeat or mirrored wrap
  uint64_t resized = 0;        // images scaled to powers of two
  uint64_t texture_bytes = 0;  // DDS bytes written
  // Texture records of each texel format: one entry unless auto gave opaque and alpha-tested ones their own.
  std::map<TexelFormat, uint64_t> textures_by_format;
  double bake_seconds = 0;
  std::vector<std::string> skipped;  // what was not imported, with the reason
};

// The texel format a texture is baked in: `chosen` when there is one, else BC1 when opaque and BC3 when alpha-
// tested (8-bit alpha keeps the coverage-rescaled alpha and the edge texels' colour; docs/design/import.md).
constexpr TexelFormat texel_format_for(std::optional<TexelFormat> chosen, bool alpha_test) {
  if (chosen) return *chosen;
  return alpha_test ? TexelFormat::kBc3 : TexelFormat::kBc1;
}

Result<ImportReport> build_scene(const Model& model, const ImportOptions& options);

}  // namespace texstream::import
