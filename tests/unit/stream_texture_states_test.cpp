// TextureStates: seed 000 Algorithm 1 / §3.5 on hand-computed cycles. Pure: no clock, no shared memory.
//
// Mip sizes used below (RGBA8, 4 bytes a texel; BC1, 8 bytes a 4x4 block):
//   256x256 RGBA8: level 6 = 4x4 = 64 B, 5 = 256 B, 4 = 1 KiB, 3 = 4 KiB, 2 = 16 KiB, 1 = 64 KiB, 0 = 256 KiB
//   1024x1024 BC1: level 8 = 4x4 = one block = 8 B
//   64x16 RGBA8:   level 4 = 4x1 = 16 B
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "texstream/stream/texture_states.hpp"

namespace texstream {
namespace {

constexpr TextureShape kBig{256, 256, 9, TexelFormat::kRgba8};     // id 0
constexpr TextureShape kBc1{1024, 1024, 11, TexelFormat::kBc1};    // id 1
constexpr TextureShape kWide{64, 16, 7, TexelFormat::kRgba8};      // id 2
constexpr TextureShape kTiny{2, 2, 2, TexelFormat::kRgba8};        // id 3
constexpr TextureShape kNoMips{256, 256, 0, TexelFormat::kRgba8};  // id 4

constexpr TextureId T0{0}, T1{1}, T2{2}, T3{3}, T4{4};
constexpr uint64_t kHuge = 1ull << 40;

std::vector<TextureShape> table() { return {kBig, kBc1, kWide, kTiny, kNoMips}; }

stream::StreamCandidate cand(TextureId t, float desired, float weight = 1) { return {t, desired, weight}; }

// A sender that accepts everything and records it.
struct Recorder {
  std::vector<stream::MipRequest> got;
  stream::TextureStates::Sender fn() {
    return [this](const stream::MipRequest& r) {
      got.push_back(r);
      return stream::SendResult::kSent;
    };
  }
};

std::vector<uint32_t> mips_of(const stream::CycleResult& r) {
  std::vector<uint32_t> m;
  for (const auto& q : r.sent) m.push_back(q.mip.value);
  return m;
}

TEST(InitialMipLevel, IsTheFourByFourLevel) {
  EXPECT_EQ(stream::initial_mip_level(kBig), 6u);   // 256 >> 6 = 4
  EXPECT_EQ(stream::initial_mip_level(kBc1), 8u);   // 1024 >> 8 = 4
  EXPECT_EQ(stream::initial_mip_level(kWide), 4u);  // larger side 64 >> 4 = 4 (the level is 4x1)
  EXPECT_EQ(stream::initial_mip_level({4, 4, 3, TexelFormat::kRgba8}), 0u);
  EXPECT_EQ(stream::initial_mip_level({8, 8, 4, TexelFormat::kRgba8}), 1u);
  // Non-power-of-two: the coarsest level whose larger side is still >= 4 (300 >> 6 = 4, 300 >> 7 = 2).
  EXPECT_EQ(stream::initial_mip_level({300, 200, 9, TexelFormat::kRgba8}), 6u);
  EXPECT_EQ(stream::initial_mip_level({7, 3, 3, TexelFormat::kRgba8}), 0u);  // 7 >> 1 = 3 < 4
  // Smaller than 4x4: the base level.
  EXPECT_EQ(stream::initial_mip_level(kTiny), 0u);
  EXPECT_EQ(stream::initial_mip_level({1, 1, 1, TexelFormat::kBc1}), 0u);
  // A file that stores fewer levels: clamped to its coarsest stored level.
  EXPECT_EQ(stream::initial_mip_level({256, 256, 3, TexelFormat::kRgba8}), 2u);
}

TEST(TextureStates, StartsInitialAndShapesWithoutMipsAreBroken) {
  stream::TextureStates s(table());
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kInitial);
  EXPECT_FALSE(s.view(T0).resident.has_value());
  EXPECT_FALSE(s.view(T0).pending.has_value());
  EXPECT_TRUE(s.view(T4).broken);
  const auto c = s.counts();
  EXPECT_EQ(c.initial, 4u);
  EXPECT_EQ(c.broken, 1u);
}

TEST(TextureStates, CoarsestFirstThenOneMipPerCycleDownToBase) {
  stream::TextureStates s(table());
  const std::vector<stream::StreamCandidate> list{cand(T0, 0.0f, 7.0f)};
  Recorder rec;

  // Cycle 1: Initial → the 4x4 level 6, Active.
  auto r = s.run_cycle(list, kHuge, 0, rec.fn());
  ASSERT_EQ(mips_of(r), std::vector<uint32_t>{6});
  EXPECT_EQ(r.sent[0].bytes, 64u);
  EXPECT_FLOAT_EQ(r.sent[0].priority, 7.0f);
  EXPECT_EQ(r.bytes, 64u);
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);
  EXPECT_EQ(s.view(T0).pending, 6u);

