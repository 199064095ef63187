#include "common/avatar/skinning.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <set>

#include "common/scene/scene_loader.h"

namespace vistream {
namespace {

using Path = AnimationChannel::Path;
using Interpolation = AnimationChannel::Interpolation;

constexpr float kHalfPi = 1.5707963f;

AnimationChannel channel(Path path, Interpolation how, std::vector<float> times,
                         std::vector<glm::vec4> values) {
  AnimationChannel c;
  c.node = 0;
  c.path = path;
  c.interpolation = how;
  c.times = std::move(times);
  c.values = std::move(values);
  return c;
}

// A rotation by `angle` about unit `axis` as glTF stores it (x, y, z, w).
glm::vec4 rotationAbout(const glm::vec3& axis, float angle) {
  return {axis * std::sin(angle / 2), std::cos(angle / 2)};
}

void expectNear(const glm::vec4& got, const glm::vec4& want, float eps = 1e-5f) {
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(got[k], want[k], eps) << "component " << k;
}

TEST(SampleChannel, LinearTranslationIsHalfwayAtTheMiddleAndHoldsOutsideTheKeys) {
  const auto c = channel(Path::Translation, Interpolation::Linear, {1.0f, 3.0f},
                         {{0, 0, 0, 0}, {4, -2, 8, 0}});
  expectNear(sampleChannel(c, 2.0f), {2, -1, 4, 0});
  expectNear(sampleChannel(c, 2.5f), {3, -1.5f, 6, 0});
  expectNear(sampleChannel(c, 0.0f), {0, 0, 0, 0});
  expectNear(sampleChannel(c, 9.0f), {4, -2, 8, 0});
  expectNear(sampleChannel(c, NAN), {0, 0, 0, 0});
}

TEST(SampleChannel, StepHoldsTheEarlierKeyUntilTheNext) {
  const auto c = channel(Path::Scale, Interpolation::Step, {0.0f, 1.0f, 2.0f},
                         {{1, 1, 1, 0}, {2, 2, 2, 0}, {3, 3, 3, 0}});
  expectNear(sampleChannel(c, 0.99f), {1, 1, 1, 0});
  expectNear(sampleChannel(c, 1.0f), {2, 2, 2, 0});
  expectNear(sampleChannel(c, 1.5f), {2, 2, 2, 0});
}

// Keys at t = 0 and 2 with values and tangents of p(t) = t^3 (p' = 3t^2): a
// cubic Hermite spline reproduces a cubic exactly.
TEST(SampleChannel, CubicSplineReproducesACubicBetweenItsKeys) {
  const auto c = channel(Path::Translation, Interpolation::CubicSpline, {0.0f, 2.0f},
                         {// key 0: in-tangent, value, out-tangent
                          {0, 0, 0, 0},
                          {0, 0, 0, 0},
                          {0, 0, 0, 0},
                          // key 1
                          {12, 0, 0, 0},
                          {8, 0, 0, 0},
                          {5, 0, 0, 0}});
  for (const float t : {0.25f, 0.5f, 1.0f, 1.5f, 1.9f})
    EXPECT_NEAR(sampleChannel(c, t).x, t * t * t, 1e-4f) << "t " << t;
}

TEST(SampleChannel, LinearRotationSlerpsAlongTheShorterArc) {
  const glm::vec3 y(0, 1, 0);
  const glm::vec4 quarter = rotationAbout(y, kHalfPi);
  const auto c =
      channel(Path::Rotation, Interpolation::Linear, {0.0f, 1.0f}, {{0, 0, 0, 1}, quarter});
  expectNear(sampleChannel(c, 0.5f), rotationAbout(y, kHalfPi / 2));
  expectNear(sampleChannel(c, 0.25f), rotationAbout(y, kHalfPi / 4));
  // The same rotation written as -q: still the short way round.
  const auto flipped =
      channel(Path::Rotation, Interpolation::Linear, {0.0f, 1.0f}, {{0, 0, 0, 1}, -quarter});
  expectNear(sampleChannel(flipped, 0.5f), rotationAbout(y, kHalfPi / 2));
}

// A parent turned a quarter about +y, its child one metre along the parent's
// +x: the child's origin lies at (0, 0, -1).
TEST(GlobalNodeMatrices, AChildFollowsItsAnimatedParentAndClipTimeWraps) {
  Scene s;
  s.nodes.resize(2);
  s.nodes[1].parent = 0;
  s.nodes[1].translation = {1, 0, 0};
  Animation a;
  a.duration = 1.0f;
  a.channels.push_back(channel(Path::Rotation, Interpolation::Linear, {0.0f, 1.0f},
                               {{0, 0, 0, 1}, rotationAbout({0, 1, 0}, 2 * kHalfPi)}));
  const auto at = [&](float t) {
    return glm::vec3(globalNodeMatrices(s, &a, t)[1] * glm::vec4(0, 0, 0, 1));
  };
  const glm::vec3 p = at(0.5f);
  EXPECT_NEAR(p.x, 0.0f, 1e-5f);
  EXPECT_NEAR(p.z, -1.0f, 1e-5f);
  const glm::vec3 wrapped = at(3.5f), negative = at(-0.5f);
  EXPECT_NEAR(glm::distance(wrapped, p), 0.0f, 1e-5f);
  EXPECT_NEAR(glm::distance(negative, p), 0.0f, 1e-5f);
  // The rest pose ignores the animation.
  EXPECT_NEAR(
      glm::distance(glm::vec3(globalNodeMatrices(s, nullptr, 0.5f)[1][3]), glm::vec3(1, 0, 0)),
      0.0f, 1e-6f);
}

// Two joints, the second moved 2 m along x; a vertex weighted (2, 2) on both
// (normalized to a half each) moves 1 m, one on the first alone stays.
TEST(PoseMesh, BlendsJointMatricesByNormalizedWeights) {
  Scene s;
  s.name = "rig";
  s.nodes.resize(2);
  s.skins.push_back(Skin{"skin", {0, 1}, {}});
  Object o;
  o.name = "body";
  o.skin = 0;
  o.dynamic = true;
  o.mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  o.mesh.triangles = {{0, 1, 2}};
  o.mesh.faceIds = {0};
  o.mesh.joints = {{0, 1, 0, 0}, {0, 0, 0, 0}, {0, 1, 0, 0}};
  o.mesh.weights = {{2, 2, 0, 0}, {1, 0, 0, 0}, {0, 0, 0, 0}};  // the last unweighted
  s.objects.push_back(o);
  const SkinnedMesh mesh = SkinnedMesh::firstOf(s);
  EXPECT_EQ(mesh.weights[0], glm::vec4(0.5f, 0.5f, 0, 0));
  EXPECT_EQ(mesh.weights[2], glm::vec4(1, 0, 0, 0));
  const std::vector<glm::mat4> joints = {glm::mat4(1.0f),
                                         glm::translate(glm::mat4(1.0f), glm::vec3(2, 0, 0))};
  PosedMesh pose;
  poseMesh(mesh, joints, pose);
  EXPECT_EQ(pose.positions[0], glm::vec3(1, 0, 0));
  EXPECT_EQ(pose.positions[1], glm::vec3(1, 0, 0));
  EXPECT_EQ(pose.positions[2], glm::vec3(0, 1, 0));
}

TEST(SkinnedMesh, RejectsASceneWithoutASkinAndAJointBeyondTheSkin) {
  Scene s;
  s.name = "plain";
  EXPECT_THROW(SkinnedMesh::firstOf(s), InputError);
  s.nodes.resize(1);
  s.skins.push_back(Skin{"skin", {0}, {}});
  Object o;
  o.skin = 0;
  o.mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  o.mesh.triangles = {{0, 1, 2}};
  o.mesh.joints = {{0, 0, 0, 0}, {3, 0, 0, 0}, {0, 0, 0, 0}};
  o.mesh.weights = {{1, 0, 0, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}};
  s.objects.push_back(o);
  EXPECT_THROW(SkinnedMesh::firstOf(s), InputError);
}

// The Fox walks: its vertices move, yet any two bound wholly to one joint
// keep their distance (that joint moves them rigidly), at every sampled time.
TEST(Fox, WalkingMovesItsVerticesAndKeepsRigidPartsRigid) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  for (const char* clip : {"Survey", "Walk", "Run"}) EXPECT_TRUE(findAnimation(fox, clip)) << clip;
  const Animation* walk = findAnimation(fox, "walk");
  ASSERT_TRUE(walk);
  const SkinnedMesh mesh = SkinnedMesh::firstOf(fox);
  EXPECT_EQ(mesh.triangles.size(), 576u);
  const Skin& skin = fox.skins.at(size_t(mesh.skin));
  EXPECT_EQ(skin.joints.size(), 24u);
  // Vertices bound to one joint, grouped by it.
  std::vector<std::vector<size_t>> rigid(skin.joints.size());
  for (size_t v = 0; v < mesh.positions.size(); ++v)
    for (int k = 0; k < 4; ++k)
      if (mesh.weights[v][k] > 0.9999f) rigid[mesh.joints[v][k]].push_back(v);
  Box3f bind;
  for (const glm::vec3& p : mesh.positions) bind.extend(p);
  const float size = glm::length(bind.hi - bind.lo);
  PosedMesh first, pose;
  poseAt(fox, mesh, walk, 0.0f, first);
  float moved = 0.0f;
  size_t pairs = 0;
  for (const float t : {0.1f, 0.35f, 0.6f}) {
    poseAt(fox, mesh, walk, t, pose);
    for (size_t v = 0; v < mesh.positions.size(); ++v)
      moved = std::max(moved, glm::distance(pose.positions[v], first.positions[v]));
    for (const auto& group : rigid)
      for (size_t i = 1; i < group.size(); ++i) {
        const size_t a = group[0], b = group[i];
        ASSERT_NEAR(glm::distance(pose.positions[a], pose.positions[b]),
                    glm::distance(first.positions[a], first.positions[b]), 1e-4f * size);
        ++pairs;
      }
  }
  EXPECT_GT(pairs, 100u);
  EXPECT_GT(moved, 0.01f * size);  // the legs swing
  EXPECT_LT(moved, 0.5f * size);   // and the fox stays in one piece
}

// Subdividing the Fox: welding leaves fewer vertices than the file's, each
// pass adds one vertex per edge and quadruples the triangles, and a
// midpoint lies halfway between its edge's ends in every pose.
TEST(SkinnedMesh, SubdivisionAddsAVertexPerEdgeAndMidpointsStayHalfway) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh mesh = SkinnedMesh::firstOf(fox);
  const SkinnedMesh welded = mesh.subdivided(0);
  EXPECT_LT(welded.positions.size(), mesh.positions.size());
  EXPECT_EQ(welded.triangles.size(), mesh.triangles.size());
  std::set<std::pair<uint32_t, uint32_t>> edges;
  for (const glm::uvec3& t : welded.triangles)
    for (int k = 0; k < 3; ++k) edges.insert(std::minmax(t[k], t[(k + 1) % 3]));
  const SkinnedMesh finer = mesh.subdivided(1);
  EXPECT_EQ(finer.positions.size(), welded.positions.size() + edges.size());
  EXPECT_EQ(finer.triangles.size(), 4 * mesh.triangles.size());
  for (const glm::vec4& w : finer.weights) EXPECT_NEAR(w.x + w.y + w.z + w.w, 1.0f, 1e-5f);
  // The first fine triangle is (a, ab, ca) of the first coarse one.
  const glm::uvec3 coarse = welded.triangles[0], fine = finer.triangles[0];
  EXPECT_EQ(fine.x, coarse.x);
  PosedMesh p;
  poseAt(fox, finer, findAnimation(fox, "Run"), 0.2f, p);
  // Linear blend skinning of a blended skin at the midpoint is not the
  // midpoint of the skinned ends in general, but stays close to it.
  const glm::vec3 mid = 0.5f * (p.positions[coarse.x] + p.positions[coarse.y]);
  Box3f bounds;
  for (const glm::vec3& q : p.positions) bounds.extend(q);
  EXPECT_LT(glm::distance(p.positions[fine.y], mid), 0.02f * glm::length(bounds.hi - bounds.lo));
}

