#include "server/visibility/hierarchical_culling.h"

#include <gtest/gtest.h>

#include "common/core/error.h"
#include "common/generate/generate.h"
#include "common/generate/path.h"
#include "common/raycast/ray_query.h"
#include "common/world/free_space.h"
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
    const FreeSpace fs = FreeSpace::build(*rays, Solids::build(triangles), scene.bounds());
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

TEST_P(CullingOnScene, VisibilityPropagationClassifiesEveryLeafLikeTheClassicalMethod) {
  const Walk w(GetParam());
  const auto a = run(w, CullingMethod::Classical), c = run(w, CullingMethod::Propagation);
  uint64_t propagated = 0, differing = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    differing += a[i].leafVisible != c[i].leafVisible;
    propagated += c[i].propagated;
  }
  EXPECT_EQ(differing, 0u);
  // And propagation did classify nodes, where there are large planar occluders.
  if (std::string(GetParam()) != "terrain") {
    EXPECT_GT(propagated, 0u);
  }
}

TEST_P(CullingOnScene, ConservativeAndAdaptiveUpdatingDrawEverythingTheClassicalMethodDraws) {
  const Walk w(GetParam());
  const auto a = run(w, CullingMethod::Classical);
  for (const auto method : {CullingMethod::Conservative, CullingMethod::Adaptive}) {
    const auto d = run(w, method, 0.7);
    uint64_t skipped = 0;
    for (size_t i = 0; i < a.size(); ++i) {
      EXPECT_TRUE(
          std::includes(d[i].faces.begin(), d[i].faces.end(), a[i].faces.begin(), a[i].faces.end()))
          << cullingMethodName(method) << " frame " << i;
      skipped += d[i].skipped;
    }
    EXPECT_GT(skipped, 0u) << cullingMethodName(method);  // it did skip tests
  }
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
        const glm::dvec3 d =
            f + r * (th * ((x + 0.5) / 16.0 - 1.0)) + u * (tv * ((y + 0.5) / 12.0 - 1.0));
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

INSTANTIATE_TEST_SUITE_P(GeneratedScenes, CullingOnScene,
                         ::testing::Values("interior", "interior2", "city1", "city2", "terrain",
                                           "bigcity"));

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
    const FrameResult r =
        viewer.frame({0.0, 1.5, 0.0}, 0.0, 0.0);  // eye on the back wall's face, looking -Z
    EXPECT_TRUE(std::binary_search(r.faces.begin(), r.faces.end(), box + testing::kPlusZ));
  }
}

// Every face that one of 64 x 48 rays through the frustum hits first is drawn
// by every method; returns the faces drawn by A.
std::vector<uint32_t> expectConservativeFrom(const Scene& s, const glm::dvec3& eye, double yaw,
                                             double pitch) {
  const CullingScene culling(s);
  const FlatTriangles tris = flattenScene(s, true);
  const auto rays = makeBruteForceRayQuery(tris);
  std::vector<uint32_t> seen;
  const glm::dvec3 f = viewDirection(yaw, pitch);
  const glm::dvec3 r = glm::normalize(glm::cross(f, glm::dvec3(0, 1, 0))), u = glm::cross(r, f);
  const double th = std::tan(30.0 * 3.14159265358979323846 / 180.0), tv = th * 0.75;
  for (int y = 0; y < 48; ++y)
    for (int x = 0; x < 64; ++x) {
      const glm::dvec3 d =
          f + r * (th * ((x + 0.5) / 32.0 - 1.0)) + u * (tv * ((y + 0.5) / 24.0 - 1.0));
      const Hit h = rays->firstHit(Ray{glm::vec3(eye), glm::vec3(d), 0.0f, 1e30f});
      if (h.valid()) seen.push_back(tris.faceIds[h.triangle]);
    }
  std::vector<uint32_t> drawnByA;
  for (const auto method :
       {CullingMethod::Classical, CullingMethod::HierarchyUpdating, CullingMethod::Propagation,
        CullingMethod::Conservative, CullingMethod::Adaptive}) {
    CullingOptions o;
    o.method = method;
    o.collectFaces = true;
    o.smallNodeFaces = 0;  // test every node
    CullingViewer viewer(culling, o);
    FrameResult result;
    for (int frame = 0; frame < 3; ++frame)
      result = viewer.frame(eye, yaw, pitch);  // coherence from the same view
    for (uint32_t face : seen)
      EXPECT_TRUE(std::binary_search(result.faces.begin(), result.faces.end(), face))
          << cullingMethodName(method) << " misses face " << face;
    if (method == CullingMethod::Classical) drawnByA = result.faces;
  }
  return drawnByA;
}

