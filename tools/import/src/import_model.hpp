#pragma once
// What texstream-import reads from a model file, before anything is baked: the two front ends (glTF through
// tinygltf, every other format through Assimp) fill this one description, and the scene builder turns it into
// a scene folder. Nothing here knows the scene format.
#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace texstream::import {

// How a texture repeats outside [0, 1] (glTF sampler wrapS/wrapT, Assimp's mapping mode).
enum class Wrap : uint8_t { kClamp = 0, kRepeat = 1, kMirror = 2 };

// glTF alphaMode. Blend is drawn as an alpha test at 0.5 (the renderer has no sorted transparency).
enum class AlphaMode : uint8_t { kOpaque, kMask, kBlend };

struct SourceImage {
  std::string name;            // for messages: the uri, or "<file> image N" for an embedded one
  std::filesystem::path file;  // an image file on disk, or empty when `bytes` holds it
  std::vector<uint8_t> bytes;  // an embedded image (glb buffer view, data uri, Assimp embedded texture)
  std::string extension;       // of an embedded image, from its MIME type (".png", ".jpg", ...)
};

struct Material {
  std::string name;
  int image = -1;                                // SourceImage index, -1: base colour only
  std::array<float, 4> base_colour{1, 1, 1, 1};  // linear RGBA factor (glTF baseColorFactor)
  Wrap wrap_u = Wrap::kRepeat;
  Wrap wrap_v = Wrap::kRepeat;
  AlphaMode alpha = AlphaMode::kOpaque;
  float alpha_cutoff = 0.5f;
};

// Triangles with one material, in the file's own frame (before the node transform and the up-axis turn).
struct Primitive {
  std::string name;
  std::vector<float> positions;  // xyz
  std::vector<float> normals;    // xyz, or empty (the builder computes them)
  std::vector<float> uvs;        // uv, top-left origin (v down), or empty (all 0)
  std::vector<uint32_t> indices;
  int material = -1;  // -1: the default material (white)
};

// A 4x4 transform, column-major (element (row, column) at [column * 4 + row]), double: node transforms keep
// map coordinates exact.
using Mat4 = std::array<double, 16>;
inline constexpr Mat4 kIdentity{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

inline Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + row] * b[c * 4 + k];
      r[c * 4 + row] = s;
    }
  return r;
}

// One placement of a primitive: the node's world transform, column-major, double (map coordinates).
struct Instance {
  uint32_t primitive = 0;
  std::array<double, 16> transform{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
};

struct Model {
  std::string source;  // the file, for messages
  bool y_up = true;    // glTF is y-up by definition; OBJ and most Assimp formats are too
  std::vector<SourceImage> images;
  std::vector<Material> materials;
  std::vector<Primitive> primitives;
  std::vector<Instance> instances;
  std::vector<std::string> skipped;  // what was read but not imported, one line each (element and reason)
};

}  // namespace texstream::import
