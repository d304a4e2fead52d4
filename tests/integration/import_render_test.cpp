// texstream-import end to end, checked against a reference made another way. The test writes a model itself
// (glTF with a node hierarchy, a specular-glossiness material, a mesh placed six times — twice by translation
// only, once rotated, once scaled, twice by one EXT_mesh_gpu_instancing node —, a mesh with two materials, repeat and
// mirrored-repeat UVs far outside [0, 1], a non-power-of-two image, an alpha-tested cut-out over another surface, an
// untextured material, a large --origin; or the same as OBJ+MTL), imports it with the real texstream-import, renders it
// with the real texstream-render + texstream-server (lock- step, validation on) and compares the last frame with a CPU
// ray cast of the test's own description of the model: each pixel's ray meets the placements (the test's transforms,
// not the importer's), the texture is sampled bilinearly with the wrap mode the test wrote into the file, from the
// baked level-0 texels decoded by the test's own BC1/BC3 decoder, alpha-tested and un-premultiplied as glTF says. Every
// surface faces the camera at a texel density below one texel per pixel, so the level shown is 0. Pixels whose
// neighbourhood spans two surfaces or whose alpha is within 0.1 of the cutoff are left out (at least 85 % must remain).
// Tolerance: PSNR
// >= 40 dB. On failure actual, expected and diff PNGs are kept and named.
#include <gtest/gtest.h>

#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "process_test_support.hpp"
#include "texstream/common/dds.hpp"
#include "texstream/common/scene_format.hpp"

namespace fs = std::filesystem;
using namespace texstream;

namespace {

const fs::path kBin = TEXSTREAM_BIN_DIR;
constexpr int kWidth = 960, kHeight = 540;
constexpr double kFovY = 60.0;
constexpr double kOrigin[3] = {392000.0, 5820000.0, 30.0};  // --origin: map coordinates, large on purpose

struct Rgba {
  uint8_t r, g, b, a;
};

struct TestImage {
  std::string file;
  int w, h;
  std::function<Rgba(int, int)> texel;
};

enum class Wrap { kClamp, kRepeat, kMirror };

struct TestMaterial {
  std::string name;
  int image = -1;                            // TestImage index, -1: base colour only
  std::array<double, 4> colour{1, 1, 1, 1};  // baseColorFactor (linear)
  Wrap wrap = Wrap::kClamp;
  bool mask = false;
  double cutoff = 0.5;
};

// A quad in the plane z = const facing the camera (glTF frame: camera at the origin looking along -z, y up):
// corners (+-hw, +-hh) in its own frame, uv (u0, v0) at the top-left corner and (u1, v1) at the bottom-right.
struct QuadMesh {
  double hw, hh, u0, v0, u1, v1;
  int material;
};

// One drawn quad: a mesh under a transform the test composes itself: scale, then a rotation about z, then a
// translation; `parent` says whether the glTF puts the rotation and scale on a child node of a translating one.
struct Placement {
  int mesh;
  double tx, ty, tz;
  double rot_deg = 0;
  double scale = 1;
  bool parent = false;
  bool gpu_instancing = false;  // one of the placements of an EXT_mesh_gpu_instancing node (the first one's tz)
};

struct TestModel {
  std::vector<TestImage> images;
  std::vector<TestMaterial> materials;
  std::vector<QuadMesh> meshes;       // a glTF mesh may hold several (see mesh_group)
  std::vector<int> mesh_group;        // glTF mesh index of each QuadMesh (primitives of one mesh)
  std::vector<Placement> placements;  // by QuadMesh index (every primitive of the group is placed)
};

double srgb_to_linear(double c) { return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4); }
double linear_to_srgb(double l) {
  l = std::clamp(l, 0.0, 1.0);
  return l <= 0.0031308 ? l * 12.92 : 1.055 * std::pow(l, 1.0 / 2.4) - 0.055;
}

