#include "scene_builder.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <thread>
#include <tuple>

#include "texstream/common/camera_path.hpp"
#include "texstream/common/scene_format.hpp"
#include "texstream/common/staged_folder.hpp"
#include "texture_baker.hpp"

namespace texstream::import {
namespace fs = std::filesystem;
namespace {

// The file's frame turned to the scene's (x east, y north, z up): a y-up model's -z (glTF "forward") is north.
Mat4 up_turn(bool y_up) {
  if (!y_up) return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  // (x, y, z) -> (x, -z, y)
  return {1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1};
}

bool only_moves(const Mat4& m) {
  const double id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r)
      if (std::abs(m[c * 4 + r] - id[c * 3 + r]) > 1e-9) return false;
  return m[3] == 0 && m[7] == 0 && m[11] == 0 && m[15] == 1;
}

// The rotation and uniform scale of a placement relative to its primitive's turned geometry: A = world3 ·
// turn3^T (column-major 3x3 of `world` times the turn's inverse). Nothing when A is not a proper rotation
// times one positive scale (a mirror, a shear, a non-uniform scale): such a placement gets its own vertices.
std::optional<scene::MeshTransform> rotation_and_scale(const Mat4& world, const Mat4& turn) {
  double a[9];  // a[c * 3 + r]
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) {
      double v = 0;
      for (int k = 0; k < 3; ++k) v += world[k * 4 + r] * turn[k * 4 + c];  // turn^T(k, c) = turn(c, k)
      a[c * 3 + r] = v;
    }
  const double det =
      a[0] * (a[4] * a[8] - a[7] * a[5]) - a[3] * (a[1] * a[8] - a[7] * a[2]) + a[6] * (a[1] * a[5] - a[4] * a[2]);
  if (!(det > 0)) return std::nullopt;
  const double s = std::cbrt(det);
  for (int c = 0; c < 3; ++c)
    for (int d = c; d < 3; ++d) {
      double dot = 0;
      for (int r = 0; r < 3; ++r) dot += a[c * 3 + r] * a[d * 3 + r];
      if (std::abs(dot - (c == d ? s * s : 0.0)) > 1e-5 * s * s) return std::nullopt;
    }
  double m[9];
  for (int i = 0; i < 9; ++i) m[i] = a[i] / s;
  // Quaternion from a rotation matrix (Shepperd's method); m(r, c) = m[c * 3 + r].
  auto at = [&](int r, int c) { return m[c * 3 + r]; };
  double q[4];
  const double tr = at(0, 0) + at(1, 1) + at(2, 2);
  if (tr > 0) {
    const double k = 0.5 / std::sqrt(tr + 1.0);
    q[3] = 0.25 / k;
    q[0] = (at(2, 1) - at(1, 2)) * k;
    q[1] = (at(0, 2) - at(2, 0)) * k;
    q[2] = (at(1, 0) - at(0, 1)) * k;
  } else if (at(0, 0) > at(1, 1) && at(0, 0) > at(2, 2)) {
    const double k = 2.0 * std::sqrt(1.0 + at(0, 0) - at(1, 1) - at(2, 2));
    q[3] = (at(2, 1) - at(1, 2)) / k;
    q[0] = 0.25 * k;
    q[1] = (at(0, 1) + at(1, 0)) / k;
    q[2] = (at(0, 2) + at(2, 0)) / k;
  } else if (at(1, 1) > at(2, 2)) {
    const double k = 2.0 * std::sqrt(1.0 + at(1, 1) - at(0, 0) - at(2, 2));
    q[3] = (at(0, 2) - at(2, 0)) / k;
    q[0] = (at(0, 1) + at(1, 0)) / k;
    q[1] = 0.25 * k;
    q[2] = (at(1, 2) + at(2, 1)) / k;
  } else {
    const double k = 2.0 * std::sqrt(1.0 + at(2, 2) - at(0, 0) - at(1, 1));
    q[3] = (at(1, 0) - at(0, 1)) / k;
    q[0] = (at(0, 2) + at(2, 0)) / k;
    q[1] = (at(1, 2) + at(2, 1)) / k;
    q[2] = 0.25 * k;
  }
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  scene::MeshTransform t{};
  for (int i = 0; i < 4; ++i) t.rotation[i] = static_cast<float>(q[i] / n);
  t.scale = static_cast<float>(s);
  return t;
}

