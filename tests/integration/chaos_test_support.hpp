#pragma once
// Shared by the chaos_* integration tests: a small scene written with the scene_format writers (texture files
// whose bytes the tests know), and where to find texstream-server.
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/protocol/completion_check.hpp"

namespace texstream::chaos_test {

namespace fs = std::filesystem;

inline std::string unique(const char* what) {
  static std::atomic<int> n{0};
  return std::string("texstream-chaos-") + what + "-" + std::to_string(::getpid()) + "-" + std::to_string(n++);
}

// $TEXSTREAM_SERVER, else this build's bin/, else the main build's.
inline fs::path find_server() {
  if (const char* env = std::getenv("TEXSTREAM_SERVER"); env && *env) return env;
  for (const fs::path& p : {fs::path(TEXSTREAM_BIN_DIR) / "texstream-server",
                            fs::path(TEXSTREAM_SOURCE_DIR) / "build/bin/texstream-server"}) {
    if (::access(p.c_str(), X_OK) == 0) return p;
  }
  return {};
}

// `count` textures cycling through a few shapes (BC1 and RGBA8, square and not), full mip chains, texel
// bytes from a known pattern.
struct SmallScene {
  fs::path dir;
  std::vector<scene::TextureRecord> textures;
  std::map<uint32_t, std::vector<std::byte>> files;

  explicit SmallScene(uint32_t count) {
    dir = fs::temp_directory_path() / unique("scene");
    fs::remove_all(dir);
    fs::create_directories(dir);
    const scene::TextureRecord kinds[] = {{64, 64, full_mip_count(64, 64), static_cast<uint32_t>(TexelFormat::kBc1)},
                                          {32, 16, full_mip_count(32, 16), static_cast<uint32_t>(TexelFormat::kRgba8)},
                                          {128, 32, full_mip_count(128, 32), static_cast<uint32_t>(TexelFormat::kBc1)},
                                          {16, 16, full_mip_count(16, 16), static_cast<uint32_t>(TexelFormat::kRgba8)}};
    for (uint32_t i = 0; i < count; ++i) textures.push_back(kinds[i % 4]);
    scene::Manifest m;
    m.name = "chaos-test";
    m.mesh_count = 0;
    m.texture_count = textures.size();
    ok_ = scene::write_manifest(dir, m).ok() && scene::write_meshes(dir, scene::MeshData{}).ok() &&
          scene::write_texture_table(dir, textures).ok() &&
          scene::write_colormap(dir, std::vector<uint32_t>(textures.size(), 0xff808080u)).ok();
    for (uint32_t id = 0; id < textures.size(); ++id) {
      const auto& t = textures[id];
      const TexelFormat f = static_cast<TexelFormat>(t.format);
      const auto header = scene::make_dds_header(f, t.width, t.height, t.mip_count);
      std::vector<std::byte> bytes(header.begin(), header.end());
      const uint64_t total = scene::dds_file_bytes(f, t.width, t.height, t.mip_count);
      for (uint64_t i = bytes.size(); i < total; ++i)
        bytes.push_back(static_cast<std::byte>((i * 7 + id * 101) & 0xff));
      const fs::path path = scene::texture_path(dir, TextureId(id));
      fs::create_directories(path.parent_path());
      std::ofstream(path, std::ios::binary)
          .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
      files[id] = std::move(bytes);
    }
  }
  ~SmallScene() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  SmallScene(const SmallScene&) = delete;
  SmallScene& operator=(const SmallScene&) = delete;
  bool ok() const { return ok_; }

  std::vector<TextureShape> shapes() const {
    std::vector<TextureShape> s;
    for (const auto& t : textures) s.push_back({t.width, t.height, t.mip_count, static_cast<TexelFormat>(t.format)});
    return s;
  }

 private:
  bool ok_ = false;
};

}  // namespace texstream::chaos_test