TestModel make_model() {
  TestModel m;
  m.images.push_back({"grid.png", 64, 64, [](int x, int y) {
                        const bool dark = ((x / 8) + (y / 8)) % 2 == 0;
                        return Rgba{static_cast<uint8_t>(x * 4), static_cast<uint8_t>(y * 4),
                                    static_cast<uint8_t>(dark ? 60 : 200), 255};
                      }});
  m.images.push_back({"mirror.png", 64, 64, [](int x, int y) {
                        return Rgba{static_cast<uint8_t>(40 + x * 3), 90, static_cast<uint8_t>(250 - y * 3), 255};
                      }});
  // Not a power of two: baked at 128 x 64.
  m.images.push_back({"npot.png", 100, 60, [](int x, int y) {
                        const bool stripe = (x / 10) % 2 == 0;
                        return Rgba{static_cast<uint8_t>(stripe ? 230 : 30), static_cast<uint8_t>(y * 4),
                                    static_cast<uint8_t>(128), 255};
                      }});
  m.images.push_back({"tile.png", 64, 64, [](int x, int y) {
                        // Asymmetric so a wrong rotation or flip shows: a bright corner at the top left.
                        const bool corner = x < 20 && y < 20;
                        return Rgba{static_cast<uint8_t>(corner ? 250 : 60 + x * 2),
                                    static_cast<uint8_t>(corner ? 240 : 40),
                                    static_cast<uint8_t>(corner ? 20 : 80 + y * 2), 255};
                      }});
  m.images.push_back({"leaf.png", 64, 64, [](int x, int y) {
                        const double dx = x + 0.5 - 32, dy = y + 0.5 - 32;
                        const bool in = dx * dx + dy * dy < 24.0 * 24.0;
                        return Rgba{static_cast<uint8_t>(40 + x), static_cast<uint8_t>(170), static_cast<uint8_t>(50),
                                    static_cast<uint8_t>(in ? 255 : 0)};
                      }});
  m.materials = {
      {"grid", 0, {1, 1, 1, 1}, Wrap::kRepeat, false, 0.5},
      {"mirror", 1, {1, 1, 1, 1}, Wrap::kMirror, false, 0.5},
      {"npot", 2, {1, 1, 1, 1}, Wrap::kClamp, false, 0.5},
      {"tile", 3, {1, 1, 1, 1}, Wrap::kClamp, false, 0.5},
      {"leaf", 4, {1, 1, 1, 1}, Wrap::kClamp, true, 0.5},
      {"plain", -1, {0.2, 0.5, 0.8, 1}, Wrap::kClamp, false, 0.5},
      {"plain2", -1, {0.7, 0.3, 0.1, 1}, Wrap::kClamp, false, 0.5},
  };
  // Texel densities stay below 4.6 texels per metre at 100 m: one texel per pixel or less, level 0.
  m.meshes = {
      {110, 62, -5.5, -3.1, 5.5, 3.1, 0},     // background, repeating 11 x 6.2 times
      {20, 20, 0, 0, 2, 2, 1},                // mirrored twice each way
      {25, 12, -0.25, -0.25, 1.25, 1.25, 2},  // clamped past its edges
      {8, 8, 0, 0, 1, 1, 3},                  // the tile, placed four times
      {15, 15, 0, 0, 1, 1, 4},                // cut-out
      {10, 10, 0, 0, 1, 1, 5},                // no texture
      {6, 9, 0, 0, 1, 1, 3},                  // one mesh, two materials: left half...
      {6, 9, 0, 0, 1, 1, 6},                  // ...and right half
  };
  m.mesh_group = {0, 1, 2, 3, 4, 5, 6, 6};
  m.placements = {
      {0, 0, 0, -101},
      {1, -75, 30, -100},
      {2, -25, 30, -100},
      {3, 20, 35, -100},                 // translation only: shares the tile's vertices
      {3, 45, 35, -100},                 // again
      {3, 70, 35, -100, 90, 1, true},    // rotated in a child node
      {3, 85, -25, -100, 0, 1.5, true},  // scaled in a child node
      {4, -60, -25, -99},                // cut-out in front of the background
      {5, -15, -25, -100},
      {6, 24, -25, -100},                        // the two-material mesh (its second primitive is offset below)
      {7, 24, -25, -100},                        // (same node; the primitive lies 12 m to the right)
      {3, 0, -47, -100, 0, 1, false, true},      // the tile twice more, by one EXT_mesh_gpu_instancing node:
      {3, 30, -47, -100, 90, 1.2, false, true},  // translation, rotation and scale per instance
  };
  return m;
}

// ---- writing the model ----

void write_png(const fs::path& p, const TestImage& im) {
  std::vector<Rgba> px(static_cast<size_t>(im.w) * im.h);
  for (int y = 0; y < im.h; ++y)
    for (int x = 0; x < im.w; ++x) px[static_cast<size_t>(y) * im.w + x] = im.texel(x, y);
  ASSERT_NE(stbi_write_png(p.c_str(), im.w, im.h, 4, px.data(), im.w * 4), 0);
}

// Quad vertices (counter-clockwise seen from +z) in the mesh's frame; `dx` moves the quad within its mesh.
std::array<std::array<float, 5>, 4> quad_vertices(const QuadMesh& q, double dx) {
  return {
      {{static_cast<float>(dx - q.hw), static_cast<float>(q.hh), 0, static_cast<float>(q.u0), static_cast<float>(q.v0)},
       {static_cast<float>(dx - q.hw), static_cast<float>(-q.hh), 0, static_cast<float>(q.u0),
        static_cast<float>(q.v1)},
       {static_cast<float>(dx + q.hw), static_cast<float>(-q.hh), 0, static_cast<float>(q.u1),
        static_cast<float>(q.v1)},
       {static_cast<float>(dx + q.hw), static_cast<float>(q.hh), 0, static_cast<float>(q.u1),
        static_cast<float>(q.v0)}}};
}

// The second primitive of a two-primitive mesh sits 12 m to the right in the mesh's own frame.
double primitive_dx(const TestModel& m, int quad) {
  return quad > 0 && m.mesh_group[quad] == m.mesh_group[quad - 1] ? 12.0 : 0.0;
}

