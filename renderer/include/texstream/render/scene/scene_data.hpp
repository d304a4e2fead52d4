#pragma once
// The scene as the renderer reads it (common/scene_format.hpp): manifest, meshes, texture table and the City
// Colormap (seed 000 §3.7), checked against each other.
//
// Two forms, one interface (the span accessors below):
//   loaded  (SceneData::load, or filled by hand in tests): everything in the vectors, every mesh checked;
//   opened  (SceneData::open, texstream-render): meshes.bin, textures.bin and colormap.bin mapped, so opening
//           costs the same for 10^3 and 10^6 meshes. Headers and sizes are checked at once, the texture table
//           record by record (the streaming side copies it anyway); a mesh is checked by check_mesh() when it is
//           first drawn (SceneGpu::make_resident), with the same error naming the file and the mesh.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/page_file.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/protocol/completion_check.hpp"

namespace texstream::render {

struct SceneData {
  std::filesystem::path dir;
  scene::Manifest manifest;
  // The loaded form; empty in the opened form (use the accessors).
  scene::MeshData meshes;
  std::vector<scene::TextureRecord> textures;
  std::vector<uint32_t> colormap;  // RGBA8 sRGB, one per texture
  std::vector<uint32_t> sampling;  // sampling.bin's flags, one per texture, or empty: all clamped and opaque
  std::vector<scene::MeshTransform> transforms;  // transforms.bin, one per mesh, or empty: all identity
  // The ground's page file (header and index only: the pages come from the server), when scene.json has a
  // "ground"; errors name the file.
  std::shared_ptr<const pages::PageFile> ground_pages;

  // Reads and cross-checks everything; errors name the file and the record.
  static Result<SceneData> load(const std::filesystem::path& dir);
  // Maps the files; O(1) in the mesh count apart from the texture table check (see above).
  static Result<SceneData> open(const std::filesystem::path& dir);

  bool is_mapped() const { return mapped_ != nullptr; }
  std::span<const scene::MeshRecord> mesh_records() const;
  std::span<const scene::Vertex> vertices() const;
  std::span<const uint32_t> indices() const;
  std::span<const scene::TextureRecord> texture_records() const;
  std::span<const uint32_t> colours() const;
  // How texture `id` is sampled (scene::sampling_flags: wrap modes, alpha test); 0 without sampling.bin.
  uint32_t sampling_flags(uint32_t id) const;
  // Mesh `id`'s rotation and scale (transforms.bin); the identity without it.
  scene::MeshTransform mesh_transform(uint32_t id) const;
  // Whether any texture is alpha-tested (the depth pre-pass then samples the cache).
  bool has_alpha_test() const;

  // Mesh `id`'s full check (ranges, finite values, indices, its texture id). Loaded scenes were checked by
  // load() (or built by hand): ok at once.
  Status check_mesh(uint32_t id) const;

  // Turns an opened scene into a loaded one (copies every array, checks every mesh): for callers that edit
  // the records (ViewRendererOptions::scene_offset). A loaded scene stays as it is.
  Status make_loaded();

  // The texture table in the form StreamClient and TextureStates take.
  std::vector<TextureShape> shapes() const;

 private:
  // sampling.bin's words in either form (empty without the file).
  std::span<const uint32_t> sampling_words() const;
  struct Mapped {
    scene::MappedMeshes meshes;
    scene::MappedTextureTable textures;
    scene::MappedColormap colormap;
    scene::MappedSampling sampling;      // empty flags when the scene has no sampling.bin
    scene::MappedTransforms transforms;  // empty when the scene has no transforms.bin
  };
  std::shared_ptr<const Mapped> mapped_;  // shared: a SceneData is copied into ViewRenderer by value
};

}  // namespace texstream::render