  // Cycle 2: still pending → nothing (one request per texture in flight).
  r = s.run_cycle(list, kHuge, 0, rec.fn());
  EXPECT_TRUE(r.sent.empty());

  // Each commit lets exactly one finer level go out in the next cycle: 5, 4, 3, 2, 1, then 0 → Final.
  const uint64_t sizes[] = {0, 65536, 16384, 4096, 1024, 256};  // bytes of levels 0..5
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  EXPECT_EQ(s.view(T0).resident, 6u);
  for (uint32_t expect = 5; expect >= 1; --expect) {
    r = s.run_cycle(list, kHuge, 0, rec.fn());
    ASSERT_EQ(mips_of(r), std::vector<uint32_t>{expect});
    EXPECT_EQ(r.sent[0].bytes, sizes[expect]);
    EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);
    // A second cycle before the commit sends nothing.
    EXPECT_TRUE(s.run_cycle(list, kHuge, 0, rec.fn()).sent.empty());
    ASSERT_TRUE(s.on_committed(T0, MipLevel(expect)));
  }
  r = s.run_cycle(list, kHuge, 0, rec.fn());
  ASSERT_EQ(mips_of(r), std::vector<uint32_t>{0});
  EXPECT_EQ(r.sent[0].bytes, 262144u);
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kFinal) << "Final as soon as the base level is requested";
  ASSERT_TRUE(s.on_committed(T0, MipLevel(0)));
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kFinal);
  EXPECT_TRUE(s.run_cycle(list, kHuge, 0, rec.fn()).sent.empty()) << "Final textures request nothing";
  EXPECT_EQ(rec.got.size(), 7u);
}

TEST(TextureStates, RefinesOnlyWhileSampledPlusBiasIsBelowResident) {
  stream::TextureStates s(table());
  Recorder rec;
  // Metadata asks for level 3: 6 → 5 → 4 → 3, then 3 + 0 < 3 is false and it stops.
  std::vector<stream::StreamCandidate> list{cand(T0, 3.0f)};
  uint32_t last = 99;
  for (int i = 0; i < 10; ++i) {
    auto r = s.run_cycle(list, kHuge, 0, rec.fn());
    if (r.sent.empty()) break;
    last = r.sent[0].mip.value;
    ASSERT_TRUE(s.on_committed(T0, r.sent[0].mip));
  }
  EXPECT_EQ(last, 3u);
  EXPECT_EQ(s.view(T0).resident, 3u);
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);

  // A fractional level between 2 and 3 asks for one more (2.5 < 3), and no further (2.5 < 2 is false).
  list[0].desired_mip = 2.5f;
  auto r = s.run_cycle(list, kHuge, 0, rec.fn());
  ASSERT_EQ(mips_of(r), std::vector<uint32_t>{2});
  ASSERT_TRUE(s.on_committed(T0, MipLevel(2)));
  EXPECT_TRUE(s.run_cycle(list, kHuge, 0, rec.fn()).sent.empty());

  // The camera moves away (coarser desire): nothing is unloaded or re-requested.
  list[0].desired_mip = 5.0f;
  EXPECT_TRUE(s.run_cycle(list, kHuge, 0, rec.fn()).sent.empty());
  EXPECT_EQ(s.view(T0).resident, 2u);
}