bool drawsAny(const std::vector<uint32_t>& faces, uint32_t firstFace, uint32_t count) {
  for (uint32_t f = firstFace; f < firstFace + count; ++f)
    if (std::binary_search(faces.begin(), faces.end(), f)) return true;
  return false;
}

TEST(HierarchicalCulling, TwoWallsSharingAnEdgeHideABoxBehindTheSeam) {
  Scene s;
  testing::addBox(s, "left_wall", {-10, 0, -10.2f}, {0, 4, -10});
  testing::addBox(s, "right_wall", {0, 0, -10.2f}, {10, 4, -10});
  const uint32_t front = testing::addBox(s, "front", {-1, 0, -6}, {1, 2, -4});
  const uint32_t behind = testing::addBox(s, "behind_the_seam", {-1, 0, -17}, {1, 2, -15});
  finalizeScene(s);
  const auto drawn = expectConservativeFrom(s, {0.0, 1.5, 0.0}, 0.0, 0.0);
  EXPECT_TRUE(drawsAny(drawn, front, 6));
  EXPECT_FALSE(drawsAny(drawn, behind, 6));  // fused across the seam, known hidden
}

TEST(HierarchicalCulling, ViewpointInAnOccludersPlaneOrOnItsEdgeStaysConservative) {
  Scene s;
  testing::addBox(s, "wall", {-10, 0, -10.2f}, {10, 4, -10});
  testing::addBox(s, "behind", {-1, 0, -17}, {1, 2, -15});
  const uint32_t beside = testing::addBox(s, "beside", {12, 0, -17}, {14, 2, -15});
  finalizeScene(s);
  // In the plane of the wall's top face, above the wall: the top is seen
  // edge-on, the box beside the wall is in view.
  auto drawn = expectConservativeFrom(s, {0.0, 4.0, 0.0}, 0.0, 0.0);
  EXPECT_TRUE(drawsAny(drawn, beside, 6));
  // On the edge between the wall's top and front faces, looking down past it:
  // both planes hold the eye, and the box behind is hidden only by the
  // wall's far face, within its thickness.
  drawn = expectConservativeFrom(s, {0.0, 4.0, -10.0}, 0.0, -20.0);
  // In the plane of the wall's front face, beside the wall, looking along it.
  drawn = expectConservativeFrom(s, {11.0, 1.5, -10.0}, 90.0, 0.0);
}

TEST(HierarchicalCulling, BoxesTouchingAShadowPlaneAreDrawn) {
  // The box's side lies exactly in the shadow plane through the eye and the
  // wall's right edge (x = 2 at the wall, x = 4 at twice the distance).
  Scene s;
  testing::addBox(s, "wall", {-2, 0, -5.2f}, {2, 6, -5});
  const uint32_t touching = testing::addBox(s, "touching", {4, 0, -12}, {5, 2, -10});
  finalizeScene(s);
  const auto drawn = expectConservativeFrom(s, {0.0, 1.5, 0.0}, 0.0, 0.0);
  EXPECT_TRUE(drawsAny(drawn, touching, 6));
}

TEST(HierarchicalCulling, ParsesEveryMethodNameAndRejectsOthersWithAClearMessage) {
  for (const char* name : {"A", "B", "C", "D", "adaptive"})
    EXPECT_STREQ(cullingMethodName(parseCullingMethod(name)), name);
  EXPECT_THROW(parseCullingMethod("Z"), InputError);
  EXPECT_THROW(parseCullingMethod("a"), InputError);
}

}  // namespace
}  // namespace vistream
