#include "texstream/common/scene_format.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <system_error>
#include <type_traits>
#include <utility>

#include "texstream/common/mesh_index.hpp"

namespace texstream::scene {

namespace fs = std::filesystem;

namespace {

constexpr const char* kManifestFile = "scene.json";
constexpr const char* kMeshFile = "meshes.bin";
constexpr const char* kTextureFile = "textures.bin";
constexpr const char* kColormapFile = "colormap.bin";
constexpr const char* kSamplingFile = "sampling.bin";
constexpr const char* kTransformFile = "transforms.bin";
constexpr const char* kMeshIndexFile = "mesh_index.bin";

// ---- small binary I/O helpers (stdio: one FILE*, large buffer, explicit error checks) ----

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f != nullptr) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

std::string errno_text() { return std::error_code(errno, std::generic_category()).message(); }

// An input file and its size, opened for reading the header and arrays in order.
struct InputFile {
  FilePtr file;
  uint64_t size = 0;
  std::string what;

  Status read(void* dst, uint64_t bytes, const char* part) {
    if (bytes == 0) return ok_status();
    if (std::fread(dst, 1, bytes, file.get()) != bytes)
      return make_error(ErrorCode::kIo, what + ": short read of the " + part);
    return ok_status();
  }
};

Result<InputFile> open_input(const fs::path& path) {
  InputFile in;
  in.what = path.string();
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (ec) {
    const auto code = ec == std::errc::no_such_file_or_directory ? ErrorCode::kNotFound : ErrorCode::kIo;
    return make_error(code, in.what + ": " + ec.message());
  }
  in.size = size;
  in.file.reset(std::fopen(path.c_str(), "rb"));
  if (!in.file) return make_error(ErrorCode::kIo, in.what + ": cannot open: " + errno_text());
  return in;
}

// Writes a file as <path>.tmp and renames it into place, so that a crash never leaves a half-written file
// under the real name (readers would otherwise find a header whose counts do not match the size).
// `per_process`: <path>.tmp.<pid>, for files that several processes may write at once (mesh_index.bin, which
// renderers starting together on one scene may all build): each writes its own and the last rename wins.
class OutputFile {
 public:
  static Result<OutputFile> create(const fs::path& path, bool per_process = false) {
    OutputFile out;
    out.path_ = path;
    out.tmp_ = path;
    out.tmp_ += per_process ? ".tmp." + std::to_string(::getpid()) : std::string(".tmp");
    out.file_.reset(std::fopen(out.tmp_.c_str(), "wb"));
    if (!out.file_) return make_error(ErrorCode::kIo, out.tmp_.string() + ": cannot create: " + errno_text());
    // One large stdio buffer: the header and each array reach the kernel in few big writes.
    std::setvbuf(out.file_.get(), nullptr, _IOFBF, 1 << 20);
    return out;
  }

  void write(const void* src, uint64_t bytes) {
    if (bytes != 0 && ok_ && std::fwrite(src, 1, bytes, file_.get()) != bytes) ok_ = false;
  }

  Status commit() {
    std::FILE* f = file_.release();
    const bool flushed = ok_ && std::fflush(f) == 0;
    const bool closed = std::fclose(f) == 0;
    if (!flushed || !closed) {
      const std::string err = errno_text();
      std::error_code ec;
      fs::remove(tmp_, ec);
      return make_error(ErrorCode::kIo, tmp_.string() + ": write failed: " + err);
    }
    std::error_code ec;
    fs::rename(tmp_, path_, ec);
    if (ec) return make_error(ErrorCode::kIo, path_.string() + ": cannot rename from .tmp: " + ec.message());
    return ok_status();
  }

 private:
  FilePtr file_;
  fs::path path_;
  fs::path tmp_;
  bool ok_ = true;
};

template <class T>
void write_array(OutputFile& out, std::span<const T> items) {
  static_assert(std::is_trivially_copyable_v<T>);
  out.write(items.data(), items.size_bytes());
}

// Checks magic and version of a binary header; `T` has magic and version fields.
template <class T>
Status check_magic_version(const T& h, uint64_t magic, const std::string& what) {
  if (h.magic != magic)
    return make_error(ErrorCode::kCorrupt, what + ": bad magic (not a texstream file of this kind)");
  if (h.version != kSceneFormatVersion)
    return make_error(ErrorCode::kUnsupported, what + ": version " + std::to_string(h.version) + ", expected " +
                                                   std::to_string(kSceneFormatVersion));
  return ok_status();
}

bool finite3(const float v[3]) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }
bool finite3(const double v[3]) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

// The arrays of meshes.bin, wherever they live (read into vectors or mapped).
struct MeshArrays {
  std::span<const MeshRecord> meshes;
  std::span<const Vertex> vertices;
  std::span<const uint32_t> indices;
};

