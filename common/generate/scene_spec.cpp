#include "common/generate/scene_spec.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <charconv>
#include <filesystem>

#include "common/core/error.h"
#include "common/generate/generate.h"
#include "common/scene/manifest.h"
#include "common/scene/scene_loader.h"

namespace vistream {

std::string sceneSpecHelp() {
  return fmt::format(
      "A SCENE is a file (.obj, .gltf, .glb, .json manifest) or a built-in name ({}; "
      "'city1@SEED' picks a seed; 'walker' is a skinned figure for avatars).",
      fmt::join(sceneTypes(), ", "));
}

Scene openScene(const std::string& spec, const SceneLimits& limits) {
  std::error_code ec;
  if (std::filesystem::exists(spec, ec)) {
    Scene scene = loadScene(spec, limits);
    // A manifest warns per entry, where the entry's "scale" is known.
    if (std::filesystem::path(spec).extension() != ".json")
      warnImplausiblyLargeDynamicObjects(scene, spec);
    return scene;
  }
  std::string type = spec;
  uint64_t seed = 1;
  if (const size_t at = spec.find('@'); at != std::string::npos) {
    type = spec.substr(0, at);
    const std::string s = spec.substr(at + 1);
    const auto [ptr, err] = std::from_chars(s.data(), s.data() + s.size(), seed);
    if (err != std::errc() || ptr != s.data() + s.size())
      throwInputError("scene '{}': seed '{}' is not a non-negative integer", spec, s);
  }
  if (spec == "walker") return generateWalker();
  const auto& types = sceneTypes();
  if (std::find(types.begin(), types.end(), type) == types.end())
    throwInputError("scene '{}': no such file, and not a built-in scene ({})", spec,
                    fmt::join(types, ", "));
  spdlog::info("generating built-in scene {} (seed {})", type, seed);
  Scene scene = toScene(generate(type, seed));
  scene.name = type;
  return scene;
}

}  // namespace vistream
