// stream.fade_ms's rule on texture-table entries (cache/mip_fades.hpp): what fades from what, for how long,
// and that an eviction, a coarser level or a preload never fades.
#include <gtest/gtest.h>

#include <bit>
#include <limits>
#include <vector>

#include "texstream/render/cache/mip_fades.hpp"

namespace {

using texstream::render::MipFades;
namespace gpu = texstream::gpu;

float left(const gpu::TextureGpu& t) { return std::bit_cast<float>(t.colour.z); }

struct Table {
  std::vector<gpu::TextureGpu> entries = std::vector<gpu::TextureGpu>(4);
  Table() {
    for (auto& t : entries) {
      t.placement = {0, gpu::kNotResident, 0, 10};
      t.colour = {0, gpu::kNotResident, 0, 0};
    }
  }
  // Texture `id` now has levels [finest, coarsest] resident: what TextureCache::publish does.
  void publish(MipFades& f, uint32_t id, uint32_t finest, uint32_t coarsest = 9) {
    auto& t = entries[id];
    const uint32_t before = t.placement.y;
    t.placement.y = finest;
    t.placement.z = coarsest;
    f.on_publish(id, t, before);
  }
};

TEST(MipFades, AFirstLevelFadesInFromTheColormapOverTheFadeTime) {
  MipFades f(0.2);
  Table tb;
  f.advance(0.0, tb.entries);
  tb.publish(f, 1, 7);
  EXPECT_EQ(tb.entries[1].colour.y, gpu::kNotResident);  // from the colormap
  EXPECT_FLOAT_EQ(left(tb.entries[1]), 1.0f);
  f.advance(0.05, tb.entries);
  EXPECT_FLOAT_EQ(left(tb.entries[1]), 0.75f);
  f.advance(0.1, tb.entries);
  EXPECT_FLOAT_EQ(left(tb.entries[1]), 0.25f);
  f.advance(0.1, tb.entries);
  EXPECT_EQ(left(tb.entries[1]), 0.0f);
  EXPECT_EQ(f.fading(), 0u);
  EXPECT_EQ(tb.entries[0].colour.z, 0u);  // untouched
}

TEST(MipFades, AFinerLevelFadesFromTheLevelBeforeIt) {
  MipFades f(1.0);
  Table tb;
  f.advance(0.0, tb.entries);
  tb.publish(f, 2, 6);
  f.advance(2.0, tb.entries);  // settled
  tb.publish(f, 2, 5);
  EXPECT_EQ(tb.entries[2].colour.y, 6u);
  EXPECT_FLOAT_EQ(left(tb.entries[2]), 1.0f);
}

TEST(MipFades, ALevelArrivingMidFadeNeverJumpsByMoreThanHalfALevel) {
  MipFades f(1.0);
  Table tb;
  f.advance(0.0, tb.entries);
  tb.publish(f, 0, 6);
  f.advance(2.0, tb.entries);
  tb.publish(f, 0, 5);  // fades from 6
  f.advance(0.25, tb.entries);
  tb.publish(f, 0, 4);  // 0.75 left: still from 6, the fade goes on
  EXPECT_EQ(tb.entries[0].colour.y, 6u);
  EXPECT_FLOAT_EQ(left(tb.entries[0]), 0.75f);
  f.advance(0.5, tb.entries);
  tb.publish(f, 0, 3);  // 0.25 left: now from 4 (the level that was fading in), a whole fade again
  EXPECT_EQ(tb.entries[0].colour.y, 4u);
  EXPECT_FLOAT_EQ(left(tb.entries[0]), 1.0f);
  EXPECT_EQ(f.fading(), 1u);  // listed once
}

TEST(MipFades, EvictionCoarserLevelsAndPreloadsDoNotFade) {
  MipFades f(1.0);
  Table tb;
  tb.publish(f, 0, 0);  // before the first frame: a preload shows at once
  EXPECT_EQ(tb.entries[0].colour.z, 0u);
  f.advance(0.0, tb.entries);
  tb.publish(f, 1, 3);
  tb.publish(f, 1, 3, 8);  // a coarser level under a fading one: the fade goes on
  EXPECT_FLOAT_EQ(left(tb.entries[1]), 1.0f);
  tb.publish(f, 1, gpu::kNotResident);  // evicted
  EXPECT_EQ(tb.entries[1].colour.z, 0u);
  EXPECT_EQ(tb.entries[1].colour.y, gpu::kNotResident);
  tb.publish(f, 1, 5);  // back: fades from the colormap, listed once
  EXPECT_EQ(tb.entries[1].colour.y, gpu::kNotResident);
  EXPECT_FLOAT_EQ(left(tb.entries[1]), 1.0f);
  tb.publish(f, 2, 4);
  tb.entries[2].placement.y = 6;  // a coarser finest level (partly evicted): at once
  f.on_publish(2, tb.entries[2], 4);
  EXPECT_EQ(tb.entries[2].colour.z, 0u);
  f.advance(0.5, tb.entries);
  EXPECT_FLOAT_EQ(left(tb.entries[1]), 0.5f);
  EXPECT_EQ(f.fading(), 1u);
}

TEST(MipFades, NoFadeTimeMeansNoFades) {
  MipFades f(0.0);
  Table tb;
  f.advance(0.0, tb.entries);
  tb.publish(f, 3, 2);
  EXPECT_EQ(tb.entries[3].colour.z, 0u);
  EXPECT_EQ(f.fading(), 0u);
}

}  // namespace

// stream.fade_when = still: a frame whose camera moved advances by an infinite step, which ends every fade.
TEST(MipFades, AnInfiniteStepEndsEveryFade) {
  MipFades f(100.0);
  Table tb;
  f.advance(0.0, tb.entries);
  tb.publish(f, 0, 7);
  tb.publish(f, 3, 5);
  f.advance(0.1, tb.entries);
  EXPECT_EQ(f.fading(), 2u);
  f.advance(std::numeric_limits<double>::infinity(), tb.entries);
  EXPECT_EQ(f.fading(), 0u);
  for (uint32_t id : {0u, 3u}) {
    EXPECT_EQ(tb.entries[id].colour.y, gpu::kNotResident) << id;
    EXPECT_EQ(tb.entries[id].colour.z, 0u) << id;
  }
}
