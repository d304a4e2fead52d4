#pragma once
// The on-disk scene: what texstream-gen writes, the server reads (texture files) and the renderer reads
// (meshes, texture table, colormap). All binary files are little-endian with a magic and a version.
//
//   <scene>/scene.json         manifest: counts, format, origin and bounds (map coordinates, metres)
//   <scene>/meshes.bin         MeshFileHeader, MeshRecord[mesh_count], Vertex[vertex_count], uint32 index[index_count]
//   <scene>/textures.bin       TextureFileHeader, TextureRecord[texture_count]
//   <scene>/colormap.bin       ColormapFileHeader, uint32 RGBA8[texture_count]   (seed 000 §3.7 City Colormap)
//   <scene>/sampling.bin       optional: ColormapFileHeader (magic TSSAMP01), uint32 flags[texture_count], how
//                              each texture is sampled (wrap modes, alpha test; sampling_flags below). Absent:
//                              every texture clamped and opaque (what texstream-gen scenes are)
//   <scene>/transforms.bin     optional: TransformFileHeader, MeshTransform[mesh_count]: a rotation and uniform
//                              scale per mesh, applied to its vertices before its origin (instances of one
//                              geometry placed at any orientation). Absent: every mesh unrotated, scale 1
//   <scene>/camera_path.txt    the default fly-through (see camera_path.hpp)
//   <scene>/mesh_index.bin     optional: the broad phase's quadtree over meshes.bin (mesh_index.hpp)
//   <scene>/<ground.pages>     optional: the ground as one huge texture in pages (page_file.hpp), placed by
//                              scene.json's "ground" (GroundPages below); read by the server one page at a time
//   <scene>/textures/XXX/YYYYYYYY.dds   one DDS per texture (RGBA8, BC1 or BC3), all mips finest first, no DX10
//   extension:
//                              mip L of texture T lies at 128 + mip_chain_offset(format, w, h, L)
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "texstream/common/dds.hpp"
#include "texstream/common/ids.hpp"
#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"