Status validate_mesh(const MeshArrays& d, size_t i, const std::string& what) {
  const MeshRecord& m = d.meshes[i];
  // The message prefix only on failure: this runs for every mesh (10^6 string builds cost ~0.1 s).
  const auto rec = [&] { return what + ": mesh " + std::to_string(i) + ": "; };
  if (uint64_t{m.first_vertex} + m.vertex_count > d.vertices.size())
    return make_error(ErrorCode::kCorrupt, rec() + "vertex range [" + std::to_string(m.first_vertex) + ", +" +
                                               std::to_string(m.vertex_count) + ") exceeds " +
                                               std::to_string(d.vertices.size()) + " vertices");
  if (uint64_t{m.first_index} + m.index_count > d.indices.size())
    return make_error(ErrorCode::kCorrupt, rec() + "index range [" + std::to_string(m.first_index) + ", +" +
                                               std::to_string(m.index_count) + ") exceeds " +
                                               std::to_string(d.indices.size()) + " indices");
  if (m.index_count % 3 != 0)
    return make_error(ErrorCode::kCorrupt,
                      rec() + "index_count " + std::to_string(m.index_count) + " is not a whole number of triangles");
  if (!finite3(m.origin) || !finite3(m.bounds_min) || !finite3(m.bounds_max))
    return make_error(ErrorCode::kCorrupt, rec() + "origin or bounds not finite");
  for (int a = 0; a < 3; ++a)
    if (m.bounds_min[a] > m.bounds_max[a]) return make_error(ErrorCode::kCorrupt, rec() + "bounds_min > bounds_max");
  for (uint32_t k = 0; k < m.index_count; ++k) {
    const uint32_t idx = d.indices[m.first_index + k];
    if (idx >= m.vertex_count)
      return make_error(ErrorCode::kCorrupt, rec() + "index " + std::to_string(k) + " = " + std::to_string(idx) +
                                                 " is outside its " + std::to_string(m.vertex_count) + " vertices");
  }
  for (uint32_t k = 0; k < m.vertex_count; ++k) {
    const Vertex& v = d.vertices[m.first_vertex + k];
    if (!finite3(v.pos) || !finite3(v.normal) || !std::isfinite(v.uv[0]) || !std::isfinite(v.uv[1]))
      return make_error(ErrorCode::kCorrupt, rec() + "vertex " + std::to_string(k) + " is not finite");
  }
  return ok_status();
}

// meshes.bin's header against the file size (`size` >= sizeof h).
Status check_mesh_header(const MeshFileHeader& h, uint64_t size, const std::string& what) {
  TS_TRY(check_magic_version(h, kMeshMagic, what));
  // Counts are bounded by the file size before any multiplication, so nothing below can overflow.
  const uint64_t body = size - sizeof h;
  if (h.mesh_count > body / sizeof(MeshRecord) || h.vertex_count > body / sizeof(Vertex) ||
      h.index_count > body / sizeof(uint32_t))
    return make_error(ErrorCode::kCorrupt, what + ": counts exceed the file size");
  const uint64_t expected =
      sizeof h + h.mesh_count * sizeof(MeshRecord) + h.vertex_count * sizeof(Vertex) + h.index_count * sizeof(uint32_t);
  if (expected != size)
    return make_error(ErrorCode::kCorrupt, what + ": size " + std::to_string(size) + " bytes, header says " +
                                               std::to_string(expected) + " (truncated or trailing data)");
  if (h.vertex_count > std::numeric_limits<uint32_t>::max() || h.index_count > std::numeric_limits<uint32_t>::max())
    return make_error(ErrorCode::kCorrupt, what + ": vertex or index count exceeds 2^32-1");
  return ok_status();
}

Status check_texture_record(const TextureRecord& r, size_t i, const std::string& what) {
  const auto rec = [&] { return what + ": texture " + std::to_string(i) + ": "; };  // on failure only
  if (!valid_texture_extent(r.width, r.height))
    return make_error(ErrorCode::kCorrupt, rec() + "extent " + std::to_string(r.width) + "x" +
                                               std::to_string(r.height) + " outside 1.." +
                                               std::to_string(kMaxTextureExtent));
  if (r.mip_count != full_mip_count(r.width, r.height))
    return make_error(ErrorCode::kCorrupt, rec() + "mip_count " + std::to_string(r.mip_count) + ", a full chain has " +
                                               std::to_string(full_mip_count(r.width, r.height)));
  if (!texel_format_from_raw(r.format))
    return make_error(ErrorCode::kUnsupported, rec() + "unknown format " + std::to_string(r.format));
  return ok_status();
}

Status check_texture_header(const TextureFileHeader& h, uint64_t size, const std::string& what) {
  TS_TRY(check_magic_version(h, kTextureMagic, what));
  const uint64_t body = size - sizeof h;
  if (h.texture_count > body / sizeof(TextureRecord) || sizeof h + h.texture_count * sizeof(TextureRecord) != size)
    return make_error(ErrorCode::kCorrupt, what + ": size " + std::to_string(size) + " bytes does not hold " +
                                               std::to_string(h.texture_count) + " texture records exactly");
  return ok_status();
}

// colormap.bin and sampling.bin: a header and one uint32 per texture.
Status check_per_texture_header(const ColormapFileHeader& h, uint64_t magic, uint64_t size, uint64_t expected_count,
                                const std::string& what, const char* noun) {
  TS_TRY(check_magic_version(h, magic, what));
  if (h.texture_count != expected_count)
    return make_error(ErrorCode::kCorrupt, what + ": holds " + std::to_string(h.texture_count) + " " + noun +
                                               ", the scene has " + std::to_string(expected_count) + " textures");
  const uint64_t body = size - sizeof h;
  if (h.texture_count > body / sizeof(uint32_t) || sizeof h + h.texture_count * sizeof(uint32_t) != size)
    return make_error(ErrorCode::kCorrupt, what + ": size " + std::to_string(size) + " bytes does not hold " +
                                               std::to_string(h.texture_count) + " " + noun + " exactly");
  return ok_status();
}

