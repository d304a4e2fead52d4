#pragma once
// CPU broad phase (seed 003): a uniform grid over the mesh origins in the ground plane; each cell keeps the
// union of its meshes' bounds. A query tests cells against the frustum, then the meshes of cells that straddle
// it. All boxes are absolute (double) and made camera-relative in double before the float frustum test.
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/render/camera.hpp"

namespace texstream::render {

class BroadPhase {
 public:
  // ~32 meshes per cell on average: small enough that straddling cells cost little, large enough that the cell
  // loop stays short for a million meshes (~31K cells).
  static constexpr double kMeshesPerCell = 32;

  explicit BroadPhase(std::span<const scene::MeshRecord> meshes);

  // Appends the ids of meshes whose bounds touch `frustum` (camera-relative) to `out` (cleared first),
  // in increasing id order within each cell.
  void query(const Frustum& frustum, const std::array<double, 3>& camera, std::vector<uint32_t>& out) const;

  uint32_t cell_count() const { return static_cast<uint32_t>(cells_.size()); }

 private:
  struct Box {
    std::array<double, 3> min;
    std::array<double, 3> max;
  };
  struct Cell {
    Box bounds;
    std::vector<uint32_t> meshes;
  };
  static Frustum::Side classify(const Frustum& f, const Box& b, const std::array<double, 3>& camera);

  std::vector<Box> mesh_bounds_;
  std::vector<Cell> cells_;  // only non-empty cells
};

}  // namespace texstream::render