TEST(TextureStates, BiasHoldsBackRefinementUntilItDrops) {
  stream::TextureStates s(table());
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 2.0f)};
  // b = 1.5: refine while 3.5 < resident: 6 (initial) → 5 → 4 → 3, then 3.5 < 3 fails.
  std::vector<uint32_t> sent;
  for (int i = 0; i < 10; ++i) {
    auto r = s.run_cycle(list, kHuge, 1.5f, rec.fn());
    if (r.sent.empty()) break;
    sent.push_back(r.sent[0].mip.value);
    ASSERT_TRUE(s.on_committed(T0, r.sent[0].mip));
  }
  EXPECT_EQ(sent, (std::vector<uint32_t>{6, 5, 4, 3}));
  // The initial level is loaded whatever the bias: b only gates the Active step.
  stream::TextureStates fresh(table());
  EXPECT_EQ(mips_of(fresh.run_cycle(list, kHuge, 100.0f, rec.fn())), std::vector<uint32_t>{6});
  // Bias falls to 0: 2 < 3 → level 2 goes out, then 2 < 2 fails.
  EXPECT_EQ(mips_of(s.run_cycle(list, kHuge, 0.0f, rec.fn())), std::vector<uint32_t>{2});
  ASSERT_TRUE(s.on_committed(T0, MipLevel(2)));
  EXPECT_TRUE(s.run_cycle(list, kHuge, 0.0f, rec.fn()).sent.empty());
}

TEST(TextureStates, LoadSizeStopsTheCycleAfterTheMipThatExceedsIt) {
  // Three Initial textures in weight order: T0 (64 B), T1 (8 B), T2 (16 B).
  const std::vector<stream::StreamCandidate> list{cand(T0, 0, 30), cand(T1, 0, 20), cand(T2, 0, 10)};
  {
    // s = 50: 0 > 50 no → T0 (64 B); 64 > 50 → stop before T1.
    stream::TextureStates s(table());
    Recorder rec;
    auto r = s.run_cycle(list, 50, 0, rec.fn());
    ASSERT_EQ(r.sent.size(), 1u);
    EXPECT_EQ(r.sent[0].texture, T0);
    EXPECT_TRUE(r.stopped_by_load_size);
    EXPECT_EQ(s.view(T1).phase, stream::TexturePhase::kInitial) << "the texture at the limit keeps its state";
    EXPECT_FALSE(s.view(T1).pending.has_value());
    // Next cycle: T0 pending, so T1 and T2 fit: 0 → T1 (8), 8 > 50 no → T2 (16).
    r = s.run_cycle(list, 50, 0, rec.fn());
    ASSERT_EQ(r.sent.size(), 2u);
    EXPECT_EQ(r.sent[0].texture, T1);
    EXPECT_EQ(r.sent[1].texture, T2);
    EXPECT_EQ(r.bytes, 24u);
    EXPECT_FALSE(r.stopped_by_load_size);
  }
  {
    // s = 64: T0 (64), 64 > 64 no → T1 (72 total), 72 > 64 → stop before T2.
    stream::TextureStates s(table());
    Recorder rec;
    auto r = s.run_cycle(list, 64, 0, rec.fn());
    ASSERT_EQ(r.sent.size(), 2u);
    EXPECT_EQ(r.bytes, 72u);
    EXPECT_TRUE(r.stopped_by_load_size);
  }
  {
    // s = 0: the first mip still goes (0 > 0 is false), then the cycle stops.
    stream::TextureStates s(table());
    Recorder rec;
    auto r = s.run_cycle(list, 0, 0, rec.fn());
    ASSERT_EQ(r.sent.size(), 1u);
    EXPECT_TRUE(r.stopped_by_load_size);
  }
}

TEST(TextureStates, MaxRequestsCapsTheCycle) {
  stream::TextureStates s(table());
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 0), cand(T1, 0), cand(T2, 0)};
  auto r = s.run_cycle(list, kHuge, 0, rec.fn(), 2);
  ASSERT_EQ(r.sent.size(), 2u);
  EXPECT_TRUE(r.stopped_by_count);
  EXPECT_FALSE(r.stopped_by_load_size);
  EXPECT_EQ(s.view(T2).phase, stream::TexturePhase::kInitial);
  r = s.run_cycle(list, kHuge, 0, rec.fn(), 2);
  ASSERT_EQ(r.sent.size(), 1u);
  EXPECT_EQ(r.sent[0].texture, T2);
  EXPECT_FALSE(r.stopped_by_count);
}