Status check_colormap_header(const ColormapFileHeader& h, uint64_t size, uint64_t expected_count,
                             const std::string& what) {
  return check_per_texture_header(h, kColormapMagic, size, expected_count, what, "colours");
}

// The typed array at `offset` of a mapped file (offsets of our formats keep every type aligned, and mmap
// returns page-aligned memory).
template <class T>
std::span<const T> mapped_array(const MappedFile& f, uint64_t offset, uint64_t count) {
  static_assert(std::is_trivially_copyable_v<T>);
  if (count == 0) return {};
  const std::byte* p = f.bytes().data() + offset;
  TS_ASSERT(reinterpret_cast<uintptr_t>(p) % alignof(T) == 0, "misaligned array in %s", f.what().c_str());
  return {reinterpret_cast<const T*>(p), count};
}

// The header of a mapped file, or an error naming it when the file is shorter.
template <class H>
Result<H> mapped_header(const MappedFile& f) {
  H h{};
  if (f.bytes().size() < sizeof h) return make_error(ErrorCode::kCorrupt, f.what() + ": shorter than its header");
  std::memcpy(&h, f.bytes().data(), sizeof h);
  return h;
}

// ---- manifest JSON helpers ----

using json = nlohmann::json;

template <class T>
Status get_field(const json& j, const char* key, T& out, const std::string& what) {
  const auto it = j.find(key);
  if (it == j.end()) return make_error(ErrorCode::kCorrupt, what + ": missing key '" + key + "'");
  // nlohmann would silently wrap a negative number into an unsigned field.
  if constexpr (std::is_unsigned_v<T>) {
    if (!it->is_number_unsigned())
      return make_error(ErrorCode::kCorrupt, what + ": key '" + key + "' must be a non-negative integer");
  }
  try {
    out = it->template get<T>();
  } catch (const json::exception& e) {
    return make_error(ErrorCode::kCorrupt, what + ": key '" + key + "' has the wrong type: " + e.what());
  }
  return ok_status();
}

Status get_vec3(const json& j, const char* key, std::array<double, 3>& out, const std::string& what) {
  std::vector<double> v;
  TS_TRY(get_field(j, key, v, what));
  if (v.size() != 3) return make_error(ErrorCode::kCorrupt, what + ": key '" + key + "' must hold 3 numbers");
  for (double x : v)
    if (!std::isfinite(x)) return make_error(ErrorCode::kCorrupt, what + ": key '" + key + "' is not finite");
  out = {v[0], v[1], v[2]};
  return ok_status();
}

}  // namespace

// ---------------------------------------------------------------- manifest

Result<Manifest> read_manifest(const fs::path& dir) {
  const fs::path path = dir / kManifestFile;
  const std::string what = path.string();
  std::ifstream in(path);
  if (!in) {
    std::error_code ec;
    const bool exists = fs::exists(path, ec);
    return make_error(exists ? ErrorCode::kIo : ErrorCode::kNotFound,
                      what + (exists ? ": cannot open" : ": not found (no scene here, or generation did not finish)"));
  }
  json j;
  try {
    j = json::parse(in);
  } catch (const json::exception& e) {
    return make_error(ErrorCode::kCorrupt, what + ": not valid JSON: " + e.what());
  }
  if (!j.is_object()) return make_error(ErrorCode::kCorrupt, what + ": top level must be an object");

  Manifest m;
  TS_TRY(get_field(j, "format_version", m.format_version, what));
  if (m.format_version != kSceneFormatVersion)
    return make_error(ErrorCode::kUnsupported, what + ": format_version " + std::to_string(m.format_version) +
                                                   ", expected " + std::to_string(kSceneFormatVersion));
  TS_TRY(get_field(j, "name", m.name, what));
  TS_TRY(get_field(j, "seed", m.seed, what));
  TS_TRY(get_field(j, "mesh_count", m.mesh_count, what));
  TS_TRY(get_field(j, "texture_count", m.texture_count, what));
  std::string format;
  TS_TRY(get_field(j, "texture_format", format, what));
  const auto f = texel_format_from_string(format);
  if (!f && format != kMixedFormats)
    return make_error(ErrorCode::kUnsupported, what + ": key 'texture_format': unknown format '" + format + "'");
  m.texture_format = f;
  TS_TRY(get_vec3(j, "origin", m.origin, what));
  TS_TRY(get_vec3(j, "bounds_min", m.bounds_min, what));
  TS_TRY(get_vec3(j, "bounds_max", m.bounds_max, what));
  for (int a = 0; a < 3; ++a)
    if (m.bounds_min[a] > m.bounds_max[a])
      return make_error(ErrorCode::kCorrupt, what + ": bounds_min[" + std::to_string(a) + "] > bounds_max");
  TS_TRY(get_field(j, "camera_path", m.camera_path, what));
  if (const auto g = j.find("ground"); g != j.end()) {
    const std::string gwhat = what + ": key 'ground'";
    if (!g->is_object()) return make_error(ErrorCode::kCorrupt, gwhat + " must be an object");
    GroundPages ground;
    TS_TRY(get_field(*g, "pages", ground.pages, gwhat));
    const fs::path rel(ground.pages);
    const bool escapes = std::any_of(rel.begin(), rel.end(), [](const fs::path& part) { return part == ".."; });
    if (ground.pages.empty() || rel.is_absolute() || escapes)
      return make_error(ErrorCode::kCorrupt,
                        gwhat + ": key 'pages' must be a path inside the scene folder, not '" + ground.pages + "'");
    TS_TRY(get_vec3(*g, "origin", ground.origin, gwhat));
    TS_TRY(get_field(*g, "metres_per_texel", ground.metres_per_texel, gwhat));
    if (!std::isfinite(ground.metres_per_texel) || ground.metres_per_texel <= 0)
      return make_error(ErrorCode::kCorrupt, gwhat + ": key 'metres_per_texel' must be a positive number");
    m.ground = std::move(ground);
  }
  // Texture ids are uint32 on the wire (TextureId) and mesh records index them with uint32.
  if (m.texture_count > std::numeric_limits<uint32_t>::max() || m.mesh_count > std::numeric_limits<uint32_t>::max())
    return make_error(ErrorCode::kCorrupt, what + ": mesh_count or texture_count exceeds 2^32-1");
  return m;
}

