#pragma once
// The look of one building, shared by all its facades and roofs so that a building reads as one object while
// buildings differ from each other (palette + hue jitter). A pure function of (seed, building id).
#include <cstdint>

#include "colour.hpp"

namespace texstream::gen {

enum class FacadeMaterial : uint8_t {
  kPlaster,  // rendered Altbau facade: smooth colour, cornices, framed windows
  kBrick,    // clinker brick: per-brick colour variation, darker mortar
  kPanel,    // prefabricated concrete panels (Plattenbau): seams on a panel grid, regular windows
  kGlass,    // curtain wall: glass panes between mullions, sky reflection
};

enum class RoofMaterial : uint8_t { kGravel, kTiles, kGreen, kMetal };

struct BuildingStyle {
  FacadeMaterial material;
  RoofMaterial roof;
  Rgb wall;    // facade base colour
  Rgb trim;    // window frames, cornices
  Rgb glass;   // glass tint
  Rgb accent;  // ground floor / door colour
  Rgb roof_colour;
  float floor_m;         // storey height
  float ground_floor_m;  // the ground floor is taller (shops)
  float window_pitch_m;  // horizontal distance between window centres
  float window_w_m;
  float window_h_m;
  float panel_w_m;     // panel grid (kPanel) / mullion spacing (kGlass)
  float lit_fraction;  // share of windows that look lit or curtained (brighter)
  float dirt;          // 0..1: weathering streaks and grime near the ground
  float texel_m;       // base texel size of this building's textures, metres per texel
  bool cornices;       // a band at every floor
  bool shop_front;     // wide shop windows on the ground floor instead of regular windows
  bool mullion_cross;  // windows divided into four panes
  bool solar;          // solar panels on flat roofs
};

// What kind of building it is decides the likely materials (towers are glass or panels, houses have tiles).
enum class BuildingClass : uint8_t { kHouse, kPerimeter, kTower };

BuildingStyle make_building_style(uint64_t seed, uint32_t building, BuildingClass cls);

}  // namespace texstream::gen
