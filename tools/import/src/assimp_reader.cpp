// OBJ+MTL, Collada, FBX and every other format Assimp 5.2 reads. Assimp triangulates, generates missing normals
// and flips UVs to the top-left origin the scene format uses; its node transforms are float (ai_real), widened to
// double here (a file that places its city at map coordinates should come as glTF or take --origin).
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <assimp/Importer.hpp>
#include <cstring>

#include "model_readers.hpp"

namespace texstream::import {
namespace {

Wrap wrap_of(int mode) {
  if (mode == aiTextureMapMode_Clamp || mode == aiTextureMapMode_Decal) return Wrap::kClamp;
  if (mode == aiTextureMapMode_Mirror) return Wrap::kMirror;
  return Wrap::kRepeat;
}

std::array<double, 16> to_column_major(const aiMatrix4x4& m) {
  // aiMatrix4x4 is row-major: a1..a4 is the first row.
  return {m.a1, m.b1, m.c1, m.d1, m.a2, m.b2, m.c2, m.d2, m.a3, m.b3, m.c3, m.d3, m.a4, m.b4, m.c4, m.d4};
}

}  // namespace

Result<Model> read_with_assimp(const std::filesystem::path& file) {
  const std::string name = file.string();
  if (!std::filesystem::exists(file)) return make_error(ErrorCode::kNotFound, name + ": no such file");
  Assimp::Importer importer;
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_POINT | aiPrimitiveType_LINE);
  const aiScene* s =
      importer.ReadFile(name, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices | aiProcess_GenSmoothNormals |
                                  aiProcess_FlipUVs | aiProcess_SortByPType | aiProcess_ValidateDataStructure);
  if (s == nullptr || (s->mFlags & AI_SCENE_FLAGS_INCOMPLETE) || s->mRootNode == nullptr) {
    const std::string why = importer.GetErrorString();
    if (why.empty() && s != nullptr && s->mNumMeshes == 0)  // cameras or lights only: Assimp marks it incomplete
      return make_error(ErrorCode::kInvalidArgument, name + ": holds no mesh (" + std::to_string(s->mNumCameras) +
                                                         " cameras, " + std::to_string(s->mNumLights) + " lights)");
    return make_error(ErrorCode::kCorrupt,
                      name + ": Assimp cannot read it: " +
                          (why.empty() ? "nothing it imports (no meshes: cameras or lights only?)" : why));
  }

  Model out;
  out.source = name;
  out.y_up = true;
  const std::filesystem::path base = file.parent_path();

  // Images: one per distinct diffuse texture path (an embedded one, "*N", keeps its bytes).
  std::vector<std::string> image_keys;
  auto image_index = [&](const std::string& path) -> int {
    for (size_t i = 0; i < image_keys.size(); ++i)
      if (image_keys[i] == path) return static_cast<int>(i);
    SourceImage im;
    if (const aiTexture* t = s->GetEmbeddedTexture(path.c_str())) {
      if (t->mHeight != 0) {
        out.skipped.push_back(name + ": embedded texture " + path + " is raw texels; not supported");
        return -1;
      }
      const auto* b = reinterpret_cast<const uint8_t*>(t->pcData);
      im.bytes.assign(b, b + t->mWidth);
      im.extension = std::string(".") + (t->achFormatHint[0] ? t->achFormatHint : "png");
      im.name = name + " embedded " + path;
    } else {
      std::string p = path;
      for (char& c : p)
        if (c == '\\') c = '/';  // Windows exporters
      im.file = std::filesystem::path(p).is_absolute() ? std::filesystem::path(p) : base / p;
      im.name = im.file.string();
    }
    image_keys.push_back(path);
    out.images.push_back(std::move(im));
    return static_cast<int>(out.images.size() - 1);
  };