TEST(TextureStates, TexturesWithNothingToLoadDoNotEndTheCycle) {
  stream::TextureStates s(table());
  Recorder rec;
  // T0 is pending after the first cycle; it must not stop T1 behind it even with s = 0.
  ASSERT_EQ(s.run_cycle(std::vector<stream::StreamCandidate>{cand(T0, 0)}, kHuge, 0, rec.fn()).sent.size(), 1u);
  auto r = s.run_cycle(std::vector<stream::StreamCandidate>{cand(T0, 0), cand(T1, 0)}, 0, 0, rec.fn());
  ASSERT_EQ(r.sent.size(), 1u);
  EXPECT_EQ(r.sent[0].texture, T1);
  EXPECT_EQ(r.sent[0].mip.value, 8u);
  EXPECT_EQ(r.sent[0].bytes, 8u) << "a BC1 4x4 level is one 8-byte block";
}

TEST(TextureStates, SmallerThanFourByFourGoesStraightToFinal) {
  stream::TextureStates s(table());
  Recorder rec;
  auto r = s.run_cycle(std::vector<stream::StreamCandidate>{cand(T3, 0)}, kHuge, 0, rec.fn());
  ASSERT_EQ(mips_of(r), std::vector<uint32_t>{0});
  EXPECT_EQ(r.sent[0].bytes, 16u);  // 2x2 RGBA8
  EXPECT_EQ(s.view(T3).phase, stream::TexturePhase::kFinal);
  // Its failure returns it to Initial (nothing is displayed), not Active.
  ASSERT_TRUE(s.on_failed(T3, MipLevel(0), CompletionStatus::kUnfilled));
  EXPECT_EQ(s.view(T3).phase, stream::TexturePhase::kInitial);
  EXPECT_EQ(mips_of(s.run_cycle(std::vector<stream::StreamCandidate>{cand(T3, 0)}, kHuge, 0, rec.fn())),
            std::vector<uint32_t>{0});
  ASSERT_TRUE(s.on_committed(T3, MipLevel(0)));
  EXPECT_EQ(s.view(T3).phase, stream::TexturePhase::kFinal);
  EXPECT_EQ(s.view(T3).resident, 0u);
}

TEST(TextureStates, TransientFailuresRollBackAndRetry) {
  stream::TextureStates s(table());
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 0)};
  // The initial request fails: back to Initial, the same level is asked again.
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{6});
  ASSERT_TRUE(s.on_failed(T0, MipLevel(6), CompletionStatus::kUnfilled));
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kInitial);
  EXPECT_FALSE(s.view(T0).pending.has_value());
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{6});
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  // A refinement fails: stays Active with level 6 resident, asks for 5 again.
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{5});
  ASSERT_TRUE(s.on_failed(T0, MipLevel(5), CompletionStatus::kTimedOut));
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);
  EXPECT_EQ(s.view(T0).resident, 6u);
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{5});
  // Lost with a dead server (kCancelled), many times: never counted, never broken.
  for (int i = 0; i < 10; ++i) {
    ASSERT_TRUE(s.on_failed(T0, MipLevel(5), CompletionStatus::kCancelled));
    ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{5});
  }
  EXPECT_FALSE(s.view(T0).broken);
  EXPECT_EQ(s.view(T0).failures, 0u);
  // Walk down to the base level; its failure returns Final → Active.
  for (uint32_t m = 5; m >= 1; --m) {
    ASSERT_TRUE(s.on_committed(T0, MipLevel(m)));
    ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{m - 1});
  }
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kFinal);
  ASSERT_TRUE(s.on_failed(T0, MipLevel(0), CompletionStatus::kUnfilled));
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);
  EXPECT_EQ(s.view(T0).resident, 1u);
  EXPECT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{0});
}

