#include "common/avatar/self_shadow.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <numbers>

#include "common/avatar/skinning.h"
#include "common/light/environment_light.h"
#include "common/scene/scene_loader.h"

namespace vistream {
namespace {

struct Mesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::uvec3> triangles;
  std::vector<glm::vec3> normals;

  // A (rows + 1) x (cols + 1) grid of vertices from f(u, v), u, v in [0, 1].
  template <class F>
  void addGrid(int rows, int cols, F&& f) {
    const uint32_t base = uint32_t(positions.size());
    for (int i = 0; i <= rows; ++i)
      for (int j = 0; j <= cols; ++j) positions.push_back(f(double(i) / rows, double(j) / cols));
    for (int i = 0; i < rows; ++i)
      for (int j = 0; j < cols; ++j) {
        const uint32_t a = base + uint32_t(i * (cols + 1) + j), b = a + 1,
                       c = a + uint32_t(cols + 1), d = c + 1;
        triangles.emplace_back(a, b, d);
        triangles.emplace_back(a, d, c);
      }
  }
  void finish() { vertexNormals(positions, triangles, normals); }
};

// A 6 m square floor (facing +y) with a ball of radius 1 floating 2 m
// above its centre: the floor under the ball is in its soft shadow.
Mesh ballOverFloor() {
  Mesh m;
  m.addGrid(12, 12, [](double u, double v) {
    return glm::vec3(float(-3 + 6 * u), 0.0f, float(-3 + 6 * v));
  });
  m.addGrid(16, 32, [](double u, double v) {
    const double theta = std::numbers::pi * u, phi = 2 * std::numbers::pi * v;
    return glm::vec3(float(std::sin(theta) * std::cos(phi)), float(2.0 + std::cos(theta)),
                     float(std::sin(theta) * std::sin(phi)));
  });
  m.finish();
  return m;
}

// A hemispherical bowl of radius 2, open upwards, its inside facing in.
Mesh bowl() {
  Mesh m;
  m.addGrid(12, 32, [](double u, double v) {
    const double theta = 0.5 * std::numbers::pi * u,
                 phi = 2 * std::numbers::pi * v;  // theta from the bottom
    return glm::vec3(float(2 * std::sin(theta) * std::cos(phi)), float(2 - 2 * std::cos(theta)),
                     float(2 * std::sin(theta) * std::sin(phi)));
  });
  m.finish();
  return m;
}

double errorAgainstMonteCarlo(const Mesh& m, const SelfShadowOptions& o) {
  const SelfShadowing shadows(o);
  std::vector<float> ours, reference;
  shadows.diffuse(m.positions, m.normals, m.triangles, ours);
  monteCarloTransfer(m.positions, m.normals, m.triangles, 16384, o.transfer.orders, reference);
  return meanRelativeL2(ours, reference, shadows.terms());
}

// The paper's transfer vectors are within 2.5-8% of the reference; ours
// must be too, with and without downsampling.
TEST(SelfShadow, ABallOverAFloorMatchesConvergedMonteCarlo) {
  const Mesh m = ballOverFloor();
  for (const bool downsample : {false, true}) {
    SelfShadowOptions o;
    o.transfer.downsample = downsample;
    const double e = errorAgainstMonteCarlo(m, o);
    EXPECT_LT(e, 0.08) << "downsample " << downsample;
    RecordProperty(downsample ? "l2_downsampled" : "l2_full", std::to_string(e));
  }
}

TEST(SelfShadow, AConcaveBowlMatchesConvergedMonteCarlo) {
  const Mesh m = bowl();
  // Its inside faces the bowl's centre.
  const size_t side = 6 * 33 + 3;
  EXPECT_GT(glm::dot(m.normals[side], glm::vec3(0, 2, 0) - m.positions[side]), 0.0f);
  const double e = errorAgainstMonteCarlo(m, {});
  EXPECT_LT(e, 0.08);
}

// The shadow is there: floor vertices under the ball receive less light
// from straight above than those at the floor's corners.
TEST(SelfShadow, TheFloorUnderTheBallIsDarkerThanItsCorners) {
  const Mesh m = ballOverFloor();
  const SelfShadowing shadows;
  std::vector<float> t;
  shadows.diffuse(m.positions, m.normals, m.triangles, t);
  const int terms = shadows.terms();
  // Y_1^{-1} is 0.4886 y: its coefficient measures light from above.
  const size_t centre = 6 * 13 + 6, corner = 0;
  // The ball faces outwards, the floor up.
  EXPECT_GT(m.normals[169 + 8 * 33 + 5].x, 0.5f);
  EXPECT_GT(m.normals[centre].y, 0.99f);
  EXPECT_LT(t[centre * size_t(terms)], 0.8f * t[corner * size_t(terms)]);
  EXPECT_LT(t[centre * size_t(terms) + 1], 0.8f * t[corner * size_t(terms) + 1]);
}

TEST(SelfShadow, ExactPlanesAndThePlaneTableAgreeWithinTheTablesQuantization) {
  const Mesh m = bowl();
  SelfShadowOptions exact;
  exact.planeTable = 0;
  const SelfShadowing a(exact), b;
  std::vector<float> ta, tb;
  a.diffuse(m.positions, m.normals, m.triangles, ta);
  b.diffuse(m.positions, m.normals, m.triangles, tb);
  EXPECT_LT(meanRelativeL2(tb, ta, a.terms()), 0.03);
}

// The Fox mid-walk against Monte Carlo: the real model meets the same bound.
TEST(SelfShadow, TheWalkingFoxMatchesConvergedMonteCarlo) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh mesh = SkinnedMesh::firstOf(fox);
  PosedMesh pose;
  poseAt(fox, mesh, findAnimation(fox, "Walk"), 0.3f, pose);
  const SelfShadowing shadows;
  std::vector<float> ours, reference;
  SelfShadowStats stats;
  shadows.diffuse(pose.positions, pose.normals, mesh.triangles, ours, {.stats = &stats});
  monteCarloTransfer(pose.positions, pose.normals, mesh.triangles, 16384, 5, reference);
  const double e = meanRelativeL2(ours, reference, shadows.terms());
  EXPECT_LT(e, 0.08);
  EXPECT_EQ(stats.vertices, pose.positions.size());
  EXPECT_EQ(stats.blockerTests, pose.positions.size() * mesh.triangles.size());
  EXPECT_GT(stats.rasterized, 0u);
  EXPECT_LT(stats.rasterized, stats.blockerTests);
}

