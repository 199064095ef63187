// Convex occluder extraction and the strict segment test. Every expected
// answer below follows from the geometry written next to it: which meshes are
// closed and convex, which coplanar groups are convex, and which segments
// cross an occluder's interior rather than touch its boundary.
#include "server/visibility/occluders.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

using testing::addBox;

using testing::addFaces;
using testing::Loop;

// A closed prism over a loop in the XZ plane from y0 to y1, outward-facing.
// The loop must have a positive signed area sum(x_i z_{i+1} - x_{i+1} z_i)
// (the fan of such a loop faces -y, so it is the bottom) and be star-shaped
// from its first vertex.
uint32_t addPrism(Scene& scene, const std::string& name, const std::vector<glm::vec2>& xz, float y0,
                  float y1) {
  std::vector<Loop> faces;
  Loop bottom, top;
  for (const glm::vec2& p : xz) bottom.emplace_back(p.x, y0, p.y);
  top.emplace_back(xz[0].x, y1, xz[0].y);  // reversed, keeping the first vertex first
  for (size_t i = xz.size() - 1; i >= 1; --i) top.emplace_back(xz[i].x, y1, xz[i].y);
  faces.push_back(bottom);
  faces.push_back(top);
  for (size_t i = 0; i < xz.size(); ++i) {
    const glm::vec2 a = xz[i], b = xz[(i + 1) % xz.size()];
    faces.push_back({{a.x, y0, a.y}, {a.x, y1, a.y}, {b.x, y1, b.y}, {b.x, y0, b.y}});
  }
  return addFaces(scene, name, faces);
}

// An upward-facing quad at height y over [x0,x1] x [z0,z1].
Loop floorQuad(float x0, float z0, float x1, float z1, float y = 0.0f) {
  return {{x0, y, z0}, {x0, y, z1}, {x1, y, z1}, {x1, y, z0}};
}

// The extraction rules without the size cut (OccluderOptions::minOccluderSize),
// so that a unit quad or a degenerate triangle is judged by shape alone.
OccluderOptions everySize() {
  OccluderOptions o;
  o.minOccluderSize = 0.0;
  return o;
}

OccluderSet extract(Scene& scene, const OccluderOptions& options = everySize()) {
  finalizeScene(scene);
  return extractOccluders(scene, options);
}

size_t countKind(const OccluderSet& set, ConvexOccluder::Kind kind) {
  size_t n = 0;
  for (const ConvexOccluder& o : set.occluders) n += o.kind == kind;
  return n;
}

bool anyBlocks(const OccluderSet& set, const glm::dvec3& a, const glm::dvec3& b) {
  for (const ConvexOccluder& o : set.occluders)
    if (occluderBlocksSegment(o, a, b)) return true;
  return false;
}

constexpr auto kSolid = ConvexOccluder::Kind::Solid;
constexpr auto kPolygon = ConvexOccluder::Kind::Polygon;

// --- Extraction -------------------------------------------------------------

TEST(Occluders, ClosedBoxBecomesExactlyOneSolid) {
  Scene scene;
  addBox(scene, "box", {-1, -1, -1}, {1, 1, 1});
  const OccluderSet set = extract(scene);
  ASSERT_EQ(set.occluders.size(), 1u);
  EXPECT_EQ(set.occluders[0].kind, kSolid);
  EXPECT_EQ(set.occluders[0].object, 0u);
  EXPECT_EQ(set.stats.solids, 1u);
  EXPECT_EQ(set.stats.polygons, 0u);
  // Its region is the box: the bounds and the surface area 6 * 2 * 2.
  EXPECT_EQ(set.occluders[0].bounds.lo, glm::vec3(-1));
  EXPECT_EQ(set.occluders[0].bounds.hi, glm::vec3(1));
  EXPECT_NEAR(set.occluders[0].area, 24.0, 1e-9);
}

TEST(Occluders, ConvexPrismFromTheTestHelperIsASolid) {
  // Control for the L-shaped prism below: the same helper on a square loop
  // gives a closed, consistently oriented, convex mesh.
  Scene scene;
  addPrism(scene, "square", {{0, 0}, {2, 0}, {2, 2}, {0, 2}}, 0, 1);
  const OccluderSet set = extract(scene);
  ASSERT_EQ(set.occluders.size(), 1u);
  EXPECT_EQ(set.occluders[0].kind, kSolid);
}

