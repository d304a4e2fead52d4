#include "texstream/server/load/texture_file_index.hpp"

#include "texstream/common/scene_format.hpp"

namespace texstream::server {

const char* suffix_of(TextureFileKind kind) {
  switch (kind) {
    case TextureFileKind::kDds:
      return ".dds";
    case TextureFileKind::kTx:
      return ".tx";
    case TextureFileKind::kTif:
      return ".tif";
    case TextureFileKind::kExr:
      return ".exr";
  }
  return ".dds";
}

std::string texture_file_path_text(const std::filesystem::path& scene_dir, TextureId id, TextureFileKind kind) {
  // scene::texture_path_text() with its ".dds" swapped for the kind's suffix, as text (see Storage::open_text).
  std::string s = scene::texture_path_text(scene_dir, id);
  s.resize(s.size() - 4);
  s += suffix_of(kind);
  return s;
}

std::filesystem::path texture_file_path(const std::filesystem::path& scene_dir, TextureId id, TextureFileKind kind) {
  return std::filesystem::path(texture_file_path_text(scene_dir, id, kind));
}

TextureFileIndex::TextureFileIndex() : slots_(kEntries) {}

std::optional<TextureFileEntry> TextureFileIndex::find(TextureId id) const {
  std::lock_guard lock(mutex_);
  const Slot& s = slots_[id.value & (kEntries - 1)];
  if (s.key != uint64_t{id.value} + 1) return std::nullopt;
  return s.entry;
}

void TextureFileIndex::remember(TextureId id, const TextureFileEntry& entry) {
  std::lock_guard lock(mutex_);
  slots_[id.value & (kEntries - 1)] = Slot{uint64_t{id.value} + 1, entry};
}

void TextureFileIndex::forget(TextureId id) {
  std::lock_guard lock(mutex_);
  Slot& s = slots_[id.value & (kEntries - 1)];
  if (s.key == uint64_t{id.value} + 1) s = Slot{};
}

}  // namespace texstream::server