Status write_manifest(const fs::path& dir, const Manifest& m) {
  json j;
  j["format_version"] = m.format_version;
  j["name"] = m.name;
  j["seed"] = m.seed;
  j["mesh_count"] = m.mesh_count;
  j["texture_count"] = m.texture_count;
  j["texture_format"] = m.texture_format ? std::string(to_string(*m.texture_format)) : std::string(kMixedFormats);
  j["origin"] = m.origin;
  j["bounds_min"] = m.bounds_min;
  j["bounds_max"] = m.bounds_max;
  j["camera_path"] = m.camera_path;
  if (m.ground) {
    j["ground"] = {
        {"pages", m.ground->pages}, {"origin", m.ground->origin}, {"metres_per_texel", m.ground->metres_per_texel}};
  }
  const std::string text = j.dump(2) + "\n";
  auto out = OutputFile::create(dir / kManifestFile);
  if (!out) return out.error();
  out->write(text.data(), text.size());
  return out->commit();
}

// ---------------------------------------------------------------- meshes

Result<MeshData> read_meshes(const fs::path& dir) {
  auto opened = open_input(dir / kMeshFile);
  if (!opened) return opened.error();
  InputFile& in = *opened;
  MeshFileHeader h{};
  if (in.size < sizeof h) return make_error(ErrorCode::kCorrupt, in.what + ": shorter than its header");
  TS_TRY(in.read(&h, sizeof h, "header"));
  TS_TRY(check_mesh_header(h, in.size, in.what));

  MeshData d;
  d.meshes.resize(h.mesh_count);
  d.vertices.resize(h.vertex_count);
  d.indices.resize(h.index_count);
  TS_TRY(in.read(d.meshes.data(), h.mesh_count * sizeof(MeshRecord), "mesh records"));
  TS_TRY(in.read(d.vertices.data(), h.vertex_count * sizeof(Vertex), "vertices"));
  TS_TRY(in.read(d.indices.data(), h.index_count * sizeof(uint32_t), "indices"));
  const MeshArrays arrays{d.meshes, d.vertices, d.indices};
  for (size_t i = 0; i < d.meshes.size(); ++i) TS_TRY(validate_mesh(arrays, i, in.what));
  return d;
}

Status write_meshes(const fs::path& dir, const MeshData& data) {
  auto out = OutputFile::create(dir / kMeshFile);
  if (!out) return out.error();
  const MeshFileHeader h{kMeshMagic,         kSceneFormatVersion,  0,
                         data.meshes.size(), data.vertices.size(), data.indices.size()};
  out->write(&h, sizeof h);
  write_array(*out, std::span<const MeshRecord>(data.meshes));
  write_array(*out, std::span<const Vertex>(data.vertices));
  write_array(*out, std::span<const uint32_t>(data.indices));
  return out->commit();
}

// ---------------------------------------------------------------- texture table

Result<std::vector<TextureRecord>> read_texture_table(const fs::path& dir) {
  auto opened = open_input(dir / kTextureFile);
  if (!opened) return opened.error();
  InputFile& in = *opened;
  TextureFileHeader h{};
  if (in.size < sizeof h) return make_error(ErrorCode::kCorrupt, in.what + ": shorter than its header");
  TS_TRY(in.read(&h, sizeof h, "header"));
  TS_TRY(check_texture_header(h, in.size, in.what));
  std::vector<TextureRecord> t(h.texture_count);
  TS_TRY(in.read(t.data(), h.texture_count * sizeof(TextureRecord), "texture records"));
  for (size_t i = 0; i < t.size(); ++i) TS_TRY(check_texture_record(t[i], i, in.what));
  return t;
}

Status write_texture_table(const fs::path& dir, std::span<const TextureRecord> textures) {
  auto out = OutputFile::create(dir / kTextureFile);
  if (!out) return out.error();
  const TextureFileHeader h{kTextureMagic, kSceneFormatVersion, 0, textures.size()};
  out->write(&h, sizeof h);
  write_array(*out, textures);
  return out->commit();
}

// ---------------------------------------------------------------- colormap

Result<std::vector<uint32_t>> read_colormap(const fs::path& dir, uint64_t expected_count) {
  auto opened = open_input(dir / kColormapFile);
  if (!opened) return opened.error();
  InputFile& in = *opened;
  ColormapFileHeader h{};
  if (in.size < sizeof h) return make_error(ErrorCode::kCorrupt, in.what + ": shorter than its header");
  TS_TRY(in.read(&h, sizeof h, "header"));
  TS_TRY(check_colormap_header(h, in.size, expected_count, in.what));
  std::vector<uint32_t> c(h.texture_count);
  TS_TRY(in.read(c.data(), h.texture_count * sizeof(uint32_t), "colours"));
  return c;
}

