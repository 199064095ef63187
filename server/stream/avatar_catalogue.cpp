#include "server/stream/avatar_catalogue.h"

#include "common/core/error.h"
#include "common/light/environment_light.h"
#include "common/scene/scene_loader.h"
#include "protocol/wire/messages.h"

namespace vistream {

AvatarCatalogue AvatarCatalogue::load(const std::vector<std::filesystem::path>& files,
                                      float heightM, const Scene& scene) {
  AvatarCatalogue c;
  c.light = AvatarLight::of(EnvironmentLight::of(scene.environment), scene.environment);
  if (files.size() > 1000) throwInputError("{} avatar models: at most 1000", files.size());
  SceneLimits limits;
  limits.maxFileBytes = kMaxAvatarModelBytes;
  for (const std::filesystem::path& file : files) {
    const std::string bytes = readSceneFile(file, limits);  // InputError naming the file
    // Checked as a client will read it: from memory, a glb, skinned.
    const AvatarModel model = AvatarModel::fromScene(
        loadGlbFromMemory(bytes, file.filename().string(), limits), file.string(), heightM);
    ServedAvatarModel m;
    m.name = file.filename().string();
    m.bytes = uint32_t(bytes.size());
    m.heightM = heightM;
    wire::AvatarModelDataT data;
    data.model = uint16_t(c.models.size());
    data.name = m.name;
    data.glb.assign(bytes.begin(), bytes.end());
    m.frame = std::make_shared<const std::vector<uint8_t>>(wire::encodeMessage(std::move(data)));
    c.models.push_back(std::move(m));
  }
  return c;
}

}  // namespace vistream
