#include "texstream/render/broad_phase.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>

namespace texstream::render {

namespace {

// The parallel query splits the tree into about this many subtrees: enough for TBB to balance a few cores
// when the frustum covers only part of the city, few enough that each task still does real work.
constexpr size_t kFrontierTarget = 64;

}  // namespace

BroadPhase::BroadPhase(std::span<const scene::MeshRecord> meshes) {
  mesh_bounds_.reserve(meshes.size());
  double lo[2] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max()};
  double hi[2] = {std::numeric_limits<double>::lowest(), std::numeric_limits<double>::lowest()};
  for (const auto& m : meshes) {
    Box b;
    for (int a = 0; a < 3; ++a) {
      // A record may store min > max (a bad file is not ours to judge here): order them so no test breaks.
      const double p = m.origin[a] + static_cast<double>(m.bounds_min[a]);
      const double q = m.origin[a] + static_cast<double>(m.bounds_max[a]);
      b.min[a] = std::min(p, q);
      b.max[a] = std::max(p, q);
    }
    for (int a = 0; a < 2; ++a) {
      const double c = 0.5 * (b.min[a] + b.max[a]);
      lo[a] = std::min(lo[a], c);
      hi[a] = std::max(hi[a], c);
    }
    mesh_bounds_.push_back(b);
  }
  order_.resize(meshes.size());
  for (uint32_t i = 0; i < order_.size(); ++i) order_[i] = i;
  if (meshes.empty()) return;
  // A square root region, so cells stay square however elongated the city is.
  const double side = std::max({hi[0] - lo[0], hi[1] - lo[1], 1e-3});
  build(lo[0], lo[1], side);

  // Frontier for the parallel query: expand nodes in place (children replace their parent, in order) until
  // there are enough subtrees or nothing left to expand.
  frontier_ = {0};
  while (frontier_.size() < kFrontierTarget) {
    std::vector<uint32_t> next;
    bool expanded = false;
    for (uint32_t n : frontier_) {
      const Node& node = nodes_[n];
      if (node.child_count == 0) {
        next.push_back(n);
        continue;
      }
      for (uint32_t c = 0; c < node.child_count; ++c) next.push_back(node.first_child + c);
      expanded = true;
    }
    frontier_ = std::move(next);
    if (!expanded) break;
  }
}

void BroadPhase::build(double x0, double y0, double side) {
  struct Pending {
    uint32_t node;
    std::array<double, 4> rect;  // x0, y0, x1, y1 of the quadrant the node's meshes were filed into
    uint32_t depth;
  };
  auto make_node = [&](uint32_t begin, uint32_t end) {
    Node node;
    node.begin = begin;
    node.end = end;
    node.bounds = mesh_bounds_[order_[begin]];
    for (uint32_t i = begin + 1; i < end; ++i) {
      const Box& b = mesh_bounds_[order_[i]];
      for (int a = 0; a < 3; ++a) {
        node.bounds.min[a] = std::min(node.bounds.min[a], b.min[a]);
        node.bounds.max[a] = std::max(node.bounds.max[a], b.max[a]);
      }
    }
    nodes_.push_back(node);
  };
  auto centre = [&](uint32_t id, int a) { return 0.5 * (mesh_bounds_[id].min[a] + mesh_bounds_[id].max[a]); };

  // Breadth first, so that the children of a node are appended together and stay contiguous.
  make_node(0, static_cast<uint32_t>(order_.size()));
  std::vector<Pending> queue{{0, {x0, y0, x0 + side, y0 + side}, 0}};
  for (size_t q = 0; q < queue.size(); ++q) {
    const Pending p = queue[q];
    const uint32_t begin = nodes_[p.node].begin;
    const uint32_t end = nodes_[p.node].end;
    depth_ = std::max(depth_, p.depth);
    if (end - begin <= kLeafMeshes || p.depth >= kMaxDepth) continue;
    // File each mesh into the quadrant of its centre: (x0,y0) (x1,y0) (x0,y1) (x1,y1), in that order.
    const double mx = 0.5 * (p.rect[0] + p.rect[2]);
    const double my = 0.5 * (p.rect[1] + p.rect[3]);
    uint32_t* base = order_.data();
    uint32_t* split_y = std::stable_partition(base + begin, base + end, [&](uint32_t id) { return centre(id, 1) < my; });
    uint32_t* split_x0 = std::stable_partition(base + begin, split_y, [&](uint32_t id) { return centre(id, 0) < mx; });
    uint32_t* split_x1 = std::stable_partition(split_y, base + end, [&](uint32_t id) { return centre(id, 0) < mx; });
    const std::array<uint32_t, 5> cut{begin, static_cast<uint32_t>(split_x0 - base),
                                      static_cast<uint32_t>(split_y - base), static_cast<uint32_t>(split_x1 - base),
                                      end};
    const std::array<std::array<double, 4>, 4> rects{{{p.rect[0], p.rect[1], mx, my},
                                                       {mx, p.rect[1], p.rect[2], my},
                                                       {p.rect[0], my, mx, p.rect[3]},
                                                       {mx, my, p.rect[2], p.rect[3]}}};
    const auto first_child = static_cast<uint32_t>(nodes_.size());
    uint32_t count = 0;
    for (uint32_t k = 0; k < 4; ++k) {
      if (cut[k + 1] == cut[k]) continue;
      queue.push_back({static_cast<uint32_t>(nodes_.size()), rects[k], p.depth + 1});
      make_node(cut[k], cut[k + 1]);  // may reallocate nodes_: index, never hold a reference across it
      ++count;
    }
    nodes_[p.node].first_child = first_child;
    nodes_[p.node].child_count = count;
  }
}