Status write_colormap(const fs::path& dir, std::span<const uint32_t> rgba) {
  auto out = OutputFile::create(dir / kColormapFile);
  if (!out) return out.error();
  const ColormapFileHeader h{kColormapMagic, kSceneFormatVersion, 0, rgba.size()};
  out->write(&h, sizeof h);
  write_array(*out, rgba);
  return out->commit();
}

// ---------------------------------------------------------------- mapped reading

MappedFile& MappedFile::operator=(MappedFile&& o) noexcept {
  if (this != &o) {
    if (data_ != nullptr) ::munmap(data_, size_);
    data_ = std::exchange(o.data_, nullptr);
    size_ = std::exchange(o.size_, 0);
    what_ = std::move(o.what_);
  }
  return *this;
}

MappedFile::~MappedFile() {
  if (data_ != nullptr) ::munmap(data_, size_);
}

Result<MappedFile> MappedFile::open(const fs::path& path) {
  MappedFile f;
  f.what_ = path.string();
  // O_NONBLOCK: opening a FIFO must not wait for a writer; it is refused below (a regular file ignores the flag).
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    const auto code = errno == ENOENT ? ErrorCode::kNotFound : ErrorCode::kIo;
    return make_error(code, f.what_ + ": cannot open: " + errno_text());
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const std::string err = errno_text();
    ::close(fd);
    return make_error(ErrorCode::kIo, f.what_ + ": cannot stat: " + err);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return make_error(ErrorCode::kNotAFile, f.what_ + ": not a regular file");
  }
  f.size_ = static_cast<size_t>(st.st_size);
  if (f.size_ > 0) {
    // MAP_PRIVATE + PROT_READ: another process rewriting the file through a rename leaves this mapping on the
    // old inode; nothing here can write through it.
    void* p = ::mmap(nullptr, f.size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (p == MAP_FAILED) {
      const std::string err = errno_text();
      ::close(fd);
      f.size_ = 0;
      return make_error(ErrorCode::kIo, f.what_ + ": cannot map: " + err);
    }
    f.data_ = p;
  }
  ::close(fd);  // the mapping keeps the file
  return f;
}

Status MappedMeshes::check_mesh(size_t i) const {
  TS_ASSERT(i < meshes.size(), "check_mesh(%zu) of %zu meshes", i, meshes.size());
  return validate_mesh(MeshArrays{meshes, vertices, indices}, i, file.what());
}

Result<MappedMeshes> map_meshes(const fs::path& dir) {
  auto file = MappedFile::open(dir / kMeshFile);
  if (!file) return file.error();
  auto h = mapped_header<MeshFileHeader>(*file);
  if (!h) return h.error();
  TS_TRY(check_mesh_header(*h, file->bytes().size(), file->what()));
  MappedMeshes m;
  m.file = std::move(*file);
  uint64_t at = sizeof(MeshFileHeader);
  m.meshes = mapped_array<MeshRecord>(m.file, at, h->mesh_count);
  at += h->mesh_count * sizeof(MeshRecord);
  m.vertices = mapped_array<Vertex>(m.file, at, h->vertex_count);
  at += h->vertex_count * sizeof(Vertex);
  m.indices = mapped_array<uint32_t>(m.file, at, h->index_count);
  return m;
}

Result<MappedTextureTable> map_texture_table(const fs::path& dir) {
  auto file = MappedFile::open(dir / kTextureFile);
  if (!file) return file.error();
  auto h = mapped_header<TextureFileHeader>(*file);
  if (!h) return h.error();
  TS_TRY(check_texture_header(*h, file->bytes().size(), file->what()));
  MappedTextureTable t;
  t.file = std::move(*file);
  t.textures = mapped_array<TextureRecord>(t.file, sizeof(TextureFileHeader), h->texture_count);
  for (size_t i = 0; i < t.textures.size(); ++i) TS_TRY(check_texture_record(t.textures[i], i, t.file.what()));
  return t;
}

Result<MappedColormap> map_colormap(const fs::path& dir, uint64_t expected_count) {
  auto file = MappedFile::open(dir / kColormapFile);
  if (!file) return file.error();
  auto h = mapped_header<ColormapFileHeader>(*file);
  if (!h) return h.error();
  TS_TRY(check_colormap_header(*h, file->bytes().size(), expected_count, file->what()));
  MappedColormap c;
  c.file = std::move(*file);
  c.rgba = mapped_array<uint32_t>(c.file, sizeof(ColormapFileHeader), h->texture_count);
  return c;
}

Status write_sampling(const fs::path& dir, std::span<const uint32_t> flags) {
  auto out = OutputFile::create(dir / kSamplingFile);
  if (!out) return out.error();
  const ColormapFileHeader h{kSamplingMagic, kSceneFormatVersion, 0, flags.size()};
  out->write(&h, sizeof h);
  write_array(*out, flags);
  return out->commit();
}