// Splitting around centroids: each pass adds one vertex a triangle and
// triples the triangles; triangle t's children are 3t..3t+2 and share its
// corners; a centroid's skin sums to one and it stays near its parent's
// posed centroid. Three passes take the Fox near the paper's Hand.
TEST(SkinnedMesh, CentroidSplitsTripleTheTrianglesAndKeepTheirParentsCorners) {
  const Scene fox = loadScene(std::filesystem::path(VISTREAM_SHARED_DIR) / "data" / "Fox.glb");
  const SkinnedMesh mesh = SkinnedMesh::firstOf(fox);
  const SkinnedMesh welded = mesh.subdivided(0);
  const SkinnedMesh once = mesh.subdivided(1, SkinnedMesh::Split::AtCentroids);
  EXPECT_EQ(once.triangles.size(), 3 * welded.triangles.size());
  EXPECT_EQ(once.positions.size(), welded.positions.size() + welded.triangles.size());
  for (size_t t = 0; t < welded.triangles.size(); ++t) {
    const glm::uvec3 parent = welded.triangles[t];
    const uint32_t centroid = uint32_t(welded.positions.size() + t);
    for (size_t k = 0; k < 3; ++k) {
      const glm::uvec3 child = once.triangles[3 * t + k];
      EXPECT_EQ(child.z, centroid);
      EXPECT_EQ(child.x, parent[int(k)]);
      EXPECT_EQ(child.y, parent[int((k + 1) % 3)]);
    }
  }
  for (const glm::vec4& w : once.weights) EXPECT_NEAR(w.x + w.y + w.z + w.w, 1.0f, 1e-5f);
  PosedMesh p;
  poseAt(fox, once, findAnimation(fox, "Walk"), 0.4f, p);
  // As with midpoints: skinning a blended skin is not the centroid of the
  // skinned corners in general, but stays close to it.
  Box3f bounds;
  for (const glm::vec3& q : p.positions) bounds.extend(q);
  for (size_t t = 0; t < welded.triangles.size(); ++t) {
    glm::vec3 mean(0.0f);
    for (int k = 0; k < 3; ++k) mean += p.positions[welded.triangles[t][k]] / 3.0f;
    EXPECT_LT(glm::distance(p.positions[welded.positions.size() + t], mean),
              0.02f * glm::length(bounds.hi - bounds.lo))
        << "triangle " << t;
  }
  const SkinnedMesh hand = mesh.subdivided(3, SkinnedMesh::Split::AtCentroids);
  EXPECT_EQ(hand.triangles.size(), 27 * welded.triangles.size());
  EXPECT_GT(hand.positions.size(), 7000u);
  EXPECT_LT(hand.positions.size(), 9000u);
}

}  // namespace
}  // namespace vistream