// v turned by the unit quaternion q and scaled: what scene.vert does.
std::array<double, 3> apply(const scene::MeshTransform& t, const float v[3]) {
  const double qx = t.rotation[0], qy = t.rotation[1], qz = t.rotation[2], qw = t.rotation[3];
  const double sc = t.scale, x = static_cast<double>(v[0]) * sc, y = static_cast<double>(v[1]) * sc,
               z = static_cast<double>(v[2]) * sc;
  // v + 2 q.xyz x (q.xyz x v + w v)
  const double cx = qy * z - qz * y + qw * x, cy = qz * x - qx * z + qw * y, cz = qx * y - qy * x + qw * z;
  return {x + 2 * (qy * cz - qz * cy), y + 2 * (qz * cx - qx * cz), z + 2 * (qx * cy - qy * cx)};
}

bool is_identity(const scene::MeshTransform& t) {
  return t.rotation[0] == 0 && t.rotation[1] == 0 && t.rotation[2] == 0 && t.rotation[3] == 1 && t.scale == 1;
}

// Inverse transpose of the upper 3x3 (normals), row r column c at [c * 3 + r]. Rows of m: (a b c), (d e f), (g h i).
std::array<double, 9> normal_matrix(const Mat4& m) {
  const double a = m[0], b = m[4], c = m[8], d = m[1], e = m[5], f = m[9], g = m[2], h = m[6], i = m[10];
  const double A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g;
  const double D = -(b * i - c * h), E = a * i - c * g, F = -(a * h - b * g);
  const double G = b * f - c * e, H = -(a * f - c * d), I = a * e - b * d;
  // The inverse transpose is the cofactor matrix over det (scale does not matter: normalised later); stored
  // column-major like the rest: column 0 is the cofactors' first column.
  return {A, D, G, B, E, H, C, F, I};
}

void smooth_normals(const Primitive& p, std::vector<float>& n) {
  n.assign(p.positions.size(), 0.0f);
  for (size_t t = 0; t + 2 < p.indices.size(); t += 3) {
    const float* a = &p.positions[p.indices[t] * 3];
    const float* b = &p.positions[p.indices[t + 1] * 3];
    const float* c = &p.positions[p.indices[t + 2] * 3];
    const float u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const float x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2], z = u[0] * v[1] - u[1] * v[0];
    for (int k = 0; k < 3; ++k) {
      float* o = &n[p.indices[t + k] * 3];
      o[0] += x;
      o[1] += y;
      o[2] += z;
    }
  }
}

void normalise(float* v) {
  const float l = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  if (l > 1e-20f) {
    for (int k = 0; k < 3; ++k) v[k] /= l;
  } else {
    v[0] = 0, v[1] = 0, v[2] = 1;
  }
}

// Geometry in the scene's frame: vertices relative to `origin`.
struct Placed {
  std::array<double, 3> origin{};
  std::vector<scene::Vertex> vertices;
};

// `m` applied to a primitive: positions in double, vertices relative to the origin, which is the centre of their
// box (`centre`: a placement with its own vertices) or the frame's own origin (a primitive's shared vertices,
// so that every placement's origin is its translation).
Placed place(const Primitive& p, const Mat4& m, bool centre) {
  std::vector<float> computed;
  const std::vector<float>* normals = &p.normals;
  if (p.normals.size() != p.positions.size()) {
    smooth_normals(p, computed);
    normals = &computed;
  }
  const auto nm = normal_matrix(m);
  const size_t nv = p.positions.size() / 3;
  std::vector<std::array<double, 3>> world(nv);
  double lo[3] = {std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                  std::numeric_limits<double>::max()};
  double hi[3] = {-lo[0], -lo[1], -lo[2]};
  for (size_t v = 0; v < nv; ++v) {
    const double x = p.positions[v * 3], y = p.positions[v * 3 + 1], z = p.positions[v * 3 + 2];
    for (int r = 0; r < 3; ++r) {
      world[v][r] = m[r] * x + m[4 + r] * y + m[8 + r] * z + m[12 + r];
      lo[r] = std::min(lo[r], world[v][r]);
      hi[r] = std::max(hi[r], world[v][r]);
    }
  }
  Placed out;
  for (int r = 0; r < 3; ++r) out.origin[r] = centre && nv ? 0.5 * (lo[r] + hi[r]) : 0.0;
  out.vertices.resize(nv);
  for (size_t v = 0; v < nv; ++v) {
    scene::Vertex& o = out.vertices[v];
    for (int r = 0; r < 3; ++r) o.pos[r] = static_cast<float>(world[v][r] - out.origin[r]);
    const float* n = &(*normals)[v * 3];
    for (int r = 0; r < 3; ++r)
      o.normal[r] = static_cast<float>(nm[r] * static_cast<double>(n[0]) + nm[3 + r] * static_cast<double>(n[1]) +
                                       nm[6 + r] * static_cast<double>(n[2]));
    normalise(o.normal);
    o.uv[0] = p.uvs.size() == nv * 2 ? p.uvs[v * 2] : 0.0f;
    o.uv[1] = p.uvs.size() == nv * 2 ? p.uvs[v * 2 + 1] : 0.0f;
  }
  return out;
}