Result<MappedSampling> map_sampling(const fs::path& dir, uint64_t expected_count) {
  auto file = MappedFile::open(dir / kSamplingFile);
  if (!file) return file.error();
  auto h = mapped_header<ColormapFileHeader>(*file);
  if (!h) return h.error();
  TS_TRY(check_per_texture_header(*h, kSamplingMagic, file->bytes().size(), expected_count, file->what(), "entries"));
  MappedSampling m;
  m.file = std::move(*file);
  m.flags = mapped_array<uint32_t>(m.file, sizeof(ColormapFileHeader), h->texture_count);
  for (size_t i = 0; i < m.flags.size(); ++i)
    if (auto bad = sampling_flags_error(m.flags[i]))
      return make_error(ErrorCode::kCorrupt, m.file.what() + ": texture " + std::to_string(i) + ": " + bad);
  return m;
}

Status write_transforms(const fs::path& dir, std::span<const MeshTransform> transforms) {
  auto out = OutputFile::create(dir / kTransformFile);
  if (!out) return out.error();
  const TransformFileHeader h{kTransformMagic, kSceneFormatVersion, 0, transforms.size()};
  out->write(&h, sizeof h);
  write_array(*out, transforms);
  return out->commit();
}

Result<MappedTransforms> map_transforms(const fs::path& dir, uint64_t expected_count) {
  auto file = MappedFile::open(dir / kTransformFile);
  if (!file) return file.error();
  auto h = mapped_header<TransformFileHeader>(*file);
  if (!h) return h.error();
  const std::string& what = file->what();
  TS_TRY(check_magic_version(*h, kTransformMagic, what));
  if (h->mesh_count != expected_count)
    return make_error(ErrorCode::kCorrupt, what + ": holds " + std::to_string(h->mesh_count) +
                                               " transforms, the scene has " + std::to_string(expected_count) +
                                               " meshes");
  const uint64_t size = file->bytes().size();
  if ((size - sizeof(TransformFileHeader)) / sizeof(MeshTransform) < h->mesh_count ||
      sizeof(TransformFileHeader) + h->mesh_count * sizeof(MeshTransform) != size)
    return make_error(ErrorCode::kCorrupt, what + ": size " + std::to_string(size) + " bytes does not hold " +
                                               std::to_string(h->mesh_count) + " transforms exactly");
  MappedTransforms m;
  m.file = std::move(*file);
  m.transforms = mapped_array<MeshTransform>(m.file, sizeof(TransformFileHeader), h->mesh_count);
  for (size_t i = 0; i < m.transforms.size(); ++i) {
    const MeshTransform& t = m.transforms[i];
    double n = 0;
    bool finite = std::isfinite(t.scale);
    for (float q : t.rotation) {
      finite = finite && std::isfinite(q);
      n += static_cast<double>(q) * static_cast<double>(q);
    }
    if (!finite || std::abs(n - 1.0) > 1e-3 || !(t.scale > 0.0f))
      return make_error(ErrorCode::kCorrupt,
                        m.file.what() + ": mesh " + std::to_string(i) + ": not a unit rotation with a positive scale");
  }
  return m;
}

// ---------------------------------------------------------------- mesh index (mesh_index.hpp)

void mesh_box(const MeshRecord& m, double min[3], double max[3]) {
  for (int a = 0; a < 3; ++a) {
    const double p = m.origin[a] + static_cast<double>(m.bounds_min[a]);
    const double q = m.origin[a] + static_cast<double>(m.bounds_max[a]);
    min[a] = std::min(p, q);
    max[a] = std::max(p, q);
  }
}

