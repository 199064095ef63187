// Point-based impostors on the built-in bigcity (slow: generating the city
// and its occlusion horizons takes about 20 s): known cases found by
// bench_impostor_image's walks, checked pixel by pixel against the
// impostor's own faces ray cast from the same viewpoints.
#include <gtest/gtest.h>

#include <algorithm>
#include <glm/glm.hpp>

#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"
#include "server/impostor/impostor_bake.h"
#include "server/impostor/impostor_world.h"
#include "tests/server/impostor/face_coverage.h"

namespace vistream {
namespace {

// The bake's defaults at 640x480, with few Monte Carlo rays (the points'
// places do not depend on them).
ImpostorOptions options640x480() {
  ImpostorOptions o;
  o.screen.width = 640;
  o.screen.height = 480;
  o.minRays = 2;
  o.maxRays = 4;
  return o;
}

TEST(ImpostorBake, LeavesNoHoleOnBigcityWhereACameraRanOutOfLayers) {
  // A known case: from the street cell (0,1,0)-(4,3,4) of bigcity, a facade
  // about 280 m away (round (9.4, -16.4, -282.1) in the scene's local frame)
  // lies behind more than maxLayers surfaces along one LDI camera's rays,
  // though that camera samples it best. Its points from the other cameras
  // were dropped as "sampled better" by the camera that had no sample there,
  // and the street's viewer saw holes through the facade.
  const Scene scene = openScene("bigcity");
  ImpostorWorldOptions options;
  options.lighting.aoRays = 0;  // the points' places do not depend on their colours
  const ImpostorWorld world(scene, options);
  const Box3f cell(scene.toLocal(glm::dvec3(0.0, 1.0, 0.0)),
                   scene.toLocal(glm::dvec3(4.0, 3.0, 4.0)));
  const glm::vec3 facade(9.41f, -16.40f, -282.13f);
  const ImpostorPlacement placed =
      placeImpostors(cell, world.triangles(), world.pvsTriangles(cell), ImpostorPlacementOptions{});
  const auto site = std::find_if(placed.sites.begin(), placed.sites.end(),
                                 [&](const ImpostorSite& s) { return s.box.contains(facade); });
  ASSERT_NE(site, placed.sites.end()) << placed.why;
  ImpostorStats stats;
  const Impostor imp =
      bakeImpostor(world.view(), cell, site->box, site->triangles, options640x480(), &stats);
  EXPECT_GT(stats.keptUnsampled, 0u);  // the facade's, among others
  std::vector<bool> mine(world.triangles().size(), false);
  for (uint32_t t : site->triangles) mine[t] = true;
  const auto rays = makeEmbreeRayQuery(world.triangles());
  // The walk's frame that saw the holes (bench_impostor_image, frame 1 of
  // 12: the facade near the screen's right edge, where pixels are smallest),
  // its heading and pitch stepped by quarters of a pixel.
  const glm::vec3 eye =
      cell.lo + glm::vec3(0.1f + 0.8f / 11.0f, 0.5f, 0.1f + 0.8f / 11.0f) * cell.extent();
  std::vector<Camera> cameras;
  for (int k = 0; k < 16; ++k) {
    Camera c;
    c.width = 640;
    c.height = 480;
    c.eye = eye;
    const float pixelDeg = c.vfovDeg / float(c.height);
    c.yawDeg = 30.0f + pixelDeg * float(k % 4) / 4.0f;
    c.pitchDeg = 2.0f + pixelDeg * float(k / 4) / 4.0f;
    cameras.push_back(c);
  }
  const testing::FaceCoverage c = testing::faceCoverage(*rays, mine, imp, cameras);
  EXPECT_GT(c.seen, 20000u);
  EXPECT_EQ(c.uncovered, 0u) << "of " << c.seen << " pixels that see the impostor's faces";
}

}  // namespace
}  // namespace vistream
