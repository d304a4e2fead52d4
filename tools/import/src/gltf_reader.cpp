// glTF 2.0 (.gltf, .glb) through tinygltf. Images are not decoded here: an embedded image keeps its bytes, an
// external one its path (the baker decodes each once, in parallel). Node transforms are composed in double, so a
// city placed at map coordinates by its root node keeps millimetres.
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "model_readers.hpp"

namespace texstream::import {
namespace {

// T * R * S from a translation, a unit quaternion (x, y, z, w) and a scale.
Mat4 compose(const double t[3], const double q[4], const double s[3]) {
  const double x = q[0], y = q[1], z = q[2], w = q[3];
  Mat4 m{};
  m[0] = (1 - 2 * (y * y + z * z)) * s[0];
  m[1] = (2 * (x * y + z * w)) * s[0];
  m[2] = (2 * (x * z - y * w)) * s[0];
  m[4] = (2 * (x * y - z * w)) * s[1];
  m[5] = (1 - 2 * (x * x + z * z)) * s[1];
  m[6] = (2 * (y * z + x * w)) * s[1];
  m[8] = (2 * (x * z + y * w)) * s[2];
  m[9] = (2 * (y * z - x * w)) * s[2];
  m[10] = (1 - 2 * (x * x + y * y)) * s[2];
  m[12] = t[0];
  m[13] = t[1];
  m[14] = t[2];
  m[15] = 1;
  return m;
}

Mat4 node_local(const tinygltf::Node& n) {
  if (n.matrix.size() == 16) {
    Mat4 m{};
    for (int i = 0; i < 16; ++i) m[i] = n.matrix[i];
    return m;
  }
  double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
  if (n.translation.size() == 3) std::memcpy(t, n.translation.data(), sizeof t);
  if (n.rotation.size() == 4) std::memcpy(q, n.rotation.data(), sizeof q);
  if (n.scale.size() == 3) std::memcpy(s, n.scale.data(), sizeof s);
  return compose(t, q, s);
}

// Reads accessor `index` as `components` floats per element (normalized integers mapped to [0, 1] / [-1, 1]).
Status read_floats(const tinygltf::Model& m, int index, int components, std::vector<float>& out,
                   const std::string& what) {
  if (index < 0 || index >= static_cast<int>(m.accessors.size()))
    return make_error(ErrorCode::kCorrupt, what + ": accessor " + std::to_string(index) + " does not exist");
  const tinygltf::Accessor& a = m.accessors[index];
  const int have = tinygltf::GetNumComponentsInType(a.type);
  if (have != components)
    return make_error(ErrorCode::kUnsupported, what + ": accessor " + std::to_string(index) + " has " +
                                                   std::to_string(have) + " components, expected " +
                                                   std::to_string(components));
  if (a.sparse.isSparse)
    return make_error(ErrorCode::kUnsupported, what + ": sparse accessor " + std::to_string(index));
  out.assign(a.count * components, 0.0f);
  if (a.bufferView < 0) return ok_status();  // all zeros, as the spec says
  const tinygltf::BufferView& v = m.bufferViews.at(a.bufferView);
  const tinygltf::Buffer& b = m.buffers.at(v.buffer);
  const int csize = tinygltf::GetComponentSizeInBytes(a.componentType);
  if (csize <= 0)
    return make_error(ErrorCode::kCorrupt, what + ": bad component type in accessor " + std::to_string(index));
  const size_t stride = v.byteStride ? v.byteStride : static_cast<size_t>(csize * components);
  const size_t start = v.byteOffset + a.byteOffset;
  const size_t need = a.count == 0 ? 0 : start + stride * (a.count - 1) + static_cast<size_t>(csize * components);
  if (need > b.data.size())
    return make_error(ErrorCode::kCorrupt, what + ": accessor " + std::to_string(index) + " runs past its buffer");
  for (size_t i = 0; i < a.count; ++i) {
    const uint8_t* p = b.data.data() + start + i * stride;
    for (int c = 0; c < components; ++c) {
      const uint8_t* q = p + static_cast<size_t>(c * csize);
      float f = 0;
      switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
          std::memcpy(&f, q, 4);
          break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
          f = a.normalized ? *q / 255.0f : *q;
          break;
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
          const auto s = static_cast<int8_t>(*q);
          f = a.normalized ? std::max(s / 127.0f, -1.0f) : s;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          uint16_t u;
          std::memcpy(&u, q, 2);
          f = a.normalized ? u / 65535.0f : u;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
          int16_t s;
          std::memcpy(&s, q, 2);
          f = a.normalized ? std::max(s / 32767.0f, -1.0f) : s;
          break;
        }
        default:
          return make_error(ErrorCode::kUnsupported, what + ": accessor " + std::to_string(index) +
                                                         " has component type " + std::to_string(a.componentType));
      }
      out[i * components + c] = f;
    }
  }
  return ok_status();
}

