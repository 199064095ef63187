// Which effects a scene calls for, and why.
//
// vistream simulates only what a scene needs: far-field ray casting,
// horizon tracing, impostors and self-shadowing each run only where the
// scene calls for them. decideEffects() derives the decision from the
// geometry and the manifest, and every decision carries a one-line reason
// that `vistream-scene info` prints.
#pragma once

#include <string>
#include <vector>

#include "common/scene/scene.h"
#include "common/world/free_space.h"

namespace vistream {

struct EffectDecision {
  std::string effect;  // "far_field_ray_casting", "horizon_tracing", "impostors", "self_shadowing",
                       // "environment_light"
  bool enabled = false;
  std::string reason;
};

struct SceneEffects {
  bool farFieldRayCasting = false;
  bool horizonTracing = false;
  bool impostors = false;
  bool selfShadowing = false;
  bool environmentLight = false;
  double openSkyFraction = 0.0;  // share of free-space columns whose upward ray escapes
  std::vector<EffectDecision> decisions;
};

// `freeSpace` is the scene's free space (built over the static geometry);
// `rays` answers queries over the same static geometry.
SceneEffects decideEffects(const Scene& scene, const RayQuery& rays, const FreeSpace& freeSpace);

}  // namespace vistream
