#include "texstream/render/scene/scene_data.hpp"

#include <algorithm>
#include <string>

namespace texstream::render {

namespace {

// The checks both forms make at load/open: counts against the manifest, and what the GPU can address.
Status check_counts(const SceneData& s, size_t mesh_count, size_t vertex_count, size_t texture_count) {
  if (mesh_count != s.manifest.mesh_count || texture_count != s.manifest.texture_count) {
    return make_error(ErrorCode::kCorrupt, (s.dir / "scene.json").string() + ": mesh_count/texture_count (" +
                                               std::to_string(s.manifest.mesh_count) + "/" +
                                               std::to_string(s.manifest.texture_count) +
                                               ") differ from meshes.bin/textures.bin (" + std::to_string(mesh_count) +
                                               "/" + std::to_string(texture_count) + ")");
  }
  // The GPU addresses meshes and textures with 32-bit ids, and vertex offsets are int32 in an indirect draw.
  if (vertex_count > 0x7fffffffull) {
    return make_error(ErrorCode::kUnsupported, (s.dir / "meshes.bin").string() + ": more than 2^31 vertices");
  }
  return ok_status();
}

Status check_texture_id(const SceneData& s, uint32_t mesh, const scene::MeshRecord& m) {
  if (m.texture_id < s.texture_records().size()) return ok_status();
  return make_error(ErrorCode::kCorrupt, (s.dir / "meshes.bin").string() + ": mesh " + std::to_string(mesh) +
                                             " names texture " + std::to_string(m.texture_id) + " of " +
                                             std::to_string(s.texture_records().size()));
}

// scene.json's "ground": its page file's header and index, checked (page_file.hpp names file and field).
Status open_ground(SceneData& s) {
  if (!s.manifest.ground) return ok_status();
  auto file = pages::PageFile::open(s.dir / s.manifest.ground->pages);
  if (!file) {
    return make_error(file.error().code, (s.dir / "scene.json").string() + ": key 'ground': " + file.error().message);
  }
  s.ground_pages = std::make_shared<const pages::PageFile>(std::move(*file));
  return ok_status();
}

}  // namespace

Result<SceneData> SceneData::load(const std::filesystem::path& dir) {
  SceneData s;
  s.dir = dir;
  auto manifest = scene::read_manifest(dir);
  if (!manifest) return manifest.error();
  s.manifest = std::move(*manifest);
  TS_TRY(open_ground(s));
  auto meshes = scene::read_meshes(dir);
  if (!meshes) return meshes.error();
  s.meshes = std::move(*meshes);
  auto textures = scene::read_texture_table(dir);
  if (!textures) return textures.error();
  s.textures = std::move(*textures);
  auto colormap = scene::read_colormap(dir, s.textures.size());
  if (!colormap) return colormap.error();
  s.colormap = std::move(*colormap);
  auto sampling = scene::map_sampling(dir, s.textures.size());
  if (sampling.ok())
    s.sampling.assign(sampling->flags.begin(), sampling->flags.end());
  else if (sampling.error().code != ErrorCode::kNotFound)
    return sampling.error();
  auto transforms = scene::map_transforms(dir, s.meshes.meshes.size());
  if (transforms.ok())
    s.transforms.assign(transforms->transforms.begin(), transforms->transforms.end());
  else if (transforms.error().code != ErrorCode::kNotFound)
    return transforms.error();

  TS_TRY(check_counts(s, s.meshes.meshes.size(), s.meshes.vertices.size(), s.textures.size()));
  for (size_t i = 0; i < s.meshes.meshes.size(); ++i)
    TS_TRY(check_texture_id(s, static_cast<uint32_t>(i), s.meshes.meshes[i]));
  return s;
}

Result<SceneData> SceneData::open(const std::filesystem::path& dir) {
  SceneData s;
  s.dir = dir;
  auto manifest = scene::read_manifest(dir);
  if (!manifest) return manifest.error();
  s.manifest = std::move(*manifest);
  TS_TRY(open_ground(s));
  auto mapped = std::make_shared<Mapped>();
  auto meshes = scene::map_meshes(dir);
  if (!meshes) return meshes.error();
  mapped->meshes = std::move(*meshes);
  auto textures = scene::map_texture_table(dir);
  if (!textures) return textures.error();
  mapped->textures = std::move(*textures);
  auto colormap = scene::map_colormap(dir, mapped->textures.textures.size());
  if (!colormap) return colormap.error();
  mapped->colormap = std::move(*colormap);
  auto sampling = scene::map_sampling(dir, mapped->textures.textures.size());
  if (sampling.ok())
    mapped->sampling = std::move(*sampling);
  else if (sampling.error().code != ErrorCode::kNotFound)
    return sampling.error();
  auto transforms = scene::map_transforms(dir, mapped->meshes.meshes.size());
  if (transforms.ok())
    mapped->transforms = std::move(*transforms);
  else if (transforms.error().code != ErrorCode::kNotFound)
    return transforms.error();
  s.mapped_ = std::move(mapped);
  TS_TRY(check_counts(s, s.mesh_records().size(), s.vertices().size(), s.texture_records().size()));
  return s;
}

std::span<const scene::MeshRecord> SceneData::mesh_records() const {
  return mapped_ ? mapped_->meshes.meshes : std::span<const scene::MeshRecord>(meshes.meshes);
}
std::span<const scene::Vertex> SceneData::vertices() const {
  return mapped_ ? mapped_->meshes.vertices : std::span<const scene::Vertex>(meshes.vertices);
}
std::span<const uint32_t> SceneData::indices() const {
  return mapped_ ? mapped_->meshes.indices : std::span<const uint32_t>(meshes.indices);
}
std::span<const scene::TextureRecord> SceneData::texture_records() const {
  return mapped_ ? mapped_->textures.textures : std::span<const scene::TextureRecord>(textures);
}
std::span<const uint32_t> SceneData::colours() const {
  return mapped_ ? mapped_->colormap.rgba : std::span<const uint32_t>(colormap);
}

std::span<const uint32_t> SceneData::sampling_words() const {
  return mapped_ ? mapped_->sampling.flags : std::span<const uint32_t>(sampling);
}

uint32_t SceneData::sampling_flags(uint32_t id) const {
  const std::span<const uint32_t> flags = sampling_words();
  return id < flags.size() ? flags[id] : 0u;
}

scene::MeshTransform SceneData::mesh_transform(uint32_t id) const {
  const std::span<const scene::MeshTransform> t =
      mapped_ ? mapped_->transforms.transforms : std::span<const scene::MeshTransform>(transforms);
  return id < t.size() ? t[id] : scene::kIdentityTransform;
}

bool SceneData::has_alpha_test() const {
  const std::span<const uint32_t> flags = sampling_words();
  return std::any_of(flags.begin(), flags.end(),
                     [](uint32_t f) { return (f & scene::sampling_flags::kAlphaTest) != 0; });
}

Status SceneData::check_mesh(uint32_t id) const {
  if (!mapped_) return ok_status();
  TS_TRY(mapped_->meshes.check_mesh(id));
  return check_texture_id(*this, id, mapped_->meshes.meshes[id]);
}

Status SceneData::make_loaded() {
  if (!mapped_) return ok_status();
  const auto records = mesh_records();
  for (uint32_t i = 0; i < records.size(); ++i) TS_TRY(check_mesh(i));
  meshes.meshes.assign(records.begin(), records.end());
  meshes.vertices.assign(vertices().begin(), vertices().end());
  meshes.indices.assign(indices().begin(), indices().end());
  textures.assign(texture_records().begin(), texture_records().end());
  colormap.assign(colours().begin(), colours().end());
  sampling.assign(mapped_->sampling.flags.begin(), mapped_->sampling.flags.end());
  transforms.assign(mapped_->transforms.transforms.begin(), mapped_->transforms.transforms.end());
  mapped_.reset();
  return ok_status();
}

std::vector<TextureShape> SceneData::shapes() const {
  const auto records = texture_records();
  std::vector<TextureShape> out;
  out.reserve(records.size());
  for (const auto& t : records) {
    // Both forms validated the format value.
    out.push_back(
        TextureShape{t.width, t.height, t.mip_count, texel_format_from_raw(t.format).value_or(TexelFormat::kRgba8)});
  }
  return out;
}

}  // namespace texstream::render
