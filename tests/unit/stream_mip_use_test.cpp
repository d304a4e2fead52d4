// The weighted mip deficit (mip_deficit.hpp) and the mip-use ledger (mip_use_ledger.hpp) on hand-built lists
// and cache events: displayed levels, weights, the resident run, displayed and wasted bytes.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "texstream/common/texel_format.hpp"
#include "texstream/stream/mip_deficit.hpp"
#include "texstream/stream/mip_use_ledger.hpp"

namespace texstream::stream {
namespace {

using Kind = TextureEvent::Kind;

// 64x64 RGBA8: 7 levels, 16384 bytes at level 0, 4 at level 6.
TextureShape shape64() { return TextureShape{64, 64, 7, TexelFormat::kRgba8}; }
uint64_t bytes64(uint32_t mip) { return mip_bytes(TexelFormat::kRgba8, 64, 64, mip); }

ResidentLevels resident(uint32_t mip_count, uint32_t finest, uint32_t coarsest) {
  return ResidentLevels{mip_count, finest, coarsest};
}

TEST(MipDeficit, DisplayedLevelIsTheCoarserOfWantedAndFinestOrOneBeyondTheChain) {
  EXPECT_DOUBLE_EQ(displayed_level(2.5, resident(7, 4, 4)), 4.0);
  EXPECT_DOUBLE_EQ(displayed_level(2.5, resident(7, 1, 4)), 2.5);
  EXPECT_DOUBLE_EQ(displayed_level(5.0, resident(7, 3, 4)), 5.0);  // coarser than resident: no deficit
  EXPECT_DOUBLE_EQ(displayed_level(0.0, ResidentLevels{7, {}, {}}), 7.0);
}

TEST(MipDeficit, WeightedMeanOverTheList) {
  // Texture 0: wants 1, finest 4 -> 3 levels short, W 1. Texture 1: wants 0.5, nothing -> 10 - 0.5, W 3.
  // Texture 2: wants 2, finest 1 -> 0, W 4.
  const std::vector<StreamCandidate> list = {
      {TextureId(0), 1.0f, 1.0f}, {TextureId(1), 0.5f, 3.0f}, {TextureId(2), 2.0f, 4.0f}};
  auto levels = [](TextureId t) {
    if (t.value == 0) return resident(7, 4, 5);
    if (t.value == 1) return ResidentLevels{10, {}, {}};
    return resident(7, 1, 5);
  };
  EXPECT_DOUBLE_EQ(weighted_mip_deficit(list, levels), (1 * 3.0 + 3 * 9.5 + 4 * 0.0) / 8.0);
}

TEST(MipDeficit, EmptyListAndBadEntriesCountNothing) {
  auto none = [](TextureId) { return ResidentLevels{7, {}, {}}; };
  EXPECT_DOUBLE_EQ(weighted_mip_deficit({}, none), 0.0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<StreamCandidate> bad = {
      {TextureId(0), nan, 1.0f}, {TextureId(1), 1.0f, 0.0f}, {TextureId(2), 1.0f, nan}, {TextureId(3), 6.0f, 2.0f}};
  EXPECT_DOUBLE_EQ(weighted_mip_deficit(bad, none), 1.0);  // only texture 3: 7 - 6
}

TEST(MipUseLedger, ResidencyFollowsTheCacheEventsAndTheRunEndingAtTheCoarsest) {
  MipUseLedger ledger({shape64(), shape64()});
  EXPECT_FALSE(ledger.levels(TextureId(0)).finest.has_value());
  const std::vector<TextureEvent> events = {{Kind::kCommitted, TextureId(0), MipLevel(4)},
                                            {Kind::kCommitted, TextureId(0), MipLevel(3)},
                                            {Kind::kCommitted, TextureId(0), MipLevel(1)},  // a gap at 2
                                            {Kind::kFailed, TextureId(1), MipLevel(4)},
                                            {Kind::kCommitted, TextureId(9), MipLevel(0)}};  // unknown: ignored
  ledger.apply(events);
  const ResidentLevels l = ledger.levels(TextureId(0));
  ASSERT_TRUE(l.finest.has_value());
  EXPECT_EQ(*l.finest, 3u);  // level 1 is not sampled: the shader's run ends at the gap
  EXPECT_EQ(*l.coarsest, 4u);
  EXPECT_EQ(ledger.bytes_uploaded(), bytes64(4) + bytes64(3) + bytes64(1));
  EXPECT_FALSE(ledger.levels(TextureId(1)).finest.has_value());
}

TEST(MipUseLedger, ObserveGivesTheDeficitOfWhatIsResidentNow) {
  MipUseLedger ledger({shape64(), shape64()});
  const std::vector<StreamCandidate> list = {{TextureId(0), 2.0f, 1.0f}, {TextureId(1), 0.0f, 1.0f}};
  EXPECT_DOUBLE_EQ(ledger.observe(list), (5.0 + 7.0) / 2);  // nothing resident: 7 - 2 and 7 - 0
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(4)}});
  EXPECT_DOUBLE_EQ(ledger.observe(list), (2.0 + 7.0) / 2);
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(3)},
                                         {Kind::kCommitted, TextureId(0), MipLevel(2)},
                                         {Kind::kCommitted, TextureId(1), MipLevel(0)}});
  EXPECT_DOUBLE_EQ(ledger.observe(list), 0.0);
  ledger.apply(std::vector<TextureEvent>{{Kind::kInvalidated, TextureId(1), {}}});
  EXPECT_DOUBLE_EQ(ledger.observe(list), 7.0 / 2);
}

