#include "common/avatar/avatar_model.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <glm/gtc/matrix_transform.hpp>

#include "common/core/error.h"
#include "common/generate/generate.h"
#include "common/light/spherical_harmonics.h"

namespace vistream {
namespace {

std::filesystem::path foxFile() {
  return std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb";
}

Box3f boundsOf(const std::vector<glm::vec3>& points) {
  Box3f b;
  for (const glm::vec3& p : points) b.extend(p);
  return b;
}

TEST(Gait, FollowsSpeed) {
  EXPECT_EQ(gaitForSpeed(0.0f), Gait::Stand);
  EXPECT_EQ(gaitForSpeed(NAN), Gait::Stand);
  EXPECT_EQ(gaitForSpeed(1.4f), Gait::Walk);
  EXPECT_EQ(gaitForSpeed(3.6f), Gait::Run);
}

// The Fox in metres: its rest pose is as tall as asked, stands on y = 0 and
// is centred over the origin; every clip's poses stay inside the bounding
// sphere; the gaits play the Fox's own clips.
TEST(AvatarModel, TheFoxStandsOnTheOriginAsTallAsAsked) {
  const AvatarModel fox = AvatarModel::load(foxFile(), 1.2f);
  EXPECT_EQ(fox.triangleCount(), 576u);
  ASSERT_NE(fox.clip(Gait::Walk), nullptr);
  EXPECT_EQ(fox.clip(Gait::Walk)->name, "Walk");
  EXPECT_EQ(fox.clip(Gait::Run)->name, "Run");
  EXPECT_EQ(fox.clip(Gait::Stand)->name, "Survey");

  PosedMesh rest;
  fox.pose(Gait::Stand, 0.0f, rest);
  const Box3f b = boundsOf(rest.positions);
  EXPECT_NEAR(b.lo.y, 0.0f, 0.05f);  // the first frame of Survey is close to the rest pose
  EXPECT_NEAR(b.hi.y - b.lo.y, 1.2f, 0.1f);
  EXPECT_NEAR(0.5f * (b.lo.x + b.hi.x), 0.0f, 0.2f);  // Survey starts looking aside
  EXPECT_NEAR(0.5f * (b.lo.z + b.hi.z), 0.0f, 0.2f);
  // A fox is longer (along +Z, glTF's front) than it is wide.
  EXPECT_GT(b.hi.z - b.lo.z, 1.5f * (b.hi.x - b.lo.x));

  const glm::vec3 centre(0.0f, 0.6f, 0.0f);
  for (Gait g : {Gait::Stand, Gait::Walk, Gait::Run})
    for (float t = 0.0f; t < fox.clipDuration(g); t += 0.05f) {
      PosedMesh p;
      fox.pose(g, t, p);
      for (const glm::vec3& x : p.positions)
        ASSERT_LE(glm::length(x - centre), fox.boundingRadius()) << gaitName(g) << " t " << t;
    }
}

// The Fox's texture is orange: most corners' albedo is red above blue.
TEST(AvatarModel, CornerAlbedoComesFromTheTexture) {
  const AvatarModel fox = AvatarModel::load(foxFile(), 1.0f);
  ASSERT_EQ(fox.cornerAlbedo().size(), 3 * fox.triangleCount());
  size_t orange = 0;
  for (const glm::vec3& a : fox.cornerAlbedo()) orange += a.r > 1.5f * a.b;
  EXPECT_GT(orange, fox.cornerAlbedo().size() / 2);
  EXPECT_TRUE(fox.warnings().empty());
}

// The light of a white environment of radiance 1 with no sun: an open
// transfer vector (the clamped cosine about n, no blockers) gives
// skyExposure's ambient on an up-facing surface, whatever the yaw.
TEST(AvatarLight, AnOpenUpFacingSurfaceGetsTheAmbientOfTheBake) {
  const EnvironmentLight white =
      EnvironmentLight::project([](const glm::vec3&) { return glm::vec3(1.0f); }, 64, "white");
  Environment scene;
  scene.sunIntensity = 0.0f;
  LightingOptions options;
  options.ambient = 0.7f;
  const AvatarLight light = AvatarLight::of(white, scene, options);
  // The clamped cosine about +Y in 25 SH terms: zonal about z, rotated to y.
  float zonal[25] = {}, up[25];
  for (int l = 0; l < 5; ++l) zonal[l * l + l] = float(clampedCosineZonal(l));
  const glm::mat3 zToY = glm::mat3(glm::rotate(glm::mat4(1.0f), -1.5707963f, glm::vec3(1, 0, 0)));
  ShRotation(zToY, 5).apply(zonal, up);
  for (float yaw : {0.0f, 90.0f, 217.0f}) {
    const glm::vec3 c = light.turned(yaw).apply(up);
    EXPECT_NEAR(c.r, 0.7f, 0.02f) << "yaw " << yaw;
    EXPECT_NEAR(c.g, 0.7f, 0.02f);
  }
}

// A sun alone: an open surface facing it gets sunIntensity, one facing away
// nothing (within the ringing of 25 terms), and sunVisible 0 puts it out.
TEST(AvatarLight, TheSunLightsWhatFacesItAndTheSceneCanShadeIt) {
  const EnvironmentLight black =
      EnvironmentLight::project([](const glm::vec3&) { return glm::vec3(0.0f); }, 32, "black");
  Environment scene;
  scene.sunIntensity = 0.5f;
  scene.sunDirection = glm::vec3(0.0f, 0.0f, 1.0f);
  const AvatarLight light = AvatarLight::of(black, scene);
  float towards[25] = {}, away[25];
  for (int l = 0; l < 5; ++l) towards[l * l + l] = float(clampedCosineZonal(l));  // about +z
  const glm::mat3 flip = glm::mat3(glm::rotate(glm::mat4(1.0f), 3.14159265f, glm::vec3(1, 0, 0)));
  ShRotation(flip, 5).apply(towards, away);
  EXPECT_NEAR(light.apply(towards).r, 0.5f, 0.05f);
  EXPECT_LT(light.apply(away).r, 0.05f);
  EXPECT_EQ(light.apply(towards, 0.0f).r, 0.0f);
}

// The shader reuses sampled poses: the same clip time twice shades once,
// and its colours are the model's albedo times its light.
TEST(AvatarShader, ReusesASampledPoseAndColoursByAlbedoTimesLight) {
  auto fox = std::make_shared<const AvatarModel>(AvatarModel::load(foxFile(), 1.0f));
  AvatarShaderOptions options;
  options.poseRate = 10.0f;
  AvatarShader shader(fox, options);
  const EnvironmentLight sky = EnvironmentLight::sky(glm::vec3(0.55f, 0.7f, 0.9f));
  const AvatarLight light = AvatarLight::of(sky, Environment{});
  ShadedAvatar a, b;
  shader.shade(Gait::Walk, 0.31f, light, 1.0f, a);
  shader.shade(Gait::Walk, 0.33f, light, 1.0f, b);  // the same 0.1 s sample
  EXPECT_EQ(shader.stats().posesShaded, 1u);
  EXPECT_EQ(shader.stats().posesReused, 1u);
  EXPECT_EQ(a.corners, b.corners);
  ASSERT_EQ(a.corners.size(), 3 * fox->triangleCount());
  // Orange fur stays orange under a bluish sky: red above blue at most corners.
  size_t orange = 0;
  for (const glm::u8vec3& c : a.corners) orange += c.r > c.b;
  EXPECT_GT(orange, a.corners.size() / 2);
  // Putting the sun out darkens every corner or leaves it.
  ShadedAvatar shade;
  shader.shade(Gait::Walk, 0.31f, light, 0.0f, shade);
  for (size_t c = 0; c < a.corners.size(); ++c) ASSERT_LE(shade.corners[c].r, a.corners[c].r);
}

// The shader builds a per-clip PVS the first time a clip plays and shades
// with it: the colours stay within a level or two of shading with every
// triangle (the PVS is exact at its poses and within 2% between them).
// A metre-tall Fox and a bluish sky for the shader's tests.
std::shared_ptr<const AvatarModel> metreFox() {
  return std::make_shared<const AvatarModel>(AvatarModel::load(foxFile(), 1.0f));
}
AvatarLight bluishSky() {
  return AvatarLight::of(EnvironmentLight::sky(glm::vec3(0.55f, 0.7f, 0.9f)), Environment{});
}

TEST(AvatarShader, ShadesWithTheClipsPvsAndMatchesEveryTriangleClosely) {
  const auto fox = metreFox();
  const AvatarLight light = bluishSky();
  AvatarShaderOptions withPvs, without;
  without.pvsPoses = 0;
  AvatarShader a(fox, withPvs), b(fox, without);
  ShadedAvatar sa, sb;
  a.shade(Gait::Walk, 0.37f, light, 1.0f, sa);
  b.shade(Gait::Walk, 0.37f, light, 1.0f, sb);
  EXPECT_GT(a.stats().pvsMs, 0.0);
  EXPECT_EQ(b.stats().pvsMs, 0.0);
  ASSERT_EQ(sa.corners.size(), sb.corners.size());
  double sum = 0.0;
  int worst = 0;
  for (size_t c = 0; c < sa.corners.size(); ++c)
    for (int k = 0; k < 3; ++k) {
      const int d = std::abs(int(sa.corners[c][k]) - int(sb.corners[c][k]));
      sum += d;
      worst = std::max(worst, d);
    }
  EXPECT_LT(sum / double(3 * sa.corners.size()), 0.5);
  EXPECT_LE(worst, 8);
}

// The glossy term (Phong lobe about the viewer's reflection, through each
// vertex's mask): off without a viewer; with one it only adds light, and
// where depends on where the viewer stands.
TEST(AvatarShader, AGlossyTermAddsAViewDependentHighlight) {
  const auto fox = metreFox();
  const AvatarLight light = bluishSky();
  AvatarShaderOptions diffuseOnly, glossy;
  glossy.glossExponent = 16.0f;
  glossy.specular = 0.5f;
  AvatarShader plain(fox, diffuseOnly), shiny(fox, glossy);
  ShadedAvatar base, noViewer, front, side;
  plain.shade(Gait::Stand, 0.5f, light, 1.0f, base);
  shiny.shade(Gait::Stand, 0.5f, light, 1.0f, noViewer);
  EXPECT_EQ(noViewer.corners, base.corners);
  const glm::vec3 eyeFront(0.0f, 0.8f, 3.0f), eyeSide(3.0f, 0.2f, 0.0f);
  shiny.shade(Gait::Stand, 0.5f, light, 1.0f, front, &eyeFront);
  shiny.shade(Gait::Stand, 0.5f, light, 1.0f, side, &eyeSide);
  EXPECT_GT(shiny.stats().glossyMs, 0.0);
  size_t brighter = 0, differ = 0;
  for (size_t c = 0; c < base.corners.size(); ++c) {
    for (int k = 0; k < 3; ++k) ASSERT_GE(front.corners[c][k], base.corners[c][k]) << c;
    brighter += front.corners[c] != base.corners[c];
    differ += front.corners[c] != side.corners[c];
  }
  EXPECT_GT(brighter, base.corners.size() / 10);
  EXPECT_GT(differ, base.corners.size() / 10);
}

// The pose cache is bounded by bytes as well as poses: glossy poses keep
// 128 bytes of masks a vertex, so a cache room for two glossy Fox poses
// forgets the first of three, while a diffuse cache of the same bytes keeps
// all three.
TEST(AvatarShader, ThePoseCacheForgetsWhatPassesItsByteBound) {
  const auto fox = metreFox();
  const AvatarLight light = bluishSky();
  const size_t vertices = fox->vertexCount();
  const size_t glossyPose = vertices * (2 * 12 + 25 * 4 + 128);
  AvatarShaderOptions glossy, diffuse;
  glossy.glossExponent = 16.0f;
  glossy.maxCacheBytes = diffuse.maxCacheBytes = 2 * glossyPose + glossyPose / 2;
  glossy.poseRate = diffuse.poseRate = 10.0f;
  for (const bool shiny : {true, false}) {
    AvatarShader shader(fox, shiny ? glossy : diffuse);
    ShadedAvatar out;
    for (const float t : {0.05f, 0.15f, 0.25f, 0.05f})
      shader.shade(Gait::Walk, t, light, 1.0f, out);
    EXPECT_EQ(shader.stats().posesShaded, shiny ? 4u : 3u) << "glossy " << shiny;
    EXPECT_EQ(shader.stats().posesReused, shiny ? 0u : 1u) << "glossy " << shiny;
  }
}

// The triangles of a shaded avatar whose plane has `eye` strictly in front.
std::vector<size_t> trianglesFacing(const AvatarModel& model, const ShadedAvatar& shaded,
                                    const glm::vec3& eye) {
  std::vector<size_t> out;
  for (size_t t = 0; t < model.triangleCount(); ++t) {
    const glm::uvec3 i = model.triangles()[t];
    const glm::vec3 a = shaded.positions[i.x], b = shaded.positions[i.y], c = shaded.positions[i.z];
    if (glm::dot(glm::cross(b - a, c - a), eye - a) > 0.0f) out.push_back(t);
  }
  return out;
}

// The paper's front-facing saving, shared between viewers: a viewer gets
// exactly the colours whole shading gives every triangle facing it, for
// only part of the work; a second viewer on the other side shades just what
// the first left, after which both are served from the cache.
TEST(AvatarShader, ShadesWhatAViewerFacesAndTheRestWhenAnotherViewerNeedsIt) {
  const auto walker = std::make_shared<const AvatarModel>(
      AvatarModel::fromScene(generateWalker(), "walker", 1.75f));
  const AvatarLight light = bluishSky();
  AvatarShaderOptions wholeOptions;
  wholeOptions.frontFacingOnly = false;
  AvatarShader front(walker), whole(walker, wholeOptions);
  ASSERT_TRUE(front.shadesFrontFacingOnly());
  EXPECT_TRUE(AvatarShader(metreFox()).shadesFrontFacingOnly()) << "the Fox is closed too";
  ASSERT_FALSE(whole.shadesFrontFacingOnly());
  const glm::vec3 eyeA(0.4f, 1.2f, 4.0f), eyeB(-0.3f, 1.0f, -4.0f);
  ShadedAvatar a, b, again, all;
  front.shade(Gait::Walk, 0.3f, light, 1.0f, a, &eyeA);
  whole.shade(Gait::Walk, 0.3f, light, 1.0f, all, &eyeA);
  const size_t vertices = walker->vertexCount();
  EXPECT_EQ(whole.stats().verticesShaded, vertices);
  const uint64_t firstViewer = front.stats().verticesShaded;
  EXPECT_GT(firstViewer, 0u);
  EXPECT_LT(firstViewer, vertices);
  const std::vector<size_t> facingA = trianglesFacing(*walker, a, eyeA);
  ASSERT_FALSE(facingA.empty());
  for (const size_t t : facingA)
    for (int k = 0; k < 3; ++k)
      ASSERT_EQ(a.corners[3 * t + size_t(k)], all.corners[3 * t + size_t(k)]);

  front.shade(Gait::Walk, 0.3f, light, 1.0f, b, &eyeB);
  EXPECT_EQ(front.stats().posesShaded, 2u);
  EXPECT_GT(front.stats().verticesShaded, firstViewer);
  EXPECT_LE(front.stats().verticesShaded, vertices);
  for (const size_t t : trianglesFacing(*walker, b, eyeB))
    for (int k = 0; k < 3; ++k)
      ASSERT_EQ(b.corners[3 * t + size_t(k)], all.corners[3 * t + size_t(k)]);

  front.shade(Gait::Walk, 0.3f, light, 1.0f, again, &eyeA);
  EXPECT_EQ(front.stats().posesShaded, 2u);
  EXPECT_EQ(front.stats().posesReused, 1u);
  for (const size_t t : facingA)
    for (int k = 0; k < 3; ++k)
      ASSERT_EQ(again.corners[3 * t + size_t(k)], all.corners[3 * t + size_t(k)]);
}

// A model with a hole is not shaded by facing (its inside may show).
TEST(AvatarShader, AnOpenModelIsShadedWholeForEveryViewer) {
  Scene scene = generateWalker();
  bool cut = false;
  for (Object& o : scene.objects)
    if (o.skin >= 0 && !cut) {
      o.mesh.triangles.pop_back();
      if (!o.mesh.faceIds.empty()) o.mesh.faceIds.pop_back();
      if (!o.mesh.materials.empty()) o.mesh.materials.pop_back();
      cut = true;
    }
  ASSERT_TRUE(cut);
  const auto open =
      std::make_shared<const AvatarModel>(AvatarModel::fromScene(scene, "open", 1.75f));
  AvatarShader shader(open);
  EXPECT_FALSE(shader.shadesFrontFacingOnly());
  ShadedAvatar out;
  const glm::vec3 eye(0.0f, 1.0f, 4.0f);
  shader.shade(Gait::Walk, 0.3f, bluishSky(), 1.0f, out, &eye);
  EXPECT_EQ(shader.stats().verticesShaded, open->vertexCount());
}

// The built-in walker: a closed, outward-wound figure 1.75 m tall whose
// legs swing when it walks: the top of its head sees the whole sky (its
// transfer vector is the open cosine's), and a foot moves between two
// moments of the Walk clip while the head stays level.
TEST(Walker, IsAClosedFigureWhoseLegsSwingWhenItWalks) {
  const AvatarModel walker = AvatarModel::fromScene(generateWalker(), "walker", 1.75f);
  EXPECT_EQ(walker.clip(Gait::Walk)->name, "Walk");
  EXPECT_EQ(walker.clip(Gait::Run)->name, "Run");
  EXPECT_EQ(walker.clip(Gait::Stand)->name, "Survey");
  PosedMesh a, b;
  walker.pose(Gait::Walk, 0.0f, a);
  walker.pose(Gait::Walk, 0.25f, b);
  const Box3f rest = boundsOf(a.positions);
  EXPECT_NEAR(rest.hi.y - rest.lo.y, 1.75f, 0.05f);
  size_t top = 0, foot = 0;
  for (size_t v = 0; v < a.positions.size(); ++v) {
    if (a.positions[v].y > a.positions[top].y) top = v;
    if (a.positions[v].y < a.positions[foot].y) foot = v;
  }
  EXPECT_GT(glm::length(a.positions[foot] - b.positions[foot]), 0.1f);  // the swing
  EXPECT_GT(a.normals[top].y, 0.5f);  // outward: the head's top faces up
  const SelfShadowing shadows;
  std::vector<float> t;
  shadows.diffuse(a.positions, a.normals, walker.triangles(), t);
  std::vector<float> open;
  shadows.diffuse(a.positions, a.normals, std::vector<glm::uvec3>{}, open);
  EXPECT_LT(
      meanRelativeL2(
          {t.begin() + std::ptrdiff_t(25 * top), t.begin() + std::ptrdiff_t(25 * top + 25)},
          {open.begin() + std::ptrdiff_t(25 * top), open.begin() + std::ptrdiff_t(25 * top + 25)},
          25),
      0.02);
  // A vertex in the armpit is shadowed: its transfer is far from open.
  double shadowed = 0.0;
  for (size_t v = 0; v < a.positions.size(); ++v)
    shadowed = std::max(
        shadowed,
        meanRelativeL2(
            {t.begin() + std::ptrdiff_t(25 * v), t.begin() + std::ptrdiff_t(25 * v + 25)},
            {open.begin() + std::ptrdiff_t(25 * v), open.begin() + std::ptrdiff_t(25 * v + 25)},
            25));
  EXPECT_GT(shadowed, 0.3);
}

TEST(AvatarModel, ASceneWithoutASkinIsAnInputError) {
  Scene s;
  s.name = "boxes";
  EXPECT_THROW(AvatarModel::fromScene(s, "boxes", 1.0f), InputError);
  EXPECT_THROW(AvatarModel::load(foxFile(), 0.0f), InputError);
}

}  // namespace
}  // namespace vistream