Status read_indices(const tinygltf::Model& m, int index, size_t vertex_count, std::vector<uint32_t>& out,
                    const std::string& what) {
  if (index < 0) {  // non-indexed
    out.resize(vertex_count);
    for (size_t i = 0; i < vertex_count; ++i) out[i] = static_cast<uint32_t>(i);
    return ok_status();
  }
  if (index >= static_cast<int>(m.accessors.size()))
    return make_error(ErrorCode::kCorrupt, what + ": index accessor " + std::to_string(index) + " does not exist");
  const tinygltf::Accessor& a = m.accessors[index];
  if (a.bufferView < 0 || a.sparse.isSparse)
    return make_error(ErrorCode::kUnsupported, what + ": index accessor without a buffer view, or sparse");
  const tinygltf::BufferView& v = m.bufferViews.at(a.bufferView);
  const tinygltf::Buffer& b = m.buffers.at(v.buffer);
  const int csize = tinygltf::GetComponentSizeInBytes(a.componentType);
  if (csize != 1 && csize != 2 && csize != 4)
    return make_error(ErrorCode::kCorrupt, what + ": index component type " + std::to_string(a.componentType));
  const size_t stride = v.byteStride ? v.byteStride : static_cast<size_t>(csize);
  const size_t start = v.byteOffset + a.byteOffset;
  if (a.count && start + stride * (a.count - 1) + csize > b.data.size())
    return make_error(ErrorCode::kCorrupt, what + ": index accessor runs past its buffer");
  out.resize(a.count);
  for (size_t i = 0; i < a.count; ++i) {
    const uint8_t* p = b.data.data() + start + i * stride;
    uint32_t value = 0;
    if (csize == 1) value = *p;
    if (csize == 2) {
      uint16_t u;
      std::memcpy(&u, p, 2);
      value = u;
    }
    if (csize == 4) std::memcpy(&value, p, 4);
    if (value >= vertex_count)
      return make_error(ErrorCode::kCorrupt, what + ": index " + std::to_string(value) + " at " + std::to_string(i) +
                                                 " is past the " + std::to_string(vertex_count) + " vertices");
    out[i] = value;
  }
  return ok_status();
}

// Triangle strips and fans as triangle lists; lines and points cannot carry a texture.
bool to_triangle_list(int mode, std::vector<uint32_t>& idx) {
  if (mode == TINYGLTF_MODE_TRIANGLES) {
    idx.resize(idx.size() / 3 * 3);
    return true;
  }
  std::vector<uint32_t> out;
  if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
    for (size_t i = 2; i < idx.size(); ++i) {
      if (i % 2 == 0)
        out.insert(out.end(), {idx[i - 2], idx[i - 1], idx[i]});
      else
        out.insert(out.end(), {idx[i - 1], idx[i - 2], idx[i]});
    }
  } else if (mode == TINYGLTF_MODE_TRIANGLE_FAN) {
    for (size_t i = 2; i < idx.size(); ++i) out.insert(out.end(), {idx[0], idx[i - 1], idx[i]});
  } else {
    return false;
  }
  idx = std::move(out);
  return true;
}

