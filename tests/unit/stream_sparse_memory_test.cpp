// The renderer's per-texture streaming records cost nothing for a texture not in view (issue 26 item 4;
// docs/design/host_memory.md): TextureStates and MipUseLedger keep an entry only for textures in a state other
// than the default one, and the texture table can be a view of records someone else holds (textures.bin's
// mapping in texstream-render). The heap bound below fails if either record becomes dense again.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdio>
#include <memory>
#include <vector>

#include "../support/heap_usage.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/stream/mip_use_ledger.hpp"
#include "texstream/stream/texture_states.hpp"
#include "texstream/stream/texture_table.hpp"

namespace texstream::stream {
namespace {

using Kind = TextureEvent::Kind;

// 64x64 RGBA8, 7 levels (its initial mip is level 4, 4x4).
constexpr scene::TextureRecord kRecord{64, 64, 7, static_cast<uint32_t>(TexelFormat::kRgba8)};

// The records as a view, as texstream-render hands them over (there: textures.bin's mapping).
TextureTable view_of(std::vector<scene::TextureRecord> records) {
  auto owner = std::make_shared<const std::vector<scene::TextureRecord>>(std::move(records));
  return TextureTable(owner, *owner);
}

TEST(TextureTable, ViewConvertsRecordsAndKeepsTheirOwnerAlive) {
  auto owner = std::make_shared<std::vector<scene::TextureRecord>>(
      std::vector<scene::TextureRecord>{kRecord, {8, 4, 4, static_cast<uint32_t>(TexelFormat::kBc1)}});
  const std::weak_ptr<std::vector<scene::TextureRecord>> alive = owner;
  TextureTable table(owner, *owner);
  owner.reset();
  const TextureTable copy = table;
  table = TextureTable();
  ASSERT_FALSE(alive.expired());  // the copy holds the records
  ASSERT_EQ(copy.size(), 2u);
  EXPECT_EQ(copy[1].width, 8u);
  EXPECT_EQ(copy[1].height, 4u);
  EXPECT_EQ(copy[1].mip_count, 4u);
  EXPECT_EQ(copy[1].format, TexelFormat::kBc1);
  uint32_t widths = 0;
  for (const TextureShape& s : copy) widths += s.width;
  EXPECT_EQ(widths, 72u);
}

TEST(TextureStates, EntriesOnlyForTexturesNotInTheDefaultState) {
  TextureStates states(view_of({kRecord, kRecord, kRecord, {64, 64, 0, kRecord.format}}));
  EXPECT_EQ(states.tracked(), 0u);
  EXPECT_TRUE(states.view(TextureId(3)).broken);  // no mips: from its shape, no entry
  EXPECT_EQ(states.counts().broken, 1u);
  const std::vector<StreamCandidate> list{{TextureId(0), 0, 1}, {TextureId(1), 0, 1}, {TextureId(2), 0, 1}};
  const auto sent = states.run_cycle(list, UINT64_MAX, 0, [](const MipRequest&) { return SendResult::kSent; });
  ASSERT_EQ(sent.sent.size(), 3u);
  EXPECT_EQ(states.tracked(), 3u);
  ASSERT_TRUE(states.on_committed(TextureId(0), MipLevel(4)));
  ASSERT_TRUE(states.on_no_room(TextureId(1), MipLevel(4)));   // back to the default state: its entry goes
  ASSERT_TRUE(states.on_rejected(TextureId(2), MipLevel(4)));  // a counted failure: kept
  EXPECT_EQ(states.tracked(), 2u);
  states.invalidate(TextureId(0));
  states.invalidate(TextureId(2));
  EXPECT_EQ(states.tracked(), 1u);  // texture 2 keeps its failure count
  EXPECT_EQ(states.view(TextureId(2)).failures, 1u);
  EXPECT_EQ(states.view(TextureId(0)).phase, TexturePhase::kInitial);
  const TextureStateCounts c = states.counts();
  EXPECT_EQ(c.initial, 3u);
  EXPECT_EQ(c.broken, 1u);
}

TEST(MipUseLedger, EntriesOnlyWhileAMipIsResident) {
  MipUseLedger ledger(view_of({kRecord, kRecord}));
  const std::vector<TextureEvent> commits{{Kind::kCommitted, TextureId(0), MipLevel(4)},
                                          {Kind::kCommitted, TextureId(0), MipLevel(3)},
                                          {Kind::kCommitted, TextureId(1), MipLevel(4)}};
  ledger.apply(commits);
  EXPECT_EQ(ledger.tracked(), 2u);
  const std::vector<TextureEvent> trim{{Kind::kTrimmed, TextureId(0), MipLevel(4)}};
  ledger.apply(trim);  // level 3 leaves, 4 stays
  EXPECT_EQ(ledger.tracked(), 2u);
  const std::vector<TextureEvent> gone{{Kind::kInvalidated, TextureId(1)}};
  ledger.apply(gone);
  EXPECT_EQ(ledger.tracked(), 1u);
  EXPECT_FALSE(ledger.levels(TextureId(1)).finest.has_value());
  ledger.finish();
  EXPECT_EQ(ledger.tracked(), 0u);
  EXPECT_EQ(ledger.bytes_wasted(), ledger.bytes_uploaded());  // nothing was ever displayed
}

// Bytes malloc holds (arena and mmap'd blocks: a dense 2 M-entry vector is one of the latter).
int64_t heap_in_use() { return static_cast<int64_t>(test::heap_bytes()); }

// 2 M textures, ~1,000 of them streamed, committed, displayed and some evicted over a few cycles: the states and
// the ledger must grow the heap by less than a byte per texture (dense, they were 16 + 8 bytes per texture:
// 48 MB here). The table itself is a view, built before the first measurement.
TEST(TextureStatesAndMipUseLedger, CostLessThanAByteAPerTextureNotInView) {
  constexpr uint32_t kTextures = 2'000'000;
  constexpr uint32_t kInView = 1'000;
  const TextureTable table = view_of(std::vector<scene::TextureRecord>(kTextures, kRecord));
  std::vector<StreamCandidate> list;
  std::vector<TextureEvent> events;
  list.reserve(kInView);
  events.reserve(2 * kInView);
  for (uint32_t i = 0; i < kInView; ++i) list.push_back({TextureId(i * (kTextures / kInView)), 0.0f, 1.0f});

  const int64_t before = heap_in_use();
  {
    TextureStates states(table);
    MipUseLedger ledger(table);
    for (int cycle = 0; cycle < 4; ++cycle) {
      const CycleResult r = states.run_cycle(list, UINT64_MAX, 0, [](const MipRequest&) { return SendResult::kSent; });
      ASSERT_EQ(r.sent.size(), list.size()) << "cycle " << cycle;
      events.clear();
      for (const MipRequest& q : r.sent) events.push_back({Kind::kCommitted, q.texture, q.mip});
      // Every tenth texture of the list is evicted again after its commit.
      for (size_t i = 0; i < r.sent.size(); i += 10) events.push_back({Kind::kInvalidated, r.sent[i].texture});
      states.apply(events);
      ledger.apply(events);
      ledger.observe(list);
    }
    EXPECT_GT(states.tracked(), kInView / 2);  // the test streamed what it meant to
    EXPECT_LE(states.tracked(), kInView);
    EXPECT_GT(ledger.tracked(), kInView / 2);
    EXPECT_LE(ledger.tracked(), kInView);
    const int64_t grown = heap_in_use() - before;
    EXPECT_LT(grown, int64_t{kTextures}) << grown << " bytes for " << kTextures << " textures, " << states.tracked()
                                         << " of them streamed";
    std::printf("states + ledger over %u textures, %zu streamed: %lld bytes of heap (%.4f B/texture)\n", kTextures,
                states.tracked(), static_cast<long long>(grown), static_cast<double>(grown) / kTextures);
  }
}

}  // namespace
}  // namespace texstream::stream
