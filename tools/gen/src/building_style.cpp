#include "building_style.hpp"

#include <array>

#include "rng.hpp"

namespace texstream::gen {

namespace {

// Palettes read off typical Berlin street fronts: pastel and ochre plaster, red and yellow clinker, grey and
// beige concrete, blue-green and bronze glass.
constexpr std::array<std::array<int, 3>, 10> kPlaster = {{{226, 214, 188},
                                                          {214, 190, 150},
                                                          {200, 200, 196},
                                                          {232, 220, 200},
                                                          {190, 160, 130},
                                                          {222, 196, 180},
                                                          {205, 214, 190},
                                                          {238, 234, 224},
                                                          {180, 176, 170},
                                                          {226, 200, 140}}};
constexpr std::array<std::array<int, 3>, 5> kBrick = {
    {{150, 70, 50}, {128, 58, 44}, {170, 100, 70}, {190, 150, 100}, {110, 70, 60}}};
constexpr std::array<std::array<int, 3>, 5> kConcrete = {
    {{176, 174, 168}, {196, 188, 170}, {160, 164, 166}, {210, 204, 190}, {150, 146, 138}}};
constexpr std::array<std::array<int, 3>, 5> kGlass = {
    {{70, 100, 120}, {60, 90, 90}, {90, 80, 60}, {80, 90, 110}, {50, 60, 70}}};
constexpr std::array<std::array<int, 3>, 6> kAccent = {
    {{90, 40, 30}, {40, 60, 90}, {40, 70, 50}, {60, 60, 60}, {120, 90, 50}, {150, 30, 30}}};

template <size_t N>
Rgb pick(Rng& rng, const std::array<std::array<int, 3>, N>& palette) {
  const auto& c = palette[static_cast<size_t>(rng.range(0, static_cast<int>(N) - 1))];
  return rgb8(c[0], c[1], c[2]);
}

// Hue/saturation/value jitter: no two buildings share exactly one palette colour.
Rgb jitter(Rng& rng, Rgb c, float hue, float sat, float val) {
  float h, s, v;
  to_hsv(c, h, s, v);
  return from_hsv(h + rng.uniform(-hue, hue), s * (1.0f + rng.uniform(-sat, sat)), v * (1.0f + rng.uniform(-val, val)));
}

}  // namespace

BuildingStyle make_building_style(uint64_t seed, uint32_t building, BuildingClass cls) {
  Rng rng(seed, Stream::kBuilding, building);
  BuildingStyle s{};
  const float m = rng.uniform();
  switch (cls) {
    case BuildingClass::kTower:
      s.material = m < 0.55f ? FacadeMaterial::kGlass : m < 0.85f ? FacadeMaterial::kPanel : FacadeMaterial::kPlaster;
      break;
    case BuildingClass::kPerimeter:
      s.material = m < 0.55f   ? FacadeMaterial::kPlaster
                   : m < 0.75f ? FacadeMaterial::kBrick
                   : m < 0.93f ? FacadeMaterial::kPanel
                               : FacadeMaterial::kGlass;
      break;
    case BuildingClass::kHouse:
      s.material = m < 0.6f ? FacadeMaterial::kPlaster : FacadeMaterial::kBrick;
      break;
  }
  switch (s.material) {
    case FacadeMaterial::kPlaster:
      s.wall = jitter(rng, pick(rng, kPlaster), 0.04f, 0.3f, 0.08f);
      break;
    case FacadeMaterial::kBrick:
      s.wall = jitter(rng, pick(rng, kBrick), 0.02f, 0.15f, 0.1f);
      break;
    case FacadeMaterial::kPanel:
      s.wall = jitter(rng, pick(rng, kConcrete), 0.05f, 0.4f, 0.06f);
      break;
    case FacadeMaterial::kGlass:
      s.wall = jitter(rng, pick(rng, kConcrete), 0.03f, 0.2f, 0.1f);
      break;
  }
  s.trim = rng.chance(0.6f) ? jitter(rng, rgb8(235, 232, 225), 0.02f, 0.5f, 0.05f)
                            : jitter(rng, rgb8(60, 58, 56), 0.05f, 0.5f, 0.2f);
  s.glass = jitter(rng, pick(rng, kGlass), 0.03f, 0.2f, 0.15f);
  s.accent = jitter(rng, pick(rng, kAccent), 0.03f, 0.2f, 0.15f);

  s.roof = cls == BuildingClass::kHouse ? (rng.chance(0.85f) ? RoofMaterial::kTiles : RoofMaterial::kMetal)
           : rng.chance(0.15f)          ? RoofMaterial::kGreen
           : rng.chance(0.1f)           ? RoofMaterial::kMetal
                                        : RoofMaterial::kGravel;
  switch (s.roof) {
    case RoofMaterial::kGravel:
      s.roof_colour = jitter(rng, rgb8(128, 124, 118), 0.05f, 0.3f, 0.15f);
      break;
    case RoofMaterial::kTiles:
      s.roof_colour = jitter(rng, rgb8(160, 70, 45), 0.03f, 0.2f, 0.2f);
      break;
    case RoofMaterial::kGreen:
      s.roof_colour = jitter(rng, rgb8(90, 120, 60), 0.04f, 0.2f, 0.15f);
      break;
    case RoofMaterial::kMetal:
      s.roof_colour = jitter(rng, rgb8(100, 110, 115), 0.1f, 0.3f, 0.15f);
      break;
  }
  s.solar = s.roof == RoofMaterial::kGravel && rng.chance(0.3f);

  // Storeys: Berlin Altbau ~3.5-4 m, post-war and panel buildings ~2.8-3.1 m.
  s.floor_m = s.material == FacadeMaterial::kPanel ? rng.uniform(2.8f, 3.1f) : rng.uniform(3.0f, 4.0f);
  s.ground_floor_m = s.floor_m * rng.uniform(1.0f, 1.4f);
  s.window_pitch_m = rng.uniform(2.4f, 4.0f);
  s.window_w_m = s.window_pitch_m * rng.uniform(0.35f, 0.6f);
  s.window_h_m = s.floor_m * rng.uniform(0.4f, 0.62f);
  s.panel_w_m = rng.uniform(1.2f, 3.6f);
  s.lit_fraction = rng.uniform(0.05f, 0.35f);
  s.dirt = rng.uniform(0.1f, 0.9f);
  // Texel density ~0.12-0.25 m per texel: puts the median texture side at 2^7 and the mean BC1 texture near
  // the ~7 KB of the seed's Berlin data set (seed 000 Table 1).
  s.texel_m = rng.uniform(0.12f, 0.25f);
  s.cornices = s.material == FacadeMaterial::kPlaster && rng.chance(0.6f);
  s.shop_front = cls != BuildingClass::kHouse && rng.chance(0.5f);
  s.mullion_cross = rng.chance(0.5f);
  return s;
}

}  // namespace texstream::gen
