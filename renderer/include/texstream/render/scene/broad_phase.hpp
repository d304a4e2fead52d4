#pragma once
// CPU broad phase (seed 003 §2): a quadtree over the mesh bounds in the ground plane (map coordinates, double).
// The tree itself is common/mesh_index.hpp, usually mapped from the scene folder (built once, not at every
// start). Each node keeps the 3D box fitted to every mesh below it ("mesh-fitted bounding box"), so a node
// entirely inside the frustum hands over all its meshes without testing them, and one entirely outside drops
// them all. Meshes are filed by the centre of their bounds and stored depth-first in one id array, so every node's
// meshes are one contiguous range of it. Boxes are made camera-relative in double before the float frustum test (at map
// coordinates a float has 0.5 m steps). Large scenes are queried by several threads (TBB), one task per subtree of a
// fixed frontier, concatenated in tree order so the result does not depend on scheduling. Record bounds are trusted to
// hold the mesh's vertices (the frustum tests and drop_unsampled rely on it).
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "texstream/common/mesh_index.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/render/scene/camera.hpp"

namespace texstream::render {

struct SceneData;

struct BroadPhaseStats {
  uint64_t nodes_tested = 0;   // node boxes classified against the frustum
  uint64_t meshes_tested = 0;  // mesh boxes classified (only in leaves that straddle the frustum)
};

// Where the runs of BroadPhase::split_by_viewport end, as positions in the id list it reordered.
struct ViewportSplit {
  uint32_t main_end = 0;  // ids [0, main_end) touch the viewport's frustum: the main pass draws them; ids
                          // [main_end, size) lie entirely outside it: the wide pass draws them
};

// A pass's raster: its view-projection (camera-relative, as the vertex shader uses it) and its size in pixels.
struct SampleGrid {
  glm::mat4 view_proj{1.0f};
  uint32_t width = 0;
  uint32_t height = 0;
  // Pixels a box's rectangle is widened by before looking for a pixel centre (margin_px_for; the default is
  // the widest, for 4 sub-pixel bits).
  double margin_px = 1.0 / 8.0;

  // The rasterizer snaps vertices to 2^-bits pixel (VkPhysicalDeviceLimits::subPixelPrecisionBits: 8 on
  // lavapipe, at least 4 anywhere), moving them by at most half a step; float transforms move them by far
  // less (1e-4 pixel at 20 km). Four half steps cover both.
  static double margin_px_for(uint32_t sub_pixel_bits) {
    return 2.0 / static_cast<double>(1u << std::clamp(sub_pixel_bits, 4u, 16u));
  }

  // From the 16 column-major floats a pass hands the shader (gpu::PassConstants::view_proj.m): culling with
  // the very matrix the GPU projects with.
  static SampleGrid from_columns(const float (&m)[16], uint32_t width, uint32_t height, uint32_t sub_pixel_bits) {
    SampleGrid g;
    for (int c = 0; c < 4; ++c)
      for (int r = 0; r < 4; ++r) g.view_proj[c][r] = m[4 * c + r];
    g.width = width;
    g.height = height;
    g.margin_px = margin_px_for(sub_pixel_bits);
    return g;
  }
};

class BroadPhase {
 public:
  static constexpr uint32_t kLeafMeshes = scene::kMeshIndexLeafMeshes;
  static constexpr uint32_t kMaxDepth = scene::kMeshIndexMaxDepth;
  // Below this many meshes one thread wins: a serial query of 10^4 meshes takes tens of microseconds, about
  // what starting TBB tasks costs (measured with texstream-bench visibility).
  static constexpr size_t kParallelMinMeshes = 50000;

  // Builds the tree here (O(N log N)). `meshes` must outlive the BroadPhase: leaves read the records.
  explicit BroadPhase(std::span<const scene::MeshRecord> meshes);
  // Uses a tree built before (scene/mesh_index.bin), mapped: O(1) in the mesh count, apart from the
  // structure checks map_mesh_index made.
  BroadPhase(std::span<const scene::MeshRecord> meshes, scene::MappedMeshIndex index);

