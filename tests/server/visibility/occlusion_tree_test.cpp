// Occlusion tree and occluder selection. Each fixed case states the shadow it
// expects: a quad in the plane z = zq (viewpoint at z = 0 looking down -z)
// with half-width w shadows the points behind it with |x|, |y| < w * |z| / |zq|.
// The randomized test checks every answer against an independent oracle: a
// parametric segment-versus-polygon crossing test on sampled box points.
#include "server/visibility/occlusion_tree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>
#include <vector>

namespace vistream {
namespace {

constexpr auto kInvisible = NodeVisibility::Invisible;
constexpr auto kPartial = NodeVisibility::PartiallyVisible;
constexpr auto kVisible = NodeVisibility::Visible;

// An axis-aligned quad in the plane z = z, wound counter-clockwise seen from +z.
OccluderPolygon quadZ(double x0, double x1, double y0, double y1, double z) {
  return {{{x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z}}};
}

Box3f box(float x0, float x1, float y0, float y1, float z0, float z1) {
  return Box3f({x0, y0, z0}, {x1, y1, z1});
}

OccluderPolygon translated(OccluderPolygon p, const glm::dvec3& offset) {
  for (glm::dvec3& v : p.vertices) v += offset;
  return p;
}

Box3f translated(const Box3f& b, const glm::vec3& offset) {
  return Box3f(b.lo + offset, b.hi + offset);
}

// The oracle: does the segment from `from` to `to` cross the polygon's
// interior? Intersects the segment's line with the polygon's plane
// parametrically and tests the hit point against every edge, a formulation
// that shares nothing with the tree's cones of planes.
bool segmentCrossesPolygon(const glm::dvec3& from, const glm::dvec3& to,
                           const OccluderPolygon& polygon) {
  const std::vector<glm::dvec3>& v = polygon.vertices;
  const glm::dvec3 n = glm::cross(v[1] - v[0], v[2] - v[0]);
  const double sFrom = glm::dot(n, from - v[0]);
  const double sTo = glm::dot(n, to - v[0]);
  if (!(sFrom * sTo < 0.0)) return false;  // both ends on one side, or an end on the plane
  const glm::dvec3 hit = from + (sFrom / (sFrom - sTo)) * (to - from);
  for (size_t i = 0; i < v.size(); ++i) {
    const glm::dvec3& a = v[i];
    const glm::dvec3& b = v[(i + 1) % v.size()];
    if (!(glm::dot(glm::cross(b - a, hit - a), n) > 0.0)) return false;
  }
  return true;
}

bool shadowedByAny(const glm::dvec3& viewpoint, const glm::dvec3& p,
                   const std::vector<OccluderPolygon>& occluders) {
  for (const OccluderPolygon& o : occluders)
    if (segmentCrossesPolygon(viewpoint, p, o)) return true;
  return false;
}

NodeVisibility classifyWith(const glm::dvec3& viewpoint,
                            const std::vector<OccluderPolygon>& occluders, const Box3f& b) {
  return OcclusionTree(viewpoint, occluders).classify(b);
}

// The single-quad scene: a 2 m square at z = -4 seen from the origin. Its
// shadow is z < -4 with |x|, |y| < |z| / 4.
const std::vector<OccluderPolygon> kSingleQuad = {quadZ(-1, 1, -1, 1, -4)};

TEST(OcclusionTree, QuadInFrontHidesTheBoxBehindIt) {
  // At z = -6 the shadow reaches |x|, |y| < 1.5, so the box (|x|, |y| <= 0.5) is deep inside.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(-0.5f, 0.5f, -0.5f, 0.5f, -9, -6)),
            kInvisible);
}

TEST(OcclusionTree, BoxBesideTheShadowIsVisible) {
  // At z = -9 the shadow reaches only |x| < 2.25; the box starts at x = 3.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(3, 4, -0.5f, 0.5f, -9, -6)), kVisible);
}

TEST(OcclusionTree, BoxHalfBehindTheQuadIsPartiallyVisible) {
  // At z = -6, x in [1, 1.5) is shadowed and x in (1.75, 3] is not at any depth of the box.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(1, 3, -0.5f, 0.5f, -7, -6)), kPartial);
}

TEST(OcclusionTree, BoxBetweenTheViewpointAndTheQuadIsVisible) {
  // Nothing in front of the quad's plane is shadowed.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(-0.5f, 0.5f, -0.5f, 0.5f, -3, -1)), kVisible);
}

TEST(OcclusionTree, BoxPiercingTheQuadIsPartiallyVisible) {
  // The half in front of z = -4 is seen, the half behind is not.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(-0.5f, 0.5f, -0.5f, 0.5f, -5, -3)), kPartial);
}

TEST(OcclusionTree, TwoQuadsSharingAnEdgeHideABoxBehindTheSeam) {
  // Quads x in [-2, 0] and [0, 2] at z = -4. The box spans x in [-0.5, 0.5]
  // behind the seam x = 0: each quad shadows only its own side of the seam's
  // plane, so only their fused shadow covers the whole box.
  const OccluderPolygon left = quadZ(-2, 0, -1, 1, -4), right = quadZ(0, 2, -1, 1, -4);
  const Box3f behindSeam = box(-0.5f, 0.5f, -0.5f, 0.5f, -7, -6);
  EXPECT_EQ(classifyWith({0, 0, 0}, {left, right}, behindSeam), kInvisible);
  EXPECT_EQ(classifyWith({0, 0, 0}, {right, left}, behindSeam), kInvisible);
  EXPECT_EQ(classifyWith({0, 0, 0}, {left}, behindSeam), kPartial);
  EXPECT_EQ(classifyWith({0, 0, 0}, {right}, behindSeam), kPartial);
}

TEST(OcclusionTree, FusesAGridOfQuadsIntoOneWall) {
  // A 4 x 4 grid of 1 m tiles at z = -2 forms the wall |x|, |y| < 2; behind
  // it at z = -4 the fused shadow reaches |x|, |y| < 4. The box sits behind
  // the corner where four tiles meet.
  std::vector<OccluderPolygon> tiles;
  for (int i = -2; i < 2; ++i)
    for (int j = -2; j < 2; ++j) tiles.push_back(quadZ(i, i + 1, j, j + 1, -2));
  const OcclusionTree tree({0, 0, 0}, tiles);
  EXPECT_EQ(tree.occluderCount(), 16u);
  EXPECT_EQ(tree.classify(box(-3, 3, -3, 3, -5, -4)), kInvisible);
  EXPECT_EQ(tree.classify(box(-5, 5, -1, 1, -5, -4)), kPartial);
}

TEST(OcclusionTree, OccluderSeenEdgeOnCastsNoShadow) {
  // The viewpoint lies in the floor's plane y = 0: every segment from it to a
  // point below the floor leaves the plane at the viewpoint itself, so the
  // floor hides nothing.
  const std::vector<OccluderPolygon> floor = {
      {{{-5, 0, -10}, {5, 0, -10}, {5, 0, -1}, {-5, 0, -1}}}};
  const OcclusionTree tree({0, 0, 0}, floor);
  EXPECT_EQ(tree.occluderCount(), 0u);
  EXPECT_EQ(tree.classify(box(-1, 1, -3, -1, -6, -4)), kVisible);
  EXPECT_FALSE(tree.inShadow({0, -2, -5}));
}

TEST(OcclusionTree, ViewpointOnAnOccludersEdgeIgnoresOnlyThatOccluder) {
  // The viewpoint (1, 0, -4) lies on the edge x = 1 of the quad at z = -4,
  // hence in its plane: that quad hides nothing. The quad x in [0, 2] at
  // z = -8 still casts its shadow: 4 m in front of the viewpoint, so 8 m
  // behind the viewpoint's plane it reaches |x - 1| < 2, |y| < 2.
  const glm::dvec3 viewpoint(1, 0, -4);
  const std::vector<OccluderPolygon> occluders = {quadZ(-1, 1, -1, 1, -4), quadZ(0, 2, -1, 1, -8)};
  const OcclusionTree tree(viewpoint, occluders);
  EXPECT_EQ(tree.occluderCount(), 1u);
  EXPECT_EQ(tree.classify(box(0.75f, 1.25f, -0.25f, 0.25f, -13, -12)), kInvisible);
  EXPECT_EQ(tree.classify(box(-1, 0.5f, -0.5f, 0.5f, -4.5f, -4.25f)), kVisible);
}

TEST(OcclusionTree, BoxTouchingTheShadowBoundaryFromInsideIsNotInvisible) {
  // The shadow plane of the edge x = 1 is x = |z| / 4. The box x in [1, 2],
  // z in [-9, -8] lies in the closed shadow but its edge x = 2, z = -8 is on
  // that plane: segments to it graze the quad's edge, so they are not blocked.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(1, 2, -0.5f, 0.5f, -9, -8)), kPartial);
  // Pulled 0.1 m inside the boundary, the same box is hidden.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(1, 1.9f, -0.5f, 0.5f, -9, -8)), kInvisible);
}

TEST(OcclusionTree, BoxTouchingTheShadowBoundaryFromOutsideIsPartiallyVisible) {
  // The box x in [2, 3], z in [-8, -7] touches the shadow plane x = |z| / 4
  // only along its edge x = 2, z = -8 and holds no shadowed point. The
  // contract treats a box within the rounding tolerance of a plane as
  // straddling it, so the conservative answer is PartiallyVisible, never Invisible.
  EXPECT_EQ(classifyWith({0, 0, 0}, kSingleQuad, box(2, 3, -0.5f, 0.5f, -8, -7)), kPartial);
}

TEST(OcclusionTree, ClosedRoomHidesEverythingOutsideAndNothingInside) {
  // Six quads close the cube |x|, |y|, |z| <= 2 around the viewpoint: every
  // point outside it is hidden, every point inside it is seen.
  const std::vector<OccluderPolygon> room = {quadZ(-2, 2, -2, 2, -2),
                                             quadZ(-2, 2, -2, 2, 2),
                                             {{{-2, -2, -2}, {-2, 2, -2}, {-2, 2, 2}, {-2, -2, 2}}},
                                             {{{2, -2, -2}, {2, 2, -2}, {2, 2, 2}, {2, -2, 2}}},
                                             {{{-2, -2, -2}, {2, -2, -2}, {2, -2, 2}, {-2, -2, 2}}},
                                             {{{-2, 2, -2}, {2, 2, -2}, {2, 2, 2}, {-2, 2, 2}}}};
  const OcclusionTree tree({0, 0, 0}, room);
  EXPECT_EQ(tree.occluderCount(), 6u);
  EXPECT_EQ(tree.classify(box(5, 6, -1, 1, -1, 1)), kInvisible);
  EXPECT_EQ(tree.classify(box(3, 4, 3, 4, 3, 4)), kInvisible);   // behind a corner of the room
  EXPECT_EQ(tree.classify(box(-1, 1, -1, 1, -1, 1)), kVisible);  // contains the viewpoint
  EXPECT_EQ(tree.classify(box(0, 1, 0, 1, 0, 1)), kVisible);     // touches it with a corner
  EXPECT_EQ(tree.classify(box(-3, 3, -3, 3, -3, 3)), kPartial);  // contains the viewpoint and walls
  EXPECT_EQ(tree.classify(box(0, 5, 0, 5, 0, 5)), kPartial);     // touches it and reaches outside
}

TEST(OcclusionTree, BoxContainingTheViewpointIsNeverInvisible) {
  // A quad 1 mm in front of the viewpoint hides almost the whole half-space
  // z < -0.001, but a box holding the viewpoint is always partly seen.
  const std::vector<OccluderPolygon> visor = {quadZ(-10, 10, -10, 10, -0.001)};
  const OcclusionTree tree({0, 0, 0}, visor);
  EXPECT_EQ(tree.classify(box(-0.5f, 0.5f, -0.5f, 0.5f, -5, 0)), kPartial);
  EXPECT_EQ(tree.classify(box(-0.5f, 0.5f, -0.5f, 0.5f, -5, -1)), kInvisible);
  EXPECT_FALSE(tree.inShadow({0, 0, 0}));
}

TEST(OcclusionTree, IgnoresDegenerateOccluders) {
  const std::vector<OccluderPolygon> degenerate = {
      {},                                                    // no vertices
      {{{0, 0, -4}, {1, 0, -4}}},                            // two vertices
      {{{-1, -1, -4}, {0, 0, -4}, {1, 1, -4}}},              // collinear
      {{{0, 0, -4}, {0, 0, -4}, {0, 0, -4}}},                // one point thrice
      {{{-1, 0, -4}, {1, 0, -4}, {1, 0, -4}, {-1, 0, -4}}},  // zero-width quad
  };
  const OcclusionTree tree({0, 0, 0}, degenerate);
  EXPECT_EQ(tree.occluderCount(), 0u);
  EXPECT_EQ(tree.nodeCount(), 1u);
  EXPECT_EQ(tree.classify(box(-0.5f, 0.5f, -0.5f, 0.5f, -9, -6)), kVisible);

  // A quad listing a vertex twice is still a quad.
  std::vector<OccluderPolygon> withRepeat = degenerate;
  withRepeat.push_back({{{-1, -1, -4}, {1, -1, -4}, {1, -1, -4}, {1, 1, -4}, {-1, 1, -4}}});
  const OcclusionTree repeated({0, 0, 0}, withRepeat);
  EXPECT_EQ(repeated.occluderCount(), 1u);
  EXPECT_EQ(repeated.classify(box(-0.5f, 0.5f, -0.5f, 0.5f, -9, -6)), kInvisible);
}

TEST(OcclusionTree, WindingDoesNotMatter) {
  OccluderPolygon reversed = kSingleQuad[0];
  std::reverse(reversed.vertices.begin(), reversed.vertices.end());
  const OcclusionTree a({0, 0, 0}, kSingleQuad), b({0, 0, 0}, std::vector{reversed});
  EXPECT_EQ(a.nodeCount(), b.nodeCount());
  for (const Box3f& q : {box(-0.5f, 0.5f, -0.5f, 0.5f, -9, -6), box(1, 3, -0.5f, 0.5f, -7, -6),
                         box(3, 4, -0.5f, 0.5f, -9, -6)})
    EXPECT_EQ(a.classify(q), b.classify(q));
}

TEST(OcclusionTree, FarFromTheOriginGivesTheSameAnswers) {
  // Two quads sharing an edge and a third further right, near the origin and
  // translated by ~1e4 m. Offsets and box coordinates are multiples of 1/4,
  // exact in float at 1e4. The boxes: behind the seam; partly behind the
  // right quad; touching its shadow boundary x = |z| / 2 along x = 3, z = -6;
  // in front of both; and two deep in the right quad's shadow.
  const glm::dvec3 offset(12288, 36, -8192);
  const glm::vec3 offsetf(offset);
  const std::vector<OccluderPolygon> near = {quadZ(-2, 0, -1, 1, -4), quadZ(0, 2, -1, 1, -4),
                                             quadZ(3, 5, -1, 1, -6)};
  std::vector<OccluderPolygon> far;
  for (const OccluderPolygon& p : near) far.push_back(translated(p, offset));
  const std::vector<Box3f> boxes = {
      box(-0.5f, 0.5f, -0.5f, 0.5f, -7, -6), box(3, 4, -0.5f, 0.5f, -9, -6),
      box(1, 3, -0.5f, 0.5f, -7, -6),        box(-0.5f, 0.5f, -0.5f, 0.5f, -3, -1),
      box(1, 2, -0.5f, 0.5f, -9, -8),        box(2.5f, 3, -0.25f, 0.25f, -9, -8)};
  const std::array<NodeVisibility, 6> expected = {kInvisible, kPartial,   kPartial,
                                                  kVisible,   kInvisible, kInvisible};
  const OcclusionTree nearTree({0, 0, 0}, near), farTree(offset, far);
  EXPECT_EQ(nearTree.nodeCount(), farTree.nodeCount());
  for (size_t i = 0; i < boxes.size(); ++i) {
    EXPECT_EQ(nearTree.classify(boxes[i]), expected[i]) << "box " << i;
    EXPECT_EQ(farTree.classify(translated(boxes[i], offsetf)), expected[i]) << "box " << i;
  }
}

TEST(OcclusionTree, WithoutOccludersEverythingIsVisible) {
  const OcclusionTree tree({1, 2, 3}, std::span<const OccluderPolygon>());
  EXPECT_EQ(tree.nodeCount(), 1u);
  EXPECT_EQ(tree.classify(box(-100, 100, -100, 100, -100, 100)), kVisible);
  EXPECT_EQ(tree.classify(Box3f()), kVisible);  // empty box
}

TEST(OcclusionTree, OccluderHiddenByAnEarlierOneAddsNoNodes) {
  // The small quad at z = -8 lies inside the big quad's shadow: inserting it
  // reaches only 'in' leaves.
  const OccluderPolygon big = quadZ(-2, 2, -2, 2, -4), hidden = quadZ(-1, 1, -1, 1, -8);
  EXPECT_EQ(OcclusionTree({0, 0, 0}, std::vector{big, hidden}).nodeCount(),
            OcclusionTree({0, 0, 0}, std::vector{big}).nodeCount());
  EXPECT_EQ(OcclusionTree({0, 0, 0}, std::vector{big, hidden}).occluderCount(), 2u);
}

TEST(OcclusionTree, ConstrainedSearchVisitsOnlyPartOfTheTree) {
  // Eight quads in a row; a box behind the first one never enters the
  // subtrees of the others.
  std::vector<OccluderPolygon> row;
  for (int i = 0; i < 8; ++i) row.push_back(quadZ(3 * i, 3 * i + 2, -1, 1, -4));
  const OcclusionTree tree({0, 0, 0}, row);
  uint64_t visited = 0;
  EXPECT_EQ(tree.classify(box(0.5f, 1.5f, -0.25f, 0.25f, -7, -6), &visited), kInvisible);
  EXPECT_GT(visited, 0u);
  EXPECT_LT(visited, tree.nodeCount() / 2);
  uint64_t total = visited;
  tree.classify(box(0.5f, 1.5f, -0.25f, 0.25f, -7, -6), &total);
  EXPECT_EQ(total, 2 * visited);  // counts accumulate
}

// Three uniform numbers in [0, 1), drawn in order (the order in which
// function arguments are evaluated differs between compilers).
glm::dvec3 uniform3(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double x = u(rng);
  const double y = u(rng);
  return {x, y, u(rng)};
}

// A random convex quad roughly facing the viewpoint: four points at sorted
// random angles on an ellipse in a plane tilted up to ~45 degrees away from
// facing the viewpoint.
// A random unit direction within ~50 degrees (0.9 rad) of -z.
glm::dvec3 randomDirectionNearMinusZ(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double azimuth = 2.0 * std::numbers::pi * u(rng), polar = 0.9 * u(rng);
  return {std::sin(polar) * std::cos(azimuth), std::sin(polar) * std::sin(azimuth),
          -std::cos(polar)};
}

OccluderPolygon randomQuad(std::mt19937& rng, const glm::dvec3& viewpoint) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // Directions near -z, so that occluders overlap.
  const glm::dvec3 dir = randomDirectionNearMinusZ(rng);
  const glm::dvec3 centre = viewpoint + (3.0 + 5.0 * u(rng)) * dir;
  glm::dvec3 normal = glm::normalize(-dir + 0.8 * (uniform3(rng) - 0.5));
  const glm::dvec3 e1 = glm::normalize(glm::cross(normal, glm::dvec3(0.3, 1, 0.2)));
  const glm::dvec3 e2 = glm::cross(normal, e1);
  const double a = 0.8 + 2.2 * u(rng), b = 0.8 + 2.2 * u(rng);
  std::array<double, 4> angles;
  for (double& t : angles) t = 2.0 * std::numbers::pi * u(rng);
  std::sort(angles.begin(), angles.end());
  OccluderPolygon q;
  for (double t : angles)
    q.vertices.push_back(centre + a * std::cos(t) * e1 + b * std::sin(t) * e2);
  return q;
}

