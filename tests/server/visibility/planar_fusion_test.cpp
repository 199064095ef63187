// Solids fused within a plane (server/visibility/planar_fusion.h), as the
// single-occluder PVS runs them, against known answers checked by rays:
// a wall of 2 m patches (each its own object, as interior2's) hides a box
// that no single patch hides; a box seen through a door in that wall, or
// through a 1 cm slit or a 1 cm square window between patches, stays; the
// same far from the origin. Each answer's premise is checked with the sampled ground truth
// (unserved viewpoints skipped) or an explicit ray.
#include "server/visibility/planar_fusion.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "server/visibility/epsilon_pvs.h"
#include "tests/common/support/box_scenes.h"
#include "tests/common/support/pvs_truth.h"

namespace vistream {
namespace {

enum class Wall { Whole, Door, Gap, Hole };

// A ground, a wall along x from -10 to 10 (z 5 to 5.2, 3 m tall) of ten
// 2 m boxes, each its own object, and behind it a box whose -z face (z =
// 10) is the face under test. Door: the patch at x in [-2, 0] leaves a
// door 1 m wide at x in [-1, 0] under a lintel from 2.1 m up. Gap: the patches either side of x = 0
// leave a 1 cm slit. Everything moved by `offset`.
struct WallScene {
  Scene scene;
  uint32_t target = 0;
  Box3f cell;
  glm::vec3 offset{0.0f};
};

WallScene wallScene(Wall wall, glm::vec3 offset = glm::vec3(0.0f)) {
  WallScene w;
  w.offset = offset;
  const glm::vec3 o = offset;
  testing::addGround(w.scene, o.x - 40, o.z - 40, o.x + 40, o.z + 40, o.y);
  for (int k = -5; k < 5; ++k) {
    float x0 = 2.0f * float(k), x1 = x0 + 2.0f;
    const float y0 = 0.0f;
    if (wall == Wall::Door && k == -1) continue;  // replaced below
    if (wall == Wall::Gap && k == 0) x0 += 0.01f;
    if (wall == Wall::Hole && k == 0) {
      testing::addBox(w.scene, "below", o + glm::vec3(0.0f, 0.0f, 5.0f),
                      o + glm::vec3(0.01f, 1.0f, 5.2f));
      testing::addBox(w.scene, "above", o + glm::vec3(0.0f, 1.01f, 5.0f),
                      o + glm::vec3(0.01f, 3.0f, 5.2f));
      x0 += 0.01f;
    }
    const std::string name = "patch" + std::to_string(k + 5);
    testing::addBox(w.scene, name, o + glm::vec3(x0, y0, 5.0f), o + glm::vec3(x1, 3.0f, 5.2f));
  }
  if (wall == Wall::Door) {  // the patch at x in [-2, 0]: a 1 m door at x in [-1, 0]
    testing::addBox(w.scene, "patch_left", o + glm::vec3(-2.0f, 0.0f, 5.0f),
                    o + glm::vec3(-1.0f, 3.0f, 5.2f));
    testing::addBox(w.scene, "lintel", o + glm::vec3(-1.0f, 2.1f, 5.0f),
                    o + glm::vec3(0.0f, 3.0f, 5.2f));
  }
  const uint32_t first = testing::addBox(w.scene, "target", o + glm::vec3(-1.0f, 0.0f, 10.0f),
                                         o + glm::vec3(1.0f, 2.0f, 12.0f));
  w.target = first + 4;  // -z
  finalizeScene(w.scene);
  w.cell = Box3f(o + glm::vec3(-1.0f, 0.2f, -1.0f), o + glm::vec3(1.0f, 1.8f, 1.0f));
  return w;
}

bool has(const std::vector<uint32_t>& sorted, uint32_t f) {
  return std::binary_search(sorted.begin(), sorted.end(), f);
}

// Faces the sampled ground truth sees from the served viewpoints of the
// cell, rays aimed at every face as well.
std::vector<uint32_t> seenFaces(const WallScene& w) {
  const FlatTriangles triangles = flattenScene(w.scene);
  const auto rays = makeEmbreeRayQuery(triangles);
  SampledVisibilityOptions sampling;
  sampling.skipViewpoint = testing::unservedViewpointRule(triangles, *rays);
  for (uint32_t f = 0; f < w.scene.faceCount; ++f) sampling.probeFaces.push_back(f);
  return sampleVisibleFaces(*rays, triangles, w.cell, sampling).faces;
}

PvsOptions withoutPlanarFusion() {
  PvsOptions o;
  o.planarFusion = false;
  return o;
}

TEST(PlanarFusion, AWallOfPatchesHidesWhatNoSinglePatchHides) {
  for (const glm::vec3 offset : {glm::vec3(0.0f), glm::vec3(1e4f, 0.0f, -1e4f)}) {
    const WallScene w = wallScene(Wall::Whole, offset);
    ASSERT_FALSE(has(seenFaces(w), w.target)) << offset.x;
    const EpsilonPvs pvs(w.scene);
    const PvsResult single = pvs.compute(w.cell, withoutPlanarFusion());
    ASSERT_TRUE(has(single.faces, w.target)) << "no single patch hides it, " << offset.x;
    const PvsResult fused = pvs.compute(w.cell);
    EXPECT_FALSE(has(fused.faces, w.target)) << offset.x;
    EXPECT_GT(fused.stats.facesPlanar, 0u);
    // Never larger than without the stage, and everything seen stays.
    EXPECT_TRUE(std::includes(single.faces.begin(), single.faces.end(), fused.faces.begin(),
                              fused.faces.end()));
    for (uint32_t f : seenFaces(w)) EXPECT_TRUE(has(fused.faces, f)) << "face " << f;
  }
}

// The planes are found by walking their X/Z grid along the line from the
// cell to the face: a cell far off to the side, its line crossing many grid
// cells diagonally (and the grid's border), still finds the wall.
TEST(PlanarFusion, FindsTheWallFromACellFarOffAlongADiagonal) {
  WallScene w = wallScene(Wall::Whole);
  w.cell = Box3f(glm::vec3(-31.0f, 0.2f, -61.0f), glm::vec3(-29.0f, 1.8f, -59.0f));
  ASSERT_FALSE(has(seenFaces(w), w.target));
  const EpsilonPvs pvs(w.scene);
  ASSERT_TRUE(has(pvs.compute(w.cell, withoutPlanarFusion()).faces, w.target));
  EXPECT_FALSE(has(pvs.compute(w.cell).faces, w.target));
}

TEST(PlanarFusion, KeepsAFaceSeenThroughADoorInTheWall) {
  for (const glm::vec3 offset : {glm::vec3(0.0f), glm::vec3(1e4f, 0.0f, -1e4f)}) {
    const WallScene w = wallScene(Wall::Door, offset);
    const std::vector<uint32_t> seen = seenFaces(w);
    ASSERT_TRUE(has(seen, w.target)) << offset.x;
    const PvsResult r = EpsilonPvs(w.scene).compute(w.cell);
    for (uint32_t f : seen) EXPECT_TRUE(has(r.faces, f)) << "face " << f << ", " << offset.x;
  }
}

// A slit or a window a centimetre wide between solids stays open: the
// pieces are not merged across it, and what is seen through it stays.
TEST(PlanarFusion, KeepsAFaceSeenThroughACentimetreSlitOrWindowBetweenPatches) {
  for (const Wall kind : {Wall::Gap, Wall::Hole}) {
    const WallScene w = wallScene(kind);
    // The premise, by one ray: from a point of the cell through the middle
    // of the opening, the first thing met is the target face.
    const FlatTriangles triangles = flattenScene(w.scene);
    const auto rays = makeEmbreeRayQuery(triangles);
    const glm::vec3 eye(0.005f, 1.005f, 0.0f), opening(0.005f, 1.005f, 5.1f);
    const Hit hit = rays->firstHit(Ray{eye, opening - eye, 0.0f, 100.0f});
    ASSERT_TRUE(hit.valid());
    ASSERT_EQ(triangles.faceIds[hit.triangle], w.target) << int(kind);
    ASSERT_TRUE(w.cell.contains(eye));
    EXPECT_TRUE(has(EpsilonPvs(w.scene).compute(w.cell).faces, w.target)) << int(kind);
  }
}

TEST(PlanarFusion, TakesOnlyPlanesWithTheCellInFront) {
  const WallScene w = wallScene(Wall::Whole);
  OccluderSet occluders = extractOccluders(w.scene);
  const PlanarFusion fusion(occluders);
  EXPECT_GT(fusion.planeCount(), 0u);
  // A cell that reaches into the wall's front plane has it behind no
  // candidate plane of the wall's front (z = 5, normal -z).
  const Box3f touching(glm::vec3(-1.0f, 0.2f, 3.0f), glm::vec3(1.0f, 1.8f, 5.1f));
  PlanarFusion::CellPlanes planes = fusion.planesFor(touching);
  const FlatTriangles triangles = flattenScene(w.scene);
  std::vector<glm::dvec3> face;
  for (size_t t = 0; t < triangles.size(); ++t)
    if (triangles.faceIds[t] == w.target)
      for (int k = 0; k < 3; ++k) face.push_back(glm::dvec3(triangles.vertex(t, k)));
  EXPECT_FALSE(fusion.hidden(touching, planes, face));
  PlanarFusion::CellPlanes inFront = fusion.planesFor(w.cell);
  EXPECT_TRUE(fusion.hidden(w.cell, inFront, face));
}

// A cell's planes keep the lists of the grid cells read for one face for
// the next: every face gets the answer a fresh CellPlanes gives it, faces
// taken in either order (interior2's walls of patches, three cells).
TEST(PlanarFusion, AnswersEveryFaceAsAFreshCellWouldWhenTheCellsListsAreKept) {
  const Scene scene = openScene("interior2");
  const OccluderSet occluders = extractOccluders(scene);
  const PlanarFusion fusion(occluders);
  const FlatTriangles triangles = flattenScene(scene);
  std::vector<std::vector<glm::dvec3>> faces(scene.faceCount);
  for (size_t t = 0; t < triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      faces[triangles.faceIds[t]].push_back(glm::dvec3(triangles.vertex(t, k)));
  const glm::vec3 c = scene.bounds().center();
  size_t hiddenCount = 0;
  for (const glm::vec3 at :
       {c, c + glm::vec3(7.0f, 0.0f, -5.0f), c + glm::vec3(-9.0f, 0.0f, 6.0f)}) {
    const Box3f cell(glm::vec3(at.x - 1.0f, scene.bounds().lo.y + 0.2f, at.z - 1.0f),
                     glm::vec3(at.x + 1.0f, scene.bounds().lo.y + 1.8f, at.z + 1.0f));
    std::vector<uint8_t> fresh(faces.size());
    for (size_t f = 0; f < faces.size(); ++f) {
      PlanarFusion::CellPlanes own = fusion.planesFor(cell);
      fresh[f] = fusion.hidden(cell, own, faces[f]);
      hiddenCount += fresh[f];
    }
    PlanarFusion::CellPlanes forward = fusion.planesFor(cell), backward = forward;
    for (size_t f = 0; f < faces.size(); ++f)
      EXPECT_EQ(fusion.hidden(cell, forward, faces[f]), bool(fresh[f])) << "face " << f;
    for (size_t f = faces.size(); f-- > 0;)
      EXPECT_EQ(fusion.hidden(cell, backward, faces[f]), bool(fresh[f])) << "face " << f;
  }
  EXPECT_GT(hiddenCount, 0u) << "the premise: some face is hidden by fused patches";
}

}  // namespace
}  // namespace vistream
