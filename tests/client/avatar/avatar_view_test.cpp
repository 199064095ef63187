// Avatars in a client's frame: which are shaded and why, where they stand,
// how they are turned, and that both CPU renderers draw them behind what
// hides them. The simulated crowd walks where its contract says.
#include "client/avatar/avatar_view.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>

#include "client/app/walkthrough.h"
#include "client/avatar/crowd.h"
#include "client/farfield/pipeline.h"
#include "common/raycast/embree_ray_query.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/camera_at.h"

namespace vistream {
namespace {

std::shared_ptr<const AvatarModel> fox() {
  static const auto model = std::make_shared<const AvatarModel>(
      AvatarModel::load(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb", 1.0f));
  return model;
}

// Ground from y = -1 to 0 around the origin, and optionally a wall across
// the view at z = -3.
Scene yard(bool wall) {
  Scene s;
  s.name = "yard";
  testing::addBox(s, "ground", {-60, -1, -60}, {60, 0, 60});
  if (wall) testing::addBox(s, "wall", {-6, 0, -3.2f}, {6, 4, -3});
  finalizeScene(s);
  return s;
}

struct Yard {
  Scene scene;
  RenderGeometry geometry;
  FlatTriangles flat;
  std::unique_ptr<RayQuery> rays;
  explicit Yard(bool wall)
      : scene(yard(wall)),
        geometry(renderGeometryFromScene(scene)),
        flat(flattenScene(scene)),
        rays(makeEmbreeRayQuery(flat)) {}
  AvatarView view() const {
    return AvatarView(fox(),
                      AvatarLight::of(EnvironmentLight::of(scene.environment), scene.environment),
                      geometry.haze, rays.get());
  }
};

AvatarState standingAt(glm::vec3 eye, float yawDeg) {
  AvatarState a;
  a.id = 1;
  a.eye = eye;
  a.yawDeg = yawDeg;
  return a;
}

const Camera kCamera = testing::cameraAt({0.0f, 1.7f, 0.0f}, 0.0f, -10.0f, 320, 240);

TEST(AvatarView, SaysNoDynamicObjectsWithoutUsers) {
  const Yard y(false);
  AvatarView view = y.view();
  RenderGeometry out;
  const AvatarFrame f = view.build(kCamera, 50.0f, {}, out);
  EXPECT_EQ(f.why, "no dynamic objects");
  EXPECT_EQ(out.size(), 0u);
}

// One user in front, one behind the viewer, one beyond d: only the first
// is posed and shaded, and `why` counts each.
TEST(AvatarView, ShadesOnlyTheAvatarsInViewAndSaysWhereTheOthersAre) {
  const Yard y(false);
  AvatarView view = y.view();
  RenderGeometry out;
  const AvatarFrame f = view.build(
      kCamera, 50.0f,
      {standingAt({0, 1.7f, -6}, 180), standingAt({0, 1.7f, 8}, 0), standingAt({0, 1.7f, -90}, 0)},
      out);
  EXPECT_EQ(f.inView, 1u);
  EXPECT_EQ(f.outside, 1u);
  EXPECT_EQ(f.beyond, 1u);
  EXPECT_EQ(f.why, "1 avatar in view, 1 beyond d, 1 outside the view");
  EXPECT_EQ(f.posesShaded, 1u);
  EXPECT_EQ(out.size(), fox()->triangleCount());
  EXPECT_EQ(out.lighting.size(), out.size());
  for (uint32_t o : out.triangles.objectIds) ASSERT_EQ(o, 0u);  // the first state
}

// Feet on the floor a ray finds below the eye (here 2.5 m below it), not
// kEyeHeight below the eye.
TEST(AvatarView, StandsTheAvatarOnTheFloorBelowItsEye) {
  const Yard y(false);
  AvatarView view = y.view();
  RenderGeometry out;
  view.build(kCamera, 50.0f, {standingAt({0, 2.5f, -6}, 0)}, out);
  EXPECT_NEAR(out.bounds.lo.y, 0.0f, 0.06f);
  AvatarView floating(fox(), AvatarLight{}, Haze{}, nullptr);
  floating.build(kCamera, 50.0f, {standingAt({0, 2.5f, -6}, 0)}, out);
  EXPECT_NEAR(out.bounds.lo.y, 2.5f - kEyeHeight, 0.06f);
}

// Yaw 90 looks along -X: the model's front (+Z, its nose) must point there.
TEST(AppendAvatar, TurnsTheModelsFrontToTheUsersViewDirection) {
  AvatarShader shader(fox());
  ShadedAvatar shaded;
  shader.shade(Gait::Stand, 0.0f, AvatarLight{}, 1.0f, shaded);
  size_t nose = 0;
  for (size_t v = 0; v < shaded.positions.size(); ++v)
    if (shaded.positions[v].z > shaded.positions[nose].z) nose = v;
  RenderGeometry out;
  appendAvatar(*fox(), shaded, glm::vec3(10, 0, 0), 90.0f, 0, out);
  float minX = 1e9f;
  for (const glm::vec3& p : out.triangles.positions) minX = std::min(minX, p.x);
  const glm::vec3 noseWorld =
      glm::vec3(10, 0, 0) +
      glm::vec3(-shaded.positions[nose].z, shaded.positions[nose].y, shaded.positions[nose].x);
  EXPECT_NEAR(minX, noseWorld.x, 1e-4f);
}

// The avatar drawn over a headless frame: orange pixels where it stands in
// the open; none behind a wall; and the same pixels whether the frame's
// depth comes from the near field or from rays (raycast-all).
TEST(DrawDynamic, DrawsTheAvatarInFrontAndNotBehindAWall) {
  for (bool wall : {false, true}) {
    const Yard y(wall);
    AvatarView view = y.view();
    RenderGeometry avatars;
    view.build(kCamera, 50.0f, {standingAt({0, 1.7f, -6}, 90)}, avatars);  // side on
    PipelineOptions o;
    o.nearDistance = 50.0f;
    o.polygonBudget = 0;
    ImageRgb8 images[2];
    size_t drawn[2];
    int k = 0;
    for (RenderMode mode : {RenderMode::Pipeline, RenderMode::RaycastAll}) {
      o.mode = mode;
      FrameRenderer r(y.geometry, o);
      r.render(kCamera, images[k]);
      drawn[k] = r.drawDynamic(kCamera, avatars, images[k]);
      ++k;
    }
    if (wall) {
      EXPECT_EQ(drawn[0], 0u);
      EXPECT_EQ(drawn[1], 0u);
      continue;
    }
    EXPECT_GT(drawn[0], 500u);
    EXPECT_NEAR(double(drawn[1]), double(drawn[0]), 0.01 * double(drawn[0]));
    const ImageDifference d = compareImages(images[1], images[0], 1);
    EXPECT_LT(d.differingFraction, 0.005);
    // The Fox is orange: the image's reddest pixels are its.
    size_t orange = 0;
    for (int py = 0; py < images[0].height; ++py)
      for (int px = 0; px < images[0].width; ++px) {
        const glm::u8vec3 c = images[0].at(px, py);
        orange += c.r > c.b + 40;
      }
    EXPECT_GT(orange, drawn[0] / 2);
  }
}

// A straight path along -Z walked at 1.4 m/s: the crowd's roles as the
// contract lists them.
TEST(LocalCrowd, WalksAheadComesTowardsRunsAndStandsBesideThePath) {
  std::vector<PathSample> path;
  for (int i = 0; i <= 600; ++i) {  // 28 m
    PathSample s;
    s.t = i / 30.0;
    s.position = glm::dvec3(100.0, 1.7, -1.4 * s.t);
    path.push_back(s);
  }
  const LocalCrowd crowd(path, glm::dvec3(100.0, 0.0, 0.0), 4);
  const std::vector<AvatarState> at = crowd.at(2.0);  // the viewer at z = -2.8
  ASSERT_EQ(at.size(), 4u);
  EXPECT_NEAR(at[0].eye.z, -2.8f - 6.0f, 0.05f);  // ahead
  EXPECT_NEAR(at[0].speed, 1.4f, 0.05f);
  EXPECT_EQ(gaitForSpeed(at[0].speed), Gait::Walk);
  EXPECT_NEAR(at[0].yawDeg, 0.0f, 0.5f);
  EXPECT_NEAR(std::abs(at[0].eye.x), 0.7f, 1e-3f);   // beside the path
  EXPECT_NEAR(at[1].eye.z, -(20.0f - 2.8f), 0.05f);  // oncoming, facing the viewer
  EXPECT_NEAR(std::abs(at[1].yawDeg), 180.0f, 0.5f);
  EXPECT_EQ(gaitForSpeed(at[2].speed), Gait::Run);
  EXPECT_NEAR(at[2].eye.z, -(-3.0f + 3.6f * 2.0f), 0.05f);
  EXPECT_EQ(gaitForSpeed(at[3].speed), Gait::Stand);
  EXPECT_NEAR(at[3].eye.z, -10.0f, 0.05f);
  EXPECT_GT(at[0].eye.x * at[1].eye.x, -1.0f);  // left and right alternate
  EXPECT_LT(at[0].eye.x * at[1].eye.x, 0.0f);
}

// A wall 0.5 m beside the path keeps the sideways offset 0.3 m from it.
TEST(LocalCrowd, KeepsClearOfAWallBesideThePath) {
  Scene s;
  s.name = "corridor";
  testing::addBox(s, "left", {-3.0f, 0.0f, -40.0f}, {-0.5f, 3.0f, 10.0f});
  testing::addBox(s, "right", {0.5f, 0.0f, -40.0f}, {3.0f, 3.0f, 10.0f});
  finalizeScene(s);
  const FlatTriangles flat = flattenScene(s);
  const auto rays = makeEmbreeRayQuery(flat);
  std::vector<PathSample> path;
  for (int i = 0; i <= 60; ++i) {
    PathSample p;
    p.t = i / 30.0;
    p.position = s.origin + glm::dvec3(0.0, 1.7, -0.5 * i);
    path.push_back(p);
  }
  const LocalCrowd crowd(path, s.origin, 2, rays.get());
  for (const AvatarState& a : crowd.at(1.0)) EXPECT_NEAR(std::abs(a.eye.x), 0.2f, 1e-3f);
}

}  // namespace
}  // namespace vistream
