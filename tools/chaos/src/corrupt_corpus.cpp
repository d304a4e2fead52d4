#include "corrupt_corpus.hpp"

#include "child_process.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <tuple>

namespace texstream::chaos {

namespace fs = std::filesystem;

namespace {

// The header fields this corpus damages, at the offsets common's one DDS parser reads.
constexpr size_t kOffSize = scene::dds_field::kSize, kOffHeight = scene::dds_field::kHeight,
                 kOffWidth = scene::dds_field::kWidth, kOffMipCount = scene::dds_field::kMipMapCount,
                 kOffPfFlags = scene::dds_field::kPfFlags, kOffFourCc = scene::dds_field::kPfFourCC;

using Bytes = std::vector<std::byte>;

void put_u32(Bytes& b, size_t off, uint32_t v) {
  if (off + 4 <= b.size()) std::memcpy(b.data() + off, &v, 4);
}

Result<Bytes> read_all(const fs::path& p) {
  const auto text = read_whole_file(p);
  if (!text) return make_error(ErrorCode::kNotFound, "cannot read '" + p.string() + "'");
  Bytes b(text->size());
  if (!text->empty()) std::memcpy(b.data(), text->data(), text->size());  // an empty vector's data() may be null
  return b;
}

Status write_all(const fs::path& p, const Bytes& b) {
  fs::create_directories(p.parent_path());
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  if (!out) return make_error(ErrorCode::kIo, "cannot write '" + p.string() + "'");
  return ok_status();
}

// Another container for an RGBA8 texture's mip 0, written by OpenImageIO: what the server also accepts
// (texture_server texture_file_index.hpp: .tx/.tif, .exr) and a JPEG under a .tif name (OpenImageIO falls back
// to the reader that recognises the bytes; the server has no .jpg lookup).
enum class OtherFormat { kTiff, kExr, kJpegAsTif };

// The file bytes of `dds` (an uncompressed RGBA8 DDS as scene_format writes it) in `format`: mipmapped and
// tiled as maketx writes them (TIFF, EXR), or a single-level baseline JPEG. Empty if OpenImageIO failed.
Bytes encode_other(const Bytes& dds, const scene::TextureRecord& t, OtherFormat format, const fs::path& scratch) {
  if (dds.size() < scene::kDdsHeaderBytes + uint64_t{t.width} * t.height * 4) return {};
  OIIO::ImageSpec spec(static_cast<int>(t.width), static_cast<int>(t.height), 4, OIIO::TypeDesc::UINT8);
  OIIO::ImageBuf src(spec);
  src.set_pixels(OIIO::ROI::All(), OIIO::TypeDesc::UINT8, dds.data() + scene::kDdsHeaderBytes);
  const fs::path tmp = scratch.string() + (format == OtherFormat::kExr    ? ".exr"
                                           : format == OtherFormat::kTiff ? ".tif"
                                                                          : ".jpg");
  bool ok = false;
  if (format == OtherFormat::kJpegAsTif) {
    OIIO::ImageBuf rgb = OIIO::ImageBufAlgo::channels(src, 3, {});  // JPEG has no alpha
    ok = rgb.write(tmp.string(), OIIO::TypeDesc::UINT8, "jpeg");
  } else {
    OIIO::ImageSpec config;
    config.tile_width = 16;
    config.tile_height = 16;
    config.attribute("maketx:filtername", "box");
    if (format == OtherFormat::kExr) {
      config.attribute("maketx:fileformatname", "openexr");
      config.set_format(OIIO::TypeDesc::HALF);
    }
    ok = OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, src, tmp.string(), config);
  }
  Bytes out;
  if (ok) {
    if (Result<Bytes> bytes = read_all(tmp); bytes.ok()) out = std::move(*bytes);
  }
  std::error_code ec;
  fs::remove(tmp, ec);
  return out;
}

// One mutation: edits the file bytes (or the file itself) and fills in the case's expectations.
struct Mutation {
  std::string name;
  std::function<void(Bytes&, CorruptCase&)> apply;
  enum Kind { kBytes, kMissing, kDirectory, kUnreadable } kind = kBytes;
};

// Truncations of the other containers (RGBA8 textures only: the server never encodes BC1 from them). The
// file replaces the DDS (the lookup takes .dds first). Zero bytes and a cut inside the first 8 bytes leave
// nothing to open: every mip fails. A cut anywhere past that loses at least the coarsest level: maketx
// writes the levels finest first, each TIFF directory after its level's tiles, the EXR tiles level by level.
void add_other_format_mutations(std::vector<Mutation>& m, const scene::TextureRecord& t, const fs::path& scratch) {
  if (static_cast<TexelFormat>(t.format) != TexelFormat::kRgba8) return;
  struct Kind {
    OtherFormat format;
    const char* name;
    const char* suffix;
  };
  for (const Kind k : {Kind{OtherFormat::kTiff, "TIFF", ".tif"}, Kind{OtherFormat::kExr, "OpenEXR", ".exr"},
                       Kind{OtherFormat::kJpegAsTif, "JPEG named .tif", ".tif"}}) {
    // Eighths of the file, and the last byte.
    for (int eighth : {0, 1, 2, 4, 6, 7, 8}) {
      std::string what = eighth == 8 ? "cut by its last byte" : "truncated at " + std::to_string(eighth) + "/8";
      m.push_back({std::string(k.name) + " " + what, [k, eighth, t, scratch](Bytes& b, CorruptCase& c) {
                     Bytes file = encode_other(b, t, k.format, scratch);
                     c.file.replace_extension(k.suffix);
                     c.header_changed = true;  // decoded by OpenImageIO: a kOk payload is not the file's bytes
                     c.other_format = true;
                     if (file.empty()) {  // OpenImageIO could not write it: an empty file (all must fail)
                       b.clear();
                       c.all_must_fail = true;
                       return;
                     }
                     const size_t cut = eighth == 8 ? file.size() - 1 : file.size() * static_cast<size_t>(eighth) / 8;
                     file.resize(cut);
                     c.mutation += " (" + std::to_string(cut) + " bytes)";
                     // A JPEG holds one level: mips past 0 are never there. Any cut of its bytes loses the
                     // end-of-image marker at least.
                     if (k.format == OtherFormat::kJpegAsTif || cut <= 8) {
                       c.all_must_fail = true;
                     } else {
                       c.first_failing_mip = t.mip_count - 1;
                     }
                     b = std::move(file);
                   }});
    }
  }
}

std::vector<Mutation> mutations_for(const scene::TextureRecord& t, std::mt19937_64& rng, const fs::path& scratch) {
  const auto f = static_cast<TexelFormat>(t.format);
  std::vector<Mutation> m;
  // Truncation at every mip boundary, and one byte short of each (the header end is boundary 0).
  for (uint32_t level = 0; level <= t.mip_count; ++level) {
    const uint64_t end = scene::dds_mip_offset(f, t.width, t.height, level);
    for (uint64_t cut : {end, end - 1}) {
      if (level == t.mip_count && cut == end) continue;  // the whole file: not a truncation
      // Mip l lies in [off(l), off(l+1)): it is intact iff off(l+1) <= cut.
      uint32_t first_bad = 0;
      while (first_bad < t.mip_count && scene::dds_mip_offset(f, t.width, t.height, first_bad + 1) <= cut) ++first_bad;
      m.push_back({"truncated at " + std::to_string(cut) + " bytes", [cut, first_bad](Bytes& b, CorruptCase& c) {
                     b.resize(cut);
                     if (cut < scene::kDdsHeaderBytes) c.all_must_fail = true;
                     c.first_failing_mip = first_bad;
                   }});
    }
  }
  for (uint64_t cut : {0ull, 3ull, 4ull, 64ull, 127ull}) {
    m.push_back({"truncated inside the header at " + std::to_string(cut) + " bytes", [cut](Bytes& b, CorruptCase& c) {
                   b.resize(cut);
                   c.all_must_fail = true;
                 }});
  }
  auto header = [&](std::string name, size_t off, uint32_t v, bool must_fail) {
    m.push_back({std::move(name), [off, v, must_fail](Bytes& b, CorruptCase& c) {
                   put_u32(b, off, v);
                   c.all_must_fail = must_fail;
                 }});
  };
  header("bad magic", 0, 0x20534444u ^ 0x01010101u, true);
  header("header size 0", kOffSize, 0, true);
  header("header size 0xffffffff", kOffSize, 0xffffffffu, true);
  header("header size 200", kOffSize, 200, true);
  header("width 0", kOffWidth, 0, true);
  header("height 0", kOffHeight, 0, true);
  header("width 0x7fffffff", kOffWidth, 0x7fffffffu, true);
  header("height 0xffffffff", kOffHeight, 0xffffffffu, true);
  header("width 65536", kOffWidth, 65536, true);
  header("width doubled (not the table's extent)", kOffWidth, t.width * 2, true);
  header("mip count 0xffffffff", kOffMipCount, 0xffffffffu, false);  // may be refused, or read as "levels present"
  header("mip count 0", kOffMipCount, 0, false);                     // legacy files: 0 means one level
  header("mip count 1 more than possible", kOffMipCount, t.mip_count + 1, false);
  header("pixel-format flags 0", kOffPfFlags, 0, f == TexelFormat::kBc1);
  header("unknown FourCC 'XYZW'", kOffFourCc, 0x575a5958u, f == TexelFormat::kBc1);
  header("FourCC DXT5", kOffFourCc, 0x35545844u, f == TexelFormat::kBc1);  // a bc1 texture is never re-encoded
  for (int i = 0; i < 6; ++i) {
    const size_t bit = std::uniform_int_distribution<size_t>(0, scene::kDdsHeaderBytes * 8 - 1)(rng);
    m.push_back({"bit flip in the header (bit " + std::to_string(bit) + ")",
                 [bit](Bytes& b, CorruptCase&) { b[bit / 8] ^= static_cast<std::byte>(1u << (bit % 8)); }});
  }
  const uint64_t data_bytes = scene::dds_file_bytes(f, t.width, t.height, t.mip_count) - scene::kDdsHeaderBytes;
  for (int i = 0; i < 4; ++i) {
    const uint64_t bit = std::uniform_int_distribution<uint64_t>(0, data_bytes * 8 - 1)(rng);
    m.push_back({"bit flip in the texel data (bit " + std::to_string(bit) + ")", [bit](Bytes& b, CorruptCase&) {
                   b[scene::kDdsHeaderBytes + bit / 8] ^= static_cast<std::byte>(1u << (bit % 8));
                 }});
  }
  m.push_back({"texel data zeroed", [](Bytes& b, CorruptCase&) {
                 std::fill(b.begin() + static_cast<std::ptrdiff_t>(scene::kDdsHeaderBytes), b.end(), std::byte{0});
               }});
  m.push_back({"whole file zero bytes", [](Bytes& b, CorruptCase& c) {
                 std::fill(b.begin(), b.end(), std::byte{0});
                 c.all_must_fail = true;
               }});
  m.push_back({"1 MiB of trailing garbage", [&rng](Bytes& b, CorruptCase&) {
                 for (int i = 0; i < (1 << 20); ++i) b.push_back(static_cast<std::byte>(rng()));
               }});
  m.push_back({"random bytes with a valid magic", [&rng](Bytes& b, CorruptCase&) {
                 for (size_t i = 4; i < b.size(); ++i) b[i] = static_cast<std::byte>(rng());
               }});
  add_other_format_mutations(m, t, scratch);
  m.push_back({"missing file", {}, Mutation::kMissing});
  m.push_back({"a directory in place of the file", {}, Mutation::kDirectory});
  m.push_back({"unreadable (chmod 000)", {}, Mutation::kUnreadable});
  return m;
}

}  // namespace