Wrap wrap_of(int gl) {
  if (gl == TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE) return Wrap::kClamp;
  if (gl == TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT) return Wrap::kMirror;
  return Wrap::kRepeat;
}

std::string extension_of_mime(const std::string& mime) {
  if (mime == "image/png") return ".png";
  if (mime == "image/jpeg") return ".jpg";
  if (mime == "image/vnd-ms.dds" || mime == "image/vnd.ms-dds") return ".dds";
  if (mime == "image/webp") return ".webp";
  if (mime == "image/ktx2") return ".ktx2";
  return ".png";
}

// Keeps an embedded image's encoded bytes; an external image is re-read by the baker from its path, so that a
// city's images are never all in memory at once.
bool keep_encoded(tinygltf::Image* image, const int, std::string*, std::string*, int, int, const unsigned char* bytes,
                  int size, void*) {
  image->as_is = true;
  if (image->uri.empty() || image->uri.rfind("data:", 0) == 0) image->image.assign(bytes, bytes + size);
  return true;
}

// Percent-decoding of a relative uri ("my%20image.png").
std::string uri_decode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out.push_back(static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16)));
      i += 2;
    } else {
      out.push_back(s[i]);
    }
  }
  return out;
}

// The image a texture samples: its source, or the source of an extension that replaces it (DDS, WebP).
int texture_source(const tinygltf::Texture& t) {
  if (t.source >= 0) return t.source;
  for (const char* ext : {"MSFT_texture_dds", "EXT_texture_webp", "KHR_texture_basisu"}) {
    auto it = t.extensions.find(ext);
    if (it != t.extensions.end() && it->second.Has("source")) return it->second.Get("source").GetNumberAsInt();
  }
  return -1;
}

}  // namespace

