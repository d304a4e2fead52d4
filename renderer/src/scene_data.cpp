#include "texstream/render/scene_data.hpp"

#include <string>

namespace texstream::render {

Result<SceneData> SceneData::load(const std::filesystem::path& dir) {
  SceneData s;
  s.dir = dir;
  auto manifest = scene::read_manifest(dir);
  if (!manifest) return manifest.error();
  s.manifest = std::move(*manifest);
  auto meshes = scene::read_meshes(dir);
  if (!meshes) return meshes.error();
  s.meshes = std::move(*meshes);
  auto textures = scene::read_texture_table(dir);
  if (!textures) return textures.error();
  s.textures = std::move(*textures);
  auto colormap = scene::read_colormap(dir, s.textures.size());
  if (!colormap) return colormap.error();
  s.colormap = std::move(*colormap);

  const std::string meshes_file = (dir / "meshes.bin").string();
  if (s.meshes.meshes.size() != s.manifest.mesh_count || s.textures.size() != s.manifest.texture_count) {
    return make_error(ErrorCode::kCorrupt, (dir / "scene.json").string() + ": mesh_count/texture_count (" +
                                               std::to_string(s.manifest.mesh_count) + "/" +
                                               std::to_string(s.manifest.texture_count) +
                                               ") differ from meshes.bin/textures.bin (" +
                                               std::to_string(s.meshes.meshes.size()) + "/" +
                                               std::to_string(s.textures.size()) + ")");
  }
  // The GPU addresses meshes and textures with 32-bit ids, and vertex offsets are int32 in an indirect draw.
  if (s.meshes.vertices.size() > 0x7fffffffull) {
    return make_error(ErrorCode::kUnsupported, meshes_file + ": more than 2^31 vertices");
  }
  for (size_t i = 0; i < s.meshes.meshes.size(); ++i) {
    if (s.meshes.meshes[i].texture_id >= s.textures.size()) {
      return make_error(ErrorCode::kCorrupt, meshes_file + ": mesh " + std::to_string(i) + " names texture " +
                                                 std::to_string(s.meshes.meshes[i].texture_id) + " of " +
                                                 std::to_string(s.textures.size()));
    }
  }
  return s;
}

std::vector<TextureShape> SceneData::shapes() const {
  std::vector<TextureShape> out;
  out.reserve(textures.size());
  for (const auto& t : textures) {
    // read_texture_table validated the format value.
    out.push_back(TextureShape{t.width, t.height, t.mip_count,
                               texel_format_from_raw(t.format).value_or(TexelFormat::kRgba8)});
  }
  return out;
}

}  // namespace texstream::render
