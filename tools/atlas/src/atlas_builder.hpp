#pragma once
// Texture atlases for a scene folder (seed 000 §3.1): meshes are grouped by their centre in a uniform grid of
// `cell_m` metres and, within a cell, by the global axis closest to their mean normal (six groups); the textures
// of a cell are packed into square atlases of at most `atlas_px`, in rows of one height (the group's textures
// sorted by height, then width), so every texture sits at a multiple of its own size and each of its levels is
// the atlas's texels at that level; a group's rows continue in the atlas the previous group left. UVs are
// remapped, the City Colormap is each atlas's 1x1 level.
//
// A texture is packed only where that changes nothing it shows: power-of-two sides of 4..atlas_px, BC1, BC3 or
// RGBA8 with its full chain, clamped and opaque (sampling.bin 0), and every UV of its meshes inside [0, 1].
// Other textures keep their files (hard-linked). Levels of an atlas that are whole blocks of one texture are that
// texture's blocks, byte for byte; smaller ones are filtered in linear light from the level above and encoded.
// docs/design/atlas.md.
#include <cstdint>
#include <filesystem>
#include <functional>

#include "texstream/common/result.hpp"

namespace texstream::atlas {

struct AtlasOptions {
  std::filesystem::path in;
  std::filesystem::path out;
  uint32_t atlas_px = 512;  // seed 000 Table 1, Berlin (atlas): 512 x 512
  double cell_m = 100;      // grid cell side, metres
  unsigned threads = 0;     // 0: every core
  bool force = false;       // replace a non-empty `out`
};

struct AtlasStats {
  uint64_t textures_in = 0;
  uint64_t textures_out = 0;  // atlases + textures kept as they were
  uint64_t atlases = 0;
  uint64_t textures_packed = 0;    // textures now inside an atlas
  uint64_t textures_kept = 0;      // textures left as they were
  uint64_t kept_not_eligible = 0;  // of those: size, format, wrap, alpha or UVs (the reasons above)
  uint64_t meshes = 0;
  uint64_t vertex_ranges_copied = 0;  // shared geometry whose users ended in different places
  uint64_t texel_bytes_in = 0;        // level-0 bytes of the packed textures
  uint64_t atlas_bytes = 0;           // level-0 bytes of the atlases (fill = texel_bytes_in / atlas_bytes)
  uint64_t file_bytes_in = 0;         // every texture file before
  uint64_t file_bytes_out = 0;        // and after
  double seconds = 0;
};

using AtlasProgress = std::function<void(uint64_t done, uint64_t total)>;

// Reads the scene at `in` and writes the atlased scene at `out` (a temporary sibling renamed into place, so a
// failure leaves nothing half written). Errors name the file.
Result<AtlasStats> build_atlases(const AtlasOptions& options, const AtlasProgress& progress = {});

}  // namespace texstream::atlas