TEST(Occluders, OpenBoxWithFiveFacesBecomesFivePolygonsNotASolid) {
  Scene scene;
  // The closed box's faces without the top (+y): not closed, so no solid;
  // each side is two coplanar triangles with a convex union: one polygon.
  addFaces(scene, "open_box",
           {{{-1, -1, -1}, {-1, -1, 1}, {-1, 1, 1}, {-1, 1, -1}},
            {{1, -1, -1}, {1, 1, -1}, {1, 1, 1}, {1, -1, 1}},
            {{-1, -1, -1}, {1, -1, -1}, {1, -1, 1}, {-1, -1, 1}},
            {{-1, -1, -1}, {-1, 1, -1}, {1, 1, -1}, {1, -1, -1}},
            {{-1, -1, 1}, {1, -1, 1}, {1, 1, 1}, {-1, 1, 1}}});
  const OccluderSet set = extract(scene);
  EXPECT_EQ(countKind(set, kSolid), 0u);
  EXPECT_EQ(countKind(set, kPolygon), 5u);
  EXPECT_EQ(set.stats.mergedPolygons, 5u);
  // Through the open top and out through the bottom: the bottom blocks it.
  EXPECT_TRUE(anyBlocks(set, {0, 2, 0}, {0, -2, 0}));
  // In through the open top, ending inside the box: nothing blocks it.
  EXPECT_FALSE(anyBlocks(set, {0, 2, 0}, {0, 0, 0}));
}

TEST(Occluders, LShapedClosedPrismIsNotASolid) {
  // L in XZ: the unit squares [0,2]x[0,1] and [0,1]x[0,2]; the notch is
  // [1,2]x[1,2]. Closed and consistently oriented, but not convex.
  Scene scene;
  addPrism(scene, "L", {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}}, 0, 1);
  const OccluderSet set = extract(scene);
  EXPECT_EQ(countKind(set, kSolid), 0u);
  EXPECT_EQ(set.stats.solids, 0u);
  // Straight down through the notch: outside the L, so no occluder may block it.
  EXPECT_FALSE(anyBlocks(set, {1.5, 2, 1.5}, {1.5, -1, 1.5}));
  EXPECT_FALSE(anyBlocks(set, {1.25, 2, 1.75}, {1.75, -1, 1.25}));
  // Straight down through the L's material: the polygons left of it block it.
  EXPECT_TRUE(anyBlocks(set, {1.5, 2, 0.25}, {1.5, -1, 0.25}));
}

TEST(Occluders, TwoCoplanarQuadsSharingAnEdgeMergeIntoOnePolygon) {
  // A wall at z = 0 made of [0,1]x[0,1] and [1,2]x[0,1], sharing the edge x = 1.
  Scene scene;
  addFaces(
      scene, "wall",
      {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}, {{1, 0, 0}, {2, 0, 0}, {2, 1, 0}, {1, 1, 0}}});
  const OccluderSet set = extract(scene);
  ASSERT_EQ(set.occluders.size(), 1u);
  EXPECT_EQ(set.occluders[0].kind, kPolygon);
  EXPECT_EQ(set.stats.mergedPolygons, 1u);
  EXPECT_NEAR(set.occluders[0].area, 2.0, 1e-9);
  // A line through the seam between the two quads is blocked by the merged
  // polygon: the seam lies inside it.
  EXPECT_TRUE(occluderBlocksSegment(set.occluders[0], {1, 0.5, -1}, {1, 0.5, 1}));
  // A line through the wall's outer edge is not.
  EXPECT_FALSE(occluderBlocksSegment(set.occluders[0], {2, 0.5, -1}, {2, 0.5, 1}));
}

TEST(Occluders, TwoCoplanarQuadsTouchingAtAVertexStayApart) {
  // [0,1]^2 and [1,2]^2 in XZ share only the point (1, 0, 1): their union is
  // not convex, and the straight line through that point must pass.
  Scene scene;
  addFaces(scene, "floor", {floorQuad(0, 0, 1, 1), floorQuad(1, 1, 2, 2)});
  const OccluderSet set = extract(scene);
  EXPECT_EQ(countKind(set, kPolygon), 2u);
  EXPECT_FALSE(anyBlocks(set, {1, 1, 1}, {1, -1, 1}));
  // The hull of the union covers (1.5, 0.5) and (0.5, 1.5): no occluder may.
  EXPECT_FALSE(anyBlocks(set, {1.5, 1, 0.5}, {1.5, -1, 0.5}));
  EXPECT_FALSE(anyBlocks(set, {0.5, 1, 1.5}, {0.5, -1, 1.5}));
}

