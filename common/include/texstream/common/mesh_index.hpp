#pragma once
// <scene>/mesh_index.bin: the broad phase's quadtree over the mesh bounds (seed 003 §2), built once and mapped
// at start-up, so that opening a scene of 10^6 meshes costs what opening one of 10^3 does. texstream-gen writes
// it after meshes.bin; texstream-render builds and writes it the first time it opens a scene without a valid
// one. It is optional: a scene without it (older scenes) or with a stale or broken one still loads.
//
//   MeshIndexHeader, MeshIndexNode[node_count], uint32 order[mesh_count]
//
// The tree (render/broad_phase.hpp says how it is queried): each node keeps the 3D box fitted to every mesh
// below it; meshes are filed into the quadrant of their bounds' centre in the ground plane and stored
// depth-first in `order`, so every node's meshes are one contiguous range of it; a node's children are
// consecutive nodes. Built breadth first from a square root region.
#include <cstdint>
#include <filesystem>
#include <span>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/scene_format.hpp"

namespace texstream::scene {

inline constexpr uint64_t kMeshIndexMagic = 0x3130584449534d54ull;  // "TMSIDX01"
inline constexpr uint32_t kMeshIndexVersion = 1;
// A leaf holds at most this many meshes: testing 16 boxes costs about as much as descending one level
// (4 children) and keeps straddling leaves cheap.
inline constexpr uint32_t kMeshIndexLeafMeshes = 16;
// Records of meshes.bin hashed into the index's fingerprint: a few KB read, whatever the scene size.
inline constexpr uint64_t kMeshIndexFingerprintSamples = 256;
// Depth cap: meshes whose centres coincide cannot be separated; 2^-20 of a 10 km city is 1 cm.
inline constexpr uint32_t kMeshIndexMaxDepth = 20;

struct MeshIndexHeader {
  uint64_t magic;
  uint32_t version;
  uint32_t depth;  // of the deepest node (the root is 0)
  uint64_t mesh_count;
  uint64_t node_count;
  // The meshes.bin this index was built from: its size and a fingerprint of its header and of
  // kMeshIndexFingerprintSamples records spread over the file (FNV-1a). Another meshes.bin almost always
  // differs in one of them and the index is then rebuilt rather than trusted; checking every box would read
  // every mesh. Contents only (no file time), so texstream-gen stays byte-identical for the same input.
  uint64_t meshes_file_bytes;
  uint64_t meshes_fingerprint;
};
static_assert(sizeof(MeshIndexHeader) == 48);

struct MeshIndexNode {
  double min[3];  // map coordinates: fitted to every mesh below
  double max[3];
  uint32_t begin;  // range of order
  uint32_t end;
  uint32_t first_child;  // 0: leaf (the root is node 0, so no node has it as a child)
  uint32_t child_count;  // children are first_child .. first_child + child_count - 1
};
static_assert(sizeof(MeshIndexNode) == 64);

// A tree in memory (built) or in a mapped file.
struct MeshIndexView {
  std::span<const MeshIndexNode> nodes;
  std::span<const uint32_t> order;
  uint32_t depth = 0;
};

struct MeshIndex {
  std::vector<MeshIndexNode> nodes;
  std::vector<uint32_t> order;
  uint32_t depth = 0;
  MeshIndexView view() const { return {nodes, order, depth}; }
};

// The absolute box of a mesh, min and max ordered per axis (a record with min > max is not the tree's to judge).
void mesh_box(const MeshRecord& m, double min[3], double max[3]);

// Builds the tree over `meshes` (O(N log N)); the same meshes always give the same tree.
MeshIndex build_mesh_index(std::span<const MeshRecord> meshes);

// Writes <dir>/mesh_index.bin (through a .tmp and a rename), stamped with <dir>/meshes.bin's size and
// fingerprint.
Status write_mesh_index(const std::filesystem::path& dir, const MeshIndexView& index);

struct MappedMeshIndex {
  MappedFile file;
  MeshIndexView view;
};
// Maps <dir>/mesh_index.bin and checks it against `mesh_count` and meshes.bin's stamp, and its structure: every
// node's children partition its range, every node but the root has one parent, `order` is a permutation of the
// mesh ids. So a query over it visits each mesh at most once and never reads out of bounds. kNotFound when
// there is none; kCorrupt (naming the file and the node) when it is broken or stale.
Result<MappedMeshIndex> map_mesh_index(const std::filesystem::path& dir, uint64_t mesh_count);

}  // namespace texstream::scene