void write_gltf(const fs::path& dir, const TestModel& m) {
  std::vector<uint8_t> bin;
  nlohmann::json views = nlohmann::json::array(), accessors = nlohmann::json::array();
  auto add = [&](const void* data, size_t bytes, int component, int count, const char* type) {
    while (bin.size() % 4) bin.push_back(0);
    views.push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}});
    const auto* b = static_cast<const uint8_t*>(data);
    bin.insert(bin.end(), b, b + bytes);
    accessors.push_back(
        {{"bufferView", views.size() - 1}, {"componentType", component}, {"count", count}, {"type", type}});
    return static_cast<int>(accessors.size() - 1);
  };
  nlohmann::json meshes = nlohmann::json::array();
  for (size_t q = 0; q < m.meshes.size(); ++q) {
    const auto v = quad_vertices(m.meshes[q], primitive_dx(m, static_cast<int>(q)));
    float pos[12], uv[8];
    for (int i = 0; i < 4; ++i) {
      pos[i * 3] = v[i][0], pos[i * 3 + 1] = v[i][1], pos[i * 3 + 2] = v[i][2];
      uv[i * 2] = v[i][3], uv[i * 2 + 1] = v[i][4];
    }
    const uint16_t idx[6] = {0, 1, 2, 0, 2, 3};
    const int p = add(pos, sizeof pos, 5126, 4, "VEC3");
    float lo[3] = {pos[0], pos[1], 0}, hi[3] = {pos[0], pos[1], 0};
    for (int i = 0; i < 4; ++i)
      for (int a = 0; a < 2; ++a) lo[a] = std::min(lo[a], pos[i * 3 + a]), hi[a] = std::max(hi[a], pos[i * 3 + a]);
    accessors[p]["min"] = {lo[0], lo[1], lo[2]};
    accessors[p]["max"] = {hi[0], hi[1], hi[2]};
    const int t = add(uv, sizeof uv, 5126, 4, "VEC2");
    const int i = add(idx, sizeof idx, 5123, 6, "SCALAR");
    nlohmann::json prim = {
        {"attributes", {{"POSITION", p}, {"TEXCOORD_0", t}}}, {"indices", i}, {"material", m.meshes[q].material}};
    const size_t g = static_cast<size_t>(m.mesh_group[q]);
    if (meshes.size() <= g) meshes.push_back({{"primitives", nlohmann::json::array()}});
    meshes[g]["primitives"].push_back(prim);
  }
  nlohmann::json images = nlohmann::json::array(), textures = nlohmann::json::array(),
                 samplers = nlohmann::json::array(), materials = nlohmann::json::array();
  for (const TestImage& im : m.images) {
    write_png(dir / im.file, im);
    images.push_back({{"uri", im.file}});
  }
  const int wrap_gl[3] = {33071, 10497, 33648};
  for (const TestMaterial& mt : m.materials) {
    nlohmann::json pbr = {{"baseColorFactor", {mt.colour[0], mt.colour[1], mt.colour[2], mt.colour[3]}}};
    if (mt.image >= 0) {
      samplers.push_back(
          {{"wrapS", wrap_gl[static_cast<int>(mt.wrap)]}, {"wrapT", wrap_gl[static_cast<int>(mt.wrap)]}});
      textures.push_back({{"source", mt.image}, {"sampler", samplers.size() - 1}});
      pbr["baseColorTexture"] = {{"index", textures.size() - 1}};
    }
    nlohmann::json mat = {{"name", mt.name}, {"pbrMetallicRoughness", pbr}};
    if (mt.name == "npot") {
      // The older specular-glossiness workflow, as many exporters still write it: the colour is diffuseTexture.
      mat["pbrMetallicRoughness"].erase("baseColorTexture");
      mat["extensions"] = {{"KHR_materials_pbrSpecularGlossiness",
                            {{"diffuseTexture", {{"index", textures.size() - 1}}}, {"diffuseFactor", {1, 1, 1, 1}}}}};
    }
    if (mt.mask) mat["alphaMode"] = "MASK", mat["alphaCutoff"] = mt.cutoff;
    materials.push_back(mat);
  }
  // Nodes: a root that only groups, then per placement either one node (TRS) or a translating parent with a
  // rotating/scaling child. A two-primitive mesh is placed once (its first QuadMesh's placement).
  nlohmann::json nodes = nlohmann::json::array();
  nodes.push_back({{"name", "root"}, {"children", nlohmann::json::array()}});
  // EXT_mesh_gpu_instancing: one node at (0, 0, tz) whose instances carry the placements' translations,
  // rotations and scales (float accessors), as glTF cities place trees and lamps.
  std::vector<float> it, ir, is;
  int instanced_mesh = -1;
  double instanced_z = 0;
  for (const Placement& pl : m.placements) {
    if (!pl.gpu_instancing) continue;
    const double half = pl.rot_deg * M_PI / 360.0;
    it.insert(it.end(), {static_cast<float>(pl.tx), static_cast<float>(pl.ty), 0.0f});
    ir.insert(ir.end(), {0.0f, 0.0f, static_cast<float>(std::sin(half)), static_cast<float>(std::cos(half))});
    is.insert(is.end(), {static_cast<float>(pl.scale), static_cast<float>(pl.scale), static_cast<float>(pl.scale)});
    instanced_mesh = m.mesh_group[pl.mesh];
    instanced_z = pl.tz;
  }
  if (instanced_mesh >= 0) {
    const int count = static_cast<int>(it.size() / 3);
    const int ta = add(it.data(), it.size() * 4, 5126, count, "VEC3");
    const int ra = add(ir.data(), ir.size() * 4, 5126, count, "VEC4");
    const int sa = add(is.data(), is.size() * 4, 5126, count, "VEC3");
    nodes.push_back(
        {{"mesh", instanced_mesh},
         {"translation", {0.0, 0.0, instanced_z}},
         {"extensions",
          {{"EXT_mesh_gpu_instancing", {{"attributes", {{"TRANSLATION", ta}, {"ROTATION", ra}, {"SCALE", sa}}}}}}}});
    nodes[0]["children"].push_back(nodes.size() - 1);
  }
  for (const Placement& pl : m.placements) {
    const int q = pl.mesh;
    if (q > 0 && m.mesh_group[q] == m.mesh_group[q - 1]) continue;  // placed with its group
    if (pl.gpu_instancing) continue;                                // placed by the instancing node
    const double half = pl.rot_deg * M_PI / 360.0;
    nlohmann::json trs = {{"mesh", m.mesh_group[q]}};
    if (pl.rot_deg != 0) trs["rotation"] = {0, 0, std::sin(half), std::cos(half)};
    if (pl.scale != 1) trs["scale"] = {pl.scale, pl.scale, pl.scale};
    if (pl.parent) {
      nodes.push_back({{"translation", {pl.tx, pl.ty, pl.tz}}, {"children", {nodes.size() + 1}}});
      nodes[0]["children"].push_back(nodes.size() - 1);
      nodes.push_back(trs);
    } else {
      trs["translation"] = {pl.tx, pl.ty, pl.tz};
      nodes.push_back(trs);
      nodes[0]["children"].push_back(nodes.size() - 1);
    }
  }
  std::ofstream(dir / "model.bin", std::ios::binary).write(reinterpret_cast<const char*>(bin.data()), bin.size());
  const nlohmann::json gltf = {{"asset", {{"version", "2.0"}, {"generator", "texstream import test"}}},
                               {"extensionsUsed", {"EXT_mesh_gpu_instancing", "KHR_materials_pbrSpecularGlossiness"}},
                               {"scene", 0},
                               {"scenes", {{{"nodes", {0}}}}},
                               {"nodes", nodes},
                               {"meshes", meshes},
                               {"materials", materials},
                               {"textures", textures},
                               {"samplers", samplers},
                               {"images", images},
                               {"buffers", {{{"uri", "model.bin"}, {"byteLength", bin.size()}}}},
                               {"bufferViews", views},
                               {"accessors", accessors}};
  std::ofstream(dir / "model.gltf") << gltf.dump(1);
}