// A random viewpoint at eye height (y = 1.7) over x, z in [-5, 5].
glm::dvec3 randomViewpoint(std::mt19937& rng) {
  const glm::dvec3 spot = uniform3(rng);
  return {10.0 * spot.x - 5.0, 1.7, 10.0 * spot.z - 5.0};
}

// A random box 2 to 20 m from the viewpoint in a direction near -z (among
// randomQuad's occluders), with half-sizes from 0.05 to 1.25 m.
Box3f randomQueryBox(std::mt19937& rng, const glm::dvec3& viewpoint) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const glm::dvec3 dir = randomDirectionNearMinusZ(rng);
  const glm::dvec3 centre = viewpoint + (2.0 + 18.0 * u(rng)) * dir;
  const glm::dvec3 half = glm::dvec3(0.05) + 1.2 * uniform3(rng);
  return Box3f(glm::vec3(centre - half), glm::vec3(centre + half));
}

TEST(OcclusionTree, AgreesWithTheSegmentCrossingOracleOnRandomScenes) {
  std::mt19937 rng(20010523);
  std::array<size_t, 3> counts{};
  size_t pointsChecked = 0, pointDisagreements = 0;
  for (int scene = 0; scene < 10; ++scene) {
    const glm::dvec3 viewpoint = randomViewpoint(rng);
    std::vector<OccluderPolygon> occluders;
    for (int i = 0; i < 16; ++i) occluders.push_back(randomQuad(rng, viewpoint));
    const OcclusionTree tree(viewpoint, occluders);
    ASSERT_EQ(tree.occluderCount(), occluders.size());

    for (int b = 0; b < 150; ++b) {
      const Box3f query = randomQueryBox(rng, viewpoint);
      const NodeVisibility v = tree.classify(query);
      ++counts[size_t(v)];

      // Corners, face centres and the centre, then random interior and surface points.
      const glm::dvec3 lo(query.lo), hi(query.hi);
      std::vector<glm::dvec3> samples;
      for (int c = 0; c < 27; ++c) {
        const glm::dvec3 t(c % 3 * 0.5, c / 3 % 3 * 0.5, c / 9 * 0.5);
        samples.push_back(lo + t * (hi - lo));
      }
      for (int i = 0; i < 120; ++i) {
        glm::dvec3 t = uniform3(rng);
        if (i % 2 == 0) t[i / 2 % 3] = double(i / 6 % 2);  // on a face
        samples.push_back(lo + t * (hi - lo));
      }
      for (const glm::dvec3& p : samples) {
        const bool shadowed = shadowedByAny(viewpoint, p, occluders);
        if (v == kInvisible) {
          ASSERT_TRUE(shadowed) << "scene " << scene << " box " << b << " point " << p.x << " "
                                << p.y << " " << p.z;
        }
        if (v == kVisible) {
          ASSERT_FALSE(shadowed) << "scene " << scene << " box " << b << " point " << p.x << " "
                                 << p.y << " " << p.z;
        }
        // inShadow never claims a seen point; it may miss a shadowed one only
        // within the rounding tolerance of a boundary, which random points
        // essentially never are.
        const bool claimed = tree.inShadow(p);
        if (claimed) {
          ASSERT_TRUE(shadowed);
        }
        ++pointsChecked;
        pointDisagreements += claimed != shadowed;
      }
    }
  }
  const size_t total = counts[0] + counts[1] + counts[2];
  std::printf(
      "random boxes: %zu invisible, %zu partially visible, %zu visible; %zu points, %zu "
      "disagreements\n",
      counts[0], counts[1], counts[2], pointsChecked, pointDisagreements);
  // Each class must be common, so the test proves the tree is not answering
  // PartiallyVisible to everything.
  EXPECT_GT(counts[size_t(kInvisible)], total / 10);
  EXPECT_GT(counts[size_t(kPartial)], total / 10);
  EXPECT_GT(counts[size_t(kVisible)], total / 10);
  EXPECT_EQ(pointDisagreements, 0u);
}

