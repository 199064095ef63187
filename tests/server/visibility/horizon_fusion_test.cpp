// The fused occlusion-horizon stage (server/visibility/horizon_fusion.h)
// against known answers and the sampled ground truth.
//
// Known answers: a row of touching boxes hides a face that no single box
// hides (the single-occluder PVS keeps it, the fused stage removes it, and
// no sampled ray sees it); the same row wound inside out, with one face of
// each box wound the other way, or open at the base (buildings without a
// ground surface) still hides it; a row with a hole above the base (boxes
// without a top) does not occlude at all; a row floating above the cell's
// bottom keeps what is seen under it; a cell cutting into a box, closed or
// open at the base, is served outside the box only, and keeps everything
// seen from there; a cell reaching down to an open base gets no occlusion
// from that box. Open sheets hide what they hide together: a fence of
// panels, a V of two sheets meeting at a corner (each sheet alone does
// not), but not through an opening or a slit at the corner.
//
// Sampled ground truth: on street cells of the generated cities and of the
// real city model (../shared/data/delfshaven.obj), no face seen by
// sampleVisibleFaces may be removed. Candidates are the single-occluder PVS.
// The oracle casts its rays over the sealed surface (cracks narrower than
// the weld tolerance closed, common/world/sealed_surface.h), the reading
// the solids are made from.
#include "server/visibility/horizon_fusion.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <iostream>
#include <iterator>
#include <numbers>
#include <string>
#include <vector>

#include "common/generate/generate.h"
#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/raycast/sampled_visibility.h"
#include "common/world/sealed_surface.h"
#include "common/world/static_world.h"
#include "server/visibility/epsilon_pvs.h"
#include "tests/common/support/box_scenes.h"