TEST(Occluders, LShapedFloorOfQuadsDoesNotCoverItsNotch) {
  // Three coplanar, edge-connected unit quads: [0,1]x[0,1], [1,2]x[0,1],
  // [0,1]x[1,2]. Their union is an L whose hull would cover the notch [1,2]x[1,2].
  Scene scene;
  addFaces(scene, "floor", {floorQuad(0, 0, 1, 1), floorQuad(1, 0, 2, 1), floorQuad(0, 1, 1, 2)});
  const OccluderSet set = extract(scene);
  EXPECT_EQ(set.stats.nonConvexGroups, 1u);
  EXPECT_EQ(countKind(set, kPolygon), 3u);  // one per quad
  for (const glm::dvec2 p :
       {glm::dvec2(1.5, 1.5), glm::dvec2(1.1, 1.1), glm::dvec2(1.9, 1.9), glm::dvec2(1.2, 1.7)})
    EXPECT_FALSE(anyBlocks(set, {p.x, 1, p.y}, {p.x, -1, p.y}))
        << "through the notch at " << p.x << "," << p.y;
  // Each quad still blocks lines through its own interior.
  for (const glm::dvec2 p : {glm::dvec2(0.5, 0.5), glm::dvec2(1.5, 0.5), glm::dvec2(0.5, 1.5)})
    EXPECT_TRUE(anyBlocks(set, {p.x, 1, p.y}, {p.x, -1, p.y}))
        << "through the floor at " << p.x << "," << p.y;
}

TEST(Occluders, DegenerateTrianglesNeverMakeOccluders) {
  Scene scene;
  Object o;
  o.name = "degenerate";
  // Collinear, a repeated vertex, and all three equal.
  o.mesh.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}, {0, 1, 0}, {1, 1, 1}, {3, 3, 3}};
  o.mesh.triangles = {{0, 1, 2}, {3, 4, 5}, {6, 6, 6}, {0, 2, 1}};
  o.mesh.faceIds = {0, 1, 2, 3};
  scene.objects.push_back(o);
  scene.faceCount = 4;
  const OccluderSet set = extract(scene);
  EXPECT_TRUE(set.occluders.empty());
}

TEST(Occluders, ClosedBoxWithAnExtraDegenerateTriangleIsStillOneSolid) {
  // A zero-area triangle along an edge of the box does not open the mesh.
  Scene scene;
  addBox(scene, "box", {-1, -1, -1}, {1, 1, 1});
  Object& box = scene.objects[0];
  const uint32_t base = uint32_t(box.mesh.positions.size());
  box.mesh.positions.insert(box.mesh.positions.end(), {{-1, -1, -1}, {0, -1, -1}, {1, -1, -1}});
  box.mesh.triangles.emplace_back(base, base + 1, base + 2);
  box.mesh.faceIds.push_back(scene.faceCount++);
  const OccluderSet set = extract(scene);
  ASSERT_EQ(set.occluders.size(), 1u);
  EXPECT_EQ(set.occluders[0].kind, kSolid);
}

TEST(Occluders, DynamicObjectsNeverOcclude) {
  Scene scene;
  addBox(scene, "car", {-1, -1, -1}, {1, 1, 1}, /*dynamic=*/true);
  addFaces(scene, "flag", {{{0, 0, 5}, {1, 0, 5}, {1, 1, 5}, {0, 1, 5}}}, /*dynamic=*/true);
  addBox(scene, "house", {4, 0, 4}, {6, 2, 6});
  const OccluderSet set = extract(scene);
  ASSERT_EQ(set.occluders.size(), 1u);
  EXPECT_EQ(set.occluders[0].object, 2u);
  EXPECT_FALSE(anyBlocks(set, {-2, 0, 0}, {2, 0, 0}));         // through the car
  EXPECT_FALSE(anyBlocks(set, {0.5, 0.5, 4}, {0.5, 0.5, 6}));  // through the flag
}

TEST(Occluders, OptionsSwitchOffSolidsAndPolygons) {
  Scene scene;
  addBox(scene, "box", {-1, -1, -1}, {1, 1, 1});
  OccluderOptions noSolids = everySize();
  noSolids.solids = false;
  const OccluderSet asPolygons = extract(scene, noSolids);
  EXPECT_EQ(countKind(asPolygons, kSolid), 0u);
  EXPECT_EQ(countKind(asPolygons, kPolygon), 6u);  // one per side
  OccluderOptions nothing = everySize();
  nothing.solids = false;
  nothing.polygons = false;
  EXPECT_TRUE(extract(scene, nothing).occluders.empty());
}

