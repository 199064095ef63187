#include "common/world/static_world.h"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <charconv>
#include <cmath>

namespace vistream {

std::optional<GroundChoice> parseGroundChoice(const std::string& text) {
  if (text == "auto") return GroundChoice{GroundMode::Auto, 0.0};
  if (text == "none") return GroundChoice{GroundMode::None, 0.0};
  double y = 0.0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), y);
  if (text.empty() || ec != std::errc() || ptr != text.data() + text.size() || !std::isfinite(y))
    return std::nullopt;
  return GroundChoice{GroundMode::Fixed, y};
}

GroundPlane decideGround(const Scene& scene, const RayQuery& rays, const GroundChoice& choice) {
  GroundPlane g;
  if (choice.mode == GroundMode::None) {
    g.why = "none assumed (--ground none)";
    return g;
  }
  if (choice.mode == GroundMode::Fixed) {
    g.y = float(choice.fileY - scene.origin.y);
    g.why = fmt::format("plane at y = {:.2f} m (--ground {:g})", choice.fileY, choice.fileY);
    return g;
  }
  Box3f statics;
  for (const Object& o : scene.objects)
    if (!o.dynamic && o.mesh.triangleCount() > 0) statics.extend(o.bounds);
  if (statics.empty()) {
    g.why = "the scene has no static geometry";
    return g;
  }
  // Vertical rays over a 64 x 64 grid of the static footprint: a column that
  // hits nothing has no ground under it.
  constexpr int kSamples = 64;
  const float top = statics.hi.y + 1.0f, depth = statics.hi.y - statics.lo.y + 2.0f;
  size_t bare = 0;
  for (int k = 0; k < kSamples; ++k)
    for (int i = 0; i < kSamples; ++i) {
      const float x = statics.lo.x + (float(i) + 0.5f) / kSamples * (statics.hi.x - statics.lo.x);
      const float z = statics.lo.z + (float(k) + 0.5f) / kSamples * (statics.hi.z - statics.lo.z);
      bare += !rays.occluded(Ray{{x, top, z}, {0.0f, -1.0f, 0.0f}, 0.0f, depth});
    }
  g.bareFootprint = double(bare) / double(kSamples * kSamples);
  if (g.bareFootprint < kBareFootprintForGround) {
    g.why = fmt::format("the scene's own (surfaces under {:.0f}% of its footprint)",
                        100.0 * (1.0 - g.bareFootprint));
    return g;
  }
  g.y = statics.lo.y;
  g.why = fmt::format(
      "assumed: a plane at the lowest base of its objects, y = {:.2f} m, because {:.0f}% of its "
      "footprint has no surface under it (--ground none to turn off)",
      scene.origin.y + double(statics.lo.y), 100.0 * g.bareFootprint);
  return g;
}

StaticWorld buildStaticWorld(const Scene& scene, const StaticWorldOptions& options) {
  StaticWorld w;
  w.triangles = std::make_unique<const FlatTriangles>(flattenScene(scene, /*staticOnly=*/true));
  w.rays = makeEmbreeRayQuery(*w.triangles);
  if (options.parts == StaticWorldParts::Rays) return w;
  w.ground = decideGround(scene, *w.rays, options.ground);
  if (w.ground.y) spdlog::info("scene '{}': ground {}", scene.name, w.ground.why);
  if (options.parts == StaticWorldParts::Ground) return w;
  w.solids = Solids::build(*w.triangles);
  if (options.parts == StaticWorldParts::Solids) return w;
  FreeSpaceOptions fo = options.freeSpace;
  fo.groundY = w.ground.y;
  w.freeSpace = FreeSpace::build(*w.rays, w.solids, scene.bounds(), fo);
  return w;
}

}  // namespace vistream