bool finite_geometry(const Placed& g) {
  for (const auto& v : g.vertices)
    for (float f : {v.pos[0], v.pos[1], v.pos[2], v.uv[0], v.uv[1]})
      if (!std::isfinite(f)) return false;
  return true;
}

// What a texture's baked file depends on: baked once, however many wrap modes share it. The format is part of
// it so that one file is never linked under two formats (with auto it follows the alpha mode).
struct TexelKey {
  int image;
  std::array<float, 4> factor;
  bool alpha_test;
  float cutoff;
  TexelFormat format;
  auto tie() const { return std::tie(image, factor, alpha_test, cutoff, format); }
  bool operator<(const TexelKey& o) const { return tie() < o.tie(); }
};

struct TextureKey {
  TexelKey texels;
  Wrap u, v;
  bool operator<(const TextureKey& o) const { return std::tie(texels, u, v) < std::tie(o.texels, o.u, o.v); }
};

scene::TextureWrap to_scene(Wrap w) {
  return w == Wrap::kRepeat   ? scene::TextureWrap::kRepeat
         : w == Wrap::kMirror ? scene::TextureWrap::kMirror
                              : scene::TextureWrap::kClamp;
}

// An orbit around the scene's box looking at its centre, a pause, a cut to a closer view and a slow approach:
// something to look at with every scene (seed 000 §4.1's path has pauses and cuts too).
CameraPath orbit_path(const std::array<double, 3>& lo, const std::array<double, 3>& hi) {
  const double c[3] = {0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])};
  const double span = std::max({hi[0] - lo[0], hi[1] - lo[1], 1.0});
  const double height = std::max(hi[2] - lo[2], 1.0);
  auto pose_at = [&](double angle, double radius, double above) {
    CameraPose p{};
    p.position[0] = c[0] + radius * std::sin(angle);
    p.position[1] = c[1] - radius * std::cos(angle);
    p.position[2] = hi[2] + above;
    const double dx = c[0] - p.position[0], dy = c[1] - p.position[1], dz = c[2] - p.position[2];
    p.yaw_deg = std::atan2(dx, dy) * 180.0 / M_PI;
    p.pitch_deg = std::atan2(dz, std::hypot(dx, dy)) * 180.0 / M_PI;
    return p;
  };
  std::vector<CameraKey> keys;
  const double radius = 0.8 * span, above = 0.35 * span + 0.25 * height;
  for (int k = 0; k <= 8; ++k) keys.push_back({3.0 * k, pose_at(k * M_PI / 4, radius, above)});
  keys.push_back({26.0, keys.back().pose});                                  // pause
  keys.push_back({26.0, pose_at(M_PI / 3, 0.45 * span, 0.15 * span)});       // cut
  keys.push_back({32.0, pose_at(M_PI / 2, 0.3 * span, 0.08 * span + 1.0)});  // approach
  return CameraPath(std::move(keys));
}

Status write_text(const fs::path& file, const std::string& text) {
  std::ofstream f(file, std::ios::binary | std::ios::trunc);
  f << text;
  f.close();
  if (!f) return make_error(ErrorCode::kIo, file.string() + ": cannot write");
  return ok_status();
}

}  // namespace

