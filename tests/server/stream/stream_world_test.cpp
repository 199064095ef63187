// StreamWorld's ground decision, which every client's Welcome carries.
#include "server/stream/stream_world.h"

#include <gtest/gtest.h>

#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

// A district of box buildings with bases at known heights and nothing
// between them, like a LoD2 city model.
Scene buildingsOnly(bool withGround) {
  Scene scene;
  scene.name = withGround ? "district with ground" : "district";
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      const float x = float(i) * 40.0f, z = float(k) * 40.0f;
      const float base = 2.0f - 0.75f * float(i + k);  // the lowest is -1 m (i = k = 2)
      testing::addBox(scene, "b", {x, base, z}, {x + 20.0f, 15.0f, z + 20.0f});
    }
  if (withGround) testing::addGround(scene, -10.0f, -10.0f, 110.0f, 110.0f, -1.0f);
  finalizeScene(scene);
  return scene;
}

TEST(StreamWorld, AssumesAGroundPlaneAtTheLowestBaseOfAModelWithoutOne) {
  StreamWorldOptions options;
  options.cellSize = 8.0f;
  const StreamWorld world(buildingsOnly(false), options);
  ASSERT_TRUE(world.ground().y.has_value()) << world.ground().why;
  EXPECT_FLOAT_EQ(float(world.scene().toFile(glm::vec3(0.0f, *world.ground().y, 0.0f)).y), -1.0f);
}

TEST(StreamWorld, KeepsTheScenesOwnGroundAndHonoursGroundNone) {
  StreamWorldOptions options;
  options.cellSize = 8.0f;
  EXPECT_FALSE(StreamWorld(buildingsOnly(true), options).ground().y.has_value());
  options.ground.mode = GroundMode::None;
  EXPECT_FALSE(StreamWorld(buildingsOnly(false), options).ground().y.has_value());
}

}  // namespace
}  // namespace vistream
