#pragma once
// The scene as the renderer reads it (common/scene_format.hpp): manifest, meshes, texture table and the City
// Colormap (seed 000 §3.7), checked against each other.
#include <cstdint>
#include <filesystem>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/completion_check.hpp"

namespace texstream::render {

struct SceneData {
  std::filesystem::path dir;
  scene::Manifest manifest;
  scene::MeshData meshes;
  std::vector<scene::TextureRecord> textures;
  std::vector<uint32_t> colormap;  // RGBA8 sRGB, one per texture

  // Reads and cross-checks everything; errors name the file and the record.
  static Result<SceneData> load(const std::filesystem::path& dir);
  // The texture table in the form StreamClient and TextureStates take.
  std::vector<TextureShape> shapes() const;
};

}  // namespace texstream::render
