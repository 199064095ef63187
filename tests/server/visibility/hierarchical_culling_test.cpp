#include "server/visibility/hierarchical_culling.h"

#include <gtest/gtest.h>

#include "common/core/error.h"
#include "common/generate/generate.h"
#include "common/generate/path.h"
#include "common/raycast/ray_query.h"
#include "common/spatial/free_space.h"
#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

struct Walk {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  std::unique_ptr<CullingScene> culling;
  std::vector<PathSample> path;  // local frame positions in `position`

  explicit Walk(const std::string& type, size_t frames = 120) {
    scene = toScene(generate(type, 1));
    triangles = flattenScene(scene, true);
    rays = makeEmbreeRayQuery(triangles);
    culling = std::make_unique<CullingScene>(scene);
    const FreeSpace fs = FreeSpace::build(*rays, scene.bounds());
    PathOptions o;
    o.frames = frames;
    o.seed = 4;
    path = generatePath(scene, fs, o);
    for (auto& s : path) s.position = glm::dvec3(scene.toLocal(s.position));
    // Sharp turns and a teleport: the coherence methods must not lag behind.
    for (size_t i = frames / 3; i < frames / 3 + 5 && i < path.size(); ++i) path[i].yawDeg += 180.0;
    if (path.size() > 10) {
      const size_t a = path.size() / 2, b = path.size() - 3;
      std::swap(path[a].position, path[b].position);
    }
  }
};

std::vector<FrameResult> run(const Walk& w, CullingMethod method, double pSkip = 0.5) {
  CullingOptions o;
  o.method = method;
  o.pSkip = pSkip;
  o.collectFaces = true;
  CullingViewer viewer(*w.culling, o);
  std::vector<FrameResult> out;
  for (const auto& s : w.path) out.push_back(viewer.frame(s.position, s.yawDeg, s.pitchDeg));
  return out;
}

class CullingOnScene : public ::testing::TestWithParam<const char*> {};

TEST_P(CullingOnScene, HierarchyUpdatingClassifiesEveryLeafLikeTheClassicalMethodOnEveryFrame) {
  const Walk w(GetParam());
  const auto a = run(w, CullingMethod::Classical), b = run(w, CullingMethod::HierarchyUpdating);
  uint64_t testsA = 0, testsB = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].leafVisible, b[i].leafVisible) << "frame " << i;
    testsA += a[i].nodeTests;
    testsB += b[i].nodeTests;
  }
  EXPECT_LT(testsB, testsA);  // and it does so with fewer node tests
}

TEST_P(CullingOnScene, ConservativeUpdatingDrawsEverythingTheClassicalMethodDraws) {
  const Walk w(GetParam());
  const auto a = run(w, CullingMethod::Classical), d = run(w, CullingMethod::Conservative, 0.7);
  for (size_t i = 0; i < a.size(); ++i)
    EXPECT_TRUE(std::includes(d[i].faces.begin(), d[i].faces.end(), a[i].faces.begin(), a[i].faces.end()))
        << "frame " << i;
}

TEST_P(CullingOnScene, EveryFaceSeenThroughTheFrustumIsDrawn) {
  const Walk w(GetParam(), 60);
  const auto a = run(w, CullingMethod::Classical);
  const double th = std::tan(30.0 * 3.14159265358979323846 / 180.0), tv = th * 0.75;
  size_t checked = 0;
  for (size_t i = 0; i < w.path.size(); i += 3) {
    const auto& s = w.path[i];
    const glm::dvec3 f = viewDirection(s.yawDeg, s.pitchDeg);
    const glm::dvec3 r = glm::normalize(glm::cross(f, glm::dvec3(0, 1, 0))), u = glm::cross(r, f);
    for (int y = 0; y < 24; ++y)
      for (int x = 0; x < 32; ++x) {
        const glm::dvec3 d = f + r * (th * ((x + 0.5) / 16.0 - 1.0)) + u * (tv * ((y + 0.5) / 12.0 - 1.0));
        const Hit h = w.rays->firstHit(Ray{glm::vec3(s.position), glm::vec3(d), 0.0f, 1e30f});
        if (!h.valid()) continue;
        ++checked;
        const uint32_t face = w.triangles.faceIds[h.triangle];
        ASSERT_TRUE(std::binary_search(a[i].faces.begin(), a[i].faces.end(), face))
            << GetParam() << " frame " << i << " misses face " << face;
      }
  }
  EXPECT_GT(checked, 1000u);
}

INSTANTIATE_TEST_SUITE_P(GeneratedScenes, CullingOnScene, ::testing::Values("interior", "city1"));

TEST(HierarchicalCulling, ViewersOnOneSceneKeepTheirOwnCoherence) {
  const Walk w("interior", 40);
  const auto alone = run(w, CullingMethod::HierarchyUpdating);
  CullingOptions o;
  o.method = CullingMethod::HierarchyUpdating;
  o.collectFaces = true;
  CullingViewer first(*w.culling, o), second(*w.culling, o);
  for (size_t i = 0; i < w.path.size(); ++i) {
    const auto& s = w.path[i];
    const auto& t = w.path[w.path.size() - 1 - i];
    const FrameResult r1 = first.frame(s.position, s.yawDeg, s.pitchDeg);
    second.frame(t.position, t.yawDeg, t.pitchDeg);  // interleaved, elsewhere
    EXPECT_EQ(r1.faces, alone[i].faces) << "frame " << i;
    EXPECT_EQ(r1.nodeTests, alone[i].nodeTests) << "frame " << i;
  }
}

TEST(HierarchicalCulling, AViewpointTouchingAWallStillSeesWhatIsInFrontOfIt) {
  // A wall in front of the viewer, the eye exactly on the face of another
  // wall behind; a box in front must be drawn.
  Scene s;
  testing::addGround(s, -20, -20, 20, 20);
  testing::addBox(s, "back_wall", {-10, 0, 0}, {10, 3, 0.2f});
  const uint32_t box = testing::addBox(s, "box", {-1, 0, -6}, {1, 2, -4});
  testing::addBox(s, "hidden", {-1, 0, -16}, {1, 2, -14});
  testing::addBox(s, "front_wall", {-10, 0, -11}, {10, 3, -10.8f});
  finalizeScene(s);
  const CullingScene culling(s);
  for (const auto method : {CullingMethod::Classical, CullingMethod::HierarchyUpdating}) {
    CullingOptions o;
    o.method = method;
    o.collectFaces = true;
    o.smallNodeFaces = 0;  // test every node
    CullingViewer viewer(culling, o);
    const FrameResult r = viewer.frame({0.0, 1.5, 0.0}, 0.0, 0.0);  // eye on the back wall's face, looking -Z
    EXPECT_TRUE(std::binary_search(r.faces.begin(), r.faces.end(), box + testing::kPlusZ));
  }
}

TEST(HierarchicalCulling, RejectsMethodsThatDoNotExistYetWithAClearMessage) {
  EXPECT_THROW(parseCullingMethod("C"), InputError);
  EXPECT_THROW(parseCullingMethod("adaptive"), InputError);
  EXPECT_THROW(parseCullingMethod("Z"), InputError);
  EXPECT_EQ(parseCullingMethod("B"), CullingMethod::HierarchyUpdating);
}

}  // namespace
}  // namespace vistream