// Turning the model and the environment together by the same rotation
// leaves every vertex's radiance as it was (up to the masks' quantization,
// which follows each vertex's own tangent frame).
TEST(SelfShadow, TurningModelAndEnvironmentTogetherLeavesRadianceUnchanged) {
  const Mesh m = ballOverFloor();
  auto sky = [](const glm::vec3& d) {
    return glm::vec3(std::exp(2.0f * d.y + d.x), std::exp(d.y), 1.0f + d.z * d.z);
  };
  const glm::mat3 r =
      glm::mat3(glm::rotate(glm::mat4(1.0f), 0.7f, glm::normalize(glm::vec3(1, 2, -1))));
  Mesh turned = m;
  for (glm::vec3& p : turned.positions) p = r * p;
  for (glm::vec3& n : turned.normals) n = glm::normalize(r * n);
  const auto env = EnvironmentLight::project(sky, 256, "sky");
  const auto turnedEnv = EnvironmentLight::project(
      [&](const glm::vec3& d) { return sky(glm::transpose(r) * d); }, 256, "turned sky");
  auto difference = [&](const SelfShadowOptions& o) {  // of all radiance
    const SelfShadowing shadows(o);
    std::vector<float> a, b;
    shadows.diffuse(m.positions, m.normals, m.triangles, a);
    shadows.diffuse(turned.positions, turned.normals, turned.triangles, b);
    double differ = 0.0, total = 0.0;  // summed over vertices
    for (size_t v = 0; v < m.positions.size(); ++v) {
      const glm::vec3 ra = env.transferred(&a[v * 25], 5),
                      rb = turnedEnv.transferred(&b[v * 25], 5);
      differ += glm::length(ra - rb);
      total += glm::length(ra);
    }
    return differ / total;
  };
  EXPECT_LT(difference({}), 0.01);
}