TEST(Occluders, OccludersSmallerThanTheMinimumSizeAreLeftOut) {
  // Solids by their longest side, polygons by the square root of their area.
  Scene scene;
  addBox(scene, "small box", {0, 0, 0}, {0.5f, 0.5f, 0.5f});
  addBox(scene, "thin slab", {2, 0, 0}, {3.5f, 0.1f, 0.1f});  // longest side 1.5 m
  addFaces(scene, "small quad", {{{0, 0, 5}, {0.5f, 0, 5}, {0.5f, 0.5f, 5}, {0, 0.5f, 5}}});
  addFaces(scene, "large quad", {{{0, 0, 8}, {2, 0, 8}, {2, 2, 8}, {0, 2, 8}}});
  OccluderOptions oneMetre = everySize();
  oneMetre.minOccluderSize = 1.0;
  const OccluderSet set = extract(scene, oneMetre);
  std::vector<uint32_t> objects;
  for (const ConvexOccluder& o : set.occluders) objects.push_back(o.object);
  EXPECT_EQ(objects, (std::vector<uint32_t>{1, 3}));
  // Without the cut all four are occluders.
  EXPECT_EQ(extract(scene).occluders.size(), 4u);
}

// --- The strict segment test --------------------------------------------------

// The segment battery for a solid box [-1,1]^3 and a polygon [-1,1]^2 at
// z = 0, both centred at `c`. Each expectation says why.
void expectBoxSegments(const ConvexOccluder& box, const glm::dvec3& c) {
  ASSERT_EQ(box.kind, kSolid);
  auto blocks = [&](glm::dvec3 a, glm::dvec3 b) {
    return occluderBlocksSegment(box, c + a, c + b);
  };
  // Through the centre, along an axis and along a diagonal.
  EXPECT_TRUE(blocks({-2, 0, 0}, {2, 0, 0}));
  EXPECT_TRUE(blocks({-2, -2, -2}, {2, 2, 2}));
  // Just inside every face near a vertex (0.99): still the interior.
  EXPECT_TRUE(blocks({2, 0.99, 0.99}, {-2, 0.99, 0.99}));
  // Lying in the face x = 1, across its middle: grazes the face.
  EXPECT_FALSE(blocks({1, -2, 0}, {1, 2, 0}));
  // Through the edge (x = 1, y = 1) at one point, outside elsewhere.
  EXPECT_FALSE(blocks({2, 0, 0}, {0, 2, 0}));
  // Along the edge (x = 1, y = 1).
  EXPECT_FALSE(blocks({1, 1, -2}, {1, 1, 2}));
  // Through the vertex (1,1,1) along (1,-1,1): x > 1 on one side, y > 1 on the other.
  EXPECT_FALSE(blocks({2, 0, 2}, {0, 2, 0}));
  // The same direction 0.01 inside the vertex crosses a corner of the interior;
  // 0.01 outside it passes: x < 1 needs s < -0.01, y < 1 needs s > 0.01.
  EXPECT_TRUE(blocks({1.99, -0.01, 1.99}, {-0.01, 1.99, -0.01}));
  EXPECT_FALSE(blocks({2.01, 0.01, 2.01}, {0.01, 2.01, 0.01}));
  // Ending on the near face: touches the surface only.
  EXPECT_FALSE(blocks({3, 0, 0}, {1, 0, 0}));
  EXPECT_FALSE(blocks({1, 0.5, 0.5}, {3, 0.5, 0.5}));
  // Ending on the far face after crossing the interior: blocked.
  EXPECT_TRUE(blocks({3, 0, 0}, {-1, 0, 0}));
  // Entirely outside, parallel to a face.
  EXPECT_FALSE(blocks({-2, 1.5, 0}, {2, 1.5, 0}));
}

