// payload_checksum() (the widest XXH3 build the CPU runs: AVX-512, AVX2 or the library's SSE2) must give exactly
// XXH3-64's value as its portable scalar build computes it, so that a server and a renderer on different CPUs agree:
// every length class of XXH3 (0, 1-3, 4-8, 9-16, 17-128, 129-240, longer, stripes and the tail after them)
// and unaligned starts.
#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <vector>

#include "texstream/protocol/checksum.hpp"

// The reference: XXH3 compiled into this file for plain scalar code (no vector unit).
#define XXH_INLINE_ALL
#define XXH_VECTOR XXH_SCALAR
#include <xxhash.h>

namespace texstream {
namespace {

uint64_t scalar_xxh3(const void* data, size_t bytes) { return XXH3_64bits(data, bytes); }

TEST(PayloadChecksum, EqualsTheScalarXxh3ForEveryLengthAndAlignment) {
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
      EXPECT_EQ(payload_checksum(bytes.data() + offset, len), scalar_xxh3(bytes.data() + offset, len))
          << "length " << len << " at offset " << offset;
    }
  }
}

// payload_checksum() runs only the widest build the CPU has: each build it may choose on another CPU is
// checked here too, where this CPU runs it.
TEST(PayloadChecksum, EveryBuildEqualsTheScalarXxh3) {
  std::vector<std::byte> bytes(70000);
  uint32_t x = 777;
  for (std::byte& b : bytes) {
    x = x * 1664525u + 1013904223u;
    b = static_cast<std::byte>(x >> 24);
  }
  for (size_t len : {0ul, 1ul, 4ul, 9ul, 17ul, 129ul, 241ul, 1024ul, 1025ul, 16384ul, 65536ul, 69999ul}) {
    for (size_t offset : {0ul, 3ul}) {
      if (offset + len > bytes.size()) continue;
      const uint64_t want = scalar_xxh3(bytes.data() + offset, len);
      EXPECT_EQ(payload_checksum_sse2(bytes.data() + offset, len), want) << "sse2, length " << len;
#if defined(__x86_64__) || defined(__i386__)
      if (__builtin_cpu_supports("avx2")) {
        EXPECT_EQ(payload_checksum_avx2(bytes.data() + offset, len), want) << "avx2, length " << len;
      }
      if (__builtin_cpu_supports("avx512f")) {
        EXPECT_EQ(payload_checksum_avx512(bytes.data() + offset, len), want) << "avx512, length " << len;
      }
#endif
    }
  }
}

TEST(PayloadChecksum, ChangesWithOneFlippedBit) {
  std::vector<std::byte> bytes(5000, std::byte{7});
  const uint64_t before = payload_checksum(bytes.data(), bytes.size());
  bytes[4321] ^= std::byte{0x10};
  EXPECT_NE(payload_checksum(bytes.data(), bytes.size()), before);
}

}  // namespace
}  // namespace texstream