// The same placements as OBJ+MTL: world positions (OBJ has no hierarchy), v flipped (OBJ's v points up).
// Wrap modes cannot be said in MTL: only clamped and repeating materials are written (Assimp's default, repeat,
// plus "-clamp on").
void write_obj(const fs::path& dir, const TestModel& m) {
  std::ofstream mtl(dir / "model.mtl");
  for (const TestMaterial& mt : m.materials) {
    mtl << "newmtl " << mt.name << "\nKd " << mt.colour[0] << " " << mt.colour[1] << " " << mt.colour[2] << "\n";
    if (mt.image >= 0) {
      write_png(dir / m.images[mt.image].file, m.images[mt.image]);
      mtl << "map_Kd " << (mt.wrap == Wrap::kClamp ? "-clamp on " : "") << m.images[mt.image].file << "\n";
    }
  }
  std::ofstream obj(dir / "model.obj");
  obj << "mtllib model.mtl\n";
  int base = 1;
  for (const Placement& pl : m.placements) {
    const int q = pl.mesh;
    const auto v = quad_vertices(m.meshes[q], primitive_dx(m, q));
    const double c = std::cos(pl.rot_deg * M_PI / 180), s = std::sin(pl.rot_deg * M_PI / 180);
    obj << "o placement" << base << "\nusemtl " << m.materials[m.meshes[q].material].name << "\n";
    for (const auto& p : v) {
      const double x = pl.scale * static_cast<double>(p[0]), y = pl.scale * static_cast<double>(p[1]);
      obj << "v " << c * x - s * y + pl.tx << " " << s * x + c * y + pl.ty << " " << pl.tz << "\n";
    }
    for (const auto& p : v) obj << "vt " << p[3] << " " << 1.0 - static_cast<double>(p[4]) << "\n";
    obj << "f " << base << "/" << base << " " << base + 1 << "/" << base + 1 << " " << base + 2 << "/" << base + 2
        << " " << base + 3 << "/" << base + 3 << "\n";
    base += 4;
  }
}

// ---- the reference ----

struct Texels {
  uint32_t w = 0, h = 0;
  std::vector<std::array<double, 4>> linear;  // premultiplied as stored (rgb linear, a)
};

