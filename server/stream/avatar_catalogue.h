// The avatar models a server offers its clients, and the light they are
// shaded with (protocol: Welcome.avatar_models, avatar_light; a client
// fetches a model's glb once with AvatarModelRequest).
//
// Each model is loaded and checked when the catalogue is built (a skinned
// glTF binary, at most kMaxAvatarModelBytes), so a bad file stops the
// server before it listens rather than failing in front of clients. The
// AvatarModelData frame of each model is encoded once and shared by every
// session that asks for it.
//
// Thread safety: immutable after construction.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "common/avatar/avatar_model.h"
#include "common/scene/scene.h"

namespace vistream {

inline constexpr uint64_t kMaxAvatarModelBytes = 8u << 20;

struct ServedAvatarModel {
  std::string name;  // the file's name
  uint32_t bytes = 0;
  float heightM = 1.2f;
  std::shared_ptr<const std::vector<uint8_t>> frame;  // the encoded AvatarModelData
};

struct AvatarCatalogue {
  std::vector<ServedAvatarModel> models;
  AvatarLight light;

  // Loads each .glb of `files` (InputError naming the file: missing, too
  // large, not a glb, no skin) for the scene's environment light.
  static AvatarCatalogue load(const std::vector<std::filesystem::path>& files, float heightM,
                              const Scene& scene);
  // The model a session is drawn as: sessions take the models in turn.
  uint16_t modelOf(uint32_t sessionId) const {
    return models.empty() ? 0 : uint16_t(sessionId % models.size());
  }
};

}  // namespace vistream