  for (unsigned i = 0; i < s->mNumMaterials; ++i) {
    const aiMaterial* am = s->mMaterials[i];
    Material m;
    aiString mname;
    m.name =
        am->Get(AI_MATKEY_NAME, mname) == AI_SUCCESS && mname.length ? mname.C_Str() : "material " + std::to_string(i);
    aiColor4D colour(1, 1, 1, 1);
    if (am->Get(AI_MATKEY_BASE_COLOR, colour) != AI_SUCCESS) am->Get(AI_MATKEY_COLOR_DIFFUSE, colour);
    float opacity = 1.0f;
    if (am->Get(AI_MATKEY_OPACITY, opacity) == AI_SUCCESS) colour.a *= opacity;
    // sRGB-authored diffuse colours in OBJ/MTL are linear factors for Assimp, as glTF's are.
    m.base_colour = {colour.r, colour.g, colour.b, colour.a};
    aiString tex;
    aiTextureType type = aiTextureType_DIFFUSE;
    if (am->GetTextureCount(aiTextureType_BASE_COLOR) > 0) type = aiTextureType_BASE_COLOR;
    if (am->GetTexture(type, 0, &tex) == AI_SUCCESS && tex.length > 0) {
      m.image = image_index(tex.C_Str());
      // A texture multiplies the diffuse colour in glTF; OBJ exporters write Kd 1 1 1 or the average colour with
      // map_Kd, which most viewers ignore: the texture alone.
      m.base_colour = {1, 1, 1, m.base_colour[3]};
      int mode = aiTextureMapMode_Wrap;
      if (am->Get(AI_MATKEY_MAPPINGMODE_U(type, 0), mode) == AI_SUCCESS) m.wrap_u = wrap_of(mode);
      if (am->Get(AI_MATKEY_MAPPINGMODE_V(type, 0), mode) == AI_SUCCESS) m.wrap_v = wrap_of(mode);
    }
    aiString alpha_mode;
    if (am->Get("$mat.gltf.alphaMode", 0, 0, alpha_mode) == AI_SUCCESS) {
      if (std::strcmp(alpha_mode.C_Str(), "MASK") == 0) m.alpha = AlphaMode::kMask;
      if (std::strcmp(alpha_mode.C_Str(), "BLEND") == 0) m.alpha = AlphaMode::kBlend;
      am->Get("$mat.gltf.alphaCutoff", 0, 0, m.alpha_cutoff);
    } else if (am->GetTextureCount(aiTextureType_OPACITY) > 0 || m.base_colour[3] < 1.0f) {
      m.alpha = AlphaMode::kMask;  // OBJ map_d / d < 1: cut-outs are what city models use them for
    }
    out.materials.push_back(std::move(m));
  }

  for (unsigned i = 0; i < s->mNumMeshes; ++i) {
    const aiMesh* am = s->mMeshes[i];
    Primitive p;
    p.name =
        name + ": mesh " + std::to_string(i) + (am->mName.length ? " (" + std::string(am->mName.C_Str()) + ")" : "");
    p.material = static_cast<int>(am->mMaterialIndex);
    if (!(am->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) || am->mNumVertices == 0) {
      out.skipped.push_back(p.name + ": no triangles");
      out.primitives.push_back(Primitive{});
      continue;
    }
    p.positions.resize(size_t{am->mNumVertices} * 3);
    for (unsigned v = 0; v < am->mNumVertices; ++v) std::memcpy(&p.positions[v * 3], &am->mVertices[v], 12);
    if (am->mNormals) {
      p.normals.resize(size_t{am->mNumVertices} * 3);
      for (unsigned v = 0; v < am->mNumVertices; ++v) std::memcpy(&p.normals[v * 3], &am->mNormals[v], 12);
    }
    if (am->mTextureCoords[0]) {
      p.uvs.resize(size_t{am->mNumVertices} * 2);
      for (unsigned v = 0; v < am->mNumVertices; ++v) {
        p.uvs[v * 2] = am->mTextureCoords[0][v].x;
        p.uvs[v * 2 + 1] = am->mTextureCoords[0][v].y;
      }
    }
    for (unsigned f = 0; f < am->mNumFaces; ++f)
      if (am->mFaces[f].mNumIndices == 3)
        p.indices.insert(p.indices.end(), am->mFaces[f].mIndices, am->mFaces[f].mIndices + 3);
    out.primitives.push_back(std::move(p));
  }

  std::vector<std::pair<const aiNode*, aiMatrix4x4>> stack{{s->mRootNode, aiMatrix4x4()}};
  while (!stack.empty()) {
    auto [n, parent] = stack.back();
    stack.pop_back();
    const aiMatrix4x4 world = parent * n->mTransformation;
    for (unsigned k = 0; k < n->mNumMeshes; ++k) {
      const unsigned mi = n->mMeshes[k];
      if (mi < out.primitives.size() && !out.primitives[mi].indices.empty())
        out.instances.push_back(Instance{mi, to_column_major(world)});
    }
    for (unsigned c = n->mNumChildren; c-- > 0;) stack.emplace_back(n->mChildren[c], world);
  }
  return out;
}

Result<Model> read_model(const std::filesystem::path& file) {
  std::string ext = file.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".gltf" || ext == ".glb") return read_gltf(file);
  return read_with_assimp(file);
}

}  // namespace texstream::import