// Cuts a convex polygon along the chord between random points of two of its
// edges; the two convex pieces share the chord as an edge.
std::array<OccluderPolygon, 2> cutAlongRandomChord(std::mt19937& rng, const OccluderPolygon& p) {
  const std::vector<glm::dvec3>& v = p.vertices;
  const size_t n = v.size();
  std::uniform_int_distribution<size_t> edge(0, n - 1);
  std::uniform_real_distribution<double> along(0.2, 0.8);
  size_t i = edge(rng), j = edge(rng);
  while (j == i) j = edge(rng);
  if (j < i) std::swap(i, j);
  const glm::dvec3 a = v[i] + along(rng) * (v[(i + 1) % n] - v[i]);
  const glm::dvec3 b = v[j] + along(rng) * (v[(j + 1) % n] - v[j]);
  OccluderPolygon first{{a}}, second{{b}};
  for (size_t k = i + 1; k <= j; ++k) first.vertices.push_back(v[k]);
  first.vertices.push_back(b);
  for (size_t k = j + 1; k != i + 1 + n; ++k) second.vertices.push_back(v[k % n]);
  second.vertices.push_back(a);
  return {first, second};
}

TEST(OcclusionTree, OccludersCutIntoPiecesFuseBackIntoTheWhole) {
  // Each random quad is cut into 3 to 4 convex pieces sharing edges, some
  // with T-junctions. The pieces' union is the quad, so the fused shadow is
  // the same, and so are the answers: the DFS counts a leaf only if the box
  // really meets its cell, so the shape of the tree does not show (the
  // oracle checks the pieces' tree on sampled points). Without fusion across
  // the cuts most boxes hidden by the whole quads would straddle a cut's
  // shadow and turn PartiallyVisible.
  std::mt19937 rng(1998);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::array<size_t, 3> counts{};
  size_t differences = 0, total = 0, invisibleWhole = 0;
  for (int scene = 0; scene < 6; ++scene) {
    const glm::dvec3 viewpoint = randomViewpoint(rng);
    std::vector<OccluderPolygon> whole, pieces;
    for (int i = 0; i < 10; ++i) {
      whole.push_back(randomQuad(rng, viewpoint));
      std::vector<OccluderPolygon> parts = {whole.back()};
      for (int cut = 0; cut < 2 + i % 2; ++cut) {
        const size_t k = size_t(u(rng) * double(parts.size()));
        const std::array<OccluderPolygon, 2> halves = cutAlongRandomChord(rng, parts[k]);
        parts[k] = halves[0];
        parts.push_back(halves[1]);
      }
      pieces.insert(pieces.end(), parts.begin(), parts.end());
    }
    std::shuffle(pieces.begin(), pieces.end(), rng);
    const OcclusionTree wholeTree(viewpoint, whole), piecesTree(viewpoint, pieces);
    for (int b = 0; b < 150; ++b) {
      const Box3f query = randomQueryBox(rng, viewpoint);
      const NodeVisibility v = piecesTree.classify(query);
      ++counts[size_t(v)];
      ++total;
      const NodeVisibility w = wholeTree.classify(query);
      differences += v != w;
      invisibleWhole += w == kInvisible;
      for (int i = 0; i < 60; ++i) {
        glm::dvec3 t = uniform3(rng);
        if (i < 8) t = glm::dvec3(i & 1, i >> 1 & 1, i >> 2 & 1);  // corners first
        const glm::dvec3 p = glm::dvec3(query.lo) + t * glm::dvec3(query.hi - query.lo);
        const bool shadowed = shadowedByAny(viewpoint, p, pieces);
        if (v == kInvisible) {
          ASSERT_TRUE(shadowed) << "scene " << scene << " box " << b;
        }
        if (v == kVisible) {
          ASSERT_FALSE(shadowed) << "scene " << scene << " box " << b;
        }
      }
    }
  }
  std::printf(
      "cut occluders: %zu invisible (uncut: %zu), %zu partially visible, %zu visible; %zu of %zu "
      "differ\n",
      counts[0], invisibleWhole, counts[1], counts[2], differences, total);
  EXPECT_GT(counts[size_t(kInvisible)], total / 10);
  EXPECT_GE(counts[size_t(kInvisible)], invisibleWhole * 9 / 10);
  EXPECT_EQ(differences, 0u);
}