TEST(TextureStates, NotFoundAndCorruptBreakTheTextureForTheSession) {
  for (CompletionStatus st : {CompletionStatus::kNotFound, CompletionStatus::kCorrupt}) {
    stream::TextureStates s(table());
    Recorder rec;
    const std::vector<stream::StreamCandidate> list{cand(T0, 0), cand(T1, 0)};
    ASSERT_EQ(s.run_cycle(list, kHuge, 0, rec.fn()).sent.size(), 2u);
    ASSERT_TRUE(s.on_failed(T0, MipLevel(6), st));
    EXPECT_TRUE(s.view(T0).broken) << to_string(st);
    ASSERT_TRUE(s.on_committed(T1, MipLevel(8)));
    // T0 is skipped from now on, even after an eviction; T1 goes on refining.
    auto r = s.run_cycle(list, kHuge, 0, rec.fn());
    ASSERT_EQ(r.sent.size(), 1u);
    EXPECT_EQ(r.sent[0].texture, T1);
    s.invalidate(T0);
    for (int i = 0; i < 3; ++i) {
      for (const auto& q : s.run_cycle(list, kHuge, 0, rec.fn()).sent) EXPECT_NE(q.texture, T0);
    }
    EXPECT_EQ(s.counts().broken, 2u);  // T0 and the mip-less T4
  }
}

TEST(TextureStates, RepeatedIoErrorsOrRejectsBreakTheTextureButACommitResetsTheCount) {
  stream::TextureStates s(table());
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 0)};
  for (uint32_t i = 0; i + 1 < stream::TextureStates::kMaxCountedFailures; ++i) {
    ASSERT_EQ(s.run_cycle(list, kHuge, 0, rec.fn()).sent.size(), 1u);
    ASSERT_TRUE(i % 2 ? s.on_rejected(T0, MipLevel(6)) : s.on_failed(T0, MipLevel(6), CompletionStatus::kIoError));
    EXPECT_FALSE(s.view(T0).broken);
  }
  EXPECT_EQ(s.view(T0).failures, stream::TextureStates::kMaxCountedFailures - 1);
  ASSERT_EQ(s.run_cycle(list, kHuge, 0, rec.fn()).sent.size(), 1u);
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  EXPECT_EQ(s.view(T0).failures, 0u);
  for (uint32_t i = 0; i < stream::TextureStates::kMaxCountedFailures; ++i) {
    ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{5});
    ASSERT_TRUE(s.on_rejected(T0, MipLevel(5)));
  }
  EXPECT_TRUE(s.view(T0).broken);
  EXPECT_TRUE(s.run_cycle(list, kHuge, 0, rec.fn()).sent.empty());
  EXPECT_EQ(s.view(T0).resident, 6u) << "what is resident stays displayable";
}

TEST(TextureStates, EvictionResetsToInitialAndRefusesTheLateAnswer) {
  stream::TextureStates s(table());
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 0)};
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{6});
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{5});
  s.invalidate(T0);  // its cache layer was reused while level 5 was in flight
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kInitial);
  EXPECT_FALSE(s.view(T0).resident.has_value());
  EXPECT_FALSE(s.view(T0).pending.has_value());
  EXPECT_FALSE(s.on_committed(T0, MipLevel(5))) << "the old request's answer must not count as resident";
  EXPECT_FALSE(s.on_failed(T0, MipLevel(5), CompletionStatus::kNotFound));
  EXPECT_FALSE(s.view(T0).broken);
  // Streaming starts over from the 4x4 level.
  EXPECT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), std::vector<uint32_t>{6});
  // A Final texture is evicted too.
  stream::TextureStates f(table());
  ASSERT_EQ(mips_of(f.run_cycle(std::vector<stream::StreamCandidate>{cand(T3, 0)}, kHuge, 0, rec.fn())),
            std::vector<uint32_t>{0});
  ASSERT_TRUE(f.on_committed(T3, MipLevel(0)));
  f.invalidate(T3);
  EXPECT_EQ(f.view(T3).phase, stream::TexturePhase::kInitial);
  EXPECT_EQ(mips_of(f.run_cycle(std::vector<stream::StreamCandidate>{cand(T3, 0)}, kHuge, 0, rec.fn())),
            std::vector<uint32_t>{0});
}