namespace vistream {
namespace {

using testing::Loop;

enum class Winding { Outward, Inward, OpenBottom, OpenTop, OneFaceFlipped };

// A box as six loops (face order -x, +x, -y, +y, -z, +z), wound as asked.
uint32_t addWoundBox(Scene& scene, const std::string& name, glm::vec3 l, glm::vec3 h,
                     Winding winding) {
  std::vector<Loop> loops = {{{l.x, l.y, l.z}, {l.x, l.y, h.z}, {l.x, h.y, h.z}, {l.x, h.y, l.z}},
                             {{h.x, l.y, l.z}, {h.x, h.y, l.z}, {h.x, h.y, h.z}, {h.x, l.y, h.z}},
                             {{l.x, l.y, l.z}, {h.x, l.y, l.z}, {h.x, l.y, h.z}, {l.x, l.y, h.z}},
                             {{l.x, h.y, l.z}, {l.x, h.y, h.z}, {h.x, h.y, h.z}, {h.x, h.y, l.z}},
                             {{l.x, l.y, l.z}, {l.x, h.y, l.z}, {h.x, h.y, l.z}, {h.x, l.y, l.z}},
                             {{l.x, l.y, h.z}, {h.x, l.y, h.z}, {h.x, h.y, h.z}, {l.x, h.y, h.z}}};
  if (winding == Winding::Inward)
    for (Loop& loop : loops) std::reverse(loop.begin(), loop.end());
  if (winding == Winding::OneFaceFlipped) std::reverse(loops[3].begin(), loops[3].end());
  if (winding == Winding::OpenBottom) loops.erase(loops.begin() + 2);
  if (winding == Winding::OpenTop) loops.erase(loops.begin() + 3);
  return testing::addFaces(scene, name, loops);
}

// A ground quad, a row of 30 boxes 2 m wide touching side by side along X
// (z 10 to 14, 8 or 9 m tall: neighbours share no edge, so each stays its
// own closed component), and behind it a 6 m wide, 4 m tall box whose
// facing side (z = 30) is the face under test.
struct RowScene {
  Scene scene;
  uint32_t hiddenFace = 0;
  Box3f cell{glm::vec3(-2.0f, 0.2f, -2.0f), glm::vec3(2.0f, 2.0f, 2.0f)};
};

// `far` moves the row and the box behind it farther by that many metres.
RowScene rowScene(Winding winding, float rowBase = 0.0f, float far = 0.0f) {
  RowScene r;
  testing::addGround(r.scene, -60.0f, -20.0f, 60.0f, 60.0f + far);
  for (int k = -15; k < 15; ++k) {
    const float odd = float(k & 1);
    addWoundBox(r.scene, "row" + std::to_string(k), {2.0f * float(k), rowBase, 10.0f + far},
                {2.0f * float(k) + 2.0f, 8.0f + odd, 14.0f + 0.5f * odd + far}, winding);
  }
  const uint32_t first =
      testing::addBox(r.scene, "behind", {-3.0f, 0.0f, 30.0f + far}, {3.0f, 4.0f, 34.0f + far});
  r.hiddenFace = first + testing::kMinusZ;
  finalizeScene(r.scene);
  return r;
}

std::vector<uint32_t> allFaces(const Scene& scene) {
  std::vector<uint32_t> f(scene.faceCount);
  for (uint32_t i = 0; i < scene.faceCount; ++i) f[i] = i;
  return f;
}

bool has(const std::vector<uint32_t>& sorted, uint32_t f) {
  return std::binary_search(sorted.begin(), sorted.end(), f);
}

TEST(HorizonFusion, CullsAFaceThatOnlyARowOfTouchingBoxesHides) {
  const RowScene r = rowScene(Winding::Outward);
  // The known answer's premises: no single box hides the face, and no
  // sampled ray sees it.
  // (Planar fusion, off here, would hide it too: the boxes' fronts are
  // coplanar.)
  const EpsilonPvs single(r.scene);
  PvsOptions oneOccluder;
  oneOccluder.planarFusion = false;
  const PvsResult paper = single.compute(r.cell, oneOccluder);
  ASSERT_TRUE(has(paper.faces, r.hiddenFace));
  const FlatTriangles triangles = flattenScene(r.scene);
  const auto rays = makeEmbreeRayQuery(triangles);
  ASSERT_FALSE(has(sampleVisibleFaces(*rays, triangles, r.cell).faces, r.hiddenFace));

  const HorizonFusion fusion(r.scene);
  const HorizonFusionResult fused = fusion.cull(r.cell, paper.faces);
  EXPECT_FALSE(has(fused.faces, r.hiddenFace));
  EXPECT_EQ(fused.stats.culled, paper.faces.size() - fused.faces.size());
  EXPECT_TRUE(std::includes(paper.faces.begin(), paper.faces.end(), fused.faces.begin(),
                            fused.faces.end()));
}

TEST(HorizonFusion, FinerBinsReachARowBeyondTheFirstHorizonsReach) {
  // The row stands 250 m away: beyond the reach of azimuthBins (163 m with
  // the defaults), within that of the next level (652 m).
  const RowScene r = rowScene(Winding::Outward, 0.0f, 240.0f);
  const FlatTriangles triangles = flattenScene(r.scene);
  const auto rays = makeEmbreeRayQuery(triangles);
  SampledVisibilityOptions sampling;
  sampling.probeFaces = {r.hiddenFace};
  ASSERT_FALSE(has(sampleVisibleFaces(*rays, triangles, r.cell, sampling).faces, r.hiddenFace));

  HorizonFusionOptions coarse;
  coarse.refinements = 0;
  ASSERT_LT(2.0 * coarse.binMargin / (2.0 * std::numbers::pi / coarse.azimuthBins), 250.0);
  const HorizonFusion withoutRefinement(r.scene, coarse);
  EXPECT_TRUE(has(withoutRefinement.cull(r.cell, allFaces(r.scene)).faces, r.hiddenFace));
  const HorizonFusion refined(r.scene);
  EXPECT_FALSE(has(refined.cull(r.cell, allFaces(r.scene)).faces, r.hiddenFace));
}

// Sealing counts edges, not winding: a row wound inside out, or with one
// face flipped, hides the same face, and so does a row open only at its
// base (its floor lies below the cell); a row with a hole above the base
// makes no solid columns and hides nothing by them. Its walls still stand:
// with walls (the default) it hides the face too.
TEST(HorizonFusion, CullsTheSameFaceBehindARowWhateverItsWindingButNotThroughHolesAboveTheBase) {
  HorizonFusionOptions columnsOnly;
  columnsOnly.walls = false;
  for (const Winding w :
       {Winding::Inward, Winding::OneFaceFlipped, Winding::OpenBottom, Winding::OpenTop}) {
    const RowScene r = rowScene(w);
    const HorizonFusion byColumns(r.scene, columnsOnly), withWalls(r.scene);
    EXPECT_EQ(has(byColumns.cull(r.cell, allFaces(r.scene)).faces, r.hiddenFace),
              w == Winding::OpenTop)
        << int(w);
    EXPECT_FALSE(has(withWalls.cull(r.cell, allFaces(r.scene)).faces, r.hiddenFace)) << int(w);
  }
}

// Fences: single vertical sheets (open meshes, no solid at all), each a
// quad the loader splits along a diagonal, standing side by side along X at
// z = 12 from x = -30 to 30, 8 m tall, with an opening of `gap` metres
// centred on x = 0; behind them the box whose facing side is the face
// under test, as in rowScene. `offset` moves everything (coordinates far
// from the origin).
RowScene fenceScene(float gap, glm::vec3 offset = glm::vec3(0.0f)) {
  RowScene r;
  const glm::vec3 o = offset;
  testing::addGround(r.scene, o.x - 60.0f, o.z - 20.0f, o.x + 60.0f, o.z + 60.0f, o.y);
  for (int k = -10; k < 10; ++k) {
    float x0 = 3.0f * float(k), x1 = x0 + 3.0f;
    if (gap > 0.0f) {
      // Cut the opening out of the panels that reach into it.
      if (x1 > -0.5f * gap && x0 < 0.5f * gap) {
        if (x0 < -0.5f * gap)
          x1 = -0.5f * gap;
        else if (x1 > 0.5f * gap)
          x0 = 0.5f * gap;
        else
          continue;
      }
    }
    testing::addFaces(r.scene, "fence" + std::to_string(k),
                      {{o + glm::vec3(x0, 0.0f, 12.0f), o + glm::vec3(x1, 0.0f, 12.0f),
                        o + glm::vec3(x1, 8.0f, 12.0f), o + glm::vec3(x0, 8.0f, 12.0f)}});
  }
  const uint32_t first = testing::addBox(r.scene, "behind", o + glm::vec3(-3.0f, 0.0f, 30.0f),
                                         o + glm::vec3(3.0f, 4.0f, 34.0f));
  r.hiddenFace = first + testing::kMinusZ;
  r.cell = Box3f(r.cell.lo + o, r.cell.hi + o);
  finalizeScene(r.scene);
  return r;
}

// The known answer: sheets that are no solid hide the face together (no
// sheet alone does: the epsilon-PVS keeps it), and only by their walls.
TEST(HorizonFusion, WallsOfOpenSheetsHideAFaceThatNoSolidHides) {
  for (const glm::vec3 offset : {glm::vec3(0.0f), glm::vec3(-30000.0f, 50.0f, 40000.0f)}) {
    const RowScene r = fenceScene(0.0f, offset);
    const FlatTriangles triangles = flattenScene(r.scene);
    const auto rays = makeEmbreeRayQuery(triangles);
    SampledVisibilityOptions sampling;
    sampling.probeFaces = {r.hiddenFace};
    ASSERT_FALSE(has(sampleVisibleFaces(*rays, triangles, r.cell, sampling).faces, r.hiddenFace));
    const EpsilonPvs single(r.scene);
    PvsOptions oneOccluder;
    oneOccluder.planarFusion = false;
    ASSERT_TRUE(has(single.compute(r.cell, oneOccluder).faces, r.hiddenFace));

    HorizonFusionOptions columnsOnly;
    columnsOnly.walls = false;
    const HorizonFusion byColumns(r.scene, columnsOnly), withWalls(r.scene);
    EXPECT_TRUE(has(byColumns.cull(r.cell, allFaces(r.scene)).faces, r.hiddenFace));
    const HorizonFusionResult fused = withWalls.cull(r.cell, allFaces(r.scene));
    EXPECT_FALSE(has(fused.faces, r.hiddenFace)) << offset.x;
    EXPECT_GT(fused.stats.wallSteps, 0u);
    // The 20 panels stand on one line: one wall line, and the box behind
    // has four.
    EXPECT_EQ(withWalls.wallLines(), 5u);
  }
}

// An opening in the fence: what is seen through it stays, whatever the
// erosion; an opening narrower than the erosion of the walls' ends still
// leaves the face in (nothing proves it hidden), which the sampled truth
// decides is seen or not; either way nothing seen is culled.
TEST(HorizonFusion, KeepsWhatIsSeenThroughAnOpeningBetweenWalls) {
  for (const float gap : {0.05f, 0.5f, 3.0f}) {
    const RowScene r = fenceScene(gap);
    const FlatTriangles triangles = flattenScene(r.scene);
    const auto rays = makeEmbreeRayQuery(triangles);
    const HorizonFusion fusion(r.scene);
    const HorizonFusionResult fused = fusion.cull(r.cell, allFaces(r.scene));
    SampledVisibilityOptions sampling;
    sampling.probeFaces = allFaces(r.scene);
    const SampledVisibility seen = sampleVisibleFaces(*rays, triangles, r.cell, sampling);
    if (gap >= 3.0f) {
      ASSERT_TRUE(has(seen.faces, r.hiddenFace));
    }
    EXPECT_TRUE(has(fused.faces, r.hiddenFace)) << gap;
    for (uint32_t f : seen.faces)
      EXPECT_TRUE(has(fused.faces, f)) << "face " << f << ", gap " << gap;
  }
}

// A V of two open sheets 8 m tall, its apex at (10, 10) pointing at the
// cell (the corner of a building without a back, seen from the street),
// and behind it a box whose two faces towards the cell are under test. The
// sheets meet at the apex, or leave a hairline (1 mm) or a real (0.4 m)
// slit there. `offset` moves everything.
struct CornerScene {
  Scene scene;
  uint32_t hiddenFaces[2] = {0, 0};
  Box3f cell{glm::vec3(-2.0f, 0.2f, -2.0f), glm::vec3(2.0f, 2.0f, 2.0f)};
};

CornerScene cornerScene(float slit, glm::vec3 offset = glm::vec3(0.0f)) {
  CornerScene r;
  const glm::vec3 o = offset;
  testing::addGround(r.scene, o.x - 20.0f, o.z - 20.0f, o.x + 60.0f, o.z + 60.0f, o.y);
  const float a = 10.0f + slit / std::sqrt(2.0f);
  testing::addFaces(r.scene, "alongX",
                    {{o + glm::vec3(a, 0.0f, 10.0f), o + glm::vec3(40.0f, 0.0f, 10.0f),
                      o + glm::vec3(40.0f, 8.0f, 10.0f), o + glm::vec3(a, 8.0f, 10.0f)}});
  testing::addFaces(r.scene, "alongZ",
                    {{o + glm::vec3(10.0f, 0.0f, 40.0f), o + glm::vec3(10.0f, 0.0f, a),
                      o + glm::vec3(10.0f, 8.0f, a), o + glm::vec3(10.0f, 8.0f, 40.0f)}});
  const uint32_t first = testing::addBox(r.scene, "behind", o + glm::vec3(20.0f, 0.0f, 20.0f),
                                         o + glm::vec3(24.0f, 4.0f, 24.0f));
  r.hiddenFaces[0] = first + testing::kMinusX;
  r.hiddenFaces[1] = first + testing::kMinusZ;
  r.cell = Box3f(r.cell.lo + o, r.cell.hi + o);
  finalizeScene(r.scene);
  return r;
}

// The known answer: behind a closed corner the box is hidden, but each
// sheet alone, eroded at the corner by the shrinking, leaves the lines of
// sight near the apex open; the chain of the two (proof, step 8) closes
// them, near the origin and 50 km from it. A 1 mm slit is a crack taken as
// closed.
TEST(HorizonFusion, ChainsOfWallsHideWhatACornerHidesAndNoWallAloneDoes) {
  for (const float slit : {0.0f, 0.001f})
    for (const glm::vec3 offset : {glm::vec3(0.0f), glm::vec3(-30000.0f, 50.0f, 40000.0f)}) {
      const CornerScene r = cornerScene(slit, offset);
      // The truth over the sealed surface: the 1 mm slit closed.
      const StaticWorld world = buildStaticWorld(r.scene);
      const auto sealed = makeSealedRayQuery(*world.triangles, world.solids.weldTolerance());
      SampledVisibilityOptions sampling;
      sampling.probeFaces = {r.hiddenFaces[0], r.hiddenFaces[1]};
      const SampledVisibility seen =
          sampleVisibleFaces(*sealed, *world.triangles, r.cell, sampling);
      ASSERT_FALSE(has(seen.faces, r.hiddenFaces[0]) || has(seen.faces, r.hiddenFaces[1]))
          << "slit " << slit << ", offset " << offset.x;
      HorizonFusionOptions alone;
      alone.wallChains = false;
      const HorizonFusion byLines(r.scene, world, alone), byChains(r.scene, world);
      const HorizonFusionResult lines = byLines.cull(r.cell, allFaces(r.scene));
      const HorizonFusionResult chains = byChains.cull(r.cell, allFaces(r.scene));
      for (const uint32_t f : r.hiddenFaces) {
        EXPECT_TRUE(has(lines.faces, f)) << "slit " << slit << ", offset " << offset.x;
        EXPECT_FALSE(has(chains.faces, f)) << "slit " << slit << ", offset " << offset.x;
      }
      EXPECT_GT(chains.stats.chainSteps, 0u);
      EXPECT_EQ(lines.stats.chainSteps, 0u);
    }
}

// A real slit at the apex: the box is seen through it, and kept.
TEST(HorizonFusion, KeepsWhatIsSeenThroughASlitAtACorner) {
  const CornerScene r = cornerScene(0.4f);
  const FlatTriangles triangles = flattenScene(r.scene);
  const auto rays = makeEmbreeRayQuery(triangles);
  SampledVisibilityOptions sampling;
  sampling.probeFaces = allFaces(r.scene);
  const SampledVisibility seen = sampleVisibleFaces(*rays, triangles, r.cell, sampling);
  ASSERT_TRUE(has(seen.faces, r.hiddenFaces[0]) || has(seen.faces, r.hiddenFaces[1]));
  const HorizonFusion fusion(r.scene);
  const HorizonFusionResult fused = fusion.cull(r.cell, allFaces(r.scene));
  for (uint32_t f : seen.faces) EXPECT_TRUE(has(fused.faces, f)) << "face " << f;
}

// Random sheets at every angle, grazing ones included, some cut into
// collinear pieces with hairline or real gaps between them, and zigzags of
// sheets turning at corners, around street cells: no face the sampled truth
// sees is culled, and walls cull something, chains of walls among them.
TEST(HorizonFusion, CullsNoSampledVisibleFaceAmongRandomWallsAtEveryAngle) {
  size_t culled = 0;
  uint64_t chainSteps = 0;
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    Scene scene;
    testing::addGround(scene, -120.0f, -120.0f, 120.0f, 120.0f);
    uint32_t state = seed * 2654435761u;
    auto uniform = [&](float a, float b) {
      state = state * 1664525u + 1013904223u;
      return a + (b - a) * float(state >> 8) / float(1u << 24);
    };
    for (int k = 0; k < 140; ++k) {
      glm::vec2 c(uniform(-100.0f, 100.0f), uniform(-100.0f, 100.0f));
      if (glm::length(c) < 12.0f) continue;  // keep clear of the cells
      const float angle = uniform(0.0f, 6.2831853f), length = uniform(2.0f, 20.0f);
      const float height = uniform(2.0f, 14.0f), base = k % 7 == 0 ? uniform(0.5f, 2.0f) : 0.0f;
      const glm::vec2 dir(std::cos(angle), std::sin(angle));
      const int pieces = 1 + k % 3;
      for (int p = 0; p < pieces; ++p) {
        // Pieces touch, or leave a hairline (1 mm) or a real (0.3 m) gap.
        const float gap = p == 0 ? 0.0f : (k % 5 == 0 ? 0.3f : (k % 5 == 1 ? 0.001f : 0.0f));
        const float s0 = length * float(p) / float(pieces) + gap,
                    s1 = length * float(p + 1) / float(pieces);
        const glm::vec2 a = c + s0 * dir, b = c + s1 * dir;
        testing::addFaces(scene, "wall" + std::to_string(k) + "_" + std::to_string(p),
                          {{{a.x, base, a.y},
                            {b.x, base, b.y},
                            {b.x, base + height, b.y},
                            {a.x, base + height, a.y}}});
      }
    }
    // Zigzags: 2 to 4 sheets turning at corners by any angle, meeting
    // there or leaving a hairline (1 mm) or a real (0.3 m) slit.
    for (int k = 0; k < 40; ++k) {
      glm::vec2 at(uniform(-100.0f, 100.0f), uniform(-100.0f, 100.0f));
      if (glm::length(at) < 14.0f) continue;
      float angle = uniform(0.0f, 6.2831853f);
      const float base = k % 6 == 0 ? uniform(0.5f, 2.0f) : 0.0f;
      const int legs = 2 + k % 3;
      for (int leg = 0; leg < legs; ++leg) {
        const glm::vec2 dir(std::cos(angle), std::sin(angle));
        const float slit = leg == 0 ? 0.0f : (k % 4 == 1 ? 0.001f : (k % 4 == 2 ? 0.3f : 0.0f));
        const glm::vec2 a = at + slit * dir, b = at + uniform(2.0f, 12.0f) * dir;
        const float height = uniform(2.0f, 12.0f);
        testing::addFaces(scene, "zigzag" + std::to_string(k) + "_" + std::to_string(leg),
                          {{{a.x, base, a.y},
                            {b.x, base, b.y},
                            {b.x, base + height, b.y},
                            {a.x, base + height, a.y}}});
        at = b;
        angle += uniform(0.3f, 2.8f) * (uniform(0.0f, 1.0f) < 0.5f ? 1.0f : -1.0f);
      }
    }
    for (int k = 0; k < 30; ++k) {
      const glm::vec2 c(uniform(-100.0f, 100.0f), uniform(-100.0f, 100.0f));
      if (glm::length(c) < 12.0f) continue;
      testing::addBox(scene, "box" + std::to_string(k), {c.x - 1.5f, 0.0f, c.y - 1.5f},
                      {c.x + 1.5f, uniform(1.0f, 6.0f), c.y + 1.5f});
    }
    finalizeScene(scene);
    const StaticWorld world = buildStaticWorld(scene);
    const HorizonFusion fusion(scene, world);
    const auto sealed = makeSealedRayQuery(*world.triangles, world.solids.weldTolerance());
    for (const glm::vec2 c : {glm::vec2(0.0f), glm::vec2(5.0f, -4.0f)}) {
      const Box3f cell(glm::vec3(c.x - 2.0f, 0.2f, c.y - 2.0f),
                       glm::vec3(c.x + 2.0f, 2.0f, c.y + 2.0f));
      const HorizonFusionResult fused = fusion.cull(cell, allFaces(scene));
      SampledVisibilityOptions sampling;
      sampling.skipViewpoint = [&world](const glm::vec3& p) {
        return world.solids.unservedViewpoint(*world.rays, p);
      };
      const std::vector<uint32_t> all = allFaces(scene);
      std::set_difference(all.begin(), all.end(), fused.faces.begin(), fused.faces.end(),
                          std::back_inserter(sampling.probeFaces));
      const SampledVisibility seen = sampleVisibleFaces(*sealed, *world.triangles, cell, sampling);
      for (uint32_t f : seen.faces)
        EXPECT_TRUE(has(fused.faces, f)) << "seed " << seed << ": face " << f << " seen but culled";
      culled += fused.stats.culled;
      chainSteps += fused.stats.chainSteps;
    }
  }
  EXPECT_GT(culled, 0u);
  EXPECT_GT(chainSteps, 0u);
}

TEST(HorizonFusion, KeepsAFaceSeenUnderARowThatFloatsAboveTheCellsBottom) {
  // The row stands on nothing from y = 1 up, closed or open at its base
  // (its floor then lies inside the cell's heights); the cell reaches down
  // to 0.2 m, and from there the face behind is seen under the row.
  for (const Winding w : {Winding::Outward, Winding::OpenBottom}) {
    const RowScene r = rowScene(w, 1.0f);
    const FlatTriangles triangles = flattenScene(r.scene);
    const auto rays = makeEmbreeRayQuery(triangles);
    ASSERT_TRUE(has(sampleVisibleFaces(*rays, triangles, r.cell).faces, r.hiddenFace));
    const HorizonFusion fusion(r.scene);
    EXPECT_TRUE(has(fusion.cull(r.cell, allFaces(r.scene)).faces, r.hiddenFace)) << int(w);
  }
}

// A cell that cuts into a building is served outside it only (the PVS
// contract, Solids::unservedViewpoint): the building's far wall, which only
// a viewpoint inside it sees, goes; nothing seen from a served viewpoint
// does.
TEST(HorizonFusion, ServesACellThatCutsIntoABuildingOutsideIt) {
  for (const Winding w : {Winding::Outward, Winding::OpenBottom}) {
    RowScene r = rowScene(w);
    // The cell reaches 0.4 m into the row box at x in [0, 2] (z from 10).
    r.cell = Box3f(glm::vec3(-1.0f, 0.2f, 6.4f), glm::vec3(3.0f, 2.0f, 10.4f));
    // Face IDs of the row box k = 0 (the 16th box after the ground quad;
    // one face fewer a box when open at the base, the far wall one earlier).
    const uint32_t perBox = w == Winding::OpenBottom ? 5 : 6;
    const uint32_t farWall = 1 + 15 * perBox + testing::kPlusZ - (perBox == 5 ? 1 : 0);
    const StaticWorld world = buildStaticWorld(r.scene);
    const FlatTriangles& triangles = *world.triangles;
    // The premises: from a viewpoint of the cell inside the box, the first
    // hit towards the far wall is the far wall, and that viewpoint is not
    // served.
    const glm::vec3 inside(1.0f, 1.0f, 10.2f), target(1.0f, 4.0f, 14.0f);
    const Hit hit = world.rays->firstHit(Ray{inside, target - inside, 0.0f, 2.0f});
    ASSERT_TRUE(hit.valid());
    ASSERT_EQ(triangles.faceIds[hit.triangle], farWall) << int(w);
    ASSERT_TRUE(r.cell.contains(inside));
    ASSERT_TRUE(world.solids.unservedViewpoint(*world.rays, inside)) << int(w);

    const HorizonFusion fusion(r.scene, world);
    const HorizonFusionResult fused = fusion.cull(r.cell, allFaces(r.scene));
    EXPECT_FALSE(has(fused.faces, farWall)) << int(w);
    EXPECT_EQ(fused.stats.excludedSolids, 0u) << int(w);
    SampledVisibilityOptions sampling;
    sampling.skipViewpoint = [&world](const glm::vec3& p) {
      return world.solids.unservedViewpoint(*world.rays, p);
    };
    sampling.probeFaces = allFaces(r.scene);
    const SampledVisibility seen = sampleVisibleFaces(*world.rays, triangles, r.cell, sampling);
    EXPECT_GT(seen.insideSolid, 0u) << int(w);
    EXPECT_GT(seen.viewpoints, 0u) << int(w);
    for (uint32_t f : seen.faces)
      EXPECT_TRUE(has(fused.faces, f)) << "face " << f << ", " << int(w);
  }
}

// An open base below the cell's bottom lets lines in under the building:
// an enclosure whose floor the cell reaches occludes nothing for it.
TEST(HorizonFusion, ExcludesABuildingOpenAtABaseTheCellReachesDownTo) {
  RowScene r = rowScene(Winding::OpenBottom);
  r.cell = Box3f(glm::vec3(-2.0f, -0.5f, -2.0f), glm::vec3(2.0f, 2.0f, 2.0f));
  const HorizonFusion fusion(r.scene);
  const HorizonFusionResult fused = fusion.cull(r.cell, allFaces(r.scene));
  EXPECT_TRUE(has(fused.faces, r.hiddenFace));
  EXPECT_GE(fused.stats.excludedSolids, 1u);
}

TEST(HorizonFusion, KeepsFacesItCannotTestAndReturnsThemSorted) {
  const RowScene r = rowScene(Winding::Outward);
  const HorizonFusion fusion(r.scene);
  std::vector<uint32_t> candidates = allFaces(r.scene);
  candidates.push_back(r.scene.faceCount + 5);  // not a face of the scene
  const HorizonFusionResult fused = fusion.cull(r.cell, candidates);
  EXPECT_TRUE(std::is_sorted(fused.faces.begin(), fused.faces.end()));
  EXPECT_TRUE(has(fused.faces, r.scene.faceCount + 5));
  EXPECT_TRUE(fusion.cull(r.cell, {}).faces.empty());
}

TEST(HorizonFusion, StatsListEveryFieldOnceWithItsKeyAndLabel) {
  std::vector<std::string> keys, labels;
  HorizonFusionStats{}.forEachField([&](const StatField& f, auto) {
    keys.emplace_back(f.key);
    labels.emplace_back(f.label);
  });
  EXPECT_EQ(keys, (std::vector<std::string>{"time_ms", "candidate_faces", "culled", "samples",
                                            "excluded_solids", "column_steps", "horizon_bins",
                                            "wall_steps", "chain_steps"}));
  EXPECT_EQ(labels,
            (std::vector<std::string>{
                "time", "candidate faces", "culled by fused horizons", "samples",
                "enclosures reaching below the cell", "columns walked", "azimuth bins traced",
                "horizon steps made by walls", "horizon steps made by chains of walls"}));
}

// Street cells of 4 m, eye height, over walkable columns spread evenly.
std::vector<Box3f> streetCells(const FreeSpace& fs, size_t count) {
  const auto columns = fs.walkableColumns();
  std::vector<Box3f> cells;
  for (size_t k = 0; k < count && !columns.empty(); ++k) {
    const glm::ivec2 c = columns[(k * columns.size() + columns.size() / 3) / count];
    const glm::vec2 xz = fs.columnCentre(c.x, c.y);
    const float y = fs.floorHeight(c.x, c.y) + 0.2f;
    cells.emplace_back(glm::vec3(xz.x - 2.0f, y, xz.y - 2.0f),
                       glm::vec3(xz.x + 2.0f, y + 1.8f, xz.y + 2.0f));
  }
  return cells;
}

// Every face is a candidate, so the stage is checked on its own; the
// single-occluder PVS and the two stages together are printed for scale.
void expectNoSampledFaceCulled(const std::string& spec, size_t cellCount, bool expectCulls) {
  const Scene scene = openScene(spec);
  const StaticWorld world = buildStaticWorld(scene);
  const EpsilonPvs single(scene);
  const HorizonFusion fusion(scene, world);  // over the same triangles and solids
  const auto sealed = makeSealedRayQuery(*world.triangles, world.solids.weldTolerance());
  const std::vector<uint32_t> all = allFaces(scene);
  size_t missing = 0, paperFaces = 0, bothFaces = 0, seenFaces = 0, culled = 0;
  for (const Box3f& cell : streetCells(world.freeSpace, cellCount)) {
    const HorizonFusionResult fused = fusion.cull(cell, all);
    const PvsResult paper = single.compute(cell);
    const HorizonFusionResult both = fusion.cull(cell, paper.faces);
    // The sampler also aims rays at every face the stage removed from the
    // single-occluder PVS: a face culled wrongly is found even when it is
    // smaller than a cube-map pixel.
    // Viewpoints the PVS contract does not serve (inside solids) are left out.
    SampledVisibilityOptions sampling;
    sampling.skipViewpoint = [&world](const glm::vec3& p) {
      return world.solids.unservedViewpoint(*world.rays, p);
    };
    std::set_difference(paper.faces.begin(), paper.faces.end(), both.faces.begin(),
                        both.faces.end(), std::back_inserter(sampling.probeFaces));
    const SampledVisibility seen = sampleVisibleFaces(*sealed, *world.triangles, cell, sampling);
    for (uint32_t f : seen.faces)
      if (!has(fused.faces, f) || !has(both.faces, f)) {
        ++missing;
        ADD_FAILURE() << spec << ": face " << f << " is seen from cell (" << cell.lo.x << ", "
                      << cell.lo.y << ", " << cell.lo.z << ") but was culled";
      }
    paperFaces += paper.faces.size();
    bothFaces += both.faces.size();
    seenFaces += seen.faces.size();
    culled += fused.stats.culled;
  }
  // The test must not be empty: the fused stage culls something here.
  if (expectCulls) {
    EXPECT_GT(culled, 0u) << spec;
  }
  std::cout << "[ fusion   ] " << spec << ": single-occluder PVS " << paperFaces << ", then fused "
            << bothFaces << ", sampled " << seenFaces << ", missing " << missing << "\n";
}

TEST(HorizonFusion, CullsNoSampledVisibleFaceOnCity1) {
  expectNoSampledFaceCulled("city1", 6, true);
}
TEST(HorizonFusion, CullsNoSampledVisibleFaceOnCity2) {
  expectNoSampledFaceCulled("city2", 6, true);
}
// Culls every face of four 4 m street cells of `name` with the default
// options and with `changed`, and hands each cell's pair of results to
// `check(defaults, changed)`.
template <class Check>
void cullStreetCellsBothWays(const std::string& name, const HorizonFusionOptions& changed,
                             Check&& check) {
  const Scene scene = openScene(name);
  const StaticWorld world = buildStaticWorld(scene);
  const HorizonFusion byDefault(scene, world), other(scene, world, changed);
  const std::vector<uint32_t> all = allFaces(scene);
  for (const Box3f& cell : streetCells(world.freeSpace, 4))
    check(byDefault.cull(cell, all), other.cull(cell, all));
}

// Skipping blocks is a shortcut of the walk, not an approximation: the
// same bins are traced and the same faces culled as by walks that read every
// column, on a sparse city whose streets and squares are mostly empty blocks.
TEST(HorizonFusion, CullsTheSameFacesWhenItSkipsBlocksAsWhenItReadsEveryColumn) {
  HorizonFusionOptions everyColumn;
  everyColumn.skipBlocks = false;
  uint64_t skippedSteps = 0, readSteps = 0;
  size_t culled = 0;
  cullStreetCellsBothWays("city2", everyColumn,
                          [&](const HorizonFusionResult& fast, const HorizonFusionResult& slow) {
                            EXPECT_EQ(fast.faces, slow.faces);
                            EXPECT_EQ(fast.stats.horizonBins, slow.stats.horizonBins);
                            skippedSteps += fast.stats.columnSteps;
                            readSteps += slow.stats.columnSteps;
                            culled += fast.stats.culled;
                          });
  EXPECT_GT(culled, 0u);
  // The skips are taken: far fewer columns are read.
  EXPECT_LT(4 * skippedSteps, readSteps);
}

// Hiding hints are a shortcut that can only add culled faces: a face the
// piece around a bin's last hiding distance does not hide gets the walk from
// the sample, the same walk as without hints. On street cells of a dense
// and a sparse city, every face hints leave is left without them too.
TEST(HorizonFusion, CullsEveryFaceWithHidingHintsThatItCullsWithout) {
  HorizonFusionOptions noHints;
  noHints.hidingHints = false;
  for (const char* name : {"city1", "city2"}) {
    size_t culledWith = 0, culledWithout = 0;
    cullStreetCellsBothWays(
        name, noHints, [&](const HorizonFusionResult& with, const HorizonFusionResult& without) {
          // Both lists are sorted: the faces kept with hints are a subset.
          EXPECT_TRUE(std::includes(without.faces.begin(), without.faces.end(), with.faces.begin(),
                                    with.faces.end()))
              << name;
          culledWith += with.stats.culled;
          culledWithout += without.stats.culled;
        });
    EXPECT_GT(culledWithout, 0u) << name;
    EXPECT_GE(culledWith, culledWithout) << name;
  }
}

// Most buildings of the real model are open at the base (no ground
// surface) or non-manifold (party walls hanging under roofs); as
// enclosures, with their dangling sheets peeled, they occlude above their
// floor.
TEST(HorizonFusion, CullsNoSampledVisibleFaceOnTheRealCityModel) {
  expectNoSampledFaceCulled(std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj", 6, true);
}

}  // namespace
}  // namespace vistream