// BC1 and BC3 as the Vulkan spec defines them (sRGB endpoints decoded after interpolation is what the GPU does; the
// difference against decoding first is below a quarter of a level on these textures).
// BC3: an alpha block (two 8-bit endpoints, 3-bit indices: 8 levels when a0 > a1, else 6 and 0 and 255), then
// a colour block decoded as BC1 always in 4-colour mode.
std::vector<Rgba> decode_bc(const uint8_t* data, uint32_t w, uint32_t h, bool bc3) {
  std::vector<Rgba> out(size_t{w} * h);
  const uint32_t bw = (w + 3) / 4, bh = (h + 3) / 4;
  for (uint32_t by = 0; by < bh; ++by)
    for (uint32_t bx = 0; bx < bw; ++bx) {
      const uint8_t* a = data + (size_t{by} * bw + bx) * (bc3 ? 16 : 8);
      const uint8_t* b = bc3 ? a + 8 : a;
      std::array<double, 8> alpha{};
      uint64_t alpha_bits = 0;
      if (bc3) {
        const double a0 = a[0], a1 = a[1];
        alpha[0] = a0, alpha[1] = a1;
        for (int k = 1; k < 7; ++k)
          alpha[k + 1] = a0 > a1 ? ((7 - k) * a0 + k * a1) / 7
                         : k < 5 ? ((5 - k) * a0 + k * a1) / 5
                                 : (k == 5 ? 0 : 255);
        for (int k = 0; k < 6; ++k) alpha_bits |= uint64_t{a[2 + k]} << (8 * k);
      }
      const uint16_t c0 = b[0] | b[1] << 8, c1 = b[2] | b[3] << 8;
      auto rgb = [](uint16_t c) {
        return std::array<double, 3>{((c >> 11) & 31) * 255.0 / 31, ((c >> 5) & 63) * 255.0 / 63,
                                     (c & 31) * 255.0 / 31};
      };
      const auto e0 = rgb(c0), e1 = rgb(c1);
      std::array<std::array<double, 4>, 4> pal{};
      for (int k = 0; k < 3; ++k) {
        pal[0][k] = e0[k], pal[1][k] = e1[k];
        const bool four = c0 > c1 || bc3;
        pal[2][k] = four ? (2 * e0[k] + e1[k]) / 3 : (e0[k] + e1[k]) / 2;
        pal[3][k] = four ? (e0[k] + 2 * e1[k]) / 3 : 0;
      }
      pal[0][3] = pal[1][3] = pal[2][3] = 255;
      pal[3][3] = c0 > c1 || bc3 ? 255 : 0;
      const uint32_t bits = b[4] | b[5] << 8 | b[6] << 16 | static_cast<uint32_t>(b[7]) << 24;
      for (uint32_t y = 0; y < 4; ++y)
        for (uint32_t x = 0; x < 4; ++x) {
          const uint32_t px = bx * 4 + x, py = by * 4 + y;
          if (px >= w || py >= h) continue;
          const auto& c = pal[(bits >> (2 * (y * 4 + x))) & 3];
          const double alpha_value = bc3 ? alpha[(alpha_bits >> (3 * (y * 4 + x))) & 7] : c[3];
          out[size_t{py} * w + px] = {static_cast<uint8_t>(std::lround(c[0])), static_cast<uint8_t>(std::lround(c[1])),
                                      static_cast<uint8_t>(std::lround(c[2])),
                                      static_cast<uint8_t>(std::lround(alpha_value))};
        }
    }
  return out;
}

Texels load_level0(const fs::path& scene_dir, uint32_t texture) {
  const auto table = scene::read_texture_table(scene_dir);
  EXPECT_TRUE(table.ok());
  const scene::TextureRecord r = (*table)[texture];
  std::ifstream f(scene::texture_path(scene_dir, TextureId{texture}), std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(f)), {});
  Texels t;
  t.w = r.width, t.h = r.height;
  const auto format = static_cast<TexelFormat>(r.format);
  std::vector<Rgba> px;
  if (is_block_compressed(format)) {
    px = decode_bc(bytes.data() + scene::kDdsHeaderBytes, r.width, r.height, format == TexelFormat::kBc3);
  } else {
    px.resize(size_t{r.width} * r.height);
    std::memcpy(px.data(), bytes.data() + scene::kDdsHeaderBytes, px.size() * 4);
  }
  t.linear.resize(px.size());
  for (size_t i = 0; i < px.size(); ++i)
    t.linear[i] = {srgb_to_linear(px[i].r / 255.0), srgb_to_linear(px[i].g / 255.0), srgb_to_linear(px[i].b / 255.0),
                   px[i].a / 255.0};
  return t;
}

int wrap_index(int i, int n, Wrap w) {
  if (w == Wrap::kRepeat) return ((i % n) + n) % n;
  if (w == Wrap::kMirror) {
    const int k = ((i % (2 * n)) + 2 * n) % (2 * n);
    return k < n ? k : 2 * n - 1 - k;
  }
  return std::clamp(i, 0, n - 1);
}

std::array<double, 4> bilinear(const Texels& t, double u, double v, Wrap w) {
  const double x = u * t.w - 0.5, y = v * t.h - 0.5;
  const double fx = std::floor(x), fy = std::floor(y);
  const double ax = x - fx, ay = y - fy;
  const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
  std::array<double, 4> out{};
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const auto& p = t.linear[static_cast<size_t>(wrap_index(iy + j, static_cast<int>(t.h), w)) * t.w +
                               wrap_index(ix + i, static_cast<int>(t.w), w)];
      const double k = (i ? ax : 1 - ax) * (j ? ay : 1 - ay);
      for (int c = 0; c < 4; ++c) out[c] += k * p[c];
    }
  return out;
}

struct Hit {
  int placement = -1;  // -1: nothing
  std::array<double, 3> linear{};
  bool uncertain = false;  // alpha near the cutoff
};

double focal_px() { return (kHeight / 2.0) / std::tan(kFovY * M_PI / 360.0); }

class Reference {
 public:
  Reference(const TestModel& m, const std::vector<Texels>& tex) : m_(m), tex_(tex) {}

