#include <gtest/gtest.h>

#include <map>
#include <random>
#include <vector>

#include "texstream/server/cache/flat_mip_map.hpp"

namespace texstream::server {
namespace {

MipKey key(uint32_t texture, uint32_t mip) { return MipKey(TextureId(texture), MipLevel(mip)); }

TEST(FlatMipMapTest, FindsInsertsAndErases) {
  FlatMipMap<int> m;
  EXPECT_TRUE(m.empty());
  EXPECT_EQ(m.find(key(1, 0)), nullptr);
  *m.insert(key(1, 0), 10) += 1;
  m.insert(key(1, 1), 20);
  ASSERT_NE(m.find(key(1, 0)), nullptr);
  EXPECT_EQ(*m.find(key(1, 0)), 11);
  EXPECT_EQ(*m.find(key(1, 1)), 20);
  EXPECT_EQ(m.size(), 2u);
  EXPECT_TRUE(m.erase(key(1, 0)));
  EXPECT_FALSE(m.erase(key(1, 0)));
  EXPECT_EQ(m.find(key(1, 0)), nullptr);
  EXPECT_EQ(*m.find(key(1, 1)), 20);
  EXPECT_EQ(m.size(), 1u);
}

// Random inserts, erases and bulk removals against std::map, through several growths: every key the
// reference holds is found with its value, every other key is not (backward-shift deletion must keep each
// remaining entry on its probe path, including runs that wrap around the end of the table).
TEST(FlatMipMapTest, MatchesAReferenceMapUnderRandomOperations) {
  FlatMipMap<uint64_t> m;
  std::map<uint64_t, uint64_t> ref;
  std::mt19937_64 rng(12345);
  for (int step = 0; step < 200000; ++step) {
    // Keys from a small range so that erases hit and probe runs collide often.
    const MipKey k = key(static_cast<uint32_t>(rng() % 600), static_cast<uint32_t>(rng() % 4));
    const uint64_t op = rng() % 100;
    if (op < 55) {
      if (ref.count(k.value) == 0) {
        m.insert(k, k.value * 3 + 1);
        ref[k.value] = k.value * 3 + 1;
      }
    } else if (op < 99) {
      EXPECT_EQ(m.erase(k), ref.erase(k.value) == 1);
    } else {
      // Remove every entry of an odd texture.
      std::vector<uint64_t> gone;
      m.erase_if_not([](MipKey kk, const uint64_t&) { return kk.texture().value % 2 == 0; },
                     [&gone](const uint64_t& v) { gone.push_back(v); });
      size_t expected = 0;
      for (auto it = ref.begin(); it != ref.end();) {
        if ((it->first >> 32) % 2 == 1) {
          ++expected;
          it = ref.erase(it);
        } else {
          ++it;
        }
      }
      EXPECT_EQ(gone.size(), expected);
    }
    ASSERT_EQ(m.size(), ref.size()) << "step " << step;
    if (step % 1000 == 0) {
      for (uint32_t t = 0; t < 600; ++t) {
        for (uint32_t l = 0; l < 4; ++l) {
          const auto it = ref.find(key(t, l).value);
          const uint64_t* v = m.find(key(t, l));
          if (it == ref.end()) {
            ASSERT_EQ(v, nullptr) << t << "/" << l << " at step " << step;
          } else {
            ASSERT_NE(v, nullptr) << t << "/" << l << " at step " << step;
            EXPECT_EQ(*v, it->second);
          }
        }
      }
      size_t seen = 0;
      m.for_each([&](MipKey kk, const uint64_t& v) {
        ++seen;
        EXPECT_EQ(ref.at(kk.value), v);
      });
      EXPECT_EQ(seen, ref.size());
    }
  }
}

}  // namespace
}  // namespace texstream::server