// The frame loop hands the cache's events over in one list (TextureCache::take_events): the same states as
// the calls one by one, in the same order.
// The cache dropped levels finer than the view wants (TextureCache::trim_one): the finest resident level moves
// up, a Final texture is Active again and refines only when the view asks for finer again.
TEST(TextureStates, TrimmedLevelsAreRefinedAgainOnlyWhenWanted) {
  stream::TextureStates s(table());
  Recorder rec;
  const std::vector<stream::StreamCandidate> close{cand(T0, 0.0f)};
  s.run_cycle(close, kHuge, 0, rec.fn());
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  for (uint32_t m = 5;; --m) {
    ASSERT_EQ(mips_of(s.run_cycle(close, kHuge, 0, rec.fn())), std::vector<uint32_t>{m});
    ASSERT_TRUE(s.on_committed(T0, MipLevel(m)));
    if (m == 0) break;
  }
  ASSERT_EQ(s.view(T0).phase, stream::TexturePhase::kFinal);
  s.apply(std::vector<stream::TextureEvent>{{stream::TextureEvent::Kind::kTrimmed, T0, MipLevel(3)}});
  EXPECT_EQ(s.view(T0).resident, 3u);
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);
  // Far (wants 4): nothing to load. A trim to a finer level than resident, or of another texture, changes nothing.
  const std::vector<stream::StreamCandidate> far{cand(T0, 4.0f)};
  EXPECT_TRUE(s.run_cycle(far, kHuge, 0, rec.fn()).sent.empty());
  s.on_trimmed(T0, MipLevel(1));
  s.on_trimmed(T0, MipLevel(32));  // no such level: ignored
  s.on_trimmed(T1, MipLevel(2));
  EXPECT_EQ(s.view(T0).resident, 3u);
  EXPECT_FALSE(s.view(T1).resident.has_value());
  // Close again (wants 1): refines 2, then 1.
  const std::vector<stream::StreamCandidate> nearer{cand(T0, 1.0f)};
  ASSERT_EQ(mips_of(s.run_cycle(nearer, kHuge, 0, rec.fn())), std::vector<uint32_t>{2});
  ASSERT_TRUE(s.on_committed(T0, MipLevel(2)));
  ASSERT_EQ(mips_of(s.run_cycle(nearer, kHuge, 0, rec.fn())), std::vector<uint32_t>{1});
}

// stream.levels_in_flight > 1: a texture's chain is pipelined. The first pass of a cycle is Algorithm 1's (each
// texture its next level, in list order); each further pass gives one more level to the textures the pass before
// sent one, at weight / 4^pass, so no texture's deeper level goes before another's next one.
TEST(TextureStates, PipelinedLevelsGoOutBreadthFirstAtFallingPriority) {
  stream::TextureStates s(table(), 3);
  EXPECT_EQ(s.levels_in_flight(), 3u);
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 0.0f, 8.0f), cand(T1, 0.0f, 4.0f), cand(T0, 0.0f, 2.0f)};
  auto r = s.run_cycle(list, kHuge, 0, rec.fn());
  ASSERT_EQ(mips_of(r), (std::vector<uint32_t>{6, 8, 5, 7, 4, 6})) << "T0 listed twice takes one level per pass";
  const float priorities[] = {8, 4, 2, 1, 0.5f, 0.25f};
  for (size_t i = 0; i < r.sent.size(); ++i) EXPECT_FLOAT_EQ(r.sent[i].priority, priorities[i]) << i;
  EXPECT_EQ(s.view(T0).pending_levels, 3u);
  EXPECT_EQ(s.view(T0).pending, 4u) << "the finest level in flight";
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);
  EXPECT_TRUE(s.run_cycle(list, kHuge, 0, rec.fn()).sent.empty()) << "three levels in flight each: nothing more";

  // Answers in any order: a finer level that arrives first is resident on its own (the shader samples the run
  // that ends at the coarsest resident level); the run grows as the coarser ones arrive.
  ASSERT_TRUE(s.on_committed(T0, MipLevel(4)));
  EXPECT_EQ(s.view(T0).resident, 4u);
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  EXPECT_EQ(s.view(T0).resident, 6u);
  // One level back in flight room: the next is the one after everything resident or pending (3).
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), (std::vector<uint32_t>{3, 2}));
  ASSERT_TRUE(s.on_committed(T0, MipLevel(5)));
  EXPECT_EQ(s.view(T0).resident, 4u);
  // The load size stops the cycle across passes too, tested before each load: 64 B (level 6) then 256 B
  // (level 5) go with s = 100 B, level 4 does not.
  stream::TextureStates fresh(table(), 3);
  const auto limited = fresh.run_cycle(std::vector<stream::StreamCandidate>{cand(T0, 0.0f)}, 100, 0, rec.fn());
  ASSERT_EQ(mips_of(limited), (std::vector<uint32_t>{6, 5}));
  EXPECT_TRUE(limited.stopped_by_load_size);
}