  // What the ray through screen point (sx, sy) (pixels, y down) sees: the nearest placement that contains it and
  // whose alpha passes.
  Hit at(double sx, double sy) const {
    std::vector<int> order(m_.placements.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
    std::stable_sort(order.begin(), order.end(),
                     [&](int a, int b) { return m_.placements[a].tz > m_.placements[b].tz; });
    for (int pi : order) {
      const Placement& pl = m_.placements[pi];
      const QuadMesh& q = m_.meshes[pl.mesh];
      const double d = -pl.tz;
      const double x = (sx - kWidth / 2.0) / focal_px() * d, y = (kHeight / 2.0 - sy) / focal_px() * d;
      const double c = std::cos(pl.rot_deg * M_PI / 180), s = std::sin(pl.rot_deg * M_PI / 180);
      const double rx = x - pl.tx, ry = y - pl.ty;
      const double lx = (c * rx + s * ry) / pl.scale - primitive_dx(m_, pl.mesh), ly = (-s * rx + c * ry) / pl.scale;
      if (std::abs(lx) > q.hw || std::abs(ly) > q.hh) continue;
      const double u = q.u0 + (lx + q.hw) / (2 * q.hw) * (q.u1 - q.u0);
      const double v = q.v0 + (q.hh - ly) / (2 * q.hh) * (q.v1 - q.v0);
      const TestMaterial& mt = m_.materials[q.material];
      const auto p = bilinear(tex_[pi], u, v, mt.wrap);
      Hit h;
      if (mt.mask) {
        if (std::abs(p[3] - mt.cutoff) < 0.1) return Hit{pi, {}, true};  // left out
        if (p[3] < mt.cutoff) continue;
        for (int k = 0; k < 3; ++k) h.linear[k] = p[k] / std::max(p[3], 1e-4);
      } else {
        for (int k = 0; k < 3; ++k) h.linear[k] = p[k];
      }
      h.placement = pi;
      return h;
    }
    return {};
  }

 private:
  const TestModel& m_;
  const std::vector<Texels>& tex_;
};

// Which texture the importer gave each placement: the mesh whose box centre (map coordinates) is nearest the
// placement's centre, turned from glTF's frame (x, -z, y) and moved by --origin.
std::vector<uint32_t> textures_of_placements(const fs::path& scene_dir, const TestModel& m) {
  const auto meshes = scene::read_meshes(scene_dir);
  EXPECT_TRUE(meshes.ok());
  std::vector<uint32_t> out;
  for (const Placement& pl : m.placements) {
    const double c = std::cos(pl.rot_deg * M_PI / 180), s = std::sin(pl.rot_deg * M_PI / 180);
    const double dx = primitive_dx(m, pl.mesh) * pl.scale;
    const double want[3] = {kOrigin[0] + pl.tx + c * dx, kOrigin[1] - pl.tz, kOrigin[2] + pl.ty + s * dx};
    double best = 1e30;
    uint32_t tex = 0;
    for (const auto& r : meshes->meshes) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double centre =
            r.origin[a] + 0.5 * (static_cast<double>(r.bounds_min[a]) + static_cast<double>(r.bounds_max[a]));
        d2 += (centre - want[a]) * (centre - want[a]);
      }
      if (d2 < best) best = d2, tex = r.texture_id;
    }
    EXPECT_LT(best, 0.01) << "no imported mesh at placement " << &pl - m.placements.data();
    out.push_back(tex);
  }
  return out;
}

std::string camera_path_text() {
  char line[256];
  std::snprintf(line, sizeof line, "0 %.3f %.3f %.3f 0 0\n1000 %.3f %.3f %.3f 0 0\n", kOrigin[0], kOrigin[1],
                kOrigin[2], kOrigin[0], kOrigin[1], kOrigin[2]);
  return std::string("# still, looking north (glTF -z) from the file's origin\n") + line;
}

struct Compared {
  double psnr = 0;
  double included = 0;
};