bool permissions_stop_reads(const fs::path& dir) {
  const fs::path probe = dir / (".perm-probe-" + std::to_string(::getpid()));
  { std::ofstream(probe) << "x"; }
  ::chmod(probe.c_str(), 0);
  const bool stopped = ::access(probe.c_str(), R_OK) != 0;
  fs::remove(probe);
  return stopped;
}

Result<Corpus> make_corrupt_corpus(const fs::path& scene_dir, const fs::path& out_dir, const CorpusOptions& o) {
  std::error_code ec;
  if (fs::equivalent(scene_dir, out_dir, ec)) {
    return make_error(ErrorCode::kInvalidArgument, "corpus folder '" + out_dir.string() + "' is the source scene");
  }
  auto table = scene::read_texture_table(scene_dir);
  if (!table) return table.error();
  fs::create_directories(out_dir);
  for (const char* f : {"scene.json", "meshes.bin", "textures.bin", "colormap.bin", "camera_path.txt"}) {
    if (fs::exists(scene_dir / f)) fs::copy_file(scene_dir / f, out_dir / f, fs::copy_options::overwrite_existing);
  }
  Corpus corpus;
  corpus.table = *table;
  const bool can_unread = permissions_stop_reads(out_dir);
  if (!can_unread) corpus.skipped = "unreadable files: chmod 000 does not stop reads here (running as root)";

  std::mt19937_64 rng(o.seed);
  // Per shape (extent, mips, format), the next mutation of that shape's list: every shape walks its whole
  // list, so each mutation meets a texture it applies to; a shape whose list is done yields intact controls.
  struct Cursor {
    size_t next = 0;
    bool exhausted = false;
  };
  std::map<std::tuple<uint32_t, uint32_t, uint32_t, uint32_t>, Cursor> cursors;
  for (uint32_t id = 0; id < table->size(); ++id) {
    const fs::path src = scene::texture_path(scene_dir, TextureId(id));
    const fs::path dst = scene::texture_path(out_dir, TextureId(id));
    auto bytes = read_all(src);
    if (!bytes) return bytes.error();
    const bool room = o.max_cases == 0 || corpus.cases.size() < o.max_cases;
    std::vector<Mutation> list = mutations_for((*table)[id], rng, out_dir / (".scratch-" + std::to_string(id)));
    if (!can_unread) std::erase_if(list, [](const Mutation& m) { return m.kind == Mutation::kUnreadable; });
    const scene::TextureRecord& shape = (*table)[id];
    Cursor& cur = cursors[{shape.width, shape.height, shape.mip_count, shape.format}];
    if (cur.next >= list.size()) {
      cur.exhausted = !o.repeat;
      cur.next = 0;
    }
    if (!room || cur.exhausted) {
      TS_TRY(write_all(dst, *bytes));
      corpus.intact.push_back(id);
      continue;
    }
    const Mutation& mu = list[cur.next++];
    CorruptCase c;
    c.texture = id;
    c.mutation = mu.name;
    c.file = dst;
    fs::create_directories(dst.parent_path());
    switch (mu.kind) {
      case Mutation::kBytes: {
        const Bytes before = *bytes;
        mu.apply(*bytes, c);
        c.header_changed = c.header_changed || bytes->size() < scene::kDdsHeaderBytes ||
                           !std::equal(bytes->begin(), bytes->begin() + scene::kDdsHeaderBytes, before.begin());
        TS_TRY(write_all(c.file, *bytes));  // another container: c.file has its suffix, no .dds is written
        break;
      }
      case Mutation::kMissing:
        fs::remove(dst);
        c.all_must_fail = true;
        break;
      case Mutation::kDirectory:
        fs::create_directories(dst);
        c.all_must_fail = true;
        break;
      case Mutation::kUnreadable:
        TS_TRY(write_all(dst, *bytes));
        ::chmod(dst.c_str(), 0);
        c.all_must_fail = true;
        c.unreadable = true;
        break;
    }
    corpus.cases.push_back(std::move(c));
  }
  return corpus;
}

}  // namespace texstream::chaos
