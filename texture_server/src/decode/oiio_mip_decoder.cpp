#include "texstream/server/decode/oiio_mip_decoder.hpp"

#include "texstream/server/decode/decode_helper_pool.hpp"

namespace texstream::server {

// OpenImageIO runs in the texstream-decode helper process (decode/main.cpp, decode_helper.hpp): the server
// does not link it (its libraries were ~121 MB of the server's resident set), and a crash or hang inside it
// on a hostile file costs one error completion, not the server.
Status decode_mip_rgba8(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                        std::span<std::byte> out, DecodeOutcome& outcome) {
  const uint64_t out_bytes = mip_bytes(TexelFormat::kRgba8, expected);
  TS_ASSERT(out.size() >= out_bytes, "decode target of %zu bytes for %llu", out.size(),
            static_cast<unsigned long long>(out_bytes));
  outcome.bytes_read = 0;
  return default_decode_helper_pool().decode(file, path, level, expected, out, outcome.bytes_read);
}

}  // namespace texstream::server