Result<ImportReport> build_scene(const Model& model, const ImportOptions& opt) {
  ImportReport report;
  report.skipped = model.skipped;
  // Written beside --out and renamed into place: a failed import leaves nothing half written.
  auto staged = StagedFolder::create(opt.out, opt.force, "import");
  if (!staged) return staged.error();
  const fs::path tmp = staged->dir();
  std::error_code ec;

  // ---- textures: one per (texels, wrap); texels baked once ----
  std::map<TextureKey, uint32_t> texture_of;
  std::vector<TextureKey> textures;
  std::map<TexelKey, uint32_t> first_texture_of_texels;
  auto texture_for = [&](int material) -> uint32_t {
    Material m;
    if (material >= 0 && material < static_cast<int>(model.materials.size())) m = model.materials[material];
    TextureKey k;
    k.texels.image = m.image;
    k.texels.factor = m.base_colour;
    k.texels.alpha_test = m.alpha != AlphaMode::kOpaque;
    k.texels.cutoff = m.alpha == AlphaMode::kMask ? m.alpha_cutoff : 0.5f;
    k.texels.format = texel_format_for(opt.format, k.texels.alpha_test);
    k.u = m.image >= 0 ? m.wrap_u : Wrap::kClamp;
    k.v = m.image >= 0 ? m.wrap_v : Wrap::kClamp;
    auto [it, added] = texture_of.emplace(k, static_cast<uint32_t>(textures.size()));
    if (added) textures.push_back(k);
    return it->second;
  };

  // ---- meshes ----
  const Mat4 turn = up_turn(opt.y_up.value_or(model.y_up));
  scene::MeshData meshes;
  std::vector<scene::MeshTransform> transforms;  // one per mesh; written only when one is not the identity
  struct Shared {
    uint32_t first_vertex, vertex_count, first_index, index_count;
    float lo[3], hi[3];
  };
  std::vector<std::optional<Shared>> shared(model.primitives.size());
  std::array<double, 3> lo{std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
                           std::numeric_limits<double>::max()};
  std::array<double, 3> hi{-lo[0], -lo[1], -lo[2]};
  auto append = [&](const Placed& g, const Primitive& p, scene::MeshRecord& r) -> bool {
    if (meshes.vertices.size() + g.vertices.size() > 0xffffffffull ||
        meshes.indices.size() + p.indices.size() > 0xffffffffull)
      return false;
    r.first_vertex = static_cast<uint32_t>(meshes.vertices.size());
    r.vertex_count = static_cast<uint32_t>(g.vertices.size());
    r.first_index = static_cast<uint32_t>(meshes.indices.size());
    r.index_count = static_cast<uint32_t>(p.indices.size());
    float blo[3] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
                    std::numeric_limits<float>::max()};
    float bhi[3] = {-blo[0], -blo[1], -blo[2]};
    for (const auto& v : g.vertices)
      for (int a = 0; a < 3; ++a) {
        blo[a] = std::min(blo[a], v.pos[a]);
        bhi[a] = std::max(bhi[a], v.pos[a]);
      }
    for (int a = 0; a < 3; ++a) {
      r.bounds_min[a] = blo[a];
      r.bounds_max[a] = bhi[a];
    }
    meshes.vertices.insert(meshes.vertices.end(), g.vertices.begin(), g.vertices.end());
    meshes.indices.insert(meshes.indices.end(), p.indices.begin(), p.indices.end());
    return true;
  };
  for (const Instance& inst : model.instances) {
    if (inst.primitive >= model.primitives.size()) continue;
    const Primitive& p = model.primitives[inst.primitive];
    if (p.indices.size() < 3) continue;
    const Mat4 world = multiply(turn, inst.transform);
    scene::MeshRecord r{};
    r.texture_id = texture_for(p.material);
    // A placement that turns and scales its primitive uniformly shares the primitive's vertices (turned once
    // into the scene's frame) and carries its rotation and scale in transforms.bin; any other is baked.
    scene::MeshTransform xf = scene::kIdentityTransform;
    const std::optional<scene::MeshTransform> shares =
        only_moves(inst.transform) ? std::optional(scene::kIdentityTransform) : rotation_and_scale(world, turn);
    if (shares) {
      xf = *shares;
      if (!shared[inst.primitive]) {
        const Placed g = place(p, turn, /*centre=*/false);
        if (!finite_geometry(g)) {
          report.skipped.push_back(p.name + ": non-finite positions or UVs");
          continue;
        }
        if (!append(g, p, r))
          return make_error(ErrorCode::kResourceExhausted, model.source + ": more than 2^32 vertices or indices");
        shared[inst.primitive] = Shared{r.first_vertex,
                                        r.vertex_count,
                                        r.first_index,
                                        r.index_count,
                                        {r.bounds_min[0], r.bounds_min[1], r.bounds_min[2]},
                                        {r.bounds_max[0], r.bounds_max[1], r.bounds_max[2]}};
      } else {
        ++report.shared_meshes;
      }
      const Shared& sh = *shared[inst.primitive];
      r.first_vertex = sh.first_vertex;
      r.vertex_count = sh.vertex_count;
      r.first_index = sh.first_index;
      r.index_count = sh.index_count;
      // The box of the turned, scaled geometry: its eight corners' box (contains every vertex).
      float blo[3] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
                      std::numeric_limits<float>::max()};
      float bhi[3] = {-blo[0], -blo[1], -blo[2]};
      for (int c = 0; c < 8; ++c) {
        const float corner[3] = {(c & 1) ? sh.hi[0] : sh.lo[0], (c & 2) ? sh.hi[1] : sh.lo[1],
                                 (c & 4) ? sh.hi[2] : sh.lo[2]};
        const auto w = apply(xf, corner);
        for (int a = 0; a < 3; ++a) {
          blo[a] = std::min(blo[a], static_cast<float>(std::nextafter(w[a], -1e300)));
          bhi[a] = std::max(bhi[a], static_cast<float>(std::nextafter(w[a], 1e300)));
        }
      }
      for (int a = 0; a < 3; ++a) {
        r.bounds_min[a] = is_identity(xf) ? sh.lo[a] : blo[a];
        r.bounds_max[a] = is_identity(xf) ? sh.hi[a] : bhi[a];
      }
      if (!is_identity(xf)) ++report.transformed_meshes;
      for (int a = 0; a < 3; ++a) r.origin[a] = world[12 + a] + opt.origin[a];
    } else {
      Placed g = place(p, world, /*centre=*/true);
      if (!finite_geometry(g)) {
        report.skipped.push_back(p.name + ": non-finite positions or UVs after its node transform");
        continue;
      }
      if (!append(g, p, r))
        return make_error(ErrorCode::kResourceExhausted, model.source + ": more than 2^32 vertices or indices");
      for (int a = 0; a < 3; ++a) r.origin[a] = g.origin[a] + opt.origin[a];
      ++report.baked_meshes;
    }
    transforms.push_back(xf);
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], r.origin[a] + static_cast<double>(r.bounds_min[a]));
      hi[a] = std::max(hi[a], r.origin[a] + static_cast<double>(r.bounds_max[a]));
    }
    report.triangles += r.index_count / 3;
    meshes.meshes.push_back(r);
  }
  if (meshes.meshes.empty()) {
    std::string why = model.source + ": no triangles to import";
    for (size_t i = 0; i < report.skipped.size() && i < 3; ++i) why += (i ? "; " : " (") + report.skipped[i];
    if (!report.skipped.empty()) why += report.skipped.size() > 3 ? "; ...)" : ")";
    return make_error(ErrorCode::kInvalidArgument, why);
  }
  report.meshes = meshes.meshes.size();

  // ---- bake: each distinct texel set once, in parallel; the other textures of it are hard links ----
  std::vector<uint32_t> bake_jobs;  // texture ids whose texels are baked
  std::vector<uint32_t> texels_source(textures.size());
  for (uint32_t t = 0; t < textures.size(); ++t) {
    auto [it, added] = first_texture_of_texels.emplace(textures[t].texels, t);
    texels_source[t] = it->second;
    if (added) bake_jobs.push_back(t);
  }
  std::vector<BakedTexture> baked(textures.size());
  std::vector<std::string> bake_errors(textures.size());
  std::atomic<size_t> next{0}, done{0};
  const auto bake_start = std::chrono::steady_clock::now();
  auto bake_one = [&](uint32_t t, const TexelKey& k, bool flat) -> Result<BakedTexture> {
    BakeInput in;
    in.image = !flat && k.image >= 0 ? &model.images[k.image] : nullptr;
    in.factor = k.factor;
    in.alpha_test = k.alpha_test;
    in.cutoff = k.cutoff;
    in.format = k.format;
    in.max_extent = opt.max_extent;
    const fs::path dds = scene::texture_path(tmp, TextureId{t});
    std::error_code e;
    fs::create_directories(dds.parent_path(), e);
    return bake_texture(in, dds, tmp / ("scratch-" + std::to_string(t)));
  };
  auto worker = [&] {
    for (size_t j; (j = next.fetch_add(1)) < bake_jobs.size();) {
      const uint32_t t = bake_jobs[j];
      auto r = bake_one(t, textures[t].texels, false);
      if (!r.ok()) {
        bake_errors[t] = r.error().message;
        r = bake_one(t, textures[t].texels, true);  // drawn in its base colour
      }
      if (r.ok())
        baked[t] = *r;
      else
        bake_errors[t] += "; and its 1x1 fallback: " + r.error().message;
      const size_t d = done.fetch_add(1) + 1;
      if (opt.progress) opt.progress(d, bake_jobs.size());
    }
  };
  const unsigned n_threads =
      std::max(1u, std::min<unsigned>(opt.threads ? opt.threads : std::thread::hardware_concurrency(),
                                      static_cast<unsigned>(bake_jobs.size())));
  {
    std::vector<std::jthread> pool;
    for (unsigned i = 1; i < n_threads; ++i) pool.emplace_back(worker);
    worker();
  }
  report.bake_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - bake_start).count();

  std::vector<scene::TextureRecord> table(textures.size());
  std::vector<uint32_t> colormap(textures.size()), sampling(textures.size());
  for (uint32_t t = 0; t < textures.size(); ++t) {
    const uint32_t src = texels_source[t];
    const BakedTexture& b = baked[src];
    if (b.width == 0) return make_error(ErrorCode::kIo, bake_errors[src]);
    if (src == t) {
      if (!bake_errors[t].empty()) {
        report.skipped.push_back(bake_errors[t] + "; drawn in its base colour");
        ++report.flat_textures;
      } else if (textures[t].texels.image < 0) {
        ++report.flat_textures;
      } else {
        ++report.images_baked;
        if (b.width != b.source_width || b.height != b.source_height) ++report.resized;
      }
      report.texture_bytes += b.file_bytes;
    } else {
      const fs::path from = scene::texture_path(tmp, TextureId{src}), to = scene::texture_path(tmp, TextureId{t});
      std::error_code e;
      fs::create_directories(to.parent_path(), e);
      fs::create_hard_link(from, to, e);
      if (e) fs::copy_file(from, to, fs::copy_options::overwrite_existing, e);
      if (e) return make_error(ErrorCode::kIo, to.string() + ": cannot link or copy: " + e.message());
    }
    const bool flat = b.width == 1 && b.height == 1;
    const TextureKey& k = textures[t];
    table[t] = scene::TextureRecord{b.width, b.height, b.mip_count, static_cast<uint32_t>(k.texels.format)};
    ++report.textures_by_format[k.texels.format];
    colormap[t] = b.colormap;
    sampling[t] = scene::make_sampling_flags(
        flat ? scene::TextureWrap::kClamp : to_scene(k.u), flat ? scene::TextureWrap::kClamp : to_scene(k.v),
        k.texels.alpha_test, static_cast<uint32_t>(std::lround(std::clamp(k.texels.cutoff, 0.0f, 1.0f) * 255.0f)));
    report.alpha_tested += k.texels.alpha_test;
    report.repeating += !flat && (k.u != Wrap::kClamp || k.v != Wrap::kClamp);
  }
  report.textures = textures.size();

  // ---- the files; scene.json last, then the rename ----
  TS_TRY(scene::write_meshes(tmp, meshes));
  TS_TRY(scene::write_texture_table(tmp, table));
  TS_TRY(scene::write_colormap(tmp, colormap));
  TS_TRY(scene::write_sampling(tmp, sampling));
  if (std::any_of(transforms.begin(), transforms.end(), [](const auto& t) { return !is_identity(t); }))
    TS_TRY(scene::write_transforms(tmp, transforms));
  scene::Manifest m;
  m.name = fs::path(model.source).stem().string();
  m.mesh_count = meshes.meshes.size();
  m.texture_count = textures.size();
  // The one format every texture shares, or "mixed".
  m.texture_format =
      report.textures_by_format.size() == 1 ? std::optional(report.textures_by_format.begin()->first) : std::nullopt;
  m.origin = {0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]};
  m.bounds_min = lo;
  m.bounds_max = hi;
  TS_TRY(write_text(tmp / m.camera_path, orbit_path(lo, hi).to_text()));
  TS_TRY(scene::write_manifest(tmp, m));
  for (const auto& e : fs::directory_iterator(tmp, ec))
    if (e.path().filename().string().rfind("scratch-", 0) == 0) fs::remove(e.path(), ec);

  TS_TRY(staged->commit());
  return report;
}

}  // namespace texstream::import
