#include "common/world/effects.h"

#include <fmt/format.h>

#include <cmath>

namespace vistream {
namespace {

// Below this share of free-space columns with a view of the sky, the sky is
// a few skylights at most and horizon tracing would cull nothing.
constexpr double kOpenSkyThreshold = 0.01;

}  // namespace

SceneEffects decideEffects(const Scene& scene, const RayQuery& rays, const FreeSpace& fs) {
  SceneEffects e;
  const Box3f b = scene.bounds();
  const float radius = scene.environment.nearFieldRadius;

  // Far field: needed unless every piece of geometry lies within d of every
  // point of the scene, which holds when the bounding box diagonal is at most d.
  const float diagonal = b.empty() ? 0.0f : glm::length(b.extent());
  e.farFieldRayCasting = diagonal > radius;
  e.decisions.push_back(
      {"far_field_ray_casting", e.farFieldRayCasting,
       e.farFieldRayCasting
           ? fmt::format("scene spans {:.0f} m, beyond the near-field radius d = {:.0f} m",
                         diagonal, radius)
           : fmt::format(
                 "all geometry lies within d = {:.0f} m of any viewpoint (scene diagonal {:.0f} m)",
                 radius, diagonal)});

  // Open sky: sample the free space and cast rays straight up.
  size_t escaped = 0, sampled = 0;
  const auto columns = fs.walkableColumns();
  const size_t stride = std::max<size_t>(1, columns.size() / 4096);
  for (size_t c = 0; c < columns.size(); c += stride) {
    const glm::vec2 xz = fs.columnCentre(columns[c].x, columns[c].y);
    const float y = fs.floorHeight(columns[c].x, columns[c].y) + 1.7f;
    ++sampled;
    if (!rays.occluded(Ray{{xz.x, y, xz.y}, {0.0f, 1.0f, 0.0f}, 0.0f, 1e30f})) ++escaped;
  }
  e.openSkyFraction = sampled ? double(escaped) / double(sampled) : 0.0;
  switch (scene.environment.sky) {
    case SkyMode::Open:
      e.horizonTracing = true;
      e.decisions.push_back({"horizon_tracing", true, "the manifest declares an open sky"});
      break;
    case SkyMode::None:
      e.horizonTracing = false;
      e.decisions.push_back({"horizon_tracing", false, "the manifest declares no sky"});
      break;
    case SkyMode::Auto:
      e.horizonTracing = e.openSkyFraction >= kOpenSkyThreshold;
      e.decisions.push_back(
          {"horizon_tracing", e.horizonTracing,
           sampled == 0 ? std::string("no free space to stand in, so no sky to see")
           : e.horizonTracing
               ? fmt::format("open sky above {:.0f}% of the free space", 100.0 * e.openSkyFraction)
               : fmt::format("no open sky: {:.1f}% of the free space sees the sky (enclosed scene)",
                             100.0 * e.openSkyFraction)});
      break;
  }

  e.impostors = e.farFieldRayCasting;
  e.decisions.push_back({"impostors", e.impostors,
                         e.impostors ? "distant geometry beyond d can be replaced by impostors"
                                     : "no geometry beyond d: nothing to replace"});

  const size_t dynamic = scene.dynamicObjectCount();
  e.selfShadowing = dynamic > 0;
  e.decisions.push_back({"self_shadowing", e.selfShadowing,
                         e.selfShadowing ? fmt::format("{} dynamic object(s) to shade", dynamic)
                                         : std::string("no dynamic objects")});

  e.environmentLight = !scene.environment.hdrImage.empty();
  e.decisions.push_back(
      {"environment_light", e.environmentLight,
       e.environmentLight
           ? fmt::format("HDR environment {}", scene.environment.hdrImage.filename().string())
           : std::string("no HDR environment given: constant sky colour")});
  return e;
}

}  // namespace vistream