MeshIndex build_mesh_index(std::span<const MeshRecord> meshes) {
  MeshIndex index;
  index.order.resize(meshes.size());
  for (uint32_t i = 0; i < index.order.size(); ++i) index.order[i] = i;
  if (meshes.empty()) return index;
  // Centres in the ground plane, by mesh id: each is read once per level of the build.
  std::vector<std::array<double, 2>> centre(meshes.size());
  double lo[2] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max()};
  double hi[2] = {std::numeric_limits<double>::lowest(), std::numeric_limits<double>::lowest()};
  for (size_t i = 0; i < meshes.size(); ++i) {
    double bmin[3], bmax[3];
    mesh_box(meshes[i], bmin, bmax);
    for (int a = 0; a < 2; ++a) {
      centre[i][a] = 0.5 * (bmin[a] + bmax[a]);
      lo[a] = std::min(lo[a], centre[i][a]);
      hi[a] = std::max(hi[a], centre[i][a]);
    }
  }
  // A square root region, so cells stay square however elongated the city is.
  const double side = std::max({hi[0] - lo[0], hi[1] - lo[1], 1e-3});

  auto& nodes = index.nodes;
  auto& order = index.order;
  auto make_node = [&](uint32_t begin, uint32_t end) {
    MeshIndexNode node{};
    node.begin = begin;
    node.end = end;
    mesh_box(meshes[order[begin]], node.min, node.max);
    for (uint32_t i = begin + 1; i < end; ++i) {
      double bmin[3], bmax[3];
      mesh_box(meshes[order[i]], bmin, bmax);
      for (int a = 0; a < 3; ++a) {
        node.min[a] = std::min(node.min[a], bmin[a]);
        node.max[a] = std::max(node.max[a], bmax[a]);
      }
    }
    nodes.push_back(node);
  };
  struct Pending {
    uint32_t node;
    std::array<double, 4> rect;  // x0, y0, x1, y1 of the quadrant the node's meshes were filed into
    uint32_t depth;
  };
  // Breadth first, so that the children of a node are appended together and stay contiguous.
  make_node(0, static_cast<uint32_t>(order.size()));
  std::vector<Pending> queue{{0, {lo[0], lo[1], lo[0] + side, lo[1] + side}, 0}};
  for (size_t q = 0; q < queue.size(); ++q) {
    const Pending p = queue[q];
    const uint32_t begin = nodes[p.node].begin;
    const uint32_t end = nodes[p.node].end;
    index.depth = std::max(index.depth, p.depth);
    if (end - begin <= kMeshIndexLeafMeshes || p.depth >= kMeshIndexMaxDepth) continue;
    // File each mesh into the quadrant of its centre: (x0,y0) (x1,y0) (x0,y1) (x1,y1), in that order.
    const double mx = 0.5 * (p.rect[0] + p.rect[2]);
    const double my = 0.5 * (p.rect[1] + p.rect[3]);
    uint32_t* base = order.data();
    uint32_t* split_y =
        std::stable_partition(base + begin, base + end, [&](uint32_t id) { return centre[id][1] < my; });
    uint32_t* split_x0 = std::stable_partition(base + begin, split_y, [&](uint32_t id) { return centre[id][0] < mx; });
    uint32_t* split_x1 = std::stable_partition(split_y, base + end, [&](uint32_t id) { return centre[id][0] < mx; });
    const std::array<uint32_t, 5> cut{begin, static_cast<uint32_t>(split_x0 - base),
                                      static_cast<uint32_t>(split_y - base), static_cast<uint32_t>(split_x1 - base),
                                      end};
    const std::array<std::array<double, 4>, 4> rects{{{p.rect[0], p.rect[1], mx, my},
                                                      {mx, p.rect[1], p.rect[2], my},
                                                      {p.rect[0], my, mx, p.rect[3]},
                                                      {mx, my, p.rect[2], p.rect[3]}}};
    const auto first_child = static_cast<uint32_t>(nodes.size());
    uint32_t count = 0;
    for (uint32_t k = 0; k < 4; ++k) {
      if (cut[k + 1] == cut[k]) continue;
      queue.push_back({static_cast<uint32_t>(nodes.size()), rects[k], p.depth + 1});
      make_node(cut[k], cut[k + 1]);  // may reallocate nodes: index, never hold a reference across it
      ++count;
    }
    nodes[p.node].first_child = first_child;
    nodes[p.node].child_count = count;
  }
  return index;
}

namespace {

// meshes.bin's size and fingerprint (MeshIndexHeader): what an index is stamped with.
Status meshes_stamp(const fs::path& dir, uint64_t& bytes, uint64_t& fingerprint) {
  auto file = MappedFile::open(dir / kMeshFile);
  if (!file) return file.error();
  const auto all = file->bytes();
  bytes = all.size();
  uint64_t h = 0xcbf29ce484222325ull;  // FNV-1a 64 offset basis
  auto mix = [&](std::span<const std::byte> b) {
    for (std::byte x : b) h = (h ^ static_cast<uint8_t>(x)) * 0x100000001b3ull;  // FNV-1a 64 prime
  };
  mix(all.first(std::min<size_t>(all.size(), sizeof(MeshFileHeader))));
  MeshFileHeader mh{};
  if (all.size() >= sizeof mh) std::memcpy(&mh, all.data(), sizeof mh);
  const uint64_t records =
      std::min<uint64_t>(mh.mesh_count, (all.size() - std::min(all.size(), sizeof mh)) / sizeof(MeshRecord));
  const uint64_t samples = std::min(records, kMeshIndexFingerprintSamples);
  for (uint64_t k = 0; k < samples; ++k) {
    // Evenly spread, first and last record included.
    const uint64_t i = samples > 1 ? k * (records - 1) / (samples - 1) : 0;
    mix(all.subspan(sizeof mh + i * sizeof(MeshRecord), sizeof(MeshRecord)));
  }
  fingerprint = h;
  return ok_status();
}

bool finite_box(const MeshIndexNode& n) { return finite3(n.min) && finite3(n.max); }

}  // namespace

Status write_mesh_index(const fs::path& dir, const MeshIndexView& index) {
  MeshIndexHeader h{kMeshIndexMagic, kMeshIndexVersion, index.depth, index.order.size(), index.nodes.size(), 0, 0};
  TS_TRY(meshes_stamp(dir, h.meshes_file_bytes, h.meshes_fingerprint));
  auto out = OutputFile::create(dir / kMeshIndexFile, /*per_process=*/true);
  if (!out) return out.error();
  out->write(&h, sizeof h);
  write_array(*out, index.nodes);
  write_array(*out, index.order);
  return out->commit();
}

