// libFuzzer: the server's DDS readers. Input = a file's bytes (+ the first 16 bytes pick the texture table
// record the loader checks it against). Invariants: parsers never crash; a layout that parses has mip byte
// ranges that do not overflow and lie after the header; MipLoader::load never writes past the mip in the
// slot, and a kOk answer's payload is the file's bytes at the table's range.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <span>

#include "fuzz_support.hpp"
#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/server/cache/eviction_policy.hpp"
#include "texstream/server/cache/mip_cache.hpp"
#include "texstream/server/load/mip_loader.hpp"
#include "texstream/server/load/server_stats.hpp"
#include "texstream/server/storage/storage.hpp"

namespace {

using namespace texstream;
using fuzz::check;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 16) return 0;
  uint32_t pick[4];
  std::memcpy(pick, data, 16);
  const std::span<const std::byte> file(reinterpret_cast<const std::byte*>(data + 16), size - 16);

  if (auto layout = scene::parse_dds_layout(file, "fuzz.dds")) {
    for (uint32_t l = 0; l < layout->mip_count && l < 32; ++l) {
      if (layout->encoding == scene::DdsEncoding::kOther) break;
      const uint64_t off = layout->mip_offset(l), n = layout->mip_size(l);
      check(off >= layout->data_offset);
      check(off + n >= off);  // no wrap-around
    }
  }

  // The loader against a texture table record chosen by the input (kept small: a slot of the real size).
  const uint32_t w = 1u + pick[0] % 512, h = 1u + pick[1] % 512;
  const auto format = (pick[2] & 1) ? TexelFormat::kBc1 : TexelFormat::kRgba8;
  const scene::TextureRecord record{w, h, full_mip_count(w, h), static_cast<uint32_t>(format)};
  const uint32_t mip = pick[3] % record.mip_count;
  static fuzz::MemoryStorage storage;
  storage.extension = ".dds";  // every .dds path is the input; other extensions do not exist
  storage.bytes = file;
  auto policy = server::make_eviction_policy("lru", {});
  if (!policy) return 0;
  server::MipCache cache(0, std::move(*policy));  // no caching: every call reads the "file"
  ServerBlock block{};
  server::ServerStats stats{};
  server::MipLoader loader("/fuzz-scene", storage, cache, block, stats);
  const uint64_t want = mip_bytes(format, w, h, mip);
  std::vector<std::byte> slot(want + 64, std::byte{0xa5});
  server::LoadRequest req{TextureId(static_cast<uint32_t>(pick[0] % 4096)), MipLevel(mip), Generation(1), 1.0f, 0};
  const CompletionRecord c = loader.load(req, record, 0, std::span<std::byte>(slot.data(), want));
  for (size_t i = want; i < slot.size(); ++i) check(slot[i] == std::byte{0xa5});  // nothing past the mip
  if (c.status == static_cast<uint32_t>(CompletionStatus::kOk)) check(c.byte_size == want);
  return 0;
}