// Renders `scene_dir` and compares its last frame with the reference; keeps images in `dir` on failure.
Compared render_and_compare(const fs::path& dir, const fs::path& scene_dir, const TestModel& m, std::string& log) {
  std::ofstream(scene_dir / "camera_path.txt") << camera_path_text();
  const fs::path out = dir / "out";
  const std::string cmd =
      (kBin / "texstream-render").string() + " --set scene.dir=" + scene_dir.string() +
      " --set render.validation=true --set render.lockstep=true --set controller.mode=none" +
      " --set render.frames=60 --set render.write_every_frames=0 --set render.width_px=" + std::to_string(kWidth) +
      " --set render.height_px=" + std::to_string(kHeight) + " --set render.fov_y_deg=" + std::to_string(kFovY) +
      " --set render.output_dir=" + out.string();
  const int rc = texstream::test::run_logged(cmd, dir / "render.log");
  log = texstream::test::slurp(dir / "render.log");
  EXPECT_EQ(rc, 0) << log;
  if (rc != 0) return {};
  const auto summary = nlohmann::json::parse(texstream::test::slurp(out / "summary.json"));
  EXPECT_EQ(summary["validation_errors"].get<int>(), 0) << log;

  const auto tex_ids = textures_of_placements(scene_dir, m);
  std::vector<Texels> tex;
  for (uint32_t id : tex_ids) tex.push_back(load_level0(scene_dir, id));
  const Reference ref(m, tex);

  int w = 0, h = 0, n = 0;
  const fs::path png = out / "frames" / "frame_00059.png";
  unsigned char* pixels = stbi_load(png.c_str(), &w, &h, &n, 4);
  EXPECT_NE(pixels, nullptr) << png;
  if (!pixels) return {};
  EXPECT_EQ(w, kWidth);
  EXPECT_EQ(h, kHeight);
  std::vector<unsigned char> expected(size_t(w) * h * 4, 0), diff(size_t(w) * h * 4, 0);
  double sq = 0;
  size_t count = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Hit c = ref.at(x + 0.5, y + 0.5);
      bool keep = c.placement >= 0 && !c.uncertain;
      // A pixel whose neighbourhood spans another surface (an edge) says nothing about texels.
      for (double oy : {-1.0, 2.0})
        for (double ox : {-1.0, 2.0}) {
          if (!keep) break;
          const Hit e = ref.at(x + ox, y + oy);
          keep = e.placement == c.placement && !e.uncertain;
        }
      const size_t o = (size_t(y) * w + x) * 4;
      expected[o + 3] = diff[o + 3] = 255;
      if (!keep) {
        diff[o + 2] = 80;  // left out: dark blue in the diff
        continue;
      }
      for (int k = 0; k < 3; ++k) {
        const double e = linear_to_srgb(c.linear[k]) * 255.0;
        const double d = pixels[o + k] - e;
        sq += d * d;
        expected[o + k] = static_cast<unsigned char>(std::lround(e));
        diff[o + k] = static_cast<unsigned char>(std::min(255.0, std::abs(d) * 8));
      }
      ++count;
    }
  Compared r;
  r.included = static_cast<double>(count) / (double(w) * h);
  const double mse = count ? sq / (3.0 * count) : 1e9;
  r.psnr = mse > 0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : 99.0;
  if (r.psnr < 40.0 || r.included < 0.85) {
    stbi_write_png((dir / "actual.png").c_str(), w, h, 4, pixels, w * 4);
    stbi_write_png((dir / "expected.png").c_str(), w, h, 4, expected.data(), w * 4);
    stbi_write_png((dir / "diff_x8.png").c_str(), w, h, 4, diff.data(), w * 4);
  }
  stbi_image_free(pixels);
  return r;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("texstream_import_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "model");
  return dir;
}

std::string origin_args() {
  char b[128];
  std::snprintf(b, sizeof b, " --origin %.3f %.3f %.3f", kOrigin[0], kOrigin[1], kOrigin[2]);
  return b;
}

}  // namespace

// The glTF case in each texel format the importer writes: BC1 (cut-outs as punch-through), BC3 (8-bit alpha),
// RGBA8, and auto (the default: the opaque materials BC1, the cut-out BC3, the manifest "mixed"). The reference
// decodes each texture's baked blocks itself, in the format its record names.
class ImportRenderGltf : public ::testing::TestWithParam<const char*> {};

TEST_P(ImportRenderGltf, HierarchyInstancingRepeatMirrorAndCutOutsDrawAsTheReference) {
  const TestModel m = make_model();
  const std::string format = GetParam();
  const fs::path dir = fresh_dir("gltf_" + format);
  write_gltf(dir / "model", m);
  if (HasFatalFailure()) return;
  const fs::path scene_dir = dir / "scene";
  const int rc =
      texstream::test::run_logged((kBin / "texstream-import").string() + " " + (dir / "model" / "model.gltf").string() +
                                      " --out " + scene_dir.string() + origin_args() + " --format " + format,
                                  dir / "import.log");
  const std::string import_log = texstream::test::slurp(dir / "import.log");
  ASSERT_EQ(rc, 0) << import_log;

  // What the file says, as the scene holds it: 13 placements; the tile's six (moved, moved, turned, scaled, and
  // two by EXT_mesh_gpu_instancing) share one copy of its vertices, turns and scales in transforms.bin.
  const auto meshes = scene::read_meshes(scene_dir);
  ASSERT_TRUE(meshes.ok());
  EXPECT_EQ(meshes->meshes.size(), 13u);
  std::map<uint32_t, int> users;
  for (const auto& r : meshes->meshes) ++users[r.first_vertex];
  EXPECT_EQ(std::count_if(users.begin(), users.end(), [](const auto& u) { return u.second == 6; }), 1)
      << "the six tiles share one range";
  const auto xf = scene::map_transforms(scene_dir, meshes->meshes.size());
  ASSERT_TRUE(xf.ok());
  int turned = 0, scaled = 0;
  for (const auto& t : xf->transforms) {
    turned += std::abs(t.rotation[3]) < 0.99f;
    scaled += std::abs(t.scale - 1.5f) < 1e-6f;
  }
  EXPECT_EQ(turned, 2);
  EXPECT_EQ(scaled, 1);
  const auto sampling = scene::map_sampling(scene_dir, scene::read_manifest(scene_dir)->texture_count);
  ASSERT_TRUE(sampling.ok());
  const auto ids = textures_of_placements(scene_dir, m);
  const uint32_t repeat =
      scene::make_sampling_flags(scene::TextureWrap::kRepeat, scene::TextureWrap::kRepeat, false, 128);
  const uint32_t mirror =
      scene::make_sampling_flags(scene::TextureWrap::kMirror, scene::TextureWrap::kMirror, false, 128);
  const uint32_t cutout = scene::make_sampling_flags(scene::TextureWrap::kClamp, scene::TextureWrap::kClamp, true, 128);
  EXPECT_EQ(sampling->flags[ids[0]], repeat);
  EXPECT_EQ(sampling->flags[ids[1]], mirror);
  EXPECT_EQ(sampling->flags[ids[7]], cutout);
  const auto table = scene::read_texture_table(scene_dir);
  EXPECT_EQ((*table)[ids[2]].width, 128u) << "100 x 60 baked at the nearest powers of two";
  EXPECT_EQ((*table)[ids[2]].height, 64u);
  EXPECT_EQ((*table)[ids[8]].width, 1u) << "an untextured material is a 1-texel texture";
  // Each texture's format: the one asked for, or with auto the one its alpha needs; the manifest names the
  // format they share, or none.
  const auto manifest = scene::read_manifest(scene_dir);
  ASSERT_TRUE(manifest.ok()) << manifest.error().message;
  const bool mixed = format == "auto";
  for (size_t p = 0; p < m.placements.size(); ++p) {
    const bool cut_out = m.materials[m.meshes[m.placements[p].mesh].material].mask;
    const std::string want = !mixed ? format : cut_out ? "bc3" : "bc1";
    EXPECT_EQ(to_string(static_cast<TexelFormat>((*table)[ids[p]].format)), want) << "placement " << p;
  }
  if (mixed)
    EXPECT_EQ(manifest->texture_format, std::nullopt) << "opaque BC1 and cut-out BC3 textures: \"mixed\"";
  else
    EXPECT_EQ(manifest->texture_format, texel_format_from_string(format));

  std::string log;
  const Compared c = render_and_compare(dir, scene_dir, m, log);
  std::printf("import render (glTF, %s): PSNR %.2f dB over %.1f %% of the pixels\n", format.c_str(), c.psnr,
              100.0 * c.included);
  EXPECT_GE(c.psnr, 40.0) << "see " << dir << "/{actual,expected,diff_x8}.png\n" << log;
  EXPECT_GE(c.included, 0.85);
  if (!HasFailure()) fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Formats, ImportRenderGltf, ::testing::Values("bc1", "bc3", "rgba8", "auto"),
                         [](const auto& p) { return std::string(p.param); });

