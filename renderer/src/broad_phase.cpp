#include "texstream/render/broad_phase.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace texstream::render {

BroadPhase::BroadPhase(std::span<const scene::MeshRecord> meshes) {
  mesh_bounds_.reserve(meshes.size());
  double lo[2] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max()};
  double hi[2] = {std::numeric_limits<double>::lowest(), std::numeric_limits<double>::lowest()};
  for (const auto& m : meshes) {
    Box b;
    for (int a = 0; a < 3; ++a) {
      b.min[a] = m.origin[a] + static_cast<double>(m.bounds_min[a]);
      b.max[a] = m.origin[a] + static_cast<double>(m.bounds_max[a]);
    }
    mesh_bounds_.push_back(b);
    for (int a = 0; a < 2; ++a) {
      lo[a] = std::min(lo[a], m.origin[a]);
      hi[a] = std::max(hi[a], m.origin[a]);
    }
  }
  if (meshes.empty()) return;
  const auto side = static_cast<uint32_t>(
      std::clamp(std::ceil(std::sqrt(static_cast<double>(meshes.size()) / kMeshesPerCell)), 1.0, 4096.0));
  const double span[2] = {std::max(hi[0] - lo[0], 1e-6), std::max(hi[1] - lo[1], 1e-6)};
  std::vector<int64_t> cell_of_grid(static_cast<size_t>(side) * side, -1);
  for (uint32_t id = 0; id < meshes.size(); ++id) {
    uint32_t g[2];
    for (int a = 0; a < 2; ++a) {
      const double t = (meshes[id].origin[a] - lo[a]) / span[a];
      g[a] = std::min(side - 1, static_cast<uint32_t>(std::max(0.0, t) * side));
    }
    int64_t& index = cell_of_grid[static_cast<size_t>(g[1]) * side + g[0]];
    if (index < 0) {
      index = static_cast<int64_t>(cells_.size());
      cells_.push_back(Cell{mesh_bounds_[id], {}});
    }
    Cell& cell = cells_[static_cast<size_t>(index)];
    for (int a = 0; a < 3; ++a) {
      cell.bounds.min[a] = std::min(cell.bounds.min[a], mesh_bounds_[id].min[a]);
      cell.bounds.max[a] = std::max(cell.bounds.max[a], mesh_bounds_[id].max[a]);
    }
    cell.meshes.push_back(id);
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

void BroadPhase::query(const Frustum& frustum, const std::array<double, 3>& camera, std::vector<uint32_t>& out) const {
  out.clear();
  for (const Cell& cell : cells_) {
    const auto side = classify(frustum, cell.bounds, camera);
    if (side == Frustum::Side::kOutside) continue;
    if (side == Frustum::Side::kInside) {
      out.insert(out.end(), cell.meshes.begin(), cell.meshes.end());
      continue;
    }
    for (uint32_t id : cell.meshes)
      if (classify(frustum, mesh_bounds_[id], camera) != Frustum::Side::kOutside) out.push_back(id);
  }
}

}  // namespace texstream::render
