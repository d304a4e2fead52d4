#pragma once
// The city's geometry: a street grid of blocks, filled from the centre outwards (dense centre, sparse
// outskirts), each block holding lots with box buildings. Every textured quad is a Surface: one mesh, one
// texture (seed 000: a mesh has one texture map). The layout is sequential and cheap; painting the textures
// is the expensive, parallel part (texture_painter.hpp).
#include <cstdint>
#include <vector>

#include "building_style.hpp"

namespace texstream::gen {

enum class SurfaceKind : uint8_t {
  kFacade,       // a building wall
  kRoof,         // a building's flat roof (or a tier's)
  kGround,       // a block's ground: half streets, sidewalks, courtyard/garden
  kUtilityWall,  // wall of a rooftop structure or chimney
  kUtilityRoof,  // its top
  kPanel,        // a free-standing billboard/fence panel (fills the last few textures to reach N exactly)
};

// One textured quad, possibly subdivided into grid x grid cells (grounds are, to follow terrain-like meshes).
// Points: corner + s*edge_u + t*edge_v for s, t in [0, 1]; texture u = s, v = 1 - t (row 0 of the image is
// at t = 1: the top of a wall, the north edge of a roof or ground).
struct Surface {
  double corner[3];  // city-local metres (x east, y north, z up; z = 0 is street level)
  float edge_u[3];   // metres
  float edge_v[3];
  float width_m;      // |edge_u|
  float height_m;     // |edge_v|
  float base_m;       // height of the quad's lower edge above the street (storeys line up across tiers)
  uint32_t building;  // style id: surfaces of one building share it
  uint16_t width_px;  // texture extent, a power of two in [kMinExtent, kMaxExtent]
  uint16_t height_px;
  SurfaceKind kind;
  BuildingClass cls;
  uint8_t grid;     // subdivisions per side (1: one quad, 2 triangles)
  uint8_t variant;  // kind-specific: for kGround 1 = park, 2 = open land beyond the blocks (city_ground.hpp); for
                    // kFacade 1 = a setback tier's wall
};

struct Block {
  int32_t i, j;   // grid cell: spans [(i - 0.5) P, (i + 0.5) P] in x, likewise j in y
  float density;  // 0 (outskirts) .. 1 (centre)
};

struct CityLayout {
  std::vector<Surface> surfaces;  // surface k is mesh k and texture k
  std::vector<Block> blocks;      // in generation order (a square spiral from the centre)
  double block_pitch_m;           // grid pitch P; street centre lines lie at (k + 0.5) P
  double street_width_m;
  uint32_t building_count = 0;
};

// Texture extents (seed 000 Table 1: the Berlin data set's textures are 2^2..2^9 per side).
inline constexpr uint32_t kMinExtent = 4;
inline constexpr uint32_t kMaxExtent = 512;

// City grid constants: Berlin's blocks are ~100-150 m on a side, its streets ~15-25 m wide.
inline constexpr double kBlockPitchM = 120.0;
inline constexpr double kStreetWidthM = 18.0;
inline constexpr double kSidewalkM = 3.5;

// Exactly `texture_count` surfaces (>= 1).
CityLayout generate_layout(uint64_t seed, uint64_t texture_count);

}  // namespace texstream::gen