TEST(SelectOccluders, PrefersANearFacingLargeQuadToAFarSmallOne) {
  // The far quad (0.25 m^2 at 20 m) subtends ~6e-4 sr, the near one (4 m^2 at 4 m) ~0.25 sr.
  const std::vector<OccluderPolygon> candidates = {quadZ(-0.25, 0.25, -0.25, 0.25, -20),
                                                   quadZ(-1, 1, -1, 1, -4)};
  EXPECT_EQ(selectOccluders({0, 0, 0}, candidates, 1), std::vector<size_t>{1});
  EXPECT_EQ(selectOccluders({0, 0, 0}, candidates, 2), (std::vector<size_t>{1, 0}));
}

TEST(SelectOccluders, PrefersAFacingQuadToAnObliqueOneOfTheSameSize) {
  // Both 4 m^2 with centroid 4 m away; the second is turned 60 degrees
  // (cos = 0.5) about the y axis through its centroid.
  const double c = 0.5, s = std::sqrt(3.0) / 2.0;
  const OccluderPolygon oblique = {
      {{-c, -1, -4 - s}, {c, -1, -4 + s}, {c, 1, -4 + s}, {-c, 1, -4 - s}}};
  const std::vector<OccluderPolygon> candidates = {oblique, quadZ(-1, 1, -1, 1, -4)};
  EXPECT_EQ(selectOccluders({0, 0, 0}, candidates, 2), (std::vector<size_t>{1, 0}));
}