Frustum::Side BroadPhase::classify(const Frustum& f, const Box& b, const std::array<double, 3>& camera) {
  // Subtract in double first: at map coordinates a float has ~0.5 m steps, relative values are exact enough.
  const glm::vec3 min(static_cast<float>(b.min[0] - camera[0]), static_cast<float>(b.min[1] - camera[1]),
                      static_cast<float>(b.min[2] - camera[2]));
  const glm::vec3 max(static_cast<float>(b.max[0] - camera[0]), static_cast<float>(b.max[1] - camera[1]),
                      static_cast<float>(b.max[2] - camera[2]));
  return f.classify(min, max);
}

void BroadPhase::query_node(uint32_t index, const Frustum& frustum, const std::array<double, 3>& camera,
                            std::vector<uint32_t>& out, BroadPhaseStats& stats) const {
  const Node& node = nodes_[index];
  ++stats.nodes_tested;
  const auto side = classify(frustum, node.bounds, camera);
  if (side == Frustum::Side::kOutside) return;
  if (side == Frustum::Side::kInside) {
    out.insert(out.end(), order_.begin() + node.begin, order_.begin() + node.end);
    return;
  }
  if (node.child_count == 0) {
    for (uint32_t i = node.begin; i < node.end; ++i) {
      ++stats.meshes_tested;
      const uint32_t id = order_[i];
      if (classify(frustum, mesh_bounds_[id], camera) != Frustum::Side::kOutside) out.push_back(id);
    }
    return;
  }
  for (uint32_t c = 0; c < node.child_count; ++c) query_node(node.first_child + c, frustum, camera, out, stats);
}

void BroadPhase::query(const Frustum& frustum, const std::array<double, 3>& camera, std::vector<uint32_t>& out,
                       BroadPhaseStats* stats, bool parallel) const {
  out.clear();
  BroadPhaseStats total;
  if (nodes_.empty()) {
    if (stats) *stats = total;
    return;
  }
  if (!parallel || order_.size() < kParallelMinMeshes || frontier_.size() < 2) {
    query_node(0, frustum, camera, out, total);
    if (stats) *stats = total;
    return;
  }
  std::vector<std::vector<uint32_t>> parts(frontier_.size());
  std::vector<BroadPhaseStats> part_stats(frontier_.size());
  tbb::parallel_for(size_t{0}, frontier_.size(), [&](size_t i) {
    query_node(frontier_[i], frustum, camera, parts[i], part_stats[i]);
  });
  size_t n = 0;
  for (const auto& p : parts) n += p.size();
  out.reserve(n);
  for (size_t i = 0; i < parts.size(); ++i) {
    out.insert(out.end(), parts[i].begin(), parts[i].end());
    total.nodes_tested += part_stats[i].nodes_tested;
    total.meshes_tested += part_stats[i].meshes_tested;
  }
  if (stats) *stats = total;
}

ViewportSplit BroadPhase::split_by_viewport(const Frustum& viewport, const std::array<double, 3>& camera,
                                           std::vector<uint32_t>& ids) const {
  std::vector<uint32_t> straddle, outside;
  uint32_t inside = 0;
  for (uint32_t id : ids) {
    if (id >= mesh_bounds_.size()) continue;  // not a mesh of this tree: dropped, as query() never returns it
    switch (classify(viewport, mesh_bounds_[id], camera)) {
      case Frustum::Side::kInside: ids[inside++] = id; break;  // inside <= position read: in-place is safe
      case Frustum::Side::kIntersects: straddle.push_back(id); break;
      case Frustum::Side::kOutside: outside.push_back(id); break;
    }
  }
  ids.resize(inside);
  ids.insert(ids.end(), straddle.begin(), straddle.end());
  const auto main_end = static_cast<uint32_t>(ids.size());
  ids.insert(ids.end(), outside.begin(), outside.end());
  return ViewportSplit{main_end, inside};
}

}  // namespace texstream::render