TEST(TextureStates, APipelinedLevelThatFailsIsAskedForAgainBeforeAnythingFiner) {
  stream::TextureStates s(table(), 3);
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 0.0f)};
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), (std::vector<uint32_t>{6, 5, 4}));
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  ASSERT_TRUE(s.on_failed(T0, MipLevel(5), CompletionStatus::kTimedOut));
  ASSERT_TRUE(s.on_committed(T0, MipLevel(4)));
  EXPECT_EQ(s.view(T0).resident, 6u) << "level 4 waits for 5: the sampled run ends at 6";
  EXPECT_FALSE(s.view(T0).pending.has_value());
  // The hole first, then what follows the run 6..4 it closes.
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), (std::vector<uint32_t>{5, 3, 2}));
  ASSERT_TRUE(s.on_committed(T0, MipLevel(5)));
  EXPECT_EQ(s.view(T0).resident, 4u);
  // An eviction drops everything, pending included; late answers are refused.
  s.invalidate(T0);
  EXPECT_FALSE(s.on_committed(T0, MipLevel(3)));
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kInitial);
  EXPECT_EQ(s.view(T0).pending_levels, 0u);
  // The base level in flight makes the texture Final only once every level down to it is covered.
  ASSERT_EQ(mips_of(s.run_cycle(list, kHuge, 0, rec.fn())), (std::vector<uint32_t>{6, 5, 4}));
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kActive);
}

TEST(TextureStates, ApplyingEventsEqualsTheCallsInOrder) {
  stream::TextureStates direct(table()), applied(table());
  Recorder rec;
  const std::vector<stream::StreamCandidate> list{cand(T0, 0), cand(T1, 0), cand(T2, 0)};
  ASSERT_EQ(mips_of(direct.run_cycle(list, kHuge, 0, rec.fn())), mips_of(applied.run_cycle(list, kHuge, 0, rec.fn())));
  direct.on_committed(T0, MipLevel(6));
  direct.on_failed(T1, MipLevel(8), CompletionStatus::kIoError);
  direct.on_rejected(T2, MipLevel(4));
  direct.invalidate(T0);
  direct.on_committed(T0, MipLevel(6));  // a late answer, refused after the invalidate
  using K = stream::TextureEvent::Kind;
  applied.apply(std::vector<stream::TextureEvent>{{K::kCommitted, T0, MipLevel(6)},
                                                  {K::kFailed, T1, MipLevel(8), CompletionStatus::kIoError},
                                                  {K::kRejected, T2, MipLevel(4)},
                                                  {K::kInvalidated, T0},
                                                  {K::kCommitted, T0, MipLevel(6)}});
  for (TextureId t : {T0, T1, T2}) {
    const stream::TextureStateView a = direct.view(t), b = applied.view(t);
    EXPECT_EQ(a.phase, b.phase) << t.value;
    EXPECT_EQ(a.resident, b.resident) << t.value;
    EXPECT_EQ(a.pending, b.pending) << t.value;
    EXPECT_EQ(a.failures, b.failures) << t.value;
  }
  EXPECT_EQ(applied.view(T0).phase, stream::TexturePhase::kInitial);
  EXPECT_EQ(applied.view(T1).failures, 1u);
  EXPECT_EQ(applied.view(T2).failures, 1u);
}

