#include "common/scene/scene_loader.h"

#include "common/core/error.h"
#include "common/scene/manifest.h"

namespace vistream {

Scene loadScene(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".obj") return loadObj(path);
  if (ext == ".gltf" || ext == ".glb") return loadGltf(path);
  if (ext == ".json") return loadManifest(path);
  throwInputError("{}: unknown scene format '{}' (expected .obj, .gltf, .glb or a .json manifest)",
                  path.string(), ext);
}

}  // namespace vistream
