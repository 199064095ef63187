// The frame pipeline against its reference: every pixel ray cast
// (RaycastAll), on generated scenes and on the hard cases of the issue.
#include "client/farfield/pipeline.h"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <utility>

#include "client/app/walkthrough.h"
#include "common/generate/generate.h"
#include "common/generate/path.h"
#include "tests/common/support/camera_at.h"

namespace vistream {
namespace {

// Adds an axis-aligned box as 12 triangles.
void addBox(RenderGeometry& g, glm::vec3 lo, glm::vec3 hi) {
  const glm::vec3 c[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z},
                          {lo.x, hi.y, lo.z}, {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z},
                          {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
  const int q[6][4] = {{0, 1, 2, 3}, {5, 4, 7, 6}, {4, 0, 3, 7},
                       {1, 5, 6, 2}, {3, 2, 6, 7}, {4, 5, 1, 0}};
  for (const auto& f : q)
    for (const auto& t :
         {std::array<int, 3>{f[0], f[1], f[2]}, std::array<int, 3>{f[0], f[2], f[3]}}) {
      for (int k : t) g.triangles.positions.push_back(c[k]);
      g.triangles.faceIds.push_back(uint32_t(g.triangles.faceIds.size() / 2));
      g.triangles.objectIds.push_back(0);
      g.triangles.degenerate.push_back(0);
    }
}

void finish(RenderGeometry& g) {
  recolour(g, [&](size_t t) {
    // A distinct colour per box so a wrong triangle shows as a wrong pixel.
    const float h = float((t / 12) % 7) / 7.0f;
    return glm::vec3(0.3f + 0.6f * h, 0.8f - 0.5f * h, 0.5f);
  });
}

// A long street: ground, and buildings on both sides for `length` metres along -Z.
RenderGeometry streetScene(float length, glm::vec3 offset = glm::vec3(0.0f)) {
  RenderGeometry g;
  addBox(g, offset + glm::vec3(-200.0f, -1.0f, -length - 200.0f),
         offset + glm::vec3(200.0f, 0.0f, 200.0f));
  for (float z = 0.0f; z > -length; z -= 25.0f) {
    const float h = 10.0f + std::fmod(std::abs(z) * 0.37f, 30.0f);
    addBox(g, offset + glm::vec3(-30.0f, 0.0f, z - 20.0f), offset + glm::vec3(-8.0f, h, z));
    addBox(g, offset + glm::vec3(8.0f, 0.0f, z - 20.0f),
           offset + glm::vec3(30.0f, h * 0.8f + 5.0f, z));
  }
  finish(g);
  return g;
}

Camera cameraAt(glm::vec3 eye, float yaw, float pitch = 0.0f) {
  return testing::cameraAt(eye, yaw, pitch, 320, 240);
}

struct Check {
  FrameReport report;
  ImageDifference diff;
  size_t interior = 0;
};

struct Renderers {
  FrameRenderer pipeline, reference;
  Renderers(const RenderGeometry& g, PipelineOptions o)
      : pipeline(g, o), reference(g, [&] {
          o.mode = RenderMode::RaycastAll;
          return o;
        }()) {}
  // Renders both and compares.
  Check frame(const Camera& c) {
    ImageRgb8 a, b;
    Check k;
    k.report = pipeline.render(c, a);
    reference.render(c, b);
    k.diff = compareImages(a, b);
    k.interior = k.diff.interiorDiffering;
    return k;
  }
};

// The pipeline's image against the reference's: no pixel differs inside a
// uniform patch (a hole or a stale pixel), and at most 0.5% differ in all.
void expectMatchesReference(size_t interior, const ImageDifference& diff) {
  EXPECT_EQ(interior, 0u) << "holes or stale pixels";
  EXPECT_LT(diff.differingFraction, 0.005);
}

// The thesis's split at d, whatever the scene's size (these scenes are small
// enough for the polygon budget, which would draw them whole).
PipelineOptions optionsWithD(float d) {
  PipelineOptions o;
  o.polygonBudget = 0;
  o.nearDistance = d;
  o.horizonCellSize = 4.0f;
  return o;
}

// optionsWithD(60) with no pixel budget: only pixels the image cache must
// refresh are traced.
PipelineOptions cacheRefreshOnly() {
  PipelineOptions o = optionsWithD(60.0f);
  o.pixelBudget = 0;
  return o;
}

// On the 1500 m street with cacheRefreshOnly(): five frames at eye height
// creeping 5 cm at a time along -Z from z, looking along -Z (so the image
// cache holds that view), then the frame of `next`.
Check frameAfterLookingDownTheStreetFrom(float z, const Camera& next) {
  const RenderGeometry g = streetScene(1500.0f);
  Renderers r(g, cacheRefreshOnly());
  for (int i = 0; i < 5; ++i) (void)r.frame(cameraAt({0.0f, 1.7f, z - 0.05f * float(i)}, 0.0f));
  return r.frame(next);
}

TEST(Pipeline, LookingAlongAStreetToTheHorizonMatchesTheReference) {
  const RenderGeometry g = streetScene(1500.0f);
  Renderers r(g, optionsWithD(60.0f));
  const auto [report, diff, interior] = r.frame(cameraAt({0.0f, 1.7f, -5.0f}, 0.0f));
  EXPECT_TRUE(report.farFieldRan) << report.farFieldWhy;
  EXPECT_TRUE(report.horizonRan) << report.horizonWhy;
  EXPECT_GT(report.pixels.rayHit, 0u) << "the far end of the street is ray cast";
  EXPECT_GT(report.pixels.horizon, 0u) << "the sky above the street is culled";
  expectMatchesReference(interior, diff);
}

TEST(Pipeline, StandingAtTheNearFieldBorderLeavesNoHole) {
  const RenderGeometry g = streetScene(1500.0f);
  // A wall whose cells straddle the near-field distance in front of the viewer.
  for (float d : {40.0f, 45.0f, 47.5f, 50.0f})
    for (float z : {-20.0f, -27.5f, -30.0f})
      for (float yaw : {0.0f, 30.0f, 90.0f}) {
        // A fresh renderer each time: the image cache plays no part here.
        Renderers r(g, optionsWithD(d));
        const auto [report, diff, interior] = r.frame(cameraAt({0.0f, 1.7f, z}, yaw));
        EXPECT_EQ(interior, 0u) << "d " << d << " z " << z << " yaw " << yaw;
        EXPECT_LT(diff.differingFraction, 0.005) << "d " << d << " z " << z << " yaw " << yaw;
      }
}

TEST(Pipeline, TurningHalfwayRoundInOneFrameShowsNoStalePixels) {
  const auto [report, diff, interior] =
      frameAfterLookingDownTheStreetFrom(-100.0f, cameraAt({0.0f, 1.7f, -100.3f}, 180.0f));
  EXPECT_GT(report.cachePlan.mustTrace, 0u) << "directions never seen are traced";
  expectMatchesReference(interior, diff);
}

TEST(Pipeline, TeleportingNeverShowsTheOldView) {
  const auto [report, diff, interior] =
      frameAfterLookingDownTheStreetFrom(-50.0f, cameraAt({0.0f, 1.7f, -700.0f}, 0.0f));
  EXPECT_EQ(report.cachePlan.reused, 0u) << "nothing cached 650 m away is valid here";
  expectMatchesReference(interior, diff);
}

TEST(Pipeline, ReusesCachedPixelsWhenStandingStillAndStaysExact) {
  const RenderGeometry g = streetScene(1500.0f);
  Renderers r(g, cacheRefreshOnly());
  (void)r.frame(cameraAt({0.0f, 1.7f, -5.0f}, 0.0f));
  const auto [report, diff, interior] = r.frame(cameraAt({0.0f, 1.7f, -5.0f}, 0.0f));
  EXPECT_GT(report.pixels.cache, 0u);
  EXPECT_EQ(report.pixels.rayHit + report.pixels.rayMiss, 0u)
      << "nothing moved, nothing to retrace";
  expectMatchesReference(interior, diff);
}

TEST(Pipeline, ASceneWithNoSkySkipsHorizonTracingAndStillMatches) {
  // A closed hall 300 m long: walls, floor and ceiling.
  RenderGeometry g;
  addBox(g, {-10.0f, -1.0f, -300.0f}, {10.0f, 0.0f, 10.0f});
  addBox(g, {-10.0f, 6.0f, -300.0f}, {10.0f, 7.0f, 10.0f});
  addBox(g, {-11.0f, 0.0f, -300.0f}, {-10.0f, 6.0f, 10.0f});
  addBox(g, {10.0f, 0.0f, -300.0f}, {11.0f, 6.0f, 10.0f});
  for (float z = -20.0f; z > -290.0f; z -= 30.0f)
    addBox(g, {-3.0f, 0.0f, z - 1.0f}, {3.0f, 3.0f, z});
  finish(g);
  Renderers r(g, optionsWithD(40.0f));
  const auto [report, diff, interior] = r.frame(cameraAt({0.0f, 1.7f, 0.0f}, 0.0f, 10.0f));
  EXPECT_FALSE(report.horizonRan);
  EXPECT_NE(report.horizonWhy.find("ceiling"), std::string::npos) << report.horizonWhy;
  EXPECT_TRUE(report.farFieldRan);
  expectMatchesReference(interior, diff);
}

TEST(Pipeline, ASceneEntirelyWithinDSwitchesTheFarFieldOff) {
  RenderGeometry g;
  addBox(g, {-20.0f, -1.0f, -20.0f}, {20.0f, 0.0f, 20.0f});
  addBox(g, {-5.0f, 0.0f, -15.0f}, {5.0f, 8.0f, -10.0f});
  finish(g);
  Renderers r(g, optionsWithD(100.0f));
  const auto [report, diff, interior] = r.frame(cameraAt({0.0f, 1.7f, 0.0f}, 0.0f, 5.0f));
  EXPECT_FALSE(report.farFieldRan);
  EXPECT_FALSE(report.horizonRan);
  EXPECT_FALSE(report.cacheRan);
  EXPECT_NE(report.farFieldWhy.find("within d"), std::string::npos) << report.farFieldWhy;
  EXPECT_EQ(report.pixels.rayHit + report.pixels.rayMiss, 0u);
  EXPECT_GT(report.pixels.background, 0u) << "the sky is background colour";
  expectMatchesReference(interior, diff);
}

TEST(Pipeline, ASceneWithinThePolygonBudgetIsDrawnWholeWithoutAFarField) {
  const RenderGeometry g = streetScene(1500.0f);
  PipelineOptions o = optionsWithD(60.0f);
  o.polygonBudget = g.size();
  Renderers r(g, o);
  const auto [report, diff, interior] = r.frame(cameraAt({0.0f, 1.7f, -5.0f}, 0.0f));
  EXPECT_FALSE(report.farFieldRan);
  EXPECT_NE(report.farFieldWhy.find("polygon budget"), std::string::npos) << report.farFieldWhy;
  EXPECT_EQ(report.pixels.rayHit + report.pixels.rayMiss, 0u);
  expectMatchesReference(interior, diff);
  // One triangle more than the budget allows, and the far field is back.
  o.polygonBudget = g.size() - 1;
  Renderers split(g, o);
  EXPECT_TRUE(split.frame(cameraAt({0.0f, 1.7f, -5.0f}, 0.0f)).report.farFieldRan);
}

TEST(Pipeline, FarFromTheOriginTheImageStillMatches) {
  const glm::vec3 offset(50'000.0f, 0.0f, -30'000.0f);
  const RenderGeometry g = streetScene(1500.0f, offset);
  Renderers r(g, optionsWithD(60.0f));
  const auto [report, diff, interior] =
      r.frame(cameraAt(offset + glm::vec3(0.0f, 1.7f, -5.0f), 0.0f));
  EXPECT_TRUE(report.farFieldRan);
  expectMatchesReference(interior, diff);
}

TEST(Pipeline, GeometryAllDrawsEveryVisibleTriangleAsPolygons) {
  const RenderGeometry g = streetScene(800.0f);
  PipelineOptions o = optionsWithD(60.0f);
  o.mode = RenderMode::GeometryAll;
  Renderers r(g, o);
  const auto [report, diff, interior] = r.frame(cameraAt({0.0f, 1.7f, -5.0f}, 10.0f));
  EXPECT_FALSE(report.farFieldRan);
  EXPECT_EQ(report.pixels.rayHit + report.pixels.rayMiss, 0u);
  expectMatchesReference(interior, diff);
}

// A walk through a generated city: with the cache and a budget the image
// stays within 1% of the reference on every frame.
// A city model without a surface of its own (static_world.h assumes a ground
// plane): pixels that see nothing below the horizon show the ground colour,
// above it the sky, in every mode and with the far field on or off. The
// oracle is the sign of each pixel ray's Y, from the camera alone.
TEST(Pipeline, AnAssumedGroundPlaneFillsEmptyPixelsBelowTheHorizon) {
  RenderGeometry g;
  addBox(g, {-10.0f, 0.0f, -300.0f}, {10.0f, 20.0f, -280.0f});  // one distant building
  finish(g);
  g.groundY = 0.0f;
  const Camera c = cameraAt({0.0f, 1.7f, 0.0f}, 0.0f);
  const Camera::PixelRays rays = c.pixelRays();
  struct Case {
    const char* name;
    RenderMode mode;
    float nearDistance;
  };
  for (const Case& k : {Case{"pipeline, far field", RenderMode::Pipeline, 50.0f},
                        Case{"pipeline, all near", RenderMode::Pipeline, 1000.0f},
                        Case{"raycast-all", RenderMode::RaycastAll, 50.0f},
                        Case{"geometry-all", RenderMode::GeometryAll, 50.0f}}) {
    SCOPED_TRACE(k.name);
    PipelineOptions o;
    o.mode = k.mode;
    o.nearDistance = k.nearDistance;
    o.polygonBudget = 0;  // never "the whole scene fits": the far field decides
    FrameRenderer renderer(g, o);
    ImageRgb8 image;
    renderer.render(c, image);
    size_t ground = 0, sky = 0;
    for (int y : {0, 1, 2, c.height - 3, c.height - 2, c.height - 1})
      for (int x = 0; x < c.width; ++x) {
        const glm::vec3 dir = rays.at(float(x) + 0.5f, float(y) + 0.5f);
        const glm::u8vec3 want = dir.y < 0.0f ? g.ground : g.sky;
        ASSERT_EQ(image.at(x, y), want) << "pixel " << x << "," << y;
        (dir.y < 0.0f ? ground : sky) += 1;
      }
    EXPECT_EQ(ground, 3u * size_t(c.width));
    EXPECT_EQ(sky, 3u * size_t(c.width));
  }
  // Without a plane, or from below it, nothing is ground.
  for (const auto& [groundY, eyeY] :
       {std::pair{std::optional<float>{}, 1.7f}, std::pair{std::optional<float>{5.0f}, 1.7f}}) {
    g.groundY = groundY;
    FrameRenderer renderer(g, PipelineOptions{});
    ImageRgb8 image;
    renderer.render(cameraAt({0.0f, eyeY, 0.0f}, 0.0f), image);
    for (int x = 0; x < c.width; ++x) EXPECT_EQ(image.at(x, c.height - 1), g.sky);
  }
}

TEST(Pipeline, AWalkThroughCity1StaysWithinOnePercentOfTheReference) {
  const Scene scene = toScene(generate("city1"));
  const RenderGeometry g = renderGeometryFromScene(scene);
  PathOptions po;
  po.frames = 40;
  po.speed = 2.0;
  const auto cams = camerasFromPath(generatePath(scene, po), scene.origin, 320, 240, 60.0f);
  PipelineOptions o = optionsWithD(60.0f);
  o.pixelBudget = 500;
  Renderers r(g, o);
  size_t cached = 0;
  for (const Camera& c : cams) {
    const auto [report, diff, interior] = r.frame(c);
    cached += report.pixels.cache;
    EXPECT_LT(diff.differingFraction, 0.01);
  }
  EXPECT_GT(cached, 0u) << "the cache served pixels on the walk";
}

}  // namespace
}  // namespace vistream
