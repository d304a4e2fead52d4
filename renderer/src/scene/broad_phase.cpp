#include "texstream/render/scene/broad_phase.hpp"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "texstream/render/scene/scene_data.hpp"

namespace texstream::render {

namespace {

// The parallel query splits the tree into about this many subtrees: enough for TBB to balance a few cores
// when the frustum covers only part of the city, few enough that each task still does real work.
constexpr size_t kFrontierTarget = 64;
// split_and_drop_unsampled asks for the record this many ids ahead: the ids come in tree order, the records lie in
// id order, so each fetch is a cache miss the prefetch overlaps (docs/design/render_stack.md).
constexpr size_t kPrefetchAhead = 16;

// Runs `test(begin, end)` over [0, n): on this thread for a small view, in blocks on every core for a large one.
template <class Test>
void test_ids(size_t n, size_t parallel_from, Test&& test) {
  if (n < parallel_from) {
    test(size_t{0}, n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096),
                    [&](const tbb::blocked_range<size_t>& r) { test(r.begin(), r.end()); });
}

}  // namespace

BroadPhase::BroadPhase(std::span<const scene::MeshRecord> meshes)
    : meshes_(meshes), built_(scene::build_mesh_index(meshes)), tree_(built_.view()) {
  init_frontier();
}

BroadPhase::BroadPhase(std::span<const scene::MeshRecord> meshes, scene::MappedMeshIndex index)
    : meshes_(meshes), mapped_(std::move(index)), tree_(mapped_.view) {
  TS_ASSERT(tree_.order.size() == meshes_.size(), "mesh index of %zu meshes for %zu", tree_.order.size(),
            meshes_.size());
  init_frontier();
}

std::unique_ptr<BroadPhase> BroadPhase::for_scene(const SceneData& scene) {
  const auto meshes = scene.mesh_records();
  if (!scene.is_mapped()) return std::make_unique<BroadPhase>(meshes);
  auto mapped = scene::map_mesh_index(scene.dir, meshes.size());
  if (mapped) return std::make_unique<BroadPhase>(meshes, std::move(*mapped));
  if (mapped.error().code != ErrorCode::kNotFound)
    spdlog::warn("broad phase: {}: building the tree instead", mapped.error().message);
  const auto t0 = std::chrono::steady_clock::now();
  auto built = std::make_unique<BroadPhase>(meshes);
  const double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (auto w = scene::write_mesh_index(scene.dir, built->tree_); !w) {
    spdlog::warn("broad phase: tree of {} meshes built in {:.2f} s but not kept ({}): every start builds it",
                 meshes.size(), build_s, w.error().message);
  } else {
    spdlog::info("broad phase: tree of {} meshes built in {:.2f} s and kept in {} for the next start", meshes.size(),
                 build_s, (scene.dir / "mesh_index.bin").string());
  }
  return built;
}

void BroadPhase::init_frontier() {
  if (tree_.nodes.empty()) return;
  // Frontier for the parallel query: expand nodes in place (children replace their parent, in order) until
  // there are enough subtrees or nothing left to expand.
  frontier_ = {0};
  while (frontier_.size() < kFrontierTarget) {
    std::vector<uint32_t> next;
    bool expanded = false;
    for (uint32_t n : frontier_) {
      const scene::MeshIndexNode& node = tree_.nodes[n];
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

Frustum::Side BroadPhase::classify(const Frustum& f, const double bmin[3], const double bmax[3],
                                   const std::array<double, 3>& camera) {
  // Subtract in double first: at map coordinates a float has ~0.5 m steps, relative values are exact enough.
  const glm::vec3 min(static_cast<float>(bmin[0] - camera[0]), static_cast<float>(bmin[1] - camera[1]),
                      static_cast<float>(bmin[2] - camera[2]));
  const glm::vec3 max(static_cast<float>(bmax[0] - camera[0]), static_cast<float>(bmax[1] - camera[1]),
                      static_cast<float>(bmax[2] - camera[2]));
  return f.classify(min, max);
}

Frustum::Side BroadPhase::classify_mesh(const Frustum& f, uint32_t id, const std::array<double, 3>& camera) const {
  double bmin[3], bmax[3];
  scene::mesh_box(meshes_[id], bmin, bmax);
  return classify(f, bmin, bmax, camera);
}

void BroadPhase::query_node(uint32_t index, const Frustum& frustum, const std::array<double, 3>& camera,
                            std::vector<uint32_t>& out, BroadPhaseStats& stats) const {
  const scene::MeshIndexNode& node = tree_.nodes[index];
  ++stats.nodes_tested;
  const auto side = classify(frustum, node.min, node.max, camera);
  if (side == Frustum::Side::kOutside) return;
  if (side == Frustum::Side::kInside) {
    out.insert(out.end(), tree_.order.begin() + node.begin, tree_.order.begin() + node.end);
    return;
  }
  if (node.child_count == 0) {
    for (uint32_t i = node.begin; i < node.end; ++i) {
      ++stats.meshes_tested;
      const uint32_t id = tree_.order[i];
      if (classify_mesh(frustum, id, camera) != Frustum::Side::kOutside) out.push_back(id);
    }
    return;
  }
  for (uint32_t c = 0; c < node.child_count; ++c) query_node(node.first_child + c, frustum, camera, out, stats);
}

void BroadPhase::query(const Frustum& frustum, const std::array<double, 3>& camera, std::vector<uint32_t>& out,
                       BroadPhaseStats* stats, bool parallel) const {
  out.clear();
  BroadPhaseStats total;
  if (tree_.nodes.empty()) {
    if (stats) *stats = total;
    return;
  }
  if (!parallel || tree_.order.size() < kParallelMinMeshes || frontier_.size() < 2) {
    query_node(0, frustum, camera, out, total);
    if (stats) *stats = total;
    return;
  }
  std::vector<std::vector<uint32_t>> parts(frontier_.size());
  std::vector<BroadPhaseStats> part_stats(frontier_.size());
  tbb::parallel_for(size_t{0}, frontier_.size(),
                    [&](size_t i) { query_node(frontier_[i], frustum, camera, parts[i], part_stats[i]); });
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
  std::vector<uint32_t> outside;
  uint32_t touching = 0;
  for (uint32_t id : ids) {
    if (id >= meshes_.size()) continue;  // not a mesh of this tree: dropped, as query() never returns it
    if (classify_mesh(viewport, id, camera) == Frustum::Side::kOutside) {
      outside.push_back(id);
    } else {
      ids[touching++] = id;  // touching <= position read: in-place is safe
    }
  }
  ids.resize(touching);
  ids.insert(ids.end(), outside.begin(), outside.end());
  // The wide pass draws only the meshes entirely outside: seed 000 §3.2 gives W = 1 to "meshes that lie outside
  // of the viewport", and a mesh straddling its edge is in it, with the main pass's metadata alone.
  return ViewportSplit{touching};
}

bool BroadPhase::covers_sample(const SampleGrid& grid, uint32_t id, const std::array<double, 3>& camera) const {
  const scene::MeshRecord& m = meshes_[id];
  // The corners as the vertex shader places vertices: the mesh's offset rounded to float (SceneGpu), plus
  // positions inside the record's bounds; projected in double. The projection is linear, so the eight corners
  // are the lowest corner's clip position plus the box's three edges' (four products instead of eight): this
  // test is most of a city frame's planning (docs/design/render_stack.md, *Planning a city frame*).
  const glm::mat4& vp = grid.view_proj;
  double lowest[3], extent[3];
  for (int a = 0; a < 3; ++a) {
    lowest[a] = static_cast<double>(static_cast<float>(m.origin[a] - camera[a])) + static_cast<double>(m.bounds_min[a]);
    extent[a] = static_cast<double>(m.bounds_max[a]) - static_cast<double>(m.bounds_min[a]);  // exact in double
  }
  std::array<std::array<double, 4>, 8> clip;
  std::array<std::array<double, 4>, 3> edge;
  for (int r = 0; r < 4; ++r) {
    clip[0][r] = static_cast<double>(vp[3][r]);
    for (int c = 0; c < 3; ++c) {
      clip[0][r] += static_cast<double>(vp[c][r]) * lowest[c];
      edge[c][r] = static_cast<double>(vp[c][r]) * extent[c];
    }
  }
  // Corner k has the bounds' maximum on axis a where bit a of k is set: corner k = corner (k without its top bit)
  // plus that bit's edge.
  for (int k = 1; k < 8; ++k) {
    const int top = k >= 4 ? 2 : (k >= 2 ? 1 : 0);
    const int from = k - (1 << top);
    for (int r = 0; r < 4; ++r) clip[k][r] = clip[from][r] + edge[top][r];
  }
  double lo[2] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max()};
  double hi[2] = {std::numeric_limits<double>::lowest(), std::numeric_limits<double>::lowest()};
  const double size[2] = {static_cast<double>(grid.width), static_cast<double>(grid.height)};
  for (const auto& c : clip) {
    // On or behind the camera plane the rectangle is unbounded: keep the mesh (1 mm: well inside any near
    // plane; NaN keeps it too).
    if (!(c[3] > 1e-3)) return true;
    const double inv_w = 1.0 / c[3];
    for (int a = 0; a < 2; ++a) {
      const double px = (c[a] * inv_w * 0.5 + 0.5) * size[a];
      if (!std::isfinite(px)) return true;  // a non-finite record: drawn, so make_resident reports it
      lo[a] = std::min(lo[a], px);
      hi[a] = std::max(hi[a], px);
    }
  }
  // A pixel centre i + 0.5 (i in [0, size)) inside [lo - margin, hi + margin] on both axes. Flipping y does not
  // change the set of centres.
  for (int a = 0; a < 2; ++a) {
    const double first = std::max(0.0, std::ceil(lo[a] - grid.margin_px - 0.5));
    const double last = std::min(size[a] - 1.0, std::floor(hi[a] + grid.margin_px - 0.5));
    if (first > last) return false;
  }
  return true;
}

ViewportSplit BroadPhase::split_and_drop_unsampled(const Frustum& viewport, const SampleGrid& main,
                                                   const SampleGrid& wide, const std::array<double, 3>& camera,
                                                   std::vector<uint32_t>& ids) const {
  enum : uint8_t { kDropped, kTouching, kOutside };
  std::vector<uint8_t> kind(ids.size());
  auto test = [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      if (i + kPrefetchAhead < end && ids[i + kPrefetchAhead] < meshes_.size()) {
        const auto* ahead = reinterpret_cast<const char*>(&meshes_[ids[i + kPrefetchAhead]]);
        __builtin_prefetch(ahead);
        __builtin_prefetch(ahead + sizeof(scene::MeshRecord) - 1);
      }
      const uint32_t id = ids[i];
      if (id >= meshes_.size()) {
        kind[i] = kDropped;  // not a mesh of this tree, as split_by_viewport drops it
        continue;
      }
      const bool outside = classify_mesh(viewport, id, camera) == Frustum::Side::kOutside;
      kind[i] = !covers_sample(outside ? wide : main, id, camera) ? kDropped : outside ? kOutside : kTouching;
    }
  };
  test_ids(ids.size(), kParallelMinMeshes, test);
  std::vector<uint32_t> outside;
  size_t touching = 0;
  for (size_t i = 0; i < ids.size(); ++i) {
    if (kind[i] == kTouching) ids[touching++] = ids[i];  // touching <= i: in place, order kept
    if (kind[i] == kOutside) outside.push_back(ids[i]);
  }
  ids.resize(touching);
  ids.insert(ids.end(), outside.begin(), outside.end());
  return ViewportSplit{static_cast<uint32_t>(touching)};
}

ViewportSplit BroadPhase::drop_unsampled(const SampleGrid& main, const SampleGrid& wide,
                                         const std::array<double, 3>& camera, std::vector<uint32_t>& ids,
                                         ViewportSplit split) const {
  const size_t main_end = std::min<size_t>(split.main_end, ids.size());
  auto keep = [&](size_t i) {
    const uint32_t id = ids[i];
    if (id >= meshes_.size()) return false;
    return covers_sample(i < main_end ? main : wide, id, camera);
  };
  // The tests on every core for a large view (a corner and three edges projected a mesh), the compaction in order.
  std::vector<uint8_t> kept_flags(ids.size());
  auto test = [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) kept_flags[i] = keep(i) ? 1 : 0;
  };
  test_ids(ids.size(), kParallelMinMeshes, test);
  size_t kept = 0;
  ViewportSplit out;
  for (size_t i = 0; i < ids.size(); ++i) {
    if (i == main_end) out.main_end = static_cast<uint32_t>(kept);
    if (kept_flags[i]) ids[kept++] = ids[i];  // kept <= i: in place, order kept
  }
  if (main_end == ids.size()) out.main_end = static_cast<uint32_t>(kept);
  ids.resize(kept);
  return out;
}

}  // namespace texstream::render