// Without a finer level the hierarchy's ring and the coarse mesh minus the
// ring's parents are every triangle once: the same transfer, exactly.
TEST(ShadowHierarchy, OnAnUnsubdividedMeshItIsEveryTriangleOnce) {
  const Mesh m = ballOverFloor();
  const SelfShadowing shadows;
  for (const int ring : {1, 2}) {
    const ShadowHierarchy h =
        ShadowHierarchy::build(m.triangles, m.triangles, 0, ring, m.positions.size());
    EXPECT_DOUBLE_EQ(h.meanBlockers(), double(m.triangles.size()));
    std::vector<float> all, split;
    shadows.diffuse(m.positions, m.normals, m.triangles, all);
    shadows.diffuse(m.positions, m.normals, m.triangles, split, {.hierarchy = &h});
    EXPECT_EQ(all, split) << "ring " << ring;
  }
}

// The Fox subdivided twice (the paper's "Hand" size): blocking through the
// original mesh beyond two rings keeps the error against Monte Carlo over
// the full fine mesh within the paper's bound, with far fewer blockers.
TEST(ShadowHierarchy, TheSubdividedFoxStaysWithinThePapersErrorWithAFractionOfTheBlockers) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh base = SkinnedMesh::firstOf(fox);
  const SkinnedMesh coarse = base.subdivided(0), fine = base.subdivided(2);
  const ShadowHierarchy h =
      ShadowHierarchy::build(fine.triangles, coarse.triangles, 2, 2, fine.positions.size());
  EXPECT_LT(h.meanBlockers(), 0.1 * double(fine.triangles.size()));
  PosedMesh pose;
  poseAt(fox, fine, findAnimation(fox, "Walk"), 0.5f, pose);
  const SelfShadowing shadows;
  std::vector<float> ours, reference;
  shadows.diffuse(pose.positions, pose.normals, fine.triangles, ours, {.hierarchy = &h});
  monteCarloTransfer(pose.positions, pose.normals, fine.triangles, 4096, 5, reference);
  EXPECT_LT(meanRelativeL2(ours, reference, shadows.terms()), 0.08);
}

// The hierarchy as blocker lists shadows exactly as the hierarchy does.
TEST(VertexBlockers, TheHierarchysListsGiveTheHierarchysTransfer) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh base = SkinnedMesh::firstOf(fox);
  const SkinnedMesh coarse = base.subdivided(0), fine = base.subdivided(1);
  const ShadowHierarchy h =
      ShadowHierarchy::build(fine.triangles, coarse.triangles, 1, 2, fine.positions.size());
  const VertexBlockers lists = VertexBlockers::of(h, fine.triangles);
  EXPECT_DOUBLE_EQ(lists.meanPerVertex(), h.meanBlockers());
  PosedMesh pose;
  poseAt(fox, fine, findAnimation(fox, "Run"), 0.2f, pose);
  const SelfShadowing shadows;
  std::vector<float> a, b;
  shadows.diffuse(pose.positions, pose.normals, fine.triangles, a, {.hierarchy = &h});
  shadows.diffuse(pose.positions, pose.normals, lists, b);
  EXPECT_EQ(a, b);
}

// The per-vertex PVS of the walking Fox, from 8 poses of the clip: at those
// poses the transfer is bit for bit that of every triangle (the mask is the
// OR of the blockers, and only blockers that set no new bit were dropped),
// with far fewer blockers; between them it stays close.
TEST(VertexPvs, IsExactAtItsPosesWithAFractionOfTheBlockersAndCloseBetweenThem) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh mesh = SkinnedMesh::firstOf(fox).subdivided(0);
  const Animation* walk = findAnimation(fox, "Walk");
  std::vector<PosedMesh> poses(8);
  for (size_t k = 0; k < poses.size(); ++k)
    poseAt(fox, mesh, walk, walk->duration * float(k) / 8.0f, poses[k]);
  const VertexBlockers all = VertexBlockers::everyTriangle(mesh.triangles, mesh.positions.size());
  const VertexBlockers pvs = potentiallyVisibleBlockers(all, poses);
  EXPECT_LT(pvs.meanPerVertex(), 0.5 * all.meanPerVertex());
  EXPECT_GT(pvs.meanPerVertex(), 0.0);
  const SelfShadowing shadows;
  std::vector<float> full, cut;
  for (const size_t k : {size_t(0), size_t(5)}) {
    shadows.diffuse(poses[k].positions, poses[k].normals, mesh.triangles, full);
    shadows.diffuse(poses[k].positions, poses[k].normals, pvs, cut);
    EXPECT_EQ(full, cut) << "pose " << k;
  }
  PosedMesh between;
  poseAt(fox, mesh, walk, walk->duration * 2.5f / 8.0f, between);
  shadows.diffuse(between.positions, between.normals, mesh.triangles, full);
  shadows.diffuse(between.positions, between.normals, pvs, cut);
  EXPECT_LT(meanRelativeL2(cut, full, shadows.terms()), 0.02);
}

