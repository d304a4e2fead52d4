#pragma once
// Pages of a huge texture (common/page_file.hpp), the renderer's side without Vulkan (issue 28, items 2-3):
//
// - PageTable: which page sits in which cache frame, and for any page the page to sample instead while it is
//   missing: itself or its nearest resident ancestor (seed 004 §3.1.4, §3.2.2.2; seed 002 Fig. 9).
// - PageFrameCache: a bounded set of frames, locked coarsest levels (seed 004 §4.3.1), and the discard rule:
//   least recently used, or seed 002 Eq. 4's p_d = f (l + 1) (frames unused times level + 1).
// - choose_pages: the needbuffer's per-pixel wants aggregated per page and ordered by one of seed 004 §4.2's
//   heuristics (Random, PixelSum, Distance, WeightedPixel, HotSpot) or seed 002 Eq. 3's p_r = r_s / r_t,
//   optionally scaled by NoiseValues, with the ancestors of needed pages streamed in Intern or Extern
//   MipMapOrder (seed 004 §4.3, NoiseValueSkipping). The LookAhead camera is a second needbuffer given to the
//   same call.
// docs/design/pages.md has the definitions where the seeds leave them open.
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "texstream/common/page_file.hpp"
#include "texstream/common/page_modes.hpp"  // DiscardRule, PageHeuristic, AncestorOrder

namespace texstream::pages {

class PageTable {
 public:
  static constexpr uint32_t kNoFrame = ~0u;
  explicit PageTable(const PageGeometry& g);

  const PageGeometry& geometry() const { return g_; }
  void set(PageId p, uint32_t frame) { frame_[g_.slot(p)] = frame; }
  void clear(PageId p) { frame_[g_.slot(p)] = kNoFrame; }
  bool resident(PageId p) const { return frame_[g_.slot(p)] != kNoFrame; }
  uint32_t frame(PageId p) const { return frame_[g_.slot(p)]; }
  // The page to sample for `p`: itself when resident, else its nearest resident ancestor; nullopt when none is.
  std::optional<PageId> available(PageId p) const;

  // Seed 004 §3.2.2.3's indirection table: for every page of the quadtree the frame and level of the page to
  // sample (kNoFrame when nothing is resident above it), made in one pass parents first.
  struct Indirection {
    uint32_t frame;
    uint32_t level;
  };
  std::vector<Indirection> indirection() const;

 private:
  PageGeometry g_;
  std::vector<uint32_t> frame_;
};

class PageFrameCache {
 public:
  // The pages of levels < locked_levels are never evicted (seed 004 §4.3.1 locks the first four).
  PageFrameCache(const PageGeometry& g, uint32_t frames, uint32_t locked_levels, DiscardRule rule);

  const PageTable& table() const { return table_; }
  uint32_t frames() const { return static_cast<uint32_t>(page_of_frame_.size()); }
  uint32_t used_frames() const { return used_; }
  uint64_t evictions() const { return evictions_; }
  // Marks a resident page used in frame `now` (the pages a frame sampled, and those it needed).
  void touch(PageId p, uint64_t now);
  // Puts `p` into a free frame or the frame of the page the rule discards (never a locked page, never one used
  // in frame `now`); returns the frame, nullopt when every frame is locked or used now. Already resident: its frame.
  std::optional<uint32_t> insert(PageId p, uint64_t now);

 private:
  PageTable table_;
  uint32_t locked_levels_;
  DiscardRule rule_;
  std::vector<std::optional<PageId>> page_of_frame_;
  std::vector<uint64_t> last_used_;  // per frame
  uint32_t used_ = 0;
  uint64_t evictions_ = 0;
};

// One needbuffer texel (seed 004 §3.2.3): the page its pixel wants, where the pixel is, how far it is, and the
// fractional level it wants (the page's level is its floor, clamped to the quadtree).
struct PageNeedSample {
  PageId page;
  float sx = 0, sy = 0;  // screen position, -1..1 each (y down)
  float distance = 0;    // from the eye, metres
  float lod = 0;         // wanted level, fractional, in page-file levels (finest = levels - 1)
};

std::string_view to_string(PageHeuristic h);

struct PagePolicyOptions {
  PageHeuristic heuristic = PageHeuristic::kPixelSum;
  bool noise_scaling = false;  // priority times the NoiseValues between the page and its resident ancestor
  AncestorOrder order = AncestorOrder::kNeededOnly;
  bool noise_skipping = false;      // kExtern: ancestors whose NoiseValue is below the threshold are not loaded
  float noise_skip_threshold = -1;  // < 0: the mean NoiseValue of the file's stored pages (the thesis's choice)
  uint64_t seed = 1;                // kRandom
};

// HotSpot's centre: at the screen's border on the side the camera turns towards (the thesis found a centre
// sliding with the speed no better), the middle when it turns slower than `threshold` radians per frame.
struct HotSpot {
  float cx = 0, cy = 0;
};
HotSpot hotspot_from_turn(float yaw_rad, float pitch_rad, float threshold_rad);

struct PageCandidate {
  PageId page;
  double priority = 0;
};

// The pages to load this frame, best first, at most `budget`: wanted by `needs` (one or more needbuffers, the
// LookAhead camera's included), or their ancestors per the order; never resident ones or those in `pending`.
std::vector<PageCandidate> choose_pages(std::span<const PageNeedSample> needs, const PageFile& file,
                                        const PageTable& table, std::span<const PageId> pending,
                                        const PagePolicyOptions& opt, HotSpot hotspot, uint64_t frame, size_t budget);

}  // namespace texstream::pages
