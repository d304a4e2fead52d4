#pragma once
// The modes of the page policy (stream/page_policy.hpp) as config choices (pages.*): each enum's one table of
// names, here in common so that the config reads them without depending on the policy.
#include <array>
#include <cstdint>

#include "texstream/common/config_choice.hpp"

namespace texstream::pages {

enum class DiscardRule : uint8_t {
  kLru,        // the page unused longest
  kSeed002P_d  // seed 002 Eq. 4: the largest f (l + 1), f frames since last use, l the level (root 0)
};

enum class PageHeuristic : uint8_t {
  kRandom,         // seed 004: a uniform random priority (no heuristic)
  kPixelSum,       // seed 004: pixels that want the page
  kDistance,       // seed 004: 1 / the mean eye distance of those pixels
  kWeightedPixel,  // seed 004: pixels weighted by nearness to the screen centre
  kHotSpot,        // seed 004: WeightedPixel around a centre moved to the border the camera turns towards
  kTexelRatio,     // seed 002 Eq. 3: p_r = r_s / r_t, the screen size over the texture size of the page asked
};

enum class AncestorOrder : uint8_t {
  kNeededOnly,  // only the pages pixels want (seed 004 §4.2's setting)
  kIntern,      // a page's missing ancestors before it; otherwise by priority (seed 004 §4.3)
  kExtern,      // coarser levels before finer ones, by priority within a level (seed 004 §4.3)
};

}  // namespace texstream::pages

namespace texstream {

template <>
struct ChoiceTable<pages::PageHeuristic> {
  static constexpr std::array<ChoiceEntry<pages::PageHeuristic>, 6> kEntries{
      {{pages::PageHeuristic::kRandom, "random", "seed 004's baseline: no heuristic"},
       {pages::PageHeuristic::kPixelSum, "pixel_sum",
        "seed 004: pixels that want the page; best of 14 configurations in texstream-bench pages"},
       {pages::PageHeuristic::kDistance, "distance", "seed 004: 1 / mean eye distance"},
       {pages::PageHeuristic::kWeightedPixel, "weighted_pixel", "seed 004: pixels weighted towards the centre"},
       {pages::PageHeuristic::kHotSpot, "hot_spot", "seed 004: weighted_pixel around the side the camera turns to"},
       {pages::PageHeuristic::kTexelRatio, "texel_ratio", "seed 002 Eq. 3: p_r = r_s / r_t"}}};
};

template <>
struct ChoiceTable<pages::AncestorOrder> {
  static constexpr std::array<ChoiceEntry<pages::AncestorOrder>, 3> kEntries{
      {{pages::AncestorOrder::kNeededOnly, "needed_only", "only the pages pixels want"},
       {pages::AncestorOrder::kIntern, "intern", "seed 004 InternMipMapOrder: a page's missing ancestors first"},
       {pages::AncestorOrder::kExtern, "extern", "seed 004 ExternMipMapOrder: coarser levels first"}}};
};

template <>
struct ChoiceTable<pages::DiscardRule> {
  static constexpr std::array<ChoiceEntry<pages::DiscardRule>, 2> kEntries{
      {{pages::DiscardRule::kLru, "lru", "the page unused longest"},
       {pages::DiscardRule::kSeed002P_d, "seed002", "seed 002 Eq. 4: p_d = frames unused x (level + 1)"}}};
};

}  // namespace texstream
