#include "common/world/effects.h"

#include <gtest/gtest.h>

#include "common/generate/generate.h"
#include "common/world/static_world.h"
#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

using testing::addBox;
using testing::addGround;

SceneEffects effectsOf(const Scene& scene) {
  const StaticWorld world = buildStaticWorld(scene);
  return decideEffects(scene, *world.rays, world.freeSpace);
}

const EffectDecision& decision(const SceneEffects& e, const std::string& name) {
  for (const auto& d : e.decisions)
    if (d.effect == name) return d;
  throw std::runtime_error("no decision for " + name);
}

TEST(SceneEffects, ASmallOpenCourtyardNeedsHorizonTracingButNoFarField) {
  Scene s;
  addGround(s, -20, -20, 20, 20);
  addBox(s, "shed", {-3, 0, -3}, {3, 3, 3});
  finalizeScene(s);
  const SceneEffects e = effectsOf(s);
  EXPECT_FALSE(e.farFieldRayCasting);
  EXPECT_FALSE(e.impostors);
  EXPECT_TRUE(e.horizonTracing);
  EXPECT_FALSE(e.selfShadowing);
  EXPECT_NE(decision(e, "far_field_ray_casting").reason.find("within d"), std::string::npos);
}

TEST(SceneEffects, AClosedRoomHasNoSkyAndADynamicObjectNeedsSelfShadowing) {
  Scene s;
  addGround(s, 0, 0, 10, 10);
  addBox(s, "ceiling", {0, 3, 0}, {10, 3.2f, 10});
  addBox(s, "w1", {-0.2f, 0, -0.2f}, {10.2f, 3.2f, 0});
  addBox(s, "w2", {-0.2f, 0, 10}, {10.2f, 3.2f, 10.2f});
  addBox(s, "w3", {-0.2f, 0, 0}, {0, 3.2f, 10});
  addBox(s, "w4", {10, 0, 0}, {10.2f, 3.2f, 10});
  addBox(s, "avatar", {4, 0, 4}, {4.5f, 1.8f, 4.5f}, /*dynamic=*/true);
  finalizeScene(s);
  const SceneEffects e = effectsOf(s);
  EXPECT_FALSE(e.horizonTracing);
  EXPECT_EQ(e.openSkyFraction, 0.0);
  EXPECT_TRUE(e.selfShadowing);
  EXPECT_NE(decision(e, "self_shadowing").reason.find("1 dynamic"), std::string::npos);
}

TEST(SceneEffects, TheManifestCanOverrideTheSky) {
  Scene s;
  addGround(s, -20, -20, 20, 20);
  finalizeScene(s);
  s.environment.sky = SkyMode::None;
  EXPECT_FALSE(effectsOf(s).horizonTracing);
  s.environment.sky = SkyMode::Open;
  EXPECT_TRUE(effectsOf(s).horizonTracing);
}

TEST(SceneEffects, GeneratedScenesCallForWhatTheirKindNeeds) {
  const SceneEffects terrain = effectsOf(toScene(generate("terrain", 1)));
  EXPECT_TRUE(terrain.horizonTracing);
  EXPECT_TRUE(terrain.farFieldRayCasting);
  const SceneEffects interior = effectsOf(toScene(generate("interior", 1)));
  EXPECT_FALSE(interior.horizonTracing);
  const SceneEffects city = effectsOf(toScene(generate("city1", 1)));
  EXPECT_TRUE(city.horizonTracing);
  EXPECT_TRUE(city.farFieldRayCasting);
  EXPECT_FALSE(city.selfShadowing);
}

}  // namespace
}  // namespace vistream