void expectPolygonSegments(const ConvexOccluder& quad, const glm::dvec3& c) {
  ASSERT_EQ(quad.kind, kPolygon);
  auto blocks = [&](glm::dvec3 a, glm::dvec3 b) {
    return occluderBlocksSegment(quad, c + a, c + b);
  };
  // Straight through the middle and obliquely through the interior.
  EXPECT_TRUE(blocks({0, 0, -1}, {0, 0, 1}));
  EXPECT_TRUE(blocks({-0.5, -0.5, -1}, {0.5, 0.5, 1}));
  EXPECT_TRUE(blocks({0.99, 0.99, -1}, {0.99, 0.99, 1}));
  // Lying in the polygon's plane, across it.
  EXPECT_FALSE(blocks({-2, 0, 0}, {2, 0, 0}));
  EXPECT_FALSE(blocks({-0.5, -0.5, 0}, {0.5, 0.5, 0}));
  // Crossing the plane exactly on an edge and exactly on a vertex.
  EXPECT_FALSE(blocks({1, 0, -1}, {1, 0, 1}));
  EXPECT_FALSE(blocks({0.5, -1, -1}, {0.5, -1, 1}));
  EXPECT_FALSE(blocks({1, 1, -1}, {1, 1, 1}));
  EXPECT_FALSE(blocks({0, 2, -1}, {2, 0, 1}));  // oblique, through (1, 1, 0)
  // Crossing just outside the outline.
  EXPECT_FALSE(blocks({1.01, 0, -1}, {1.01, 0, 1}));
  // Ending on the polygon, and starting on it: touches, does not cross.
  EXPECT_FALSE(blocks({0, 0, 1}, {0, 0, 0}));
  EXPECT_FALSE(blocks({0, 0, 0}, {0, 0, -1}));
  // On one side only.
  EXPECT_FALSE(blocks({0, 0, 1}, {0, 0, 0.5}));
}

struct Placement {
  const char* name;
  glm::dvec3 origin;  // Scene::origin, file coordinates
  glm::vec3 local;    // where the occluders stand in the local frame
};

// Near the origin; 50 km away with small local coordinates; and 50 km away
// with local coordinates near 1e4 (10240 is exact in float, as are the
// box's coordinates around it, so every test point is exact in double).
const Placement kPlacements[] = {
    {"at the origin", {0, 0, 0}, {0, 0, 0}},
    {"50 km away, small local coordinates", {50000, 0, -50000}, {0, 0, 0}},
    {"50 km away, local coordinates near 1e4", {40000, 0, -40000}, {10240, 0, -10240}},
};

TEST(OccluderBlocksSegment, DecidesGrazingLinesTheSameWayAtTheOriginAndFiftyKilometresAway) {
  for (const Placement& at : kPlacements) {
    SCOPED_TRACE(at.name);
    Scene scene;
    scene.origin = at.origin;
    const glm::vec3 c = at.local;
    addBox(scene, "box", c + glm::vec3(-1), c + glm::vec3(1));
    addFaces(scene, "quad",
             {{c + glm::vec3(-1, -1, 5), c + glm::vec3(1, -1, 5), c + glm::vec3(1, 1, 5),
               c + glm::vec3(-1, 1, 5)}});
    const OccluderSet set = extract(scene);
    ASSERT_EQ(set.occluders.size(), 2u);
    expectBoxSegments(set.occluders[0], glm::dvec3(c));
    expectPolygonSegments(set.occluders[1], glm::dvec3(c) + glm::dvec3(0, 0, 5));
  }
}

TEST(OccluderBlocksSegment, SolidBoxFarFromTheOriginIsTheSameOccluderAsNearIt) {
  // Scene::origin only moves the file frame: the occluder, built in the local
  // frame, must not change at all.
  Scene near, far;
  far.origin = {50000.0, 0.0, 50000.0};
  addBox(near, "box", {-1, -2, -3}, {4, 5, 6});
  addBox(far, "box", {-1, -2, -3}, {4, 5, 6});
  const OccluderSet a = extract(near), b = extract(far);
  ASSERT_EQ(a.occluders.size(), 1u);
  ASSERT_EQ(b.occluders.size(), 1u);
  EXPECT_EQ(a.occluders[0].planes, b.occluders[0].planes);
}

TEST(OccluderBlocksSegment, SegmentStartingInsideASolidIsBlocked) {
  // A viewpoint inside a building sees nothing outside it: the open segment
  // from inside to outside crosses the interior.
  Scene scene;
  addBox(scene, "box", {-1, -1, -1}, {1, 1, 1});
  const OccluderSet set = extract(scene);
  ASSERT_EQ(set.occluders.size(), 1u);
  EXPECT_TRUE(occluderBlocksSegment(set.occluders[0], {0, 0, 0}, {5, 0, 0}));
  EXPECT_TRUE(occluderBlocksSegment(set.occluders[0], {0.5, 0.5, 0.5}, {-0.5, -0.5, -0.5}));
}

}  // namespace
}  // namespace vistream
