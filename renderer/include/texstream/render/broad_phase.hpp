#pragma once
// CPU broad phase (seed 003 §2): a quadtree over the mesh bounds in the ground plane (map coordinates, double).
// Each node keeps the 3D box fitted to every mesh below it ("mesh-fitted bounding box"), so a node entirely
// inside the frustum hands over all its meshes without testing them, and one entirely outside drops them all.
// Meshes are filed by the centre of their bounds and stored depth-first in one id array, so every node's meshes
// are one contiguous range of it. Boxes are made camera-relative in double before the float frustum test (at
// map coordinates a float has 0.5 m steps). Large scenes are queried by several threads (TBB), one task per
// subtree of a fixed frontier, concatenated in tree order so the result does not depend on scheduling.
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "texstream/common/scene_format.hpp"
#include "texstream/render/camera.hpp"

namespace texstream::render {

struct BroadPhaseStats {
  uint64_t nodes_tested = 0;   // node boxes classified against the frustum
  uint64_t meshes_tested = 0;  // mesh boxes classified (only in leaves that straddle the frustum)
};

// Where the runs of BroadPhase::split_by_viewport end, as positions in the id list it reordered.
struct ViewportSplit {
  uint32_t main_end = 0;    // ids [0, main_end) touch the viewport's frustum: the main pass draws them
  uint32_t wide_begin = 0;  // ids [wide_begin, size) reach outside it: the wide pass draws them
};

class BroadPhase {
 public:
  // A leaf holds at most this many meshes: testing 16 boxes costs about as much as descending one level
  // (4 children) and keeps straddling leaves cheap.
  static constexpr uint32_t kLeafMeshes = 16;
  // Depth cap: meshes whose centres coincide cannot be separated; 2^-20 of a 10 km city is 1 cm.
  static constexpr uint32_t kMaxDepth = 20;
  // Below this many meshes one thread wins: a serial query of 10^4 meshes takes tens of microseconds, about
  // what starting TBB tasks costs (measured with texstream-bench visibility).
  static constexpr size_t kParallelMinMeshes = 50000;

  explicit BroadPhase(std::span<const scene::MeshRecord> meshes);

  // Replaces `out` with the ids of meshes whose bounds touch `frustum` (camera-relative), in tree order.
  // `parallel` false forces one thread (tests compare both).
  void query(const Frustum& frustum, const std::array<double, 3>& camera, std::vector<uint32_t>& out,
             BroadPhaseStats* stats = nullptr, bool parallel = true) const;

  // Reorders `ids` (meshes the wide frustum kept, from query()) into three runs, each in its previous order:
  // meshes entirely inside `viewport` (only the main pass can see them), meshes straddling it (both passes),
  // meshes entirely outside it (only the wide pass). A mesh inside the viewport's frustum has no fragment
  // outside the viewport in the wide pass, so leaving it out there changes no metadata; one outside it has
  // no fragment in the viewport. One box test per id.
  ViewportSplit split_by_viewport(const Frustum& viewport, const std::array<double, 3>& camera,
                                  std::vector<uint32_t>& ids) const;

  size_t node_count() const { return nodes_.size(); }
  uint32_t depth() const { return depth_; }
  size_t mesh_count() const { return order_.size(); }

 private:
  struct Box {
    std::array<double, 3> min;
    std::array<double, 3> max;
  };
  struct Node {
    Box bounds;                  // fitted to every mesh below (3D)
    uint32_t begin = 0, end = 0; // range of order_
    uint32_t first_child = 0;    // 0: leaf (the root is node 0, so no node has it as a child)
    uint32_t child_count = 0;    // children are first_child .. first_child + child_count - 1
  };

  void build(double x0, double y0, double side);
  void query_node(uint32_t node, const Frustum& frustum, const std::array<double, 3>& camera,
                  std::vector<uint32_t>& out, BroadPhaseStats& stats) const;
  static Frustum::Side classify(const Frustum& f, const Box& b, const std::array<double, 3>& camera);

  std::vector<Box> mesh_bounds_;  // absolute, by mesh id
  std::vector<uint32_t> order_;   // mesh ids, depth-first by node
  std::vector<Node> nodes_;       // nodes_[0] is the root
  std::vector<uint32_t> frontier_;  // subtrees the parallel query hands to tasks (tree order)
  uint32_t depth_ = 0;
};

}  // namespace texstream::render