// Static groups (meshoptimizer's meshlets): every triangle in exactly one
// group, none over the size limit, and each group's sphere holds its
// triangles' corners in any pose. A degenerate triangle still has a group.
TEST(TriangleGroups, HoldEveryTriangleOnceInSpheresThatFollowThePose) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  SkinnedMesh mesh = SkinnedMesh::firstOf(fox).subdivided(0);
  std::vector<glm::uvec3> triangles = mesh.triangles;
  triangles.push_back({0, 0, 1});          // degenerate
  triangles.push_back(triangles.front());  // repeated
  const TriangleGroups groups = TriangleGroups::build(triangles, mesh.positions);
  ASSERT_GT(groups.size(), 1u);
  std::vector<int> seen(triangles.size(), 0);
  for (size_t g = 0; g < groups.size(); ++g) {
    const uint32_t count = groups.triangleStart[g + 1] - groups.triangleStart[g];
    if (!groups.neverCulled[g]) {
      EXPECT_LE(count, TriangleGroups::kMaxTriangles);
    }
    for (uint32_t k = groups.triangleStart[g]; k < groups.triangleStart[g + 1]; ++k) {
      ++seen[groups.members[k]];
      EXPECT_EQ(groups.groupOf[groups.members[k]], g);
    }
  }
  for (size_t t = 0; t < seen.size(); ++t) EXPECT_EQ(seen[t], 1) << "triangle " << t;
  PosedMesh pose;
  poseAt(fox, mesh, findAnimation(fox, "Run"), 0.2f, pose);
  std::vector<glm::vec4> spheres;
  groups.spheres(pose.positions, spheres);
  for (size_t t = 0; t < triangles.size(); ++t) {
    const glm::vec4 s = spheres[groups.groupOf[t]];
    for (int k = 0; k < 3; ++k)
      EXPECT_LE(glm::distance(glm::vec3(s), pose.positions[triangles[t][k]]), s.w)
          << "triangle " << t;
  }
}

// Culling whole groups below a vertex's tangent plane is only a shortcut:
// the transfer is bit for bit the same as testing every triangle, with every
// triangle and with a PVS, while far fewer triangles are looked at.
TEST(TriangleGroups, CullingThemChangesNoBitOfTheTransferAndSkipsTriangles) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh mesh = SkinnedMesh::firstOf(fox).subdivided(0);
  const Animation* walk = findAnimation(fox, "Walk");
  const TriangleGroups groups = TriangleGroups::build(mesh.triangles, mesh.positions);
  SelfShadowOptions off;
  off.cullGroups = false;
  const SelfShadowing culling, plain(off);
  std::vector<PosedMesh> poses(4);
  for (size_t k = 0; k < poses.size(); ++k)
    poseAt(fox, mesh, walk, walk->duration * float(k) / 4.0f, poses[k]);
  VertexBlockers every = VertexBlockers::everyTriangle(mesh.triangles, mesh.positions.size());
  every.groupTriangles(mesh.positions);
  const VertexBlockers pvs = potentiallyVisibleBlockers(every, poses);
  ASSERT_EQ(pvs.groups.size(), every.groups.size());
  for (const PosedMesh& pose : poses) {
    std::vector<float> a, b;
    SelfShadowStats sa, sb;
    culling.diffuse(pose.positions, pose.normals, mesh.triangles, a,
                    {.stats = &sa, .groups = &groups});
    plain.diffuse(pose.positions, pose.normals, mesh.triangles, b,
                  {.stats = &sb, .groups = &groups});
    EXPECT_EQ(a, b);
    EXPECT_EQ(sa.rasterized, sb.rasterized);
    EXPECT_GT(sa.groupsCulled, 0u);
    EXPECT_LT(double(sa.blockerTests), 0.8 * double(sb.blockerTests));
    culling.diffuse(pose.positions, pose.normals, pvs, a, {.stats = &sa});
    plain.diffuse(pose.positions, pose.normals, pvs, b, {.stats = &sb});
    EXPECT_EQ(a, b);
    EXPECT_EQ(sa.rasterized, sb.rasterized);
    EXPECT_GT(sa.groupsCulled, 0u);
    EXPECT_EQ(sb.groupsCulled, 0u);
    EXPECT_LT(sa.blockerTests, sb.blockerTests);
  }
}

