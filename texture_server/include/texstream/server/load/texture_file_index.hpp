#pragma once
// Which file holds texture T, and (for DDS) where its mips lie.
//
// Lookup: <scene>/textures/XXX/YYYYYYYY.dds (the generator's name, scene_format.hpp); if there is none, the
// same stem with .tx, .tif, then .exr (mipmapped files as `maketx` writes them; see README.md). The first
// that exists wins.
//
// What was found is remembered per texture in a bounded, direct-mapped memo (kEntries slots, a few MiB): a
// later miss of the same texture opens the right file at once and, for DDS, reads only the mip's byte range
// instead of the 128-148 header bytes again (read amplification, issue 3: ≤ 1.1). Files are assumed not to
// change while the server runs; a read that finds a file shorter than remembered forgets the entry.
// Thread-safe (workers share it).
#include <array>
#include <cstdint>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "texstream/common/dds.hpp"
#include "texstream/common/ids.hpp"

namespace texstream::server {

enum class TextureFileKind : uint8_t { kDds = 0, kTx = 1, kTif = 2, kExr = 3 };
inline constexpr std::array<TextureFileKind, 4> kTextureFileKinds = {TextureFileKind::kDds, TextureFileKind::kTx,
                                                                     TextureFileKind::kTif, TextureFileKind::kExr};
const char* suffix_of(TextureFileKind kind);

// <scene>/textures/XXX/YYYYYYYY<suffix>
std::filesystem::path texture_file_path(const std::filesystem::path& scene_dir, TextureId id, TextureFileKind kind);
// The same path as text (what texture_file_path(...).native() is), made without a std::filesystem::path
// (see Storage::open_text).
std::string texture_file_path_text(const std::filesystem::path& scene_dir, TextureId id, TextureFileKind kind);

struct TextureFileEntry {
  TextureFileKind kind = TextureFileKind::kDds;
  std::optional<scene::DdsLayout> dds;  // kDds once its header has been parsed
};

class TextureFileIndex {
 public:
  // 2^16 entries of ~40 bytes: a scene's working set of textures, about 2.5 MiB.
  static constexpr uint32_t kEntries = 1u << 16;

  TextureFileIndex();
  std::optional<TextureFileEntry> find(TextureId id) const;
  void remember(TextureId id, const TextureFileEntry& entry);
  void forget(TextureId id);

 private:
  struct Slot {
    uint64_t key = 0;  // texture id + 1; 0 = empty
    TextureFileEntry entry;
  };
  mutable std::mutex mutex_;
  std::vector<Slot> slots_;
};

}  // namespace texstream::server
