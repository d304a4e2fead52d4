#pragma once
// The two front ends of texstream-import. glTF goes through tinygltf: it keeps node transforms, instancing
// (EXT_mesh_gpu_instancing) and georeferenced translations in double and exposes glTF's sampler and alpha modes
// exactly; Assimp (which stores transforms in float) reads everything else: OBJ+MTL, Collada, FBX, ...
// docs/design/import.md says why.
#include <filesystem>

#include "import_model.hpp"
#include "texstream/common/result.hpp"

namespace texstream::import {

Result<Model> read_gltf(const std::filesystem::path& file);
Result<Model> read_with_assimp(const std::filesystem::path& file);

// By extension: .gltf and .glb through tinygltf, anything else through Assimp.
Result<Model> read_model(const std::filesystem::path& file);

}  // namespace texstream::import