Result<Model> read_gltf(const std::filesystem::path& file) {
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(keep_encoded, nullptr);
  tinygltf::Model g;
  std::string err, warn;
  const std::string name = file.string();
  const bool binary = file.extension() == ".glb" || file.extension() == ".GLB";
  const bool loaded =
      binary ? loader.LoadBinaryFromFile(&g, &err, &warn, name) : loader.LoadASCIIFromFile(&g, &err, &warn, name);
  if (!loaded) {
    if (!std::filesystem::exists(file)) return make_error(ErrorCode::kNotFound, name + ": no such file");
    return make_error(ErrorCode::kCorrupt, name + ": not a glTF 2.0 file tinygltf can read: " + err);
  }

  Model out;
  out.source = name;
  out.y_up = true;
  if (!warn.empty()) {
    size_t at = 0;
    while (at < warn.size()) {
      const size_t nl = warn.find('\n', at);
      const std::string line = warn.substr(at, nl == std::string::npos ? std::string::npos : nl - at);
      if (!line.empty()) out.skipped.push_back(name + ": " + line);
      if (nl == std::string::npos) break;
      at = nl + 1;
    }
  }
  for (const std::string& ext : g.extensionsRequired)
    if (ext != "KHR_materials_emissive_strength" && ext != "EXT_mesh_gpu_instancing" && ext != "MSFT_texture_dds" &&
        ext != "EXT_texture_webp" && ext != "KHR_texture_transform" && ext != "KHR_mesh_quantization")
      out.skipped.push_back(name + ": required extension " + ext + " is not supported; drawn without it");

  // Images.
  const std::filesystem::path base = file.parent_path();
  for (size_t i = 0; i < g.images.size(); ++i) {
    const tinygltf::Image& im = g.images[i];
    SourceImage s;
    if (!im.uri.empty() && im.uri.rfind("data:", 0) != 0) {
      s.file = base / uri_decode(im.uri);
      s.name = s.file.string();
    } else {
      s.bytes = im.image;
      std::string mime = im.mimeType;
      if (mime.empty() && im.uri.rfind("data:", 0) == 0) mime = im.uri.substr(5, im.uri.find(';') - 5);
      s.extension = extension_of_mime(mime);
      s.name = name + " image " + std::to_string(i) + (im.name.empty() ? "" : " (" + im.name + ")");
    }
    out.images.push_back(std::move(s));
  }

  // Materials. The colour texture is baseColorTexture, or for a file of the older specular-glossiness workflow
  // (KHR_materials_pbrSpecularGlossiness, still written by many exporters) its diffuseTexture and diffuseFactor.
  std::vector<int> texcoord_set(g.materials.size(), 0);
  for (size_t i = 0; i < g.materials.size(); ++i) {
    const tinygltf::Material& gm = g.materials[i];
    Material m;
    m.name = gm.name.empty() ? "material " + std::to_string(i) : gm.name;
    const auto& pbr = gm.pbrMetallicRoughness;
    for (int c = 0; c < 4 && c < static_cast<int>(pbr.baseColorFactor.size()); ++c)
      m.base_colour[c] = static_cast<float>(pbr.baseColorFactor[c]);
    if (gm.alphaMode == "MASK") m.alpha = AlphaMode::kMask;
    if (gm.alphaMode == "BLEND") m.alpha = AlphaMode::kBlend;
    m.alpha_cutoff = static_cast<float>(gm.alphaCutoff);
    int tex = pbr.baseColorTexture.index;
    texcoord_set[i] = pbr.baseColorTexture.texCoord;
    if (auto sg = gm.extensions.find("KHR_materials_pbrSpecularGlossiness"); tex < 0 && sg != gm.extensions.end()) {
      const tinygltf::Value& v = sg->second;
      if (v.Has("diffuseFactor") && v.Get("diffuseFactor").ArrayLen() == 4)
        for (int c = 0; c < 4; ++c)
          m.base_colour[c] = static_cast<float>(v.Get("diffuseFactor").Get(c).GetNumberAsDouble());
      if (v.Has("diffuseTexture") && v.Get("diffuseTexture").Has("index")) {
        tex = v.Get("diffuseTexture").Get("index").GetNumberAsInt();
        if (v.Get("diffuseTexture").Has("texCoord"))
          texcoord_set[i] = v.Get("diffuseTexture").Get("texCoord").GetNumberAsInt();
      }
    }
    if (tex >= 0 && tex < static_cast<int>(g.textures.size())) {
      const tinygltf::Texture& t = g.textures[tex];
      const int src = texture_source(t);
      if (src >= 0 && src < static_cast<int>(g.images.size()))
        m.image = src;
      else
        out.skipped.push_back(name + ": texture " + std::to_string(tex) + " of " + m.name +
                              " has no image we can read");
      if (t.sampler >= 0 && t.sampler < static_cast<int>(g.samplers.size())) {
        m.wrap_u = wrap_of(g.samplers[t.sampler].wrapS);
        m.wrap_v = wrap_of(g.samplers[t.sampler].wrapT);
      }
    }
    out.materials.push_back(std::move(m));
  }

  // Primitives: one per (glTF mesh, primitive); mesh_primitives[mesh] lists them (-1: skipped).
  std::vector<std::vector<int>> mesh_primitives(g.meshes.size());
  for (size_t mi = 0; mi < g.meshes.size(); ++mi) {
    const tinygltf::Mesh& gm = g.meshes[mi];
    for (size_t pi = 0; pi < gm.primitives.size(); ++pi) {
      const tinygltf::Primitive& gp = gm.primitives[pi];
      const std::string what = name + ": mesh " + std::to_string(mi) + (gm.name.empty() ? "" : " (" + gm.name + ")") +
                               " primitive " + std::to_string(pi);
      Primitive p;
      p.name = what;
      p.material = gp.material;
      auto pos = gp.attributes.find("POSITION");
      if (pos == gp.attributes.end()) {
        out.skipped.push_back(what + ": no POSITION");
        mesh_primitives[mi].push_back(-1);
        continue;
      }
      Status st = read_floats(g, pos->second, 3, p.positions, what + " POSITION");
      const size_t nv = p.positions.size() / 3;
      if (st.ok()) {
        if (auto n = gp.attributes.find("NORMAL"); n != gp.attributes.end()) {
          if (!read_floats(g, n->second, 3, p.normals, what + " NORMAL").ok() || p.normals.size() != nv * 3)
            p.normals.clear();
        }
        int set = 0;
        if (p.material >= 0 && p.material < static_cast<int>(g.materials.size()))
          set = texcoord_set[static_cast<size_t>(p.material)];
        if (auto t = gp.attributes.find("TEXCOORD_" + std::to_string(set)); t != gp.attributes.end()) {
          st = read_floats(g, t->second, 2, p.uvs, what + " TEXCOORD_" + std::to_string(set));
          if (st.ok() && p.uvs.size() != nv * 2)
            st = make_error(ErrorCode::kCorrupt, what + ": TEXCOORD count differs from POSITION");
        }
      }
      if (st.ok()) st = read_indices(g, gp.indices, nv, p.indices, what);
      if (st.ok() && !to_triangle_list(gp.mode, p.indices))
        st = make_error(ErrorCode::kUnsupported, what + ": mode " + std::to_string(gp.mode) + " (points or lines)");
      if (!st.ok()) {
        out.skipped.push_back(st.error().message);
        mesh_primitives[mi].push_back(-1);
        continue;
      }
      // KHR_texture_transform on the base colour texture: offset, rotation, scale applied to the UVs.
      if (p.material >= 0 && p.material < static_cast<int>(g.materials.size())) {
        const auto& ti = g.materials[p.material].pbrMetallicRoughness.baseColorTexture;
        if (auto e = ti.extensions.find("KHR_texture_transform"); e != ti.extensions.end()) {
          double off[2] = {0, 0}, sc[2] = {1, 1}, rot = 0;
          const tinygltf::Value& v = e->second;
          if (v.Has("offset") && v.Get("offset").ArrayLen() == 2)
            for (int k = 0; k < 2; ++k) off[k] = v.Get("offset").Get(k).GetNumberAsDouble();
          if (v.Has("scale") && v.Get("scale").ArrayLen() == 2)
            for (int k = 0; k < 2; ++k) sc[k] = v.Get("scale").Get(k).GetNumberAsDouble();
          if (v.Has("rotation")) rot = v.Get("rotation").GetNumberAsDouble();
          const double c = std::cos(rot), s = std::sin(rot);
          for (size_t k = 0; k + 1 < p.uvs.size(); k += 2) {
            const double u = static_cast<double>(p.uvs[k]) * sc[0], w = static_cast<double>(p.uvs[k + 1]) * sc[1];
            p.uvs[k] = static_cast<float>(c * u + s * w + off[0]);
            p.uvs[k + 1] = static_cast<float>(-s * u + c * w + off[1]);
          }
        }
      }
      mesh_primitives[mi].push_back(static_cast<int>(out.primitives.size()));
      out.primitives.push_back(std::move(p));
    }
  }

  // Nodes: every node of the default scene (or of every scene when none is named), composed in double.
  std::vector<int> roots;
  if (g.defaultScene >= 0 && g.defaultScene < static_cast<int>(g.scenes.size()))
    roots = g.scenes[g.defaultScene].nodes;
  else if (!g.scenes.empty())
    roots = g.scenes[0].nodes;
  else
    for (size_t i = 0; i < g.nodes.size(); ++i) roots.push_back(static_cast<int>(i));  // no scene: every node
  std::vector<std::pair<int, Mat4>> stack;
  for (auto it = roots.rbegin(); it != roots.rend(); ++it) stack.emplace_back(*it, kIdentity);
  size_t visited = 0;
  while (!stack.empty()) {
    auto [ni, parent] = stack.back();
    stack.pop_back();
    if (ni < 0 || ni >= static_cast<int>(g.nodes.size())) {
      out.skipped.push_back(name + ": node " + std::to_string(ni) + " does not exist");
      continue;
    }
    if (++visited > 64u * g.nodes.size() + 64) {
      return make_error(ErrorCode::kCorrupt,
                        name + ": the node hierarchy has a cycle (node " + std::to_string(ni) + ")");
    }
    const tinygltf::Node& n = g.nodes[ni];
    const Mat4 world = multiply(parent, node_local(n));
    if (n.mesh >= 0 && n.mesh < static_cast<int>(g.meshes.size())) {
      std::vector<Mat4> placements{world};
      // EXT_mesh_gpu_instancing: one placement per TRANSLATION/ROTATION/SCALE element, in the node's frame.
      if (auto e = n.extensions.find("EXT_mesh_gpu_instancing");
          e != n.extensions.end() && e->second.Has("attributes")) {
        const tinygltf::Value& attrs = e->second.Get("attributes");
        std::vector<float> t, r, s;
        const std::string what = name + ": node " + std::to_string(ni) + " EXT_mesh_gpu_instancing";
        Status st = ok_status();
        if (attrs.Has("TRANSLATION"))
          st = read_floats(g, attrs.Get("TRANSLATION").GetNumberAsInt(), 3, t, what + " TRANSLATION");
        if (st.ok() && attrs.Has("ROTATION"))
          st = read_floats(g, attrs.Get("ROTATION").GetNumberAsInt(), 4, r, what + " ROTATION");
        if (st.ok() && attrs.Has("SCALE"))
          st = read_floats(g, attrs.Get("SCALE").GetNumberAsInt(), 3, s, what + " SCALE");
        const size_t count = std::max({t.size() / 3, r.size() / 4, s.size() / 3});
        if (!st.ok()) {
          out.skipped.push_back(st.error().message);
        } else if (count > 0) {
          placements.clear();
          for (size_t k = 0; k < count; ++k) {
            double tt[3] = {0, 0, 0}, qq[4] = {0, 0, 0, 1}, ss[3] = {1, 1, 1};
            if (k * 3 + 2 < t.size())
              for (int c = 0; c < 3; ++c) tt[c] = t[k * 3 + c];
            if (k * 4 + 3 < r.size())
              for (int c = 0; c < 4; ++c) qq[c] = r[k * 4 + c];
            if (k * 3 + 2 < s.size())
              for (int c = 0; c < 3; ++c) ss[c] = s[k * 3 + c];
            placements.push_back(multiply(world, compose(tt, qq, ss)));
          }
        }
      }
      for (const Mat4& m : placements)
        for (int p : mesh_primitives[n.mesh])
          if (p >= 0) out.instances.push_back(Instance{static_cast<uint32_t>(p), m});
    } else if (n.mesh >= 0) {
      out.skipped.push_back(name + ": node " + std::to_string(ni) + " names mesh " + std::to_string(n.mesh) +
                            ", which does not exist");
    }
    if (n.skin >= 0)
      out.skipped.push_back(name + ": node " + std::to_string(ni) + " is skinned; drawn in its bind pose");
    for (auto it = n.children.rbegin(); it != n.children.rend(); ++it) stack.emplace_back(*it, world);
  }
  if (out.instances.empty() && !out.primitives.empty()) {
    // No node of the scene places a mesh (a file of meshes only, or a scene without nodes): each once, as is.
    out.skipped.push_back(name + ": no node of the scene places a mesh; each mesh is drawn once at the file's origin");
    for (uint32_t p = 0; p < out.primitives.size(); ++p) out.instances.push_back(Instance{p, kIdentity});
  }
  return out;
}

}  // namespace texstream::import