namespace texstream::scene {

inline constexpr uint32_t kSceneFormatVersion = 1;
inline constexpr uint64_t kMeshMagic = 0x31304853454d5354ull;       // "TSMESH01"
inline constexpr uint64_t kTextureMagic = 0x3130584554535354ull;    // "TSSTEX01"
inline constexpr uint64_t kColormapMagic = 0x31304d4c4f435354ull;   // "TSCOLM01"
inline constexpr uint64_t kSamplingMagic = 0x3130504d41535354ull;   // "TSSAMP01"
inline constexpr uint64_t kTransformMagic = 0x31304d5246585354ull;  // "TSXFRM01"

struct MeshFileHeader {
  uint64_t magic;
  uint32_t version;
  uint32_t reserved;
  uint64_t mesh_count;
  uint64_t vertex_count;
  uint64_t index_count;
};
static_assert(sizeof(MeshFileHeader) == 40);

// One mesh = one texture (seed 000: "a mesh is a set of primitives with one texture map").
struct MeshRecord {
  double origin[3];     // map coordinates in metres (x east, y north, z up); vertices are relative to it
  float bounds_min[3];  // relative to origin
  float bounds_max[3];
  // A mesh owns its vertex and index ranges, or shares all four fields with another mesh (instancing: the
  // same geometry at another origin). Any other overlap is refused by the renderer when it first draws the
  // mesh (it stores indices absolute and a mesh id per vertex, renderer/src/scene/scene_gpu.cpp).
  uint32_t first_vertex;
  uint32_t vertex_count;
  uint32_t first_index;  // indices are relative to first_vertex
  uint32_t index_count;
  uint32_t texture_id;
  uint32_t reserved;
};
static_assert(sizeof(MeshRecord) == 72);

// transforms.bin: per mesh, how its vertices are turned and scaled before they are placed at its origin:
// position = origin + scale * rotate(rotation, vertex), normal = rotate(rotation, normal). The mesh record's
// bounds are those of the turned, scaled vertices (relative to the origin), so nothing but the vertex shader
// needs the transform. texstream-import writes it for placements that share their geometry.
struct TransformFileHeader {
  uint64_t magic;
  uint32_t version;
  uint32_t reserved;
  uint64_t mesh_count;
};
static_assert(sizeof(TransformFileHeader) == 24);

struct MeshTransform {
  float rotation[4];  // unit quaternion x, y, z, w
  float scale;        // uniform, > 0
};
static_assert(sizeof(MeshTransform) == 20);
inline constexpr MeshTransform kIdentityTransform{{0, 0, 0, 1}, 1};

struct Vertex {
  float pos[3];  // metres, relative to the mesh origin
  float normal[3];
  float uv[2];  // [0,1] over the mesh's texture
};
static_assert(sizeof(Vertex) == 32);

struct TextureFileHeader {
  uint64_t magic;
  uint32_t version;
  uint32_t reserved;
  uint64_t texture_count;
};
static_assert(sizeof(TextureFileHeader) == 24);

struct TextureRecord {
  uint32_t width;
  uint32_t height;
  uint32_t mip_count;  // full chain: full_mip_count(width, height)
  uint32_t format;     // TexelFormat
};
static_assert(sizeof(TextureRecord) == 16);

struct ColormapFileHeader {
  uint64_t magic;
  uint32_t version;
  uint32_t reserved;
  uint64_t texture_count;
};
static_assert(sizeof(ColormapFileHeader) == 24);

// sampling.bin's per-texture word: bits 0-1 wrap along u, 2-3 along v (TextureWrap), bit 4 alpha test, bits
// 8-15 the alpha cutoff in 1/255 (a texel is drawn when alpha >= cutoff). texstream-import writes it.
enum class TextureWrap : uint32_t { kClamp = 0, kRepeat = 1, kMirror = 2 };
namespace sampling_flags {
inline constexpr uint32_t kWrapUShift = 0, kWrapVShift = 2, kWrapMask = 3u, kAlphaTest = 1u << 4, kCutoffShift = 8,
                          kCutoffMask = 0xffu, kKnownBits = 0xff1fu;
}  // namespace sampling_flags
constexpr uint32_t make_sampling_flags(TextureWrap u, TextureWrap v, bool alpha_test, uint32_t cutoff_255) {
  using namespace sampling_flags;
  return static_cast<uint32_t>(u) << kWrapUShift | static_cast<uint32_t>(v) << kWrapVShift |
         (alpha_test ? kAlphaTest : 0u) | (cutoff_255 & kCutoffMask) << kCutoffShift;
}
// What is wrong with a word of sampling.bin, or nullptr.
constexpr const char* sampling_flags_error(uint32_t f) {
  using namespace sampling_flags;
  if ((f & ~kKnownBits) != 0) return "unknown bits set in its sampling flags";
  if (((f >> kWrapUShift) & kWrapMask) > 2 || ((f >> kWrapVShift) & kWrapMask) > 2) return "wrap mode 3 does not exist";
  return nullptr;
}

// scene.json's texture_format when the textures do not share one.
inline constexpr const char* kMixedFormats = "mixed";

// scene.json's optional "ground": one huge texture over the ground plane, streamed as pages (issue 28). Texel
// (u, v) of the page square (u, v in texels of the finest level) lies at map coordinates
// origin + (u, v, 0) * metres_per_texel: u grows east, v grows north, z is the ground's height.
struct GroundPages {
  std::string pages;  // the page file, relative to the scene folder (no "..", not absolute)
  std::array<double, 3> origin{};
  double metres_per_texel = 1;
};

struct Manifest {
  uint32_t format_version = kSceneFormatVersion;
  std::string name;
  uint64_t seed = 0;
  uint64_t mesh_count = 0;
  uint64_t texture_count = 0;
  // The textures' texel format when they all share one; nullopt ("mixed" in the file) when they do not. Each
  // texture record's own format is what the renderer and the server go by.
  std::optional<TexelFormat> texture_format = TexelFormat::kRgba8;
  std::array<double, 3> origin{};      // the city's reference point (map coordinates)
  std::array<double, 3> bounds_min{};  // map coordinates
  std::array<double, 3> bounds_max{};
  std::string camera_path = "camera_path.txt";
  std::optional<GroundPages> ground;
};

struct MeshData {
  std::vector<MeshRecord> meshes;
  std::vector<Vertex> vertices;
  std::vector<uint32_t> indices;
};

Result<Manifest> read_manifest(const std::filesystem::path& dir);
Status write_manifest(const std::filesystem::path& dir, const Manifest& m);

// Readers validate everything: magic, version, counts against the file size, every mesh's ranges against
// the arrays, every texture record's extent and mip count. Errors name the file and the record.
Result<MeshData> read_meshes(const std::filesystem::path& dir);
Result<std::vector<TextureRecord>> read_texture_table(const std::filesystem::path& dir);
Result<std::vector<uint32_t>> read_colormap(const std::filesystem::path& dir, uint64_t expected_count);

Status write_meshes(const std::filesystem::path& dir, const MeshData& data);

// ---- Mapped reading: start-up cost that does not grow with the scene (texstream-render) ----

// A whole file mapped read-only; pages arrive from the page cache as they are touched. Move-only.
class MappedFile {
 public:
  MappedFile() = default;
  MappedFile(MappedFile&& o) noexcept { *this = std::move(o); }
  MappedFile& operator=(MappedFile&& o) noexcept;
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  ~MappedFile();