// Shading only front-facing vertices (the paper's saving): the Fox seen from
// one side selects some but not all of its vertices; those get exactly the
// transfer full shading gives them, the others zeros, and the stats count
// only the shaded ones.
TEST(SelfShadow, ShadingOnlyFrontFacingVerticesGivesTheirExactTransferAndLeavesTheOthers) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh mesh = SkinnedMesh::firstOf(fox).subdivided(0);
  PosedMesh pose;
  poseAt(fox, mesh, findAnimation(fox, "Survey"), 0.5f, pose);
  const std::vector<uint8_t> front =
      frontFacingVertices(pose.positions, mesh.triangles, glm::vec3(1, -0.2f, 0.3f));
  size_t shaded = 0;
  for (const uint8_t f : front) shaded += f;
  EXPECT_GT(shaded, pose.positions.size() / 4);
  EXPECT_LT(shaded, pose.positions.size());
  const SelfShadowing shadows;
  std::vector<float> all, some, kept;
  std::vector<uint64_t> allMasks, keptMasks;
  SelfShadowStats stats;
  shadows.diffuse(pose.positions, pose.normals, mesh.triangles, all, {.masks = &allMasks});
  shadows.diffuse(pose.positions, pose.normals, mesh.triangles, some,
                  {.stats = &stats, .only = &front});
  EXPECT_EQ(stats.vertices, shaded);
  const size_t terms = size_t(shadows.terms()), words = size_t(shadows.maskWords());
  for (size_t v = 0; v < front.size(); ++v)
    for (size_t i = 0; i < terms; ++i)
      ASSERT_EQ(some[v * terms + i], front[v] ? all[v * terms + i] : 0.0f) << "vertex " << v;
  // Vectors that already hold a whole mesh keep the other vertices' entries.
  kept.assign(all.size(), -7.0f);
  keptMasks.assign(allMasks.size(), 0x5a5a5a5a5a5a5a5aull);
  shadows.diffuse(pose.positions, pose.normals, mesh.triangles, kept,
                  {.only = &front, .masks = &keptMasks});
  for (size_t v = 0; v < front.size(); ++v) {
    for (size_t i = 0; i < terms; ++i)
      ASSERT_EQ(kept[v * terms + i], front[v] ? all[v * terms + i] : -7.0f) << "vertex " << v;
    for (size_t w = 0; w < words; ++w)
      ASSERT_EQ(keptMasks[v * words + w],
                front[v] ? allMasks[v * words + w] : 0x5a5a5a5a5a5a5a5aull)
          << "vertex " << v;
  }
}

// A closed box seen along -z: the vertices of its +z face (and only they,
// with the faces seen edge-on left out) face the viewer.
TEST(SelfShadow, FrontFacingVerticesOfABoxAreItsNearFacesCorners) {
  std::vector<glm::vec3> p;
  for (int i = 0; i < 8; ++i) p.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  // Outward-wound faces of the unit cube (two triangles each).
  const std::vector<glm::uvec3> t = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6},   // z = 0, z = 1
                                     {0, 1, 4}, {1, 5, 4}, {2, 6, 3}, {3, 6, 7},   // y = 0, y = 1
                                     {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};  // x = 0, x = 1
  const std::vector<uint8_t> front = frontFacingVertices(p, t, glm::vec3(0, 0, -1));
  for (int i = 0; i < 8; ++i) EXPECT_EQ(front[size_t(i)], (i >> 2) & 1) << "corner " << i;
}

}  // namespace
}  // namespace vistream
