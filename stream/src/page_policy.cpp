#include "texstream/stream/page_policy.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <unordered_set>

namespace texstream::pages {

namespace {

uint64_t mix(uint64_t v) {  // splitmix64's finaliser
  v += 0x9e3779b97f4a7c15ull;
  v = (v ^ (v >> 30)) * 0xbf58476d1ce4e5b9ull;
  v = (v ^ (v >> 27)) * 0x94d049bb133111ebull;
  return v ^ (v >> 31);
}

PageId parent(PageId p) { return {p.level - 1, p.x / 2, p.y / 2}; }

// The page on `p`'s path at `level` (<= p.level).
PageId ancestor_at(PageId p, uint32_t level) {
  const uint32_t up = p.level - level;
  return {level, p.x >> up, p.y >> up};
}

struct Aggregate {
  double pixels = 0, weighted = 0, distance = 0, ratio = 0;
};

}  // namespace

PageTable::PageTable(const PageGeometry& g) : g_(g), frame_(g.page_slots(), kNoFrame) {}

std::optional<PageId> PageTable::available(PageId p) const {
  for (;;) {
    if (resident(p)) return p;
    if (p.level == 0) return std::nullopt;
    p = parent(p);
  }
}

std::vector<PageTable::Indirection> PageTable::indirection() const {
  std::vector<Indirection> out(frame_.size());
  for (uint64_t s = 0; s < frame_.size(); ++s) {  // slots are level-major: a parent's entry is made before
    const PageId p = g_.page_of_slot(s);
    if (frame_[s] != kNoFrame)
      out[s] = {frame_[s], p.level};
    else
      out[s] = p.level == 0 ? Indirection{kNoFrame, 0} : out[g_.slot(parent(p))];
  }
  return out;
}

PageFrameCache::PageFrameCache(const PageGeometry& g, uint32_t frames, uint32_t locked_levels, DiscardRule rule)
    : table_(g), locked_levels_(locked_levels), rule_(rule), page_of_frame_(frames), last_used_(frames, 0) {}

void PageFrameCache::touch(PageId p, uint64_t now) {
  const uint32_t f = table_.frame(p);
  if (f != PageTable::kNoFrame) last_used_[f] = std::max(last_used_[f], now);
}

std::optional<uint32_t> PageFrameCache::insert(PageId p, uint64_t now) {
  if (table_.resident(p)) return table_.frame(p);
  uint32_t frame;
  if (used_ < frames()) {
    frame = used_++;
  } else {
    std::optional<uint32_t> victim;
    double worst = -1;
    for (uint32_t f = 0; f < frames(); ++f) {
      const PageId q = *page_of_frame_[f];
      if (q.level < locked_levels_ || last_used_[f] >= now) continue;
      const double age = static_cast<double>(now - last_used_[f]);
      const double score = rule_ == DiscardRule::kLru ? age : age * (q.level + 1.0);
      if (score > worst) worst = score, victim = f;
    }
    if (!victim) return std::nullopt;
    frame = *victim;
    table_.clear(*page_of_frame_[frame]);
    ++evictions_;
  }
  page_of_frame_[frame] = p;
  last_used_[frame] = now;
  table_.set(p, frame);
  return frame;
}

std::string_view to_string(PageHeuristic h) {
  switch (h) {
    case PageHeuristic::kRandom:
      return "Random";
    case PageHeuristic::kPixelSum:
      return "PixelSum";
    case PageHeuristic::kDistance:
      return "Distance";
    case PageHeuristic::kWeightedPixel:
      return "WeightedPixel";
    case PageHeuristic::kHotSpot:
      return "HotSpot";
    case PageHeuristic::kTexelRatio:
      return "TexelRatio";
  }
  return "?";
}

HotSpot hotspot_from_turn(float yaw_rad, float pitch_rad, float threshold_rad) {
  HotSpot h;
  if (std::fabs(yaw_rad) > threshold_rad) h.cx = yaw_rad > 0 ? 1.0f : -1.0f;
  if (std::fabs(pitch_rad) > threshold_rad) h.cy = pitch_rad > 0 ? 1.0f : -1.0f;
  return h;
}

std::vector<PageCandidate> choose_pages(std::span<const PageNeedSample> needs, const PageFile& file,
                                        const PageTable& table, std::span<const PageId> pending,
                                        const PagePolicyOptions& opt, HotSpot hotspot, uint64_t frame, size_t budget) {
  const PageGeometry& g = file.geometry();
  // The weight of a pixel by its distance from a centre, 1 there and 0 at the farthest screen corner.
  const auto centre_weight = [](float sx, float sy, float cx, float cy) {
    const double rmax = std::hypot(1.0 + static_cast<double>(std::fabs(cx)), 1.0 + static_cast<double>(std::fabs(cy)));
    return std::max(0.0, 1.0 - std::hypot(static_cast<double>(sx - cx), static_cast<double>(sy - cy)) / rmax);
  };

  std::unordered_map<uint64_t, Aggregate> wanted;
  for (const PageNeedSample& n : needs) {
    if (n.page.level >= g.levels || !file.stored(n.page)) continue;
    PageId p = n.page;
    if (opt.heuristic == PageHeuristic::kTexelRatio) {
      // Seed 002: ask for the next tile down the pixel's path below what is shown (progressive transmission).
      const auto shown = table.available(p);
      if (shown && shown->level == p.level) continue;
      p = ancestor_at(p, shown ? shown->level + 1 : 0);
    }
    Aggregate& a = wanted[g.slot(p)];
    a.pixels += 1;
    a.distance += static_cast<double>(n.distance);
    a.ratio = std::max(a.ratio, std::exp2(static_cast<double>(n.lod) - p.level));
    a.weighted += opt.heuristic == PageHeuristic::kHotSpot ? centre_weight(n.sx, n.sy, hotspot.cx, hotspot.cy)
                                                           : centre_weight(n.sx, n.sy, 0, 0);
  }

  const std::unordered_set<uint64_t> in_flight = [&] {
    std::unordered_set<uint64_t> s;
    for (PageId p : pending) s.insert(g.slot(p));
    return s;
  }();
  const auto priority_of = [&](uint64_t slot, const Aggregate& a) {
    switch (opt.heuristic) {
      case PageHeuristic::kRandom:
        return static_cast<double>(mix(opt.seed ^ mix(frame ^ mix(slot))) >> 11) * 0x1.0p-53;
      case PageHeuristic::kPixelSum:
        return a.pixels;
      case PageHeuristic::kDistance:
        return a.pixels / std::max(a.distance, 1e-6);
      case PageHeuristic::kWeightedPixel:
      case PageHeuristic::kHotSpot:
        return a.weighted;
      case PageHeuristic::kTexelRatio:
        return a.ratio;
    }
    return 0.0;
  };

  std::unordered_map<uint64_t, double> priority;
  for (const auto& [slot, a] : wanted) {
    PageId p = g.page_of_slot(slot);
    double pr = priority_of(slot, a);
    if (opt.noise_scaling) {
      // Seed 004 §4.2.3.2: the NoiseValues from the page up to (not including) the page shown in its place.
      const auto shown = table.available(p);
      double noise = 0;
      for (PageId q = p;; q = parent(q)) {
        if (shown && q.level <= shown->level) break;
        noise += static_cast<double>(file.noise(q));
        if (q.level == 0) break;
      }
      pr *= noise + 1e-9;  // a page that changes nothing goes last, still ordered by its heuristic
    }
    priority[slot] += pr;
    if (opt.order == AncestorOrder::kNeededOnly || opt.heuristic == PageHeuristic::kTexelRatio) continue;
    // Ancestors: the sum of their wanted descendants' priorities (seed 004 §4.3).
    while (p.level > 0) {
      p = parent(p);
      if (table.resident(p)) break;
      priority[g.slot(p)] += pr;
    }
  }

  const double threshold =
      opt.noise_skip_threshold < 0 ? file.mean_noise() : static_cast<double>(opt.noise_skip_threshold);

  std::vector<PageCandidate> out;
  out.reserve(priority.size());
  for (const auto& [slot, pr] : priority) {
    const PageId p = g.page_of_slot(slot);
    if (table.resident(p) || in_flight.count(slot)) continue;
    const bool is_wanted = wanted.count(slot) != 0;
    if (!is_wanted && opt.order == AncestorOrder::kExtern && opt.noise_skipping &&
        static_cast<double>(file.noise(p)) < threshold)
      continue;
    out.push_back({p, pr});
  }
  const bool by_level = opt.order == AncestorOrder::kExtern;
  std::sort(out.begin(), out.end(), [&](const PageCandidate& a, const PageCandidate& b) {
    if (by_level && a.page.level != b.page.level) return a.page.level < b.page.level;
    if (a.priority != b.priority) return a.priority > b.priority;
    if (a.page.level != b.page.level) return a.page.level < b.page.level;  // an ancestor before its descendant
    return g.slot(a.page) < g.slot(b.page);
  });
  if (out.size() > budget) out.resize(budget);
  return out;
}

}  // namespace texstream::pages