TEST(SelectOccluders, ReturnsAllWhenKExceedsTheCount) {
  const std::vector<OccluderPolygon> candidates = {quadZ(-1, 1, -1, 1, -4), quadZ(-1, 1, -1, 1, -8),
                                                   quadZ(-1, 1, -1, 1, -6)};
  EXPECT_EQ(selectOccluders({0, 0, 0}, candidates, 10), (std::vector<size_t>{0, 2, 1}));
  EXPECT_TRUE(selectOccluders({0, 0, 0}, candidates, 0).empty());
}

TEST(SelectOccluders, BreaksTiesByInputOrder) {
  // Mirror images across the viewpoint score exactly the same.
  const std::vector<OccluderPolygon> candidates = {quadZ(-1, 1, -1, 1, 4), quadZ(-1, 1, -1, 1, -4),
                                                   quadZ(-1, 1, -1, 1, -4)};
  EXPECT_EQ(selectOccluders({0, 0, 0}, candidates, 3), (std::vector<size_t>{0, 1, 2}));
  EXPECT_EQ(selectOccluders({0, 0, 0}, candidates, 2), (std::vector<size_t>{0, 1}));
}

TEST(SelectOccluders, SkipsEdgeOnAndDegeneratePolygons) {
  const std::vector<OccluderPolygon> candidates = {
      {{{-5, 0, -10}, {5, 0, -10}, {5, 0, -1}, {-5, 0, -1}}},  // the viewpoint is in its plane
      {{{-1, -1, -4}, {0, 0, -4}, {1, 1, -4}}},                // collinear
      {{{0, 0, -4}, {1, 0, -4}}},                              // two vertices
      quadZ(-0.1, 0.1, -0.1, 0.1, -30)};
  EXPECT_EQ(selectOccluders({0, 0, 0}, candidates, 4), std::vector<size_t>{3});
}

}  // namespace
}  // namespace vistream
