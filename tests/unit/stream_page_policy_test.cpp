// Pages of a huge texture, the renderer's side (stream/page_policy.hpp): the page table's fallback and its
// indirection, the frame cache's discard rules and locked levels, and the order each heuristic and ancestor
// strategy gives (seed 004 §4.2-4.3, seed 002 Eq. 3-4), on page files made in memory with chosen NoiseValues.
#include <gtest/gtest.h>

#include <cstring>
#include <functional>
#include <random>

#include "texstream/stream/page_policy.hpp"

namespace texstream::pages {
namespace {

// A page file of `g` with every page in the image stored and NoiseValues from `noise`; the page bytes are zeros.
PageFile make_file(const PageGeometry& g, const std::function<float(PageId)>& noise) {
  const PageFileHeader h = make_page_file_header(g, g.pages_in_image());
  std::vector<std::byte> bytes(h.data_offset + h.stored_pages * g.page_bytes());
  std::vector<PageIndexEntry> index(g.page_slots(), PageIndexEntry{0, 0, 0.0f});
  uint64_t at = h.data_offset;
  for (uint64_t s = 0; s < index.size(); ++s) {
    const PageId p = g.page_of_slot(s);
    index[s].noise = noise(p);
    if (!g.in_image(p)) continue;
    index[s].offset = at;
    index[s].bytes = static_cast<uint32_t>(g.page_bytes());
    at += g.page_bytes();
  }
  std::memcpy(bytes.data(), &h, sizeof h);
  std::memcpy(bytes.data() + h.index_offset, index.data(), index.size() * sizeof(PageIndexEntry));
  auto f = PageFile::load(
      [&](std::span<std::byte> out, uint64_t offset) -> Result<uint64_t> {
        std::memcpy(out.data(), bytes.data() + offset, out.size());
        return out.size();
      },
      bytes.size(), "memory");
  EXPECT_TRUE(f.ok()) << f.error().message;
  return std::move(f.value());
}

PageGeometry square(uint32_t levels) {
  return PageGeometry::make(TexelFormat::kRgba8, 16u << (levels - 1), 16u << (levels - 1), 16, 0, PageWrap::kClamp, "t")
      .value();
}

PageNeedSample need(PageId p, float sx = 0, float sy = 0, float distance = 10, float lod = -1) {
  return {p, sx, sy, distance, lod < 0 ? static_cast<float>(p.level) : lod};
}

TEST(PageTable, FallsBackToTheNearestResidentAncestorAndTheIndirectionSaysTheSame) {
  const PageGeometry g = square(5);
  PageTable t(g);
  EXPECT_FALSE(t.available({4, 9, 3}).has_value());
  t.set({0, 0, 0}, 7);
  t.set({2, 2, 0}, 3);
  EXPECT_EQ(t.available({4, 9, 3}), (PageId{2, 2, 0}));
  EXPECT_EQ(t.available({4, 0, 15}), (PageId{0, 0, 0}));
  t.clear({2, 2, 0});
  EXPECT_EQ(t.available({4, 9, 3}), (PageId{0, 0, 0}));
  std::mt19937 rng(3);
  for (int round = 0; round < 20; ++round) {
    PageTable r(g);
    for (uint64_t s = 0; s < g.page_slots(); ++s)
      if (rng() % 3 == 0) r.set(g.page_of_slot(s), static_cast<uint32_t>(s));
    const auto ind = r.indirection();
    for (uint64_t s = 0; s < g.page_slots(); ++s) {
      const auto a = r.available(g.page_of_slot(s));
      if (!a) {
        EXPECT_EQ(ind[s].frame, PageTable::kNoFrame);
        continue;
      }
      EXPECT_EQ(ind[s].frame, r.frame(*a));
      EXPECT_EQ(ind[s].level, a->level);
    }
  }
}

TEST(PageFrameCache, EvictsByItsRuleNeverLockedNorUsedNow) {
  const PageGeometry g = square(5);
  for (DiscardRule rule : {DiscardRule::kLru, DiscardRule::kSeed002P_d}) {
    PageFrameCache c(g, 3, 1, rule);
    ASSERT_TRUE(c.insert({0, 0, 0}, 1).has_value());  // locked (level 0)
    ASSERT_TRUE(c.insert({1, 0, 0}, 1).has_value());
    ASSERT_TRUE(c.insert({4, 5, 5}, 2).has_value());
    EXPECT_EQ(c.used_frames(), 3u);
    c.touch({0, 0, 0}, 1);
    // now = 4: the level-1 page unused for 3 frames (p_d 3 * 2 = 6), the level-4 page for 2 (p_d 2 * 5 = 10).
    ASSERT_TRUE(c.insert({3, 1, 1}, 4).has_value());
    const bool lru = rule == DiscardRule::kLru;
    EXPECT_EQ(c.table().resident({1, 0, 0}), !lru) << "rule " << int(rule);
    EXPECT_EQ(c.table().resident({4, 5, 5}), lru) << "rule " << int(rule);
    EXPECT_TRUE(c.table().resident({0, 0, 0}));
    EXPECT_EQ(c.evictions(), 1u);
    // Everything but the locked page used in frame 9: nothing may go.
    c.touch({3, 1, 1}, 9);
    c.touch(lru ? PageId{4, 5, 5} : PageId{1, 0, 0}, 9);
    EXPECT_FALSE(c.insert({2, 0, 0}, 9).has_value());
    EXPECT_TRUE(c.insert({2, 0, 0}, 10).has_value());
  }
}

TEST(ChoosePages, EachHeuristicOrdersAsDefined) {
  const PageGeometry g = square(4);
  const PageFile f = make_file(g, [](PageId) { return 1.0f; });
  PageTable t(g);
  t.set({0, 0, 0}, 0);
  const PageId a{3, 1, 1}, b{3, 6, 6}, c{3, 7, 0};
  std::vector<PageNeedSample> needs;
  for (int i = 0; i < 5; ++i) needs.push_back(need(a, -0.9f, -0.9f, 50));  // many pixels, far, in a corner
  for (int i = 0; i < 3; ++i) needs.push_back(need(b, 0.0f, 0.0f, 20));    // centre
  for (int i = 0; i < 2; ++i) needs.push_back(need(c, 0.95f, 0.0f, 5));    // near, right border
  PagePolicyOptions opt;
  auto order = [&](PageHeuristic h, HotSpot hs = {}) {
    opt.heuristic = h;
    std::vector<PageId> ids;
    for (const auto& pc : choose_pages(needs, f, t, {}, opt, hs, 1, 10)) ids.push_back(pc.page);
    return ids;
  };
  EXPECT_EQ(order(PageHeuristic::kPixelSum), (std::vector<PageId>{a, b, c}));
  EXPECT_EQ(order(PageHeuristic::kDistance), (std::vector<PageId>{c, b, a}));
  EXPECT_EQ(order(PageHeuristic::kWeightedPixel)[0], b);  // 3 centre pixels (weight 1) beat 2 at the border (0.33)
  // Turning right: the centre moves to the right border; there c's 2 pixels weigh 0.98 each, b's 3 only 0.55.
  EXPECT_EQ(order(PageHeuristic::kHotSpot, hotspot_from_turn(0.2f, 0, 0.05f))[0], c);
  EXPECT_EQ(hotspot_from_turn(0.01f, -0.3f, 0.05f).cx, 0.0f);
  EXPECT_EQ(hotspot_from_turn(0.01f, -0.3f, 0.05f).cy, -1.0f);
  const auto r1 = order(PageHeuristic::kRandom);
  EXPECT_EQ(r1.size(), 3u);
  EXPECT_EQ(r1, order(PageHeuristic::kRandom));  // deterministic for one frame and seed
  // Resident and pending pages are never chosen; the budget holds.
  opt.heuristic = PageHeuristic::kPixelSum;
  t.set(a, 1);
  const std::vector<PageId> pending{b};
  const auto rest = choose_pages(needs, f, t, pending, opt, {}, 1, 10);
  ASSERT_EQ(rest.size(), 1u);
  EXPECT_EQ(rest[0].page, c);
  EXPECT_EQ(choose_pages(needs, f, PageTable(g), {}, opt, {}, 1, 2).size(), 2u);
}

TEST(ChoosePages, AncestorOrdersAndNoiseValues) {
  const PageGeometry g = square(4);
  // NoiseValue 0 for level 2 pages on the left half, 10 elsewhere.
  const PageFile f = make_file(g, [](PageId p) { return p.level == 2 && p.x < 2 ? 0.0f : 10.0f; });
  PageTable t(g);
  t.set({0, 0, 0}, 0);
  const PageId left{3, 1, 1}, right{3, 6, 6};
  std::vector<PageNeedSample> needs;
  for (int i = 0; i < 4; ++i) needs.push_back(need(left));
  needs.push_back(need(right));
  PagePolicyOptions opt;
  auto order = [&] {
    std::vector<PageId> ids;
    for (const auto& pc : choose_pages(needs, f, t, {}, opt, {}, 1, 20)) ids.push_back(pc.page);
    return ids;
  };
  // Needed only: just the two pages.
  EXPECT_EQ(order(), (std::vector<PageId>{left, right}));
  // Intern: each page's missing ancestors right before it would come (their priority is the sum below them).
  opt.order = AncestorOrder::kIntern;
  EXPECT_EQ(order(), (std::vector<PageId>{{1, 0, 0}, {2, 0, 0}, left, {1, 1, 1}, {2, 3, 3}, right}));
  // Extern: level by level.
  opt.order = AncestorOrder::kExtern;
  EXPECT_EQ(order(), (std::vector<PageId>{{1, 0, 0}, {1, 1, 1}, {2, 0, 0}, {2, 3, 3}, left, right}));
  // NoiseValueSkipping: the left level-2 ancestor adds nothing over its parent (noise 0 < mean): skipped.
  opt.noise_skipping = true;
  EXPECT_EQ(order(), (std::vector<PageId>{{1, 0, 0}, {1, 1, 1}, {2, 3, 3}, left, right}));
  // NoiseValue scaling: the NoiseValues up to the root (not included): left's 10 + 0 + 10, right's 30; the
  // pixel counts still win (4 * 20 against 1 * 30), until left's whole path changes nothing.
  opt = {};
  opt.noise_scaling = true;
  EXPECT_EQ(order(), (std::vector<PageId>{left, right}));
  const PageFile quiet = make_file(g, [](PageId p) { return p.x < (1u << p.level) / 2 ? 0.0f : 10.0f; });
  std::vector<PageId> ids;
  for (const auto& pc : choose_pages(needs, quiet, t, {}, opt, {}, 1, 20)) ids.push_back(pc.page);
  EXPECT_EQ(ids, (std::vector<PageId>{right, left}));  // the left pages change nothing: last
}

TEST(ChoosePages, TexelRatioAsksForTheNextLevelDownBelowWhatIsShownByHowFarItIsFromWanted) {
  const PageGeometry g = square(5);
  const PageFile f = make_file(g, [](PageId) { return 1.0f; });
  PageTable t(g);
  t.set({0, 0, 0}, 0);
  t.set({1, 1, 1}, 1);
  PagePolicyOptions opt;
  opt.heuristic = PageHeuristic::kTexelRatio;
  // One pixel wants level 4.5 in the right-bottom quarter (shown: level 1), one wants 2.2 in the left-top (shown: 0).
  const std::vector<PageNeedSample> needs{need({4, 12, 12}, 0, 0, 10, 4.5f), need({2, 0, 0}, 0, 0, 10, 2.2f)};
  const auto got = choose_pages(needs, f, t, {}, opt, {}, 1, 10);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].page, (PageId{2, 3, 3}));  // r_s / r_t = 2^(4.5 - 2)
  EXPECT_NEAR(got[0].priority, std::exp2(2.5), 1e-9);
  EXPECT_EQ(got[1].page, (PageId{1, 0, 0}));  // 2^(2.2 - 1)
  EXPECT_NEAR(got[1].priority, std::exp2(1.2), 1e-6);
}

}  // namespace
}  // namespace texstream::pages