Result<MappedMeshIndex> map_mesh_index(const fs::path& dir, uint64_t mesh_count) {
  auto file = MappedFile::open(dir / kMeshIndexFile);
  if (!file) return file.error();
  const std::string what = file->what();
  auto hr = mapped_header<MeshIndexHeader>(*file);
  if (!hr) return hr.error();
  const MeshIndexHeader h = *hr;
  if (h.magic != kMeshIndexMagic) return make_error(ErrorCode::kCorrupt, what + ": bad magic (not a mesh index)");
  if (h.version != kMeshIndexVersion)
    return make_error(ErrorCode::kUnsupported, what + ": version " + std::to_string(h.version) + ", expected " +
                                                   std::to_string(kMeshIndexVersion));
  if (h.mesh_count != mesh_count)
    return make_error(ErrorCode::kCorrupt, what + ": indexes " + std::to_string(h.mesh_count) +
                                               " meshes, the scene has " + std::to_string(mesh_count));
  uint64_t bytes = 0, fingerprint = 0;
  TS_TRY(meshes_stamp(dir, bytes, fingerprint));
  if (bytes != h.meshes_file_bytes || fingerprint != h.meshes_fingerprint)
    return make_error(ErrorCode::kCorrupt, what + ": stale (built from another meshes.bin: size or records differ)");
  const uint64_t size = file->bytes().size();
  const uint64_t body = size - sizeof h;
  if (h.node_count > body / sizeof(MeshIndexNode) || h.mesh_count > body / sizeof(uint32_t) ||
      sizeof h + h.node_count * sizeof(MeshIndexNode) + h.mesh_count * sizeof(uint32_t) != size)
    return make_error(ErrorCode::kCorrupt, what + ": size " + std::to_string(size) + " bytes does not hold " +
                                               std::to_string(h.node_count) + " nodes and " +
                                               std::to_string(h.mesh_count) + " ids exactly");
  if ((h.mesh_count == 0) != (h.node_count == 0) || h.node_count > std::numeric_limits<uint32_t>::max() ||
      h.depth > kMeshIndexMaxDepth)
    return make_error(ErrorCode::kCorrupt, what + ": node count " + std::to_string(h.node_count) + " or depth " +
                                               std::to_string(h.depth) + " impossible for " +
                                               std::to_string(h.mesh_count) + " meshes");
  MappedMeshIndex m;
  m.file = std::move(*file);
  m.view.nodes = mapped_array<MeshIndexNode>(m.file, sizeof h, h.node_count);
  m.view.order = mapped_array<uint32_t>(m.file, sizeof h + h.node_count * sizeof(MeshIndexNode), h.mesh_count);
  m.view.depth = h.depth;

  // Structure: O(nodes + meshes) integer checks over a few MB, no mesh record read.
  const auto& nodes = m.view.nodes;
  std::vector<uint8_t> parents(nodes.size(), 0);
  for (size_t i = 0; i < nodes.size(); ++i) {
    const MeshIndexNode& n = nodes[i];
    const auto rec = [&] { return m.file.what() + ": node " + std::to_string(i) + ": "; };  // on failure only
    if (n.begin >= n.end || n.end > h.mesh_count || (i == 0 && (n.begin != 0 || n.end != h.mesh_count)))
      return make_error(ErrorCode::kCorrupt, rec() + "range [" + std::to_string(n.begin) + ", " +
                                                 std::to_string(n.end) + ") is empty or outside the " +
                                                 std::to_string(h.mesh_count) + " meshes");
    if (!finite_box(n)) return make_error(ErrorCode::kCorrupt, rec() + "box not finite");
    if (n.child_count == 0) continue;
    // Children come after their parent (so no cycle), are at most four, and cut its range in order.
    if (n.child_count > 4 || n.first_child <= i || uint64_t{n.first_child} + n.child_count > nodes.size())
      return make_error(ErrorCode::kCorrupt, rec() + "children " + std::to_string(n.first_child) + " +" +
                                                 std::to_string(n.child_count) + " out of place");
    uint32_t at = n.begin;
    for (uint32_t c = n.first_child; c < n.first_child + n.child_count; ++c) {
      if (nodes[c].begin != at || ++parents[c] > 1)
        return make_error(ErrorCode::kCorrupt, rec() + "child " + std::to_string(c) +
                                                   " does not continue its parent's range, or has two parents");
      at = nodes[c].end;
    }
    if (at != n.end) return make_error(ErrorCode::kCorrupt, rec() + "children do not cover its range");
  }
  for (size_t i = 1; i < nodes.size(); ++i)
    if (parents[i] != 1)
      return make_error(ErrorCode::kCorrupt, m.file.what() + ": node " + std::to_string(i) + " has no parent");
  std::vector<bool> seen(h.mesh_count, false);
  for (size_t i = 0; i < m.view.order.size(); ++i) {
    const uint32_t id = m.view.order[i];
    if (id >= h.mesh_count || seen[id])
      return make_error(ErrorCode::kCorrupt, m.file.what() + ": order[" + std::to_string(i) +
                                                 "] = " + std::to_string(id) + " is out of range or repeated");
    seen[id] = true;
  }
  return m;
}

// ---------------------------------------------------------------- texture files

std::string texture_path_text(const fs::path& dir, TextureId id) {
  // Built as one string: the server makes one name per texture it opens, and snprintf plus three path
  // appends (each re-splitting the path into components) were ~5 % of its dispatcher's time in
  // texstream-bench server's miss stream. The text is what dir / "textures" / folder / file gives on POSIX.
  static constexpr char kHex[] = "0123456789abcdef";
  const std::string& d = dir.native();
  std::string s;
  s.reserve(d.size() + 32);
  s += d;
  if (!d.empty() && d.back() != '/') s += '/';
  s += "textures/";
  const uint32_t folder = (id.value >> 12) & 0xfffu;
  for (int shift = 8; shift >= 0; shift -= 4) s += kHex[(folder >> shift) & 0xfu];
  s += '/';
  for (int shift = 28; shift >= 0; shift -= 4) s += kHex[(id.value >> shift) & 0xfu];
  s += ".dds";
  return s;
}

fs::path texture_path(const fs::path& dir, TextureId id) { return fs::path(texture_path_text(dir, id)); }

}  // namespace texstream::scene