TEST(ImportRender, ObjWithSeveralMaterialsDrawsAsTheReference) {
  TestModel m = make_model();
  // MTL has no mirrored repeat: that quad becomes a repeating one.
  m.materials[1].wrap = Wrap::kRepeat;
  const fs::path dir = fresh_dir("obj");
  write_obj(dir / "model", m);
  if (HasFatalFailure()) return;
  const fs::path scene_dir = dir / "scene";
  const int rc =
      texstream::test::run_logged((kBin / "texstream-import").string() + " " + (dir / "model" / "model.obj").string() +
                                      " --out " + scene_dir.string() + origin_args(),
                                  dir / "import.log");
  ASSERT_EQ(rc, 0) << texstream::test::slurp(dir / "import.log");
  std::string log;
  // OBJ has no alpha mode: the leaf is drawn opaque (its transparent texels black) unless MTL says d/map_d.
  m.materials[4].mask = false;
  const Compared c = render_and_compare(dir, scene_dir, m, log);
  std::printf("import render (OBJ): PSNR %.2f dB over %.1f %% of the pixels\n", c.psnr, 100.0 * c.included);
  EXPECT_GE(c.psnr, 40.0) << "see " << dir << "/{actual,expected,diff_x8}.png\n" << log;
  EXPECT_GE(c.included, 0.85);
  if (!HasFailure()) fs::remove_all(dir);
}

TEST(ImportErrors, AMissingImageIsNamedAndItsMaterialDrawnInItsColour) {
  TestModel m = make_model();
  const fs::path dir = fresh_dir("missing");
  write_gltf(dir / "model", m);
  fs::remove(dir / "model" / "npot.png");
  const int rc =
      texstream::test::run_logged((kBin / "texstream-import").string() + " " + (dir / "model" / "model.gltf").string() +
                                      " --out " + (dir / "scene").string(),
                                  dir / "import.log");
  const std::string log = texstream::test::slurp(dir / "import.log");
  ASSERT_EQ(rc, 0) << log;
  EXPECT_NE(log.find("npot.png: no such image file; drawn in its base colour"), std::string::npos) << log;
  fs::remove_all(dir);
}

TEST(ImportErrors, ABrokenFileFailsNamingItAndLeavesNoScene) {
  const fs::path dir = fresh_dir("broken");
  std::ofstream(dir / "model" / "model.gltf") << "{\"asset\": {\"version\": \"2.0\"}, \"meshes\": [ {";
  const fs::path scene_dir = dir / "scene";
  const int rc =
      texstream::test::run_logged((kBin / "texstream-import").string() + " " + (dir / "model" / "model.gltf").string() +
                                      " --out " + scene_dir.string(),
                                  dir / "import.log");
  const std::string log = texstream::test::slurp(dir / "import.log");
  EXPECT_NE(rc, 0);
  EXPECT_NE(log.find("model.gltf"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(scene_dir));
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".import-"), std::string::npos) << "left behind: " << e.path();
  fs::remove_all(dir);
}
