// The texture table's slots (scene/texture_slots.hpp): a slot per texture drawn in the frame or kept by the cache,
// freed otherwise and reused, so the table follows the textures in use, not the scene (host_memory.md item 3).
#include <gtest/gtest.h>

#include <cstdint>
#include <set>
#include <vector>

#include "texstream/render/scene/texture_slots.hpp"

using texstream::render::TextureSlots;

TEST(TextureSlots, AFrameKeepsTheSlotsItDrawsAndFreesTheRest) {
  TextureSlots slots(1000);
  EXPECT_EQ(slots.find(7), TextureSlots::kNone);
  slots.begin_frame();
  const uint32_t a = slots.use(7), b = slots.use(500), c = slots.use(7);
  EXPECT_EQ(a, c) << "one slot per texture";
  EXPECT_NE(a, b);
  EXPECT_EQ(slots.find(500), b);
  EXPECT_EQ(slots.take_fresh(), (std::vector<uint32_t>{7, 500}));
  EXPECT_TRUE(slots.take_fresh().empty());
  slots.release_unused([](uint32_t) { return false; });
  EXPECT_EQ(slots.in_use(), 2u) << "drawn in the current frame";

  // The next frame draws 7 only; 500 has cache state (kept), 999 was acquired by a commit (freed).
  slots.begin_frame();
  slots.use(7);
  slots.acquire(999);
  slots.release_unused([](uint32_t t) { return t == 500; });
  EXPECT_EQ(slots.find(500), b);
  EXPECT_EQ(slots.find(999), TextureSlots::kNone);
  EXPECT_EQ(slots.in_use(), 2u);
  EXPECT_EQ(slots.released(), 1u);
  // A freed slot is handed out again before the table grows.
  slots.begin_frame();
  slots.use(3);
  EXPECT_EQ(slots.high_water(), 3u);
  slots.release_unused([](uint32_t) { return false; });
  EXPECT_EQ(slots.find(7), TextureSlots::kNone);
  EXPECT_EQ(slots.find(500), TextureSlots::kNone);
  EXPECT_EQ(slots.in_use(), 1u);
}

// 10^6 textures drawn 1,000 a frame, never the same twice: the slots (and the table sized by them) stay at one
// frame's worth; a per-texture table would need 10^6 entries.
TEST(TextureSlots, SlotsFollowTheFrameNotTheTexturesSeen) {
  constexpr uint32_t kTextures = 1'000'000, kPerFrame = 1000;
  TextureSlots slots(kTextures);
  for (uint32_t first = 0; first < kTextures; first += kPerFrame) {
    slots.begin_frame();
    std::set<uint32_t> used;
    for (uint32_t t = first; t < first + kPerFrame; ++t) used.insert(slots.use(t));
    EXPECT_EQ(used.size(), kPerFrame);
    for (uint32_t s : used) ASSERT_LT(s, 2 * kPerFrame);
    slots.release_unused([](uint32_t) { return false; });
  }
  EXPECT_LE(slots.high_water(), 2 * kPerFrame);
  EXPECT_EQ(slots.in_use(), kPerFrame);
}