  // The tree for `scene`. An opened scene (SceneData::open) maps its mesh_index.bin; when that is missing,
  // stale or broken the tree is built here and written there for the next start (a scene folder we cannot
  // write to only costs each start the build). A loaded scene is indexed here: its records may have been
  // edited since they were read.
  static std::unique_ptr<BroadPhase> for_scene(const SceneData& scene);

  // Replaces `out` with the ids of meshes whose bounds touch `frustum` (camera-relative), in tree order.
  // `parallel` false forces one thread (tests compare both).
  void query(const Frustum& frustum, const std::array<double, 3>& camera, std::vector<uint32_t>& out,
             BroadPhaseStats* stats = nullptr, bool parallel = true) const;

  // Reorders `ids` (meshes the wide frustum kept, from query()) into two runs, each in its previous order:
  // meshes touching `viewport` (inside or straddling it: the main pass draws them) and meshes entirely outside
  // it (the wide pass draws them, W = 1 per viewport pixel: seed 000 §3.2 "meshes that lie outside of the
  // viewport"). A straddling mesh is in the viewport: its part beyond the edge adds nothing, and the wide pass
  // draws only what can count there. One box test per id.
  ViewportSplit split_by_viewport(const Frustum& viewport, const std::array<double, 3>& camera,
                                  std::vector<uint32_t>& ids) const;

  // Drops from `ids` (the runs of split_by_viewport) the meshes that cannot produce a fragment in the passes
  // that would draw them: the screen rectangle of the mesh's box, widened by the grid's margin_px, holds no
  // pixel centre of that pass's grid (main for the first run, wide for the outside run). A mesh without a
  // sample has no fragment, so no depth, colour or metadata: the frame is the same, and the meshes of a far
  // horizon (10^5 of them a few tenths of a pixel wide in a 10^6-mesh city) are neither uploaded nor drawn. Boxes
  // reaching behind the camera plane are kept. Returns the runs' new ends.
  ViewportSplit drop_unsampled(const SampleGrid& main, const SampleGrid& wide, const std::array<double, 3>& camera,
                               std::vector<uint32_t>& ids, ViewportSplit split) const;

  // split_by_viewport and then drop_unsampled, in one pass over the records on every core (each record read
  // once): the same ids in the same order and the same runs. Most of a city frame's planning is these tests,
  // and a record fetch, not the arithmetic, is most of their cost (docs/design/render_stack.md, *Planning a
  // city frame*).
  ViewportSplit split_and_drop_unsampled(const Frustum& viewport, const SampleGrid& main, const SampleGrid& wide,
                                         const std::array<double, 3>& camera, std::vector<uint32_t>& ids) const;

  size_t node_count() const { return tree_.nodes.size(); }
  uint32_t depth() const { return tree_.depth; }
  size_t mesh_count() const { return tree_.order.size(); }
  bool from_file() const { return !mapped_.view.nodes.empty(); }

 private:
  void init_frontier();
  void query_node(uint32_t node, const Frustum& frustum, const std::array<double, 3>& camera,
                  std::vector<uint32_t>& out, BroadPhaseStats& stats) const;
  static Frustum::Side classify(const Frustum& f, const double min[3], const double max[3],
                                const std::array<double, 3>& camera);
  Frustum::Side classify_mesh(const Frustum& f, uint32_t id, const std::array<double, 3>& camera) const;
  bool covers_sample(const SampleGrid& grid, uint32_t id, const std::array<double, 3>& camera) const;

  std::span<const scene::MeshRecord> meshes_;
  scene::MeshIndex built_;          // the tree when built here
  scene::MappedMeshIndex mapped_;   // the tree when mapped from the scene
  scene::MeshIndexView tree_;       // whichever of the two
  std::vector<uint32_t> frontier_;  // subtrees the parallel query hands to tasks (tree order)
};

}  // namespace texstream::render
