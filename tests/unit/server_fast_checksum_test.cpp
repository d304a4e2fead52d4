// fast_payload_checksum() must give exactly payload_checksum()'s value (the renderer verifies with the
// latter): every length class of XXH3 (0, 1-3, 4-8, 9-16, 17-128, 129-240, longer, stripes and the tail
// after them) and unaligned starts.
#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <vector>

#include "texstream/protocol/checksum.hpp"
#include "texstream/server/support/fast_checksum.hpp"

namespace texstream::server {
namespace {

TEST(FastChecksum, EqualsThePayloadChecksumForEveryLengthAndAlignment) {
  std::vector<std::byte> bytes(70000);
  uint32_t x = 12345;
  for (std::byte& b : bytes) {
    x = x * 1664525u + 1013904223u;  // any fixed pattern that is not constant
    b = static_cast<std::byte>(x >> 24);
  }
  for (size_t len : {0ul, 1ul, 3ul, 4ul, 8ul, 9ul, 16ul, 17ul, 128ul, 129ul, 240ul, 241ul, 1023ul, 1024ul, 1025ul,
                     4096ul, 16384ul, 65536ul, 69999ul}) {
    for (size_t offset : {0ul, 1ul, 7ul}) {
      if (offset + len > bytes.size()) continue;
      EXPECT_EQ(fast_payload_checksum(bytes.data() + offset, len), payload_checksum(bytes.data() + offset, len))
          << "length " << len << " at offset " << offset;
    }
  }
}

#if defined(__x86_64__) || defined(__i386__)
// fast_payload_checksum() runs only the widest build the CPU has: each build it may choose on another CPU is
// checked here too, where this CPU runs it.
TEST(FastChecksum, EveryVectorBuildEqualsThePayloadChecksum) {
  std::vector<std::byte> bytes(70000);
  uint32_t x = 777;
  for (std::byte& b : bytes) {
    x = x * 1664525u + 1013904223u;
    b = static_cast<std::byte>(x >> 24);
  }
  bool checked_any = false;
  for (size_t len : {0ul, 1ul, 4ul, 9ul, 17ul, 129ul, 241ul, 1024ul, 1025ul, 16384ul, 65536ul, 69999ul}) {
    for (size_t offset : {0ul, 3ul}) {
      if (offset + len > bytes.size()) continue;
      const uint64_t want = payload_checksum(bytes.data() + offset, len);
      if (__builtin_cpu_supports("avx2")) {
        EXPECT_EQ(payload_checksum_avx2(bytes.data() + offset, len), want) << "avx2, length " << len;
        checked_any = true;
      }
      if (__builtin_cpu_supports("avx512f")) {
        EXPECT_EQ(payload_checksum_avx512(bytes.data() + offset, len), want) << "avx512, length " << len;
        checked_any = true;
      }
    }
  }
  if (!checked_any) GTEST_SKIP() << "this CPU has neither AVX2 nor AVX-512F";
}
#endif

TEST(FastChecksum, ChangesWithOneFlippedBit) {
  std::vector<std::byte> bytes(5000, std::byte{7});
  const uint64_t before = fast_payload_checksum(bytes.data(), bytes.size());
  bytes[4321] ^= std::byte{0x10};
  EXPECT_NE(fast_payload_checksum(bytes.data(), bytes.size()), before);
}

}  // namespace
}  // namespace texstream::server