TEST(MipUseLedger, MipsNeverSampledWhileResidentAreWasted) {
  MipUseLedger ledger({shape64(), shape64()});
  // Texture 0: 4 then 3 then 2 arrive one frame apart while the view wants 2.5: 4 and 3 are each the finest
  // for a frame (displayed); at 2 the view samples levels 2 and 3 (trilinear). Texture 1: level 4 arrives,
  // the texture leaves the list, level 3 arrives and is never sampled, then it is evicted.
  const std::vector<StreamCandidate> both = {{TextureId(0), 2.5f, 1.0f}, {TextureId(1), 1.0f, 1.0f}};
  const std::vector<StreamCandidate> only0 = {{TextureId(0), 2.5f, 1.0f}};
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(4)},
                                         {Kind::kCommitted, TextureId(1), MipLevel(4)}});
  ledger.observe(both);
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(3)},
                                         {Kind::kCommitted, TextureId(1), MipLevel(3)}});
  ledger.observe(only0);
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(2)}});
  ledger.observe(only0);
  EXPECT_EQ(ledger.bytes_wasted(), 0u);  // nothing has left yet
  ledger.apply(std::vector<TextureEvent>{{Kind::kInvalidated, TextureId(1), {}}});
  EXPECT_EQ(ledger.bytes_wasted(), bytes64(3));  // texture 1's level 4 was displayed, 3 never
  // A level 1 that arrives after the last frame was observed is wasted at the run's end.
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(1)}});
  ledger.finish();
  EXPECT_EQ(ledger.bytes_wasted(), bytes64(3) + bytes64(1));
  const uint64_t uploaded = 2 * bytes64(4) + 2 * bytes64(3) + bytes64(2) + bytes64(1);
  EXPECT_EQ(ledger.bytes_uploaded(), uploaded);
  EXPECT_DOUBLE_EQ(ledger.wasted_fraction(), static_cast<double>(bytes64(3) + bytes64(1)) / uploaded);
  EXPECT_FALSE(ledger.levels(TextureId(0)).finest.has_value());  // finish() empties the residency
}

TEST(MipUseLedger, AWantedLevelCoarserThanTheResidentRunSamplesItsCoarsestAndAReuploadReplaces) {
  MipUseLedger ledger({shape64()});
  EXPECT_TRUE(std::isnan(ledger.wasted_fraction()));
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(5)},
                                         {Kind::kCommitted, TextureId(0), MipLevel(4)}});
  // Wants 6.0, coarser than the run [4, 5]: the shader clamps to 5, so 5 is displayed and 4 is not.
  EXPECT_DOUBLE_EQ(ledger.observe(std::vector<StreamCandidate>{{TextureId(0), 6.0f, 1.0f}}), 0.0);
  // Level 5 arrives again (after a lost answer, say): the first copy leaves displayed, the new one is unseen.
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(5)}});
  EXPECT_EQ(ledger.bytes_wasted(), 0u);
  ledger.finish();
  EXPECT_EQ(ledger.bytes_wasted(), bytes64(4) + bytes64(5));
}

TEST(MipUseLedger, AFractionalWantedLevelDisplaysBothLevelsAroundIt) {
  // Levels 2 and 3 arrive before any frame sees 3 as the finest; the view wants 2.5: trilinear filtering
  // reads 2 and 3, so neither is wasted. Level 1 below it is not read (the view wants no finer than 2.5).
  MipUseLedger ledger({shape64()});
  ledger.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(3)},
                                         {Kind::kCommitted, TextureId(0), MipLevel(2)},
                                         {Kind::kCommitted, TextureId(0), MipLevel(1)}});
  EXPECT_DOUBLE_EQ(ledger.observe(std::vector<StreamCandidate>{{TextureId(0), 2.5f, 1.0f}}), 0.0);
  ledger.finish();
  EXPECT_EQ(ledger.bytes_wasted(), bytes64(1));
  // An integral wanted level reads that level alone.
  MipUseLedger whole({shape64()});
  whole.apply(std::vector<TextureEvent>{{Kind::kCommitted, TextureId(0), MipLevel(3)},
                                        {Kind::kCommitted, TextureId(0), MipLevel(2)}});
  whole.observe(std::vector<StreamCandidate>{{TextureId(0), 2.0f, 1.0f}});
  whole.finish();
  EXPECT_EQ(whole.bytes_wasted(), bytes64(3));
}

}  // namespace
}  // namespace texstream::stream