TEST(TextureStates, SenderSkipLeavesTheTextureAloneAndStopEndsTheCycle) {
  stream::TextureStates s(table());
  const std::vector<stream::StreamCandidate> list{cand(T0, 0), cand(T1, 0), cand(T2, 0)};
  std::vector<uint32_t> offered;
  auto r = s.run_cycle(list, kHuge, 0, [&](const stream::MipRequest& q) {
    offered.push_back(q.texture.value);
    if (q.texture == T0) return stream::SendResult::kSkip;
    if (q.texture == T2) return stream::SendResult::kStop;
    return stream::SendResult::kSent;
  });
  EXPECT_EQ(offered, (std::vector<uint32_t>{0, 1, 2}));
  ASSERT_EQ(r.sent.size(), 1u);
  EXPECT_EQ(r.sent[0].texture, T1);
  EXPECT_TRUE(r.stopped_by_sender);
  EXPECT_EQ(s.view(T0).phase, stream::TexturePhase::kInitial);
  EXPECT_EQ(s.view(T2).phase, stream::TexturePhase::kInitial);
  EXPECT_EQ(s.view(T1).phase, stream::TexturePhase::kActive);
}

TEST(TextureStates, DuplicateEntriesUnknownIdsAndNaNAreHarmless) {
  stream::TextureStates s(table());
  Recorder rec;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<stream::StreamCandidate> list{cand(T0, 0, 9), cand(TextureId(77), 0, 8), cand(T0, 0, 7),
                                                  cand(TextureId(0xffffffffu), 0, 6)};
  auto r = s.run_cycle(list, kHuge, 0, rec.fn());
  ASSERT_EQ(r.sent.size(), 1u) << "one request per texture per cycle";
  EXPECT_FLOAT_EQ(r.sent[0].priority, 9.0f) << "the heaviest entry decides the priority";
  EXPECT_EQ(r.unknown_textures, 2u);
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  EXPECT_TRUE(s.run_cycle(std::vector<stream::StreamCandidate>{cand(T0, nan)}, kHuge, 0, rec.fn()).sent.empty())
      << "a NaN level from the metadata refines nothing";
  EXPECT_FALSE(s.on_committed(TextureId(77), MipLevel(0)));
  s.invalidate(TextureId(77));  // ignored
}

TEST(TextureStates, EventsForMipsThatAreNotPendingAreRefused) {
  stream::TextureStates s(table());
  Recorder rec;
  EXPECT_FALSE(s.on_committed(T0, MipLevel(6))) << "nothing was asked";
  ASSERT_EQ(s.run_cycle(std::vector<stream::StreamCandidate>{cand(T0, 0)}, kHuge, 0, rec.fn()).sent.size(), 1u);
  EXPECT_FALSE(s.on_committed(T0, MipLevel(5)));
  EXPECT_FALSE(s.on_failed(T0, MipLevel(4), CompletionStatus::kCorrupt));
  EXPECT_FALSE(s.on_rejected(T0, MipLevel(3)));
  EXPECT_FALSE(s.view(T0).broken);
  EXPECT_EQ(s.view(T0).pending, 6u);
  ASSERT_TRUE(s.on_committed(T0, MipLevel(6)));
  EXPECT_FALSE(s.on_committed(T0, MipLevel(6))) << "a second commit of the same mip";
}

TEST(TextureStates, CountsFollowThePhases) {
  stream::TextureStates s(table());
  Recorder rec;
  (void)s.run_cycle(std::vector<stream::StreamCandidate>{cand(T0, 0), cand(T3, 0)}, kHuge, 0, rec.fn());
  const auto c = s.counts();
  EXPECT_EQ(c.initial, 2u);  // T1, T2
  EXPECT_EQ(c.active, 1u);   // T0
  EXPECT_EQ(c.final, 1u);    // T3
  EXPECT_EQ(c.pending, 2u);
  EXPECT_EQ(c.broken, 1u);  // T4
}

}  // namespace
}  // namespace texstream