  // kNotFound when the file is missing; errors name the path.
  static Result<MappedFile> open(const std::filesystem::path& path);
  std::span<const std::byte> bytes() const { return {static_cast<const std::byte*>(data_), size_}; }
  const std::string& what() const { return what_; }

 private:
  void* data_ = nullptr;
  size_t size_ = 0;
  std::string what_;
};

// meshes.bin, mapped. map_meshes() checks what costs O(1): magic, version, counts against the file size.
// check_mesh() is read_meshes()'s per-mesh check (ranges, triangles, finite bounds and vertices, indices in
// range), made when the mesh is first used, with the same message naming the file and the mesh.
struct MappedMeshes {
  MappedFile file;
  std::span<const MeshRecord> meshes;
  std::span<const Vertex> vertices;
  std::span<const uint32_t> indices;

  Status check_mesh(size_t i) const;
};
Result<MappedMeshes> map_meshes(const std::filesystem::path& dir);

// textures.bin, mapped, every record validated as read_texture_table() does (16 bytes a texture: cheap next
// to the table copies the streaming side makes of it).
struct MappedTextureTable {
  MappedFile file;
  std::span<const TextureRecord> textures;
};
Result<MappedTextureTable> map_texture_table(const std::filesystem::path& dir);

// colormap.bin, mapped; header and size checked (a colour has no invalid value).
struct MappedColormap {
  MappedFile file;
  std::span<const uint32_t> rgba;
};
Result<MappedColormap> map_colormap(const std::filesystem::path& dir, uint64_t expected_count);
Status write_texture_table(const std::filesystem::path& dir, std::span<const TextureRecord> textures);

// sampling.bin, mapped; kNotFound when the scene has none (then every texture is clamped and opaque).
struct MappedSampling {
  MappedFile file;
  std::span<const uint32_t> flags;
};
Result<MappedSampling> map_sampling(const std::filesystem::path& dir, uint64_t expected_count);
Status write_sampling(const std::filesystem::path& dir, std::span<const uint32_t> flags);

// transforms.bin, mapped, every entry checked (finite, a unit quaternion within 1e-3, scale > 0); kNotFound when
// the scene has none.
struct MappedTransforms {
  MappedFile file;
  std::span<const MeshTransform> transforms;
};
Result<MappedTransforms> map_transforms(const std::filesystem::path& dir, uint64_t expected_count);
Status write_transforms(const std::filesystem::path& dir, std::span<const MeshTransform> transforms);
Status write_colormap(const std::filesystem::path& dir, std::span<const uint32_t> rgba);

// <dir>/textures/<id>>12 as 3 hex digits>/<id as 8 hex digits>.dds
std::filesystem::path texture_path(const std::filesystem::path& dir, TextureId id);
// The same name as text, made without a std::filesystem::path (which splits its text into components, an
// allocation each): what the server opens per miss (Storage::open_text).
std::string texture_path_text(const std::filesystem::path& dir, TextureId id);

// The DDS header itself (writer and parser) is in dds.hpp.

}  // namespace texstream::scene
