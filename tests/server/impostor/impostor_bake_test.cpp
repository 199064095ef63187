// Point-based impostors (Wimmer 2001, chapter 5): the framing of the shaft,
// the thesis's resolution factors, and the hard cases of the issue: no holes
// from anywhere in the cell, a surface in the plane of two cameras,
// microgeometry that changes colour across the cell, a cell touching its
// box, coordinates far from the origin. Oracles: random rays from the cell to
// the box, a 1D search over the symmetric triangle, and per-pixel ray casts
// of the impostor's own geometry. Then the client's pipeline drawing an
// impostor: against a ray-cast reference of the whole scene, with held
// geometry in front of it, and outside its cell.
#include "server/impostor/impostor_bake.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <glm/gtc/constants.hpp>
#include <optional>
#include <random>
#include <set>

#include "client/farfield/pipeline.h"
#include "client/render/camera.h"
#include "client/render/impostor_splat.h"
#include "common/core/error.h"
#include "common/generate/scene_spec.h"
#include "common/raycast/ray_query.h"
#include "common/scene/scene.h"
#include "protocol/impostor/impostor_codec.h"
#include "server/impostor/impostor_world.h"
#include "tests/common/support/box_scenes.h"
#include "tests/server/impostor/face_coverage.h"

namespace vistream {
namespace {

using testing::addBox;

// A scene's static triangles with one flat colour per triangle, and the
// Embree query the bake samples.
struct ColouredScene {
  Scene scene;
  FlatTriangles triangles;
  LightingGrid lighting;
  std::unique_ptr<RayQuery> rays;
  std::vector<uint32_t> all;

  void finish(const std::function<glm::u8vec3(size_t, const glm::vec3&)>& colourOf) {
    finalizeScene(scene);
    triangles = flattenScene(scene, true);
    for (size_t t = 0; t < triangles.size(); ++t) {
      const glm::vec3 a = triangles.vertex(t, 0);
      const glm::vec3 n = glm::cross(triangles.vertex(t, 1) - a, triangles.vertex(t, 2) - a);
      lighting.appendFlat(colourOf(t, n));
      all.push_back(uint32_t(t));
    }
    rays = makeEmbreeRayQuery(triangles);
  }
  // The triangles a cell's PVS would hold: all but faces of these closed
  // boxes whose plane has the whole cell behind it (vistream-pvs culls those).
  std::vector<uint32_t> facingCell(const Box3f& cell) const {
    std::vector<uint32_t> out;
    for (uint32_t t : all) {
      const glm::vec3 a = triangles.vertex(t, 0);
      const glm::vec3 n = glm::cross(triangles.vertex(t, 1) - a, triangles.vertex(t, 2) - a);
      bool front = false;
      for (int k = 0; k < 8; ++k) {
        front = front || glm::dot(n, cell.corner(k) - a) > 0.0f;
      }
      if (front) out.push_back(t);
    }
    return out;
  }
  ImpostorScene view() const {
    Backdrop b;
    b.haze.scale = 0.0f;
    return ImpostorScene{triangles, *rays, lighting, b, std::nullopt};
  }
};

// A block of buildings at `offset` + (-40..40, 0..30, -300..-220) in front of
// a cell round `offset`: boxes of several sizes, thin poles, a low wall.
ColouredScene buildingBlock(const glm::vec3& offset = glm::vec3(0.0f)) {
  ColouredScene s;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> x(-38.0f, 30.0f), z(-295.0f, -235.0f), w(3.0f, 12.0f),
      h(5.0f, 28.0f);
  for (int k = 0; k < 14; ++k) {
    const glm::vec3 lo(x(rng), 0.0f, z(rng));
    addBox(s.scene, "b" + std::to_string(k), offset + lo,
           offset + lo + glm::vec3(w(rng), h(rng), w(rng)));
  }
  for (int k = 0; k < 6; ++k) {  // poles 0.3 m thick: a little over half a pixel at 320x240
    const glm::vec3 lo(-30.0f + 10.0f * float(k), 0.0f, -225.0f);
    addBox(s.scene, "pole" + std::to_string(k), offset + lo,
           offset + lo + glm::vec3(0.3f, 12.0f, 0.3f));
  }
  addBox(s.scene, "wall", offset + glm::vec3(-40.0f, 0.0f, -230.0f),
         offset + glm::vec3(40.0f, 2.5f, -229.5f));
  s.finish([](size_t t, const glm::vec3& n) {
    const glm::vec3 u = glm::normalize(n);
    return glm::u8vec3(uint8_t(128 + 100 * u.x), uint8_t(128 + 100 * u.y),
                       uint8_t(100 + (t * 37) % 120));
  });
  return s;
}

Box3f boundsOf(const FlatTriangles& t) {
  Box3f b;
  for (const glm::vec3& p : t.positions) b.extend(p);
  return b;
}

// Cameras at random points of the cell looking at random points of the box.
std::vector<Camera> viewsFromCell(const Box3f& cell, const Box3f& box, int count, int width,
                                  int height, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::vector<Camera> out;
  for (int k = 0; k < count; ++k) {
    Camera c;
    c.width = width;
    c.height = height;
    c.eye = cell.lo + glm::vec3(unit(rng), unit(rng), unit(rng)) * cell.extent();
    const glm::vec3 target = box.lo + glm::vec3(unit(rng), unit(rng), unit(rng)) * box.extent();
    const glm::vec3 d = glm::normalize(target - c.eye);
    c.yawDeg = glm::degrees(std::atan2(-d.x, -d.z));
    c.pitchDeg = glm::degrees(std::asin(d.y));
    out.push_back(c);
  }
  return out;
}

// Pixels whose centre ray meets the impostor's geometry inside its box but
// that no point covers.
struct HoleCount {
  size_t geometryPixels = 0, uncovered = 0;
};
HoleCount holes(const ColouredScene& s, const Impostor& imp, const Camera& camera) {
  ImpostorSplatter splatter;
  splatter.begin(camera);
  ImageRgb8 image(camera.width, camera.height);
  splatter.draw(imp, image);
  HoleCount h;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const glm::vec3 dir = camera.rayDirection(float(x) + 0.5f, float(y) + 0.5f);
      // The part of the ray inside the box.
      float t0 = 0.0f, t1 = 1e30f;
      for (int a = 0; a < 3; ++a) {
        if (dir[a] == 0.0f) continue;
        float n = (imp.box.lo[a] - camera.eye[a]) / dir[a],
              f = (imp.box.hi[a] - camera.eye[a]) / dir[a];
        if (n > f) std::swap(n, f);
        t0 = std::max(t0, n);
        t1 = std::min(t1, f);
      }
      if (t0 > t1 || !s.rays->firstHit(Ray{camera.eye, dir, t0, t1}).valid()) continue;
      ++h.geometryPixels;
      if (!splatter.covered(x, y)) ++h.uncovered;
    }
  return h;
}

// holes() summed over `count` views from random points of the cell.
HoleCount holesFromCell(const ColouredScene& s, const Impostor& imp, int count, uint32_t seed) {
  HoleCount sum;
  for (const Camera& c : viewsFromCell(imp.cell, imp.box, count, 320, 240, seed)) {
    const HoleCount h = holes(s, imp, c);
    sum.geometryPixels += h.geometryPixels;
    sum.uncovered += h.uncovered;
  }
  return sum;
}

ImpostorOptions quickOptions(int width, int height) {
  ImpostorOptions o;
  o.screen.width = width;
  o.screen.height = height;
  o.minRays = 2;
  o.maxRays = 4;
  return o;
}

// The same with points kept where they were sampled (to a few micrometres
// at these depths), for tests of where the sampling puts them.
ImpostorOptions preciseOptions(int width, int height) {
  ImpostorOptions o = quickOptions(width, height);
  o.positionError = 1e-4f;
  return o;
}

TEST(ImpostorFrame, EveryRayFromTheCellToTheBoxCrossesTheSamplingRectangle) {
  const Box3f cell({-4.0f, 0.0f, -3.0f}, {4.0f, 3.0f, 3.0f});
  const Box3f box({60.0f, 0.0f, -320.0f}, {180.0f, 45.0f, -200.0f});
  const ImpostorFrame f = frameImpostor(cell, box);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (int k = 0; k < 20000; ++k) {
    const glm::vec3 s = cell.lo + glm::vec3(unit(rng), unit(rng), unit(rng)) * cell.extent();
    const glm::vec3 p = box.lo + glm::vec3(unit(rng), unit(rng), unit(rng)) * box.extent();
    const glm::vec2 st = f.plane.textureCoordinates(s, p);
    ASSERT_GE(st.x, -1e-4f);
    ASSERT_LE(st.x, 1.0f + 1e-4f);
    ASSERT_GE(st.y, -1e-4f);
    ASSERT_LE(st.y, 1.0f + 1e-4f);
  }
  // The plane faces the box, with the whole cell behind it.
  for (int k = 0; k < 8; ++k) {
    EXPECT_LE(glm::dot(f.plane.normal, cell.corner(k) - f.plane.origin), 1e-3f);
  }
  EXPECT_GT(f.nearestDepth, 150.0f);
}

TEST(ImpostorFrame, TheCameraTriangleHasAHorizontalTopEdgeAndHoldsTheSection) {
  const Box3f cell({-4.0f, 0.0f, -3.0f}, {4.0f, 3.0f, 3.0f});
  const Box3f box({-50.0f, 0.0f, -320.0f}, {70.0f, 45.0f, -200.0f});
  const ImpostorFrame f = frameImpostor(cell, box);
  EXPECT_NEAR(f.cameras[0].y, f.cameras[1].y, 1e-3f);
  EXPECT_LT(f.cameras[2].y, f.cameras[0].y);
  const glm::vec3 u = glm::normalize(f.plane.uAxis), v = glm::normalize(f.plane.vAxis);
  std::array<glm::vec2, 3> t;
  for (size_t k = 0; k < 3; ++k)
    t[k] = {glm::dot(f.cameras[k] - f.centre, u), glm::dot(f.cameras[k] - f.centre, v)};
  auto side = [](glm::vec2 a, glm::vec2 b, glm::vec2 p) {
    return (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x);
  };
  for (const glm::vec2& p : f.section) {
    const float s0 = side(t[0], t[1], p), s1 = side(t[1], t[2], p), s2 = side(t[2], t[0], p);
    const bool inside = (s0 <= 1e-3f && s1 <= 1e-3f && s2 <= 1e-3f) ||
                        (s0 >= -1e-3f && s1 >= -1e-3f && s2 >= -1e-3f);
    EXPECT_TRUE(inside) << p.x << "," << p.y;
  }
}

TEST(ImpostorFrame, ARectangularSectionGetsTheIsoscelesTriangleOfLeastCircumference) {
  // A cell and box symmetric about the x = 0 plane, level with each other:
  // the section is symmetric, and the best triangle round a w x h rectangle
  // (top edge on its top) has perimeter min over a of
  // w + 2h tan a + (w + 2h tan a) / sin a.
  const Box3f cell({-5.0f, 0.0f, -2.0f}, {5.0f, 4.0f, 2.0f});
  const Box3f box({-5.0f, 0.0f, -402.0f}, {5.0f, 4.0f, -400.0f});
  const ImpostorFrame f = frameImpostor(cell, box);
  glm::vec2 lo(1e9f), hi(-1e9f);
  for (const glm::vec2& p : f.section) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const double w = hi.x - lo.x, h = hi.y - lo.y;
  EXPECT_NEAR(w, 10.0, 1e-3);  // the shaft between equal faces is a prism
  EXPECT_NEAR(h, 4.0, 1e-3);
  double best = 1e30;
  for (double a = 0.001; a < glm::half_pi<double>(); a += 1e-5)
    best = std::min(best, w + 2 * h * std::tan(a) + (w + 2 * h * std::tan(a)) / std::sin(a));
  EXPECT_NEAR(f.trianglePerimeter, best, 1e-3 * best);
}

TEST(ImpostorFrame, ACellTouchingOrInsideItsBoxIsRefused) {
  const Box3f cell({-4.0f, 0.0f, -4.0f}, {4.0f, 3.0f, 4.0f});
  EXPECT_THROW(frameImpostor(cell, Box3f({-10.0f, 0.0f, -40.0f}, {10.0f, 9.0f, -4.0f})),
               InputError);  // touching
  EXPECT_THROW(frameImpostor(cell, Box3f({-10.0f, 0.0f, -40.0f}, {10.0f, 9.0f, -2.0f})),
               InputError);  // overlapping
  EXPECT_THROW(frameImpostor(cell, Box3f({-100.0f, -1.0f, -100.0f}, {100.0f, 9.0f, 100.0f})),
               InputError);                                // surrounding
  EXPECT_THROW(frameImpostor(cell, Box3f()), InputError);  // empty
  EXPECT_NO_THROW(frameImpostor(cell, Box3f({-10.0f, 0.0f, -40.0f}, {10.0f, 9.0f, -4.5f})));
}

TEST(ImpostorResolution, ThePerspectiveAndDiagonalFactorsAreTheThesisFigures) {
  // Section 5.4.1: a factor of about 1.17 for a 45-degree field of view, and
  // sqrt 2 for the pixel diagonal.
  ScreenSpec s;
  s.vfovDeg = 45.0f;
  EXPECT_NEAR(s.pixelAngle() / s.sampleAngle(), 1.17 * std::sqrt(2.0), 0.01);
  EXPECT_NEAR(s.pixelAngle(), 2.0 * std::tan(glm::radians(22.5)) / 480.0, 1e-7);
}

TEST(ImpostorBake, LeavesNoHoleFromAnywhereInTheCell) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  ImpostorStats stats;
  const Impostor imp =
      bakeImpostor(s.view(), cell, box, s.facingCell(cell), quickOptions(320, 240), &stats);
  ASSERT_GT(imp.size(), 1000u);
  EXPECT_GT(stats.thinSamples, 0u);  // the poles are thinner than an LDI pixel
  const HoleCount h = holesFromCell(s, imp, 24, 11);
  EXPECT_GT(h.geometryPixels, 15000u);
  EXPECT_EQ(h.uncovered, 0u) << "of " << h.geometryPixels
                             << " pixels that see the impostor's geometry";
}

TEST(ImpostorBake, PointRemovalDropsPointsAndKeepsTheCoverage) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  ImpostorOptions all = quickOptions(320, 240);
  all.removePoints = false;
  ImpostorStats withRemoval, without;
  const Impostor removed =
      bakeImpostor(s.view(), cell, box, s.all, quickOptions(320, 240), &withRemoval);
  bakeImpostor(s.view(), cell, box, s.all, all, &without);
  EXPECT_EQ(without.removed, 0u);
  EXPECT_EQ(withRemoval.samples, without.samples);
  // The thesis: 40-60% of the points (those a viewer can see).
  EXPECT_GT(withRemoval.removed, (withRemoval.samples - withRemoval.hidden) * 2 / 5);
  EXPECT_EQ(withRemoval.points + withRemoval.removed + withRemoval.hidden, withRemoval.samples);
  EXPECT_EQ(holesFromCell(s, removed, 8, 5).uncovered, 0u);
}

// A byte budget stops the bake before the appearance exactly when the
// points' encoded positions alone exceed it; within it the bake is the
// unbounded one, byte for byte. Oracle: the unbounded bake's own sections.
TEST(ImpostorBake, ABudgetBelowThePositionsBytesStopsTheBakeBeforeItsAppearance) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  const ImpostorOptions o = quickOptions(320, 240);
  ImpostorStats full;
  const Impostor whole = bakeImpostor(s.view(), cell, box, s.all, o, &full);
  ASSERT_GT(full.positionBytes, 0u);
  ASSERT_GT(full.appearanceRays, 0u);

  ImpostorStats stopped;
  EXPECT_FALSE(bakeImpostorWithin(s.view(), cell, box, s.all, o, full.positionBytes - 1, &stopped));
  EXPECT_EQ(stopped.positionBytes, full.positionBytes);
  EXPECT_EQ(stopped.points, full.points);
  EXPECT_EQ(stopped.appearanceRays, 0u);  // the appearance never ran

  // At the positions' bytes (or the whole's) the bake goes on to the end.
  for (const uint64_t budget : {full.positionBytes, full.bytes}) {
    ImpostorStats within;
    const std::optional<Impostor> imp =
        bakeImpostorWithin(s.view(), cell, box, s.all, o, budget, &within);
    ASSERT_TRUE(imp.has_value()) << budget;
    EXPECT_EQ(wire::encodeImpostor(*imp), wire::encodeImpostor(whole));
    EXPECT_EQ(within.bytes, full.bytes);
  }
}

TEST(ImpostorBake, ACoarserResolutionGivesFewerPointsInProportionToTheLdiPixels) {
  // Removal judges "sufficient" against the spacing the LDIs were sized for,
  // so at 0.7 of the heuristic's resolution the points fall with the LDI
  // pixels' area (0.49), rather than every camera's points staying because
  // none samples sufficiently any more.
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  ImpostorOptions coarse = quickOptions(320, 240);
  coarse.resolutionFactor = 0.7f;
  ImpostorStats full, reduced;
  bakeImpostor(s.view(), cell, box, s.all, quickOptions(320, 240), &full);
  bakeImpostor(s.view(), cell, box, s.all, coarse, &reduced);
  EXPECT_GT(reduced.removed, (reduced.samples - reduced.hidden) * 2 / 5);
  const double ratio = double(reduced.points) / double(full.points);
  EXPECT_GT(ratio, 0.35);
  EXPECT_LT(ratio, 0.65);
}

TEST(ImpostorBake, DropsPointsHiddenFromTheWholeCellAndLeavesNoHole) {
  // Every face of the boxes, back faces included: a face whose plane has the
  // whole sampling rectangle behind it is hidden from every viewpoint there
  // (the boxes are closed and convex), so none of its points survive; with
  // hidden points kept, the LDIs' deeper layers put points on such faces.
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  ImpostorOptions keep = preciseOptions(320, 240);
  keep.cullHidden = false;
  ImpostorStats culledStats, keptStats;
  const Impostor culled =
      bakeImpostor(s.view(), cell, box, s.all, preciseOptions(320, 240), &culledStats);
  const Impostor kept = bakeImpostor(s.view(), cell, box, s.all, keep, &keptStats);
  EXPECT_EQ(keptStats.hidden, 0u);
  EXPECT_GT(culledStats.hidden, keptStats.points / 4);
  EXPECT_EQ(culledStats.points + culledStats.hidden + culledStats.removed, culledStats.samples);

  const ImpostorFrame f = frameImpostor(cell, box);
  const std::array<glm::vec3, 4> corners = {f.plane.at(0, 0), f.plane.at(1, 0), f.plane.at(0, 1),
                                            f.plane.at(1, 1)};
  // Points lying on a face that turns its back on the whole rectangle, more
  // than 5 cm inside it (a point on or by an edge shared with a visible face
  // is that face's too, and visibility rays stop 1 cm short of the point).
  auto onBackFaces = [&](const Impostor& imp) {
    size_t count = 0;
    for (const glm::vec3& p : imp.points) {
      bool onBack = false, onOther = false;
      for (uint32_t t : s.all) {
        const glm::vec3 a = s.triangles.vertex(t, 0), b = s.triangles.vertex(t, 1),
                        c = s.triangles.vertex(t, 2);
        const glm::vec3 n = glm::normalize(glm::cross(b - a, c - a));
        if (std::abs(glm::dot(n, p - a)) > 1e-3f) continue;  // not in its plane
        const float area = glm::dot(glm::cross(b - a, c - a), n);
        const float w0 = glm::dot(glm::cross(c - b, p - b), n) / area;
        const float w1 = glm::dot(glm::cross(a - c, p - c), n) / area;
        if (w0 < -1e-4f || w1 < -1e-4f || w0 + w1 > 1.0f + 1e-4f) continue;  // outside it
        bool back = true;
        for (const glm::vec3& corner : corners) back = back && glm::dot(n, corner - a) < -1e-3f;
        auto edgeDistance = [&](const glm::vec3& e0, const glm::vec3& e1) {
          const glm::vec3 e = e1 - e0;
          const float along = std::clamp(glm::dot(p - e0, e) / glm::dot(e, e), 0.0f, 1.0f);
          return glm::length(p - (e0 + along * e));
        };
        const float inside = std::min({edgeDistance(a, b), edgeDistance(b, c), edgeDistance(c, a)});
        if (!back)
          onOther = true;
        else if (inside > 0.05f)
          onBack = true;
      }
      count += onBack && !onOther;
    }
    return count;
  };
  EXPECT_GT(onBackFaces(kept), 100u);
  EXPECT_EQ(onBackFaces(culled), 0u);
  const HoleCount h = holesFromCell(s, culled, 12, 17);
  EXPECT_GT(h.geometryPixels, 8000u);
  EXPECT_EQ(h.uncovered, 0u) << "of " << h.geometryPixels;
}

TEST(ImpostorBake, LeavesNoHoleThroughALatticeWithOneLayerARay) {
  // A back wall seen through a lattice, sampled with one layer a ray: each
  // camera sees the back wall only through the lattice's openings, from
  // where it stands. Along the bars' edges a camera that samples the back
  // wall better than another has no sample of it (its rays stopped at the
  // lattice); there the other camera's points must stay, or a viewer looking
  // through the lattice from elsewhere in the cell sees a hole (the known
  // case on bigcity is in impostor_scenes_test.cpp).
  ColouredScene s;
  const float front = -230.0f, back = -236.0f;
  auto slab = [&](const char* name, float x0, float y0, float x1, float y1, float z) {
    addBox(s.scene, name, {x0, y0, z - 0.3f}, {x1, y1, z});
  };
  // A lattice: bars 1.5 m wide every 4 m, both ways.
  for (int k = 0; k <= 20; ++k) {
    const float x = -40.0f + 4.0f * float(k);
    slab("bar", x, 0.0f, x + 1.5f, 30.0f, front);
  }
  for (int k = 0; k <= 7; ++k) {
    const float y = 4.0f * float(k);
    slab("rail", -40.0f, y, 41.5f, y + 1.5f, front);
  }
  slab("back", -40.0f, 0.0f, 41.5f, 30.0f, back);
  s.finish([](size_t t, const glm::vec3& n) {
    return glm::u8vec3(uint8_t(60 + (t * 53) % 160), uint8_t(128 + 100 * glm::normalize(n).y),
                       uint8_t(90));
  });
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  ImpostorOptions o = quickOptions(320, 240);
  o.maxLayers = 1;
  ImpostorStats stats;
  const Impostor imp = bakeImpostor(s.view(), cell, box, s.all, o, &stats);
  EXPECT_GT(stats.removed, (stats.samples - stats.hidden) / 4);  // removal still works
  // Along the bars' edges, points stay that a better camera did not sample.
  EXPECT_GT(stats.keptUnsampled, 0u);
  EXPECT_LT(stats.keptUnsampled, stats.points);
  const HoleCount h = holesFromCell(s, imp, 40, 23);
  EXPECT_GT(h.geometryPixels, 20000u);
  EXPECT_EQ(h.uncovered, 0u) << "of " << h.geometryPixels;
}

TEST(ImpostorBake, SamplesASurfaceInThePlaneOfTwoCamerasWithTheThird) {
  // A horizontal slab at the height of the top edge (the two upper cameras):
  // they see it edge on, only the lower camera samples it.
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box({-40.0f, 0.0f, -300.0f}, {40.0f, 30.0f, -220.0f});
  const ImpostorFrame f = frameImpostor(cell, box);
  const float y = f.cameras[0].y;
  ASSERT_GT(y, box.lo.y);
  ASSERT_LT(y, box.hi.y);
  ColouredScene s;
  Object o;
  o.name = "slab";
  o.mesh.positions = {
      {-30.0f, y, -290.0f}, {30.0f, y, -290.0f}, {30.0f, y, -230.0f}, {-30.0f, y, -230.0f}};
  o.mesh.triangles = {{0, 2, 1}, {0, 3, 2}};
  o.mesh.faceIds = {0, 0};
  s.scene.objects.push_back(o);
  s.scene.faceCount = 1;
  s.finish([](size_t, const glm::vec3&) { return glm::u8vec3(200, 60, 60); });
  ImpostorStats stats;
  const Impostor imp = bakeImpostor(s.view(), cell, box, s.all, preciseOptions(320, 240), &stats);
  ASSERT_GT(imp.size(), 100u);
  for (const glm::vec3& p : imp.points) ASSERT_NEAR(p.y, y, 1e-3f);
  const HoleCount h = holesFromCell(s, imp, 8, 3);
  EXPECT_GT(h.geometryPixels, 0u);
  EXPECT_EQ(h.uncovered, 0u);
}

// V-shaped fins 0.1 m apart, 100 m ahead, walls 10 degrees off the view
// axis, far enough to be sub-pixel. The right wall of each V faces left
// (red), the left wall faces right (green): seen from the cell's left side
// the red walls show, from its right the green ones.
ColouredScene fins() {
  ColouredScene s;
  Object o;
  o.name = "fins";
  const float period = 0.1f, depth = 0.05f / std::tan(glm::radians(10.0f));
  for (int k = 0; k < 200; ++k) {
    const float x0 = -10.0f + period * float(k);
    const uint32_t b = uint32_t(o.mesh.positions.size());
    // Tooth: (x0, z=-100) -> (x0 + period/2, -100 - depth) -> (x0 + period, -100).
    const glm::vec3 a0(x0, 0.0f, -100.0f), a1(x0 + 0.5f * period, 0.0f, -100.0f - depth),
        a2(x0 + period, 0.0f, -100.0f);
    for (const glm::vec3& p : {a0, a1, a2}) {
      o.mesh.positions.push_back(p);
      o.mesh.positions.push_back(p + glm::vec3(0.0f, 10.0f, 0.0f));
    }
    // Wall a0-a1 (triangles 4k, 4k + 1) faces right, wall a1-a2 faces left.
    o.mesh.triangles.emplace_back(b + 0, b + 2, b + 3);
    o.mesh.triangles.emplace_back(b + 0, b + 3, b + 1);
    o.mesh.triangles.emplace_back(b + 2, b + 4, b + 5);
    o.mesh.triangles.emplace_back(b + 2, b + 5, b + 3);
    for (int f = 0; f < 4; ++f) o.mesh.faceIds.push_back(s.scene.faceCount + uint32_t(f / 2));
    s.scene.faceCount += 2;
  }
  s.scene.objects.push_back(o);
  s.finish([](size_t t, const glm::vec3&) {
    return t % 4 < 2 ? glm::u8vec3(20, 220, 20) : glm::u8vec3(220, 20, 20);
  });
  return s;
}

glm::dvec3 meanImpostorColour(const Impostor& imp, const Camera& c) {
  ImpostorSplatter splatter;
  splatter.begin(c);
  ImageRgb8 image(c.width, c.height);
  splatter.draw(imp, image);
  glm::dvec3 sum(0.0);
  size_t n = 0;
  for (int y = 0; y < c.height; ++y)
    for (int x = 0; x < c.width; ++x)
      if (splatter.covered(x, y)) {
        sum += glm::dvec3(image.at(x, y));
        ++n;
      }
  return n ? sum / double(n) : sum;
}

TEST(ImpostorBake, MicrogeometryShowsItsColourFromEachSideOfTheCell) {
  const ColouredScene s = fins();
  const Box3f cell({-18.0f, 4.0f, -2.0f}, {18.0f, 6.0f, 2.0f});
  const Box3f box = boundsOf(s.triangles);
  ImpostorOptions o = quickOptions(320, 240);
  o.minRays = 16;
  o.maxRays = 32;
  const Impostor imp = bakeImpostor(s.view(), cell, box, s.all, o);
  auto from = [&](float x) {
    Camera c;
    c.width = 320;
    c.height = 240;
    c.eye = {x, 5.0f, 0.0f};
    c.yawDeg = glm::degrees(std::atan2(x, 100.0f));  // towards the fins' centre
    return c;
  };
  // From x = -17 the viewer looks 9.6 degrees to the right, nearly along the
  // right-facing (green) walls, which the red walls hide.
  const glm::dvec3 left = meanImpostorColour(imp, from(-17.0f));
  const glm::dvec3 right = meanImpostorColour(imp, from(17.0f));
  EXPECT_GT(left.r, left.g + 60.0) << left.r << " " << left.g;
  EXPECT_GT(right.g, right.r + 60.0) << right.r << " " << right.g;
  // One colour a point (a 1x1 texture) cannot tell the sides apart.
  o.textureWidth = o.textureHeight = 1;
  const Impostor flat = bakeImpostor(s.view(), cell, box, s.all, o);
  const glm::dvec3 l1 = meanImpostorColour(flat, from(-17.0f)),
                   r1 = meanImpostorColour(flat, from(17.0f));
  EXPECT_LT(std::abs((l1.r - l1.g) - (r1.r - r1.g)),
            0.5 * std::abs((left.r - left.g) - (right.r - right.g)));
}

TEST(ImpostorBake, FarFromTheOriginStillLeavesNoHole) {
  const glm::vec3 offset(20000.0f, 0.0f, -20000.0f);
  const ColouredScene s = buildingBlock(offset);
  const Box3f cell(offset + glm::vec3(-6.0f, 1.0f, -6.0f), offset + glm::vec3(6.0f, 3.0f, 6.0f));
  const Box3f box = boundsOf(s.triangles);
  const Impostor imp =
      bakeImpostor(s.view(), cell, box, s.facingCell(cell), quickOptions(320, 240));
  const HoleCount h = holesFromCell(s, imp, 8, 13);
  EXPECT_GT(h.geometryPixels, 5000u);
  EXPECT_EQ(h.uncovered, 0u);
}

// The site with the most triangles among a cell's impostor sites (placed
// with 300 triangles or more, as the README's measurements), if any.
std::optional<ImpostorSite> heaviestSite(const ImpostorWorld& world, const Box3f& cell) {
  ImpostorPlacementOptions placement;
  placement.minTriangles = 300;
  const ImpostorPlacement placed =
      placeImpostors(cell, world.triangles(), world.pvsTriangles(cell), placement);
  if (placed.sites.empty()) return std::nullopt;
  return *std::max_element(placed.sites.begin(), placed.sites.end(),
                           [](const ImpostorSite& a, const ImpostorSite& b) {
                             return a.triangles.size() < b.triangles.size();
                           });
}

// The pixels of 24 views from random points of the impostor's cell (320 x
// 240, `seed`) whose first hit over the whole scene is one of the site's
// triangles, and of those the ones the impostor's points leave uncovered.
testing::FaceCoverage siteCoverage(const ImpostorWorld& world, const ImpostorSite& site,
                                   const Impostor& imp, uint32_t seed) {
  std::vector<bool> mine(world.triangles().size(), false);
  for (uint32_t t : site.triangles) mine[t] = true;
  const auto rays = makeEmbreeRayQuery(world.triangles());
  return testing::faceCoverage(*rays, mine, imp,
                               viewsFromCell(imp.cell, site.box, 24, 320, 240, seed));
}

// The real city model: a street cell's heaviest impostor (the bake as the
// server runs it: lighting, PVS, placement) leaves no hole from random
// viewpoints in the cell. Oracle: a pixel whose centre ray's first hit over
// the whole scene is one of the impostor's triangles must be covered.
TEST(ImpostorBake, LeavesNoHoleOnTheRealCityModel) {
  const Scene scene = openScene(std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj");
  const ImpostorWorld world(scene, ImpostorWorldOptions{});
  const Box3f cell({-300.0f, 1.0f, -200.0f}, {-296.0f, 3.0f, -196.0f});  // origin-centred file
  const std::optional<ImpostorSite> heaviest = heaviestSite(world, cell);
  ASSERT_TRUE(heaviest.has_value());
  const ImpostorSite& site = *heaviest;
  const Impostor imp =
      bakeImpostor(world.view(), cell, site.box, site.triangles, quickOptions(320, 240));
  const testing::FaceCoverage c = siteCoverage(world, site, imp, 5);
  EXPECT_GT(c.seen, 2000u);
  EXPECT_EQ(c.uncovered, 0u) << "of " << c.seen << " pixels that see the impostor's faces";
}

// Thinning drops only points on the odd squares of their camera's LDI whose
// four neighbours stay; the rest of the bake is the same, and no viewer in
// the cell finds a hole. On the real city model's heaviest impostor of a
// street cell, where a camera sees some roofs and walls more squarely than
// any viewer does. Oracle: the same bake without thinning, and which
// triangle each pixel's ray meets first over the whole scene.
TEST(ImpostorBake, ThinningACameraThatOversamplesKeepsTheCoverageOnTheRealCityModel) {
  const Scene scene = openScene(std::string(VISTREAM_SHARED_DIR) + "/data/delfshaven.obj");
  const ImpostorWorld world(scene, ImpostorWorldOptions{});
  const Box3f cell({0.0f, 1.0f, 200.0f}, {4.0f, 3.0f, 204.0f});  // origin-centred file
  const std::optional<ImpostorSite> heaviest = heaviestSite(world, cell);
  ASSERT_TRUE(heaviest.has_value());
  const ImpostorSite& site = *heaviest;
  ImpostorOptions unthinned = quickOptions(320, 240);
  unthinned.thinOversampled = false;
  ImpostorStats withThinning, without;
  const Impostor thinned = bakeImpostor(world.view(), cell, site.box, site.triangles,
                                        quickOptions(320, 240), &withThinning);
  bakeImpostor(world.view(), cell, site.box, site.triangles, unthinned, &without);
  EXPECT_EQ(without.thinned, 0u);
  EXPECT_GT(withThinning.thinned, 0u);
  EXPECT_EQ(withThinning.samples, without.samples);
  EXPECT_EQ(withThinning.hidden, without.hidden);
  EXPECT_EQ(withThinning.removed, without.removed + withThinning.thinned);
  EXPECT_EQ(withThinning.points + withThinning.thinned, without.points);
  const testing::FaceCoverage c = siteCoverage(world, site, thinned, 9);
  EXPECT_GT(c.seen, 2000u);
  EXPECT_EQ(c.uncovered, 0u) << "of " << c.seen << " pixels that see the impostor's faces";
}

TEST(ImpostorBake, GivesTheSameBytesOnAnyThreadCount) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  const ImpostorOptions o = quickOptions(160, 120);
  const Impostor many = bakeImpostor(s.view(), cell, box, s.all, o);
  Impostor one;
  tbb::task_arena(1).execute([&] { one = bakeImpostor(s.view(), cell, box, s.all, o); });
  ASSERT_EQ(one.size(), many.size());
  EXPECT_EQ(one.points, many.points);
  EXPECT_EQ(one.texels, many.texels);
}

// The precision the bake keeps (what the encoding carries): against a bake
// at a hundredth of the default position error and exact colours, every
// point moves by at most 0.05 of the screen's smallest pixel angle seen
// from the cell's corners and centre, single colours stay exact, textures
// move by at most half the colour step; and the encoding gives back exactly
// the impostor the bake measured.
TEST(ImpostorBake, KeepsEveryPointWithinItsPixelFractionAndTheEncodingGivesItBackExactly) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Box3f box = boundsOf(s.triangles);
  const ImpostorOptions o = quickOptions(320, 240);
  ASSERT_EQ(o.positionError, 0.05f);
  ImpostorOptions fine = o;
  fine.positionError = 5e-4f;
  fine.colourStep = 1;
  const Impostor imp = bakeImpostor(s.view(), cell, box, s.all, o);
  const Impostor exact = bakeImpostor(s.view(), cell, box, s.all, fine);
  ASSERT_EQ(imp.size(), exact.size());
  ASSERT_GT(imp.size(), 1000u);
  // The smallest angle a pixel subtends: at the border of a 60-degree screen.
  const float half = glm::radians(o.screen.vfovDeg) / 2.0f;
  const float smallest =
      2.0f * std::tan(half) / float(o.screen.height) * std::cos(half) * std::cos(half);
  std::vector<glm::vec3> eyes = {cell.center()};
  for (int k = 0; k < 8; ++k) eyes.push_back(cell.corner(k));
  float worst = 0.0f;
  size_t textured = 0;
  for (size_t k = 0; k < imp.size(); ++k) {
    for (const glm::vec3& eye : eyes) {
      const glm::vec3 a = glm::normalize(imp.points[k] - eye),
                      b = glm::normalize(exact.points[k] - eye);
      worst = std::max(worst, 2.0f * std::asin(std::min(1.0f, 0.5f * glm::length(a - b))));
    }
    ASSERT_EQ(imp.singleColour[k], exact.singleColour[k]);
    textured += !imp.singleColour[k];
    const uint32_t texels = imp.singleColour[k] ? 1 : imp.textureTexels();
    for (uint32_t i = 0; i < texels; ++i)
      for (int c = 0; c < 3; ++c) {
        const int got = imp.texels[imp.firstTexel[k] + i][c];
        const int want = exact.texels[exact.firstTexel[k] + i][c];
        if (imp.singleColour[k])
          ASSERT_EQ(got, want);
        else
          ASSERT_LE(std::abs(got - want), int(o.colourStep / 2));
      }
  }
  EXPECT_GT(textured, 0u);
  EXPECT_LE(worst, 0.05f * smallest * 1.1f) << "in pixels: " << worst / smallest;
  EXPECT_GT(worst, 0.005f * smallest) << "the default grid is coarser than the fine one";

  Impostor decoded;
  std::string error;
  ASSERT_TRUE(wire::decodeImpostor(wire::encodeImpostor(imp), decoded, error)) << error;
  // Points come back in another order: compare the sets.
  auto sorted = [](const Impostor& x) {
    std::vector<std::array<float, 7>> v;
    for (size_t k = 0; k < x.size(); ++k) {
      const glm::u8vec3 c = x.texels[x.firstTexel[k]];
      v.push_back({x.points[k].x, x.points[k].y, x.points[k].z, float(c.x), float(c.y), float(c.z),
                   float(x.singleColour[k])});
    }
    std::sort(v.begin(), v.end());
    return v;
  };
  const auto want = sorted(imp), got = sorted(decoded);
  ASSERT_EQ(got.size(), want.size());
  size_t differ = 0;
  for (size_t k = 0; k < got.size(); ++k) differ += got[k] != want[k];
  EXPECT_EQ(differ, 0u);
}

TEST(ImpostorBake, RefusesAnImpostorTooLargeToSample) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  ImpostorOptions o = quickOptions(320, 240);
  o.maxLdiPixels = 1000;
  EXPECT_THROW(bakeImpostor(s.view(), cell, boundsOf(s.triangles), s.all, o), InputError);
  o = quickOptions(320, 240);
  o.resolutionFactor = 0.0f;
  EXPECT_THROW(bakeImpostor(s.view(), cell, boundsOf(s.triangles), s.all, o), InputError);
  // A box reaching 84 degrees off the axis (tangent 10) at its near side:
  // its points' grid would lose its precision there.
  const Box3f wide({-600.0f, 0.0f, -80.0f}, {600.0f, 30.0f, -66.0f});
  try {
    bakeImpostor(s.view(), cell, wide, s.all, quickOptions(320, 240));
    ADD_FAILURE() << "a box 84 degrees wide was baked";
  } catch (const InputError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("degrees off")) << e.what();
  }
}

// The splatter skips an impostor whose box is wholly out of view; a point
// that projects onto the screen is never skipped with it. Oracle:
// every point projected on its own, from cameras looking at, beside and away
// from the box.
TEST(ImpostorSplat, SkipsOnlyBoxesWhollyOutOfView) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  const Impostor imp = bakeImpostor(s.view(), cell, boundsOf(s.triangles), s.facingCell(cell),
                                    quickOptions(160, 120));
  size_t culledViews = 0;
  for (int k = 0; k < 24; ++k) {
    Camera c;
    c.width = 160;
    c.height = 120;
    c.eye = glm::vec3(0.0f, 2.0f, 0.0f);
    c.yawDeg = float(k) * 15.0f;  // full turn: towards, beside and away from the block
    c.pitchDeg = k % 3 == 0 ? 25.0f : 0.0f;
    const glm::mat4 rp = c.rotationProjection();
    size_t expected = 0;
    for (const glm::vec3& p : imp.points) {
      const glm::vec3 rel = p - c.eye;
      if (!(glm::dot(rel, c.forward()) > c.zNear)) continue;
      const glm::vec4 clip = rp * glm::vec4(rel, 1.0f);
      expected += std::abs(clip.x) <= clip.w && std::abs(clip.y) <= clip.w;
    }
    ImpostorSplatter splatter;
    splatter.begin(c);
    ImageRgb8 image(c.width, c.height);
    EXPECT_EQ(splatter.draw(imp, image), expected) << "yaw " << c.yawDeg;
    culledViews += expected == 0;
  }
  EXPECT_GT(culledViews, 8u);  // the views away from the block
}

// The parallel splat draws what one pass over the points in order draws:
// oracle, that pass written out here (every pixel of the 3x3 round a point
// tested against the disc, the least score kept), over two impostors sharing
// a depth buffer, from views at, beside and inside the block's footprint,
// with the default splat, a wide one and one that compares depth alone;
// drawn in parallel and on one thread (ImpostorSplatter::setSerialBelow).
// The building block's impostor, baked for the 12 m cell around the origin.
Impostor blockImpostor(const ImpostorOptions& options) {
  const ColouredScene s = buildingBlock();
  const Box3f cell({-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f});
  return bakeImpostor(s.view(), cell, boundsOf(s.triangles), s.facingCell(cell), options);
}

void drawsWhatOnePassDraws(size_t serialBelow);
TEST(ImpostorSplat, DrawsWhatOnePassInThePointsOrderDraws) {
  for (const size_t serialBelow : {size_t(0), std::numeric_limits<size_t>::max()}) {
    SCOPED_TRACE(serialBelow ? "on one thread" : "in parallel");
    drawsWhatOnePassDraws(serialBelow);
  }
}

void drawsWhatOnePassDraws(size_t serialBelow) {
  const Impostor a = blockImpostor(quickOptions(320, 240));
  ImpostorOptions other = quickOptions(320, 240);
  other.resolutionFactor = 1.3f;  // another sampling of the same surfaces: depth ties and overlaps
  const Impostor b = blockImpostor(other);
  const std::array<PointSplat, 3> splats = {PointSplat{}, PointSplat{0.95f, 0.05f},
                                            PointSplat{0.6f, 0.0f}};
  ImpostorSplatter together;
  together.setSerialBelow(serialBelow);
  for (int k = 0; k < 6; ++k) {
    const PointSplat& splat = splats[size_t(k) % splats.size()];
    Camera c;
    c.width = 320;
    c.height = 240;
    c.eye = glm::vec3(-4.0f + 1.6f * float(k), 1.5f + 0.2f * float(k), 2.0f);
    c.yawDeg = -20.0f + 8.0f * float(k);
    c.pitchDeg = float(k % 3) * 4.0f;
    ImpostorSplatter splatter;
    splatter.setSerialBelow(serialBelow);
    splatter.begin(c, nullptr, splat);
    ImageRgb8 image(c.width, c.height);
    const size_t landed = splatter.draw(a, image) + splatter.draw(b, image);
    // One pass.
    const glm::mat4 rp = c.rotationProjection();
    const size_t n = size_t(c.width) * size_t(c.height);
    std::vector<float> depth(n, ImpostorSplatter::kEmpty), score(n, ImpostorSplatter::kEmpty);
    ImageRgb8 expected(c.width, c.height);
    size_t expectedLanded = 0, ties = 0;
    for (const Impostor* imp : {&a, &b})
      for (size_t p = 0; p < imp->size(); ++p) {
        const glm::vec3 rel = imp->points[p] - c.eye;
        const float z = glm::dot(rel, c.forward());
        const glm::vec4 clip = rp * glm::vec4(rel, 1.0f);
        if (!(z > c.zNear) || !(std::abs(clip.x) <= clip.w && std::abs(clip.y) <= clip.w)) continue;
        ++expectedLanded;
        const float px = (clip.x / clip.w * 0.5f + 0.5f) * float(c.width);
        const float py = (0.5f - clip.y / clip.w * 0.5f) * float(c.height);
        const int cx = int(std::floor(px)), cy = int(std::floor(py));
        for (int y = std::max(cy - 1, 0); y <= std::min(cy + 1, c.height - 1); ++y)
          for (int x = std::max(cx - 1, 0); x <= std::min(cx + 1, c.width - 1); ++x) {
            const float dx = px - (float(x) + 0.5f), dy = py - (float(y) + 0.5f);
            const float d2 = dx * dx + dy * dy;
            if (d2 > splat.radius * splat.radius) continue;
            const float sc = z * (1.0f + splat.sameSurface / (splat.radius * splat.radius) * d2);
            const size_t at = size_t(y) * size_t(c.width) + size_t(x);
            ties += sc == score[at];
            if (!(sc < score[at])) continue;
            score[at] = sc;
            depth[at] = z;
            expected.set(x, y, toBytes(imp->colourSeenFrom(p, c.eye)));
          }
      }
    EXPECT_GT(expectedLanded, 1000u) << "view " << k;
    EXPECT_EQ(landed, expectedLanded) << "view " << k;
    // Both impostors in one pass: the frame of the two draws, bit for bit
    // (by a splatter kept from view to view, which resets only what the
    // last view wrote).
    together.begin(c, nullptr, splat);
    ImageRgb8 togetherImage(c.width, c.height);
    std::vector<size_t> landedEach;
    const Impostor* both[] = {&a, &b};
    EXPECT_EQ(together.draw(both, togetherImage, &landedEach), landed) << "view " << k;
    ASSERT_EQ(landedEach.size(), 2u);
    EXPECT_EQ(landedEach[0] + landedEach[1], landed);
    EXPECT_EQ(together.score(), splatter.score()) << "view " << k;
    EXPECT_EQ(together.depth(), splatter.depth()) << "view " << k;
    EXPECT_TRUE(togetherImage.pixels == image.pixels) << "view " << k;
    // The disc's tests round alike up to a float's last bit; a pixel on its
    // very rim may differ, no more.
    size_t differ = 0;
    for (size_t p = 0; p < n; ++p)
      differ += splatter.depth()[p] != depth[p] || splatter.score()[p] != score[p] ||
                image.pixels[3 * p] != expected.pixels[3 * p] ||
                image.pixels[3 * p + 1] != expected.pixels[3 * p + 1] ||
                image.pixels[3 * p + 2] != expected.pixels[3 * p + 2];
    EXPECT_LE(differ, n / 10000) << "view " << k << " (ties " << ties << ")";
    // The views see the block: the comparison is not of empty frames.
    size_t covered = 0;
    for (size_t p = 0; p < n; ++p) covered += depth[p] < ImpostorSplatter::kEmpty;
    EXPECT_GT(covered, 500u) << "view " << k;
  }
}

TEST(ImpostorSplat, WithAMaskDrawsTheUnmaskedFrameOnItsPixelsAndNothingElse) {
  const Impostor a = blockImpostor(quickOptions(320, 240));
  Camera c;
  c.width = 320;
  c.height = 240;
  c.eye = glm::vec3(1.0f, 1.8f, 2.0f);
  c.pitchDeg = 3.0f;
  const size_t n = size_t(c.width) * size_t(c.height);
  ImpostorSplatter whole;
  whole.begin(c);
  ImageRgb8 wholeImage(c.width, c.height);
  whole.draw(a, wholeImage);
  // The rows the block covers, for the band below.
  int top = c.height, bottom = -1;
  for (size_t p = 0; p < n; ++p)
    if (whole.score()[p] < ImpostorSplatter::kEmpty) {
      top = std::min(top, int(p / size_t(c.width)));
      bottom = std::max(bottom, int(p / size_t(c.width)));
    }
  ASSERT_LT(top + 20, bottom);
  // Masks as the pipeline makes them: scattered pixels (retraced ones) and
  // a band of rows (sky), in rows, then again after a reset (as the next
  // frame does with the same mask object).
  std::mt19937 rng(7);
  PixelMask mask;
  ImpostorSplatter masked;
  for (int frame = 0; frame < 2; ++frame) {
    mask.reset(n);
    for (uint32_t p = 0; p < n; ++p)
      if (const int y = int(p / uint32_t(c.width));
          std::uniform_int_distribution<int>(0, 9)(rng) == 0 ||
          (y >= top + 10 * frame && y < top + 10 * frame + 10))
        mask.add(p);
    masked.begin(c, &mask);
    const glm::u8vec3 untouched(1, 2, 3);
    ImageRgb8 image(c.width, c.height, untouched);
    masked.draw(a, image);
    size_t maskedCovered = 0, wrong = 0, outside = 0;
    for (size_t p = 0; p < n; ++p) {
      const int x = int(p % size_t(c.width)), y = int(p / size_t(c.width));
      if (mask.has(p)) {
        maskedCovered += whole.score()[p] < ImpostorSplatter::kEmpty;
        wrong +=
            masked.score()[p] != whole.score()[p] ||
            (whole.score()[p] < ImpostorSplatter::kEmpty && image.at(x, y) != wholeImage.at(x, y));
      } else {
        outside += masked.score()[p] != ImpostorSplatter::kEmpty || image.at(x, y) != untouched;
      }
    }
    EXPECT_GT(maskedCovered, 150u) << "frame " << frame;
    EXPECT_EQ(wrong, 0u) << "frame " << frame;
    EXPECT_EQ(outside, 0u) << "frame " << frame;
  }
}

TEST(ImpostorSplat, TheReachOfAnImpostorHoldsEveryPixelItsPointsCoverAndLittleElse) {
  const Impostor baked = blockImpostor(quickOptions(320, 240));
  // As a client holds it: decoded, with the bounds of each block of points.
  Impostor a;
  std::string error;
  ASSERT_TRUE(wire::decodeImpostor(wire::encodeImpostor(baked), a, error)) << error;
  ASSERT_TRUE(a.hasBlockBounds());
  for (int k = 0; k < 4; ++k) {
    Camera c;
    c.width = 320;
    c.height = 240;
    c.eye = glm::vec3(-3.0f + 2.0f * float(k), 1.5f, 3.0f);
    c.yawDeg = -30.0f + 20.0f * float(k);
    ImpostorSplatter whole;
    whole.begin(c);
    ImageRgb8 image(c.width, c.height);
    whole.draw(a, image);
    ScreenTiles reach;
    reach.reset(c.width, c.height);
    reach.markReach(c, a);
    size_t covered = 0, outside = 0, markedPixels = 0;
    for (int y = 0; y < c.height; ++y)
      for (int x = 0; x < c.width; ++x) {
        const bool point =
            whole.score()[size_t(y) * size_t(c.width) + size_t(x)] < ImpostorSplatter::kEmpty;
        covered += point;
        outside += point && !reach.marked({x, y});
        markedPixels += reach.marked({x, y});
      }
    EXPECT_GT(covered, 300u) << "view " << k;
    EXPECT_EQ(outside, 0u) << "view " << k;
    // The blocks' footprints, not the whole screen.
    EXPECT_LT(markedPixels, size_t(c.width) * size_t(c.height) / 2) << "view " << k;
  }
}

TEST(ScreenTilesTest, AListMarksExactlyTheTilesOfItsPixelsInAnyOrder) {
  // A width that is no multiple of the tile, so the last column of tiles
  // is narrow; pixels in ascending order, then the same shuffled.
  const int w = 100, h = 37;
  std::mt19937 rng(5);
  std::vector<uint32_t> list;
  for (uint32_t p = 0; p < uint32_t(w * h); ++p)
    if (rng() % 97 == 0) list.push_back(p);
  list.push_back(uint32_t(w * h - 1));  // the bottom right pixel
  std::vector<uint32_t> shuffled = list;
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  for (const auto* pixels : {&list, &shuffled}) {
    ScreenTiles tiles;
    tiles.reset(w, h);
    tiles.markList(*pixels);
    // The oracle: a tile is marked when some listed pixel lies in it.
    std::set<std::pair<int, int>> expected;
    for (const uint32_t p : list)
      expected.insert({int(p) % w / ScreenTiles::kTile, int(p) / w / ScreenTiles::kTile});
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        EXPECT_EQ(tiles.marked({x, y}),
                  expected.count({x / ScreenTiles::kTile, y / ScreenTiles::kTile}) == 1)
            << x << "," << y;
  }
}

TEST(ImpostorSplat, RefusesARadiusOutsideOnePixelAndANegativeSameSurfaceDepth) {
  Camera c;
  ImpostorSplatter splatter;
  EXPECT_THROW(splatter.begin(c, nullptr, PointSplat{0.0f, 0.01f}), InputError);
  EXPECT_THROW(splatter.begin(c, nullptr, PointSplat{1.0f, 0.01f}), InputError);
  EXPECT_THROW(splatter.begin(c, nullptr, PointSplat{0.6f, -0.1f}), InputError);
  EXPECT_THROW(splatter.begin(c, nullptr, PointSplat{0.6f, std::nanf("")}), InputError);
  EXPECT_NO_THROW(splatter.begin(c, nullptr, PointSplat{0.6f, 0.0f}));
}

// A point nearer the pixel's centre wins over a point of the same surface a
// little nearer the viewer, and loses to a surface well in front.
TEST(ImpostorSplat, OfOneSurfaceThePointNearerThePixelCentreWins) {
  Camera c;
  c.width = 64;
  c.height = 48;
  c.eye = glm::vec3(0.0f);
  // Two points projecting a quarter pixel right of and 0.45 pixel left of
  // the centre of pixel (32, 24), the second 0.1% nearer the viewer.
  const float z = 100.0f;
  auto at = [&](float pxOff, float depthScale) {
    const glm::vec3 dir = c.rayDirection(32.5f + pxOff, 24.5f);
    return dir * (z * depthScale / glm::dot(dir, c.forward()));
  };
  auto one = [&](const glm::vec3& p, const glm::u8vec3& colour) {
    Impostor imp;
    imp.cell = Box3f({-1.0f, -1.0f, 1.0f}, {1.0f, 1.0f, 2.0f});
    imp.box = Box3f(glm::vec3(-50.0f, -50.0f, -200.0f), glm::vec3(50.0f, 50.0f, -50.0f));
    imp.textureWidth = imp.textureHeight = 1;
    imp.appendPoint(p, &colour, true);
    return imp;
  };
  const Impostor centre = one(at(0.25f, 1.0f), {200, 0, 0}),
                 nearer = one(at(-0.45f, 0.999f), {0, 200, 0}),
                 front = one(at(-0.45f, 0.9f), {0, 0, 200});
  for (bool centreFirst : {true, false}) {
    ImpostorSplatter splatter;
    splatter.begin(c);
    ImageRgb8 image(c.width, c.height);
    if (centreFirst) {
      splatter.draw(centre, image);
      splatter.draw(nearer, image);
    } else {
      splatter.draw(nearer, image);
      splatter.draw(centre, image);
    }
    EXPECT_EQ(image.at(32, 24), glm::u8vec3(200, 0, 0)) << centreFirst;
    splatter.draw(front, image);
    EXPECT_EQ(image.at(32, 24), glm::u8vec3(0, 0, 200)) << centreFirst;
  }
}

// ---- the client's pipeline drawing impostors (client/farfield/pipeline.h) ----

// The block of buildingBlock() beyond a far blocker (a tower 150 m ahead,
// beyond d but not part of the impostor) and a near box: the client holds
// the blocker and the near box, and the block only as its impostor.
struct ClientView {
  ColouredScene full;
  RenderGeometry held;  // what a connected client holds: everything but the block
  std::vector<uint32_t> block;
  std::shared_ptr<ImpostorSet> set = std::make_shared<ImpostorSet>();
  Box3f cell{{-6.0f, 1.0f, -6.0f}, {6.0f, 3.0f, 6.0f}};

  ClientView() {
    full = buildingBlock();
    const size_t blockTriangles = full.triangles.size();
    for (uint32_t t = 0; t < blockTriangles; ++t) block.push_back(t);
    // Rebuild with the blocker and the near box after the block's triangles.
    ColouredScene s;
    s.scene = full.scene;
    addBox(s.scene, "blocker", {-12.0f, 0.0f, -160.0f}, {-2.0f, 40.0f, -150.0f});
    addBox(s.scene, "near", {8.0f, 0.0f, -30.0f}, {10.0f, 3.0f, -28.0f});
    s.finish([](size_t t, const glm::vec3& n) {
      const glm::vec3 u = glm::normalize(n);
      return glm::u8vec3(uint8_t(128 + 100 * u.x), uint8_t(128 + 100 * u.y),
                         uint8_t(100 + (t * 37) % 120));
    });
    full = std::move(s);
    for (size_t t = blockTriangles; t < full.triangles.size(); ++t)
      appendTriangle(held, full.triangles, full.lighting, t);
    held.haze.scale = 0.0f;
    Box3f box;
    for (uint32_t t : block) {
      box.extend(full.triangles.triangleBounds(t).lo);
      box.extend(full.triangles.triangleBounds(t).hi);
    }
    set->cell = cell;
    set->impostors.push_back(std::make_shared<const Impostor>(
        bakeImpostor(full.view(), cell, box, full.facingCell(cell), quickOptions(320, 240))));
    set->expected = 1;
  }
  static PipelineOptions options(RenderMode mode) {
    PipelineOptions o;
    o.mode = mode;
    o.nearDistance = 50.0f;
    o.polygonBudget = 0;  // always split at d
    o.cache = false;
    return o;
  }
  // The reference: every triangle (block included) ray cast.
  ImageRgb8 reference(const Camera& c) const {
    RenderGeometry g;
    g.triangles = full.triangles;
    g.lighting = full.lighting;
    g.haze.scale = 0.0f;
    g.bounds = boundsOf(full.triangles);
    FrameRenderer r(g, options(RenderMode::RaycastAll));
    ImageRgb8 out;
    r.render(c, out);
    return out;
  }
};

Camera towardsTheBlock(const glm::vec3& eye) {
  Camera c;
  c.width = 320;
  c.height = 240;
  c.eye = eye;
  c.pitchDeg = 3.0f;
  return c;
}

TEST(ImpostorPipeline,
     DrawsTheImpostorWhereTheClientHoldsNoGeometryAndCutsTheErrorAgainstTheReference) {
  const ClientView v;
  for (const glm::vec3& eye : {glm::vec3(0.0f, 2.0f, 0.0f), glm::vec3(-5.0f, 1.2f, 5.0f)}) {
    const Camera c = towardsTheBlock(eye);
    const ImageRgb8 reference = v.reference(c);
    FrameRenderer on(v.held, ClientView::options(RenderMode::Pipeline));
    on.setImpostors(v.set);
    ImageRgb8 withImpostors, without;
    const FrameReport rep = on.render(c, withImpostors);
    EXPECT_TRUE(rep.impostorsRan) << rep.impostorsWhy;
    EXPECT_GT(rep.pixels.impostor, 500u);
    EXPECT_EQ(rep.impostorsDrawn, 1u);
    FrameRenderer off(v.held, ClientView::options(RenderMode::ImpostorOff));
    off.setImpostors(v.set);
    const FrameReport offRep = off.render(c, without);
    EXPECT_FALSE(offRep.impostorsRan);
    EXPECT_EQ(offRep.pixels.impostor, 0u);
    EXPECT_EQ(offRep.impostorsWhy, "impostor-off mode");
    // Pixels more than 48 levels off the reference in some channel: the
    // block's pixels without impostors; edges and a few texels with them.
    auto wrong = [&](const ImageRgb8& image) {
      size_t n = 0;
      for (int y = 0; y < c.height; ++y)
        for (int x = 0; x < c.width; ++x) {
          const glm::ivec3 d =
              glm::abs(glm::ivec3(image.at(x, y)) - glm::ivec3(reference.at(x, y)));
          n += std::max({d.x, d.y, d.z}) > 48;
        }
      return n;
    };
    const size_t wrongWith = wrong(withImpostors), wrongWithout = wrong(without);
    EXPECT_GT(wrongWithout, 400u);
    EXPECT_LT(wrongWith * 2, wrongWithout) << "with " << wrongWith << ", without " << wrongWithout;
  }
}

TEST(ImpostorPipeline, HeldGeometryInFrontOfTheImpostorHidesIt) {
  const ClientView v;
  const Camera c = towardsTheBlock({0.0f, 2.0f, 0.0f});
  FrameRenderer r(v.held, ClientView::options(RenderMode::Pipeline));
  r.setImpostors(v.set);
  ImageRgb8 image;
  r.render(c, image);
  const ImageRgb8 reference = v.reference(c);
  // Pixels whose centre ray hits the blocker (held, beyond d) show it.
  const auto rays = makeEmbreeRayQuery(v.held.triangles);
  size_t blocker = 0, shown = 0;
  for (int y = 0; y < c.height; y += 2)
    for (int x = 0; x < c.width; x += 2) {
      const glm::vec3 dir = c.rayDirection(float(x) + 0.5f, float(y) + 0.5f);
      const Hit h = rays->firstHit(Ray{c.eye, dir, 0.0f, 1e30f});
      if (!h.valid() || h.t * glm::length(dir) < 140.0f) continue;  // only the blocker's pixels
      ++blocker;
      shown += image.at(x, y) == reference.at(x, y);
    }
  ASSERT_GT(blocker, 100u);
  EXPECT_GT(double(shown), 0.98 * double(blocker));
}

// Pixels more than 48 levels off in some channel.
size_t pixelsOff(const ImageRgb8& a, const ImageRgb8& b) {
  size_t n = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const glm::ivec3 d = glm::abs(glm::ivec3(a.at(x, y)) - glm::ivec3(b.at(x, y)));
      n += std::max({d.x, d.y, d.z}) > 48;
    }
  return n;
}

PipelineOptions cachedOptions() {
  PipelineOptions o = ClientView::options(RenderMode::Pipeline);
  o.cache = true;
  return o;
}

TEST(ImpostorPipeline, TheCacheKeepsTheImpostorsSoAStillViewerCastsNoRayForThem) {
  const ClientView v;
  const Camera c = towardsTheBlock({0.0f, 2.0f, 0.0f});
  FrameRenderer r(v.held, cachedOptions());
  r.setImpostors(v.set);
  ImageRgb8 first, second;
  const FrameReport one = r.render(c, first);
  ASSERT_TRUE(one.impostorsRan) << one.impostorsWhy;
  ASSERT_GT(one.pixels.impostor, 500u);
  const FrameReport two = r.render(c, second);
  // Nothing moved: every far-field pixel comes from the cache, impostors included.
  EXPECT_EQ(two.pixels.rayHit + two.pixels.rayMiss, 0u);
  EXPECT_EQ(two.pixels.impostor, one.pixels.impostor);
  EXPECT_EQ(two.impostorTexelsForgotten, 0u);
  // And it is as close to the reference as the frame that splatted them.
  const ImageRgb8 reference = v.reference(c);
  EXPECT_LE(pixelsOff(second, reference), pixelsOff(first, reference) + 20);
}

TEST(ImpostorPipeline, SplattingTheSkyAboveTheHeldHorizonDrawsTheFrameThatTracesNoHorizon) {
  // The block rises above the horizon of what the client holds: those
  // pixels are sky to the horizon and the impostor's to the splat. Without
  // a horizon every such pixel is ray cast (and missed) instead.
  const ClientView v;
  for (const bool cache : {false, true})
    for (const glm::vec3& eye : {glm::vec3(0.0f, 2.0f, 0.0f), glm::vec3(-5.0f, 1.2f, 5.0f)}) {
      const Camera c = towardsTheBlock(eye);
      PipelineOptions o = ClientView::options(RenderMode::Pipeline);
      o.cache = cache;
      FrameRenderer withHorizon(v.held, o);
      o.horizonAllowed = false;  // every pixel without a polygon is a candidate
      FrameRenderer without(v.held, o);
      withHorizon.setImpostors(v.set);
      without.setImpostors(v.set);
      ImageRgb8 a, b;
      const FrameReport ra = withHorizon.render(c, a);
      const FrameReport rb = without.render(c, b);
      ASSERT_TRUE(ra.horizonRan) << ra.horizonWhy;
      ASSERT_FALSE(rb.horizonRan);
      EXPECT_GT(ra.pixels.horizon, 1000u) << "open sky stays culled";
      EXPECT_GT(ra.pixels.impostor, 500u);
      EXPECT_EQ(ra.pixels.impostor, rb.pixels.impostor) << "cache " << cache;
      size_t differ = 0;
      for (int y = 0; y < c.height; ++y)
        for (int x = 0; x < c.width; ++x) differ += a.at(x, y) != b.at(x, y);
      EXPECT_EQ(differ, 0u) << "cache " << cache;
    }
}

TEST(ImpostorPipeline, TheCacheForgetsTheImpostorsWhenTheyChangeAndShowsTheNewOnes) {
  const ClientView v;
  const Camera c = towardsTheBlock({0.0f, 2.0f, 0.0f});
  FrameRenderer r(v.held, cachedOptions());
  r.setImpostors(v.set);
  ImageRgb8 with, image;
  const FrameReport one = r.render(c, with);
  ASSERT_GT(one.pixels.impostor, 500u);
  // Without impostors the frame is the one a renderer that never had them draws.
  FrameRenderer never(v.held, cachedOptions());
  ImageRgb8 without;
  never.render(c, without);
  const size_t impostorShown = pixelsOff(with, without);
  ASSERT_GT(impostorShown, 400u);
  r.setImpostors(nullptr);
  const FrameReport two = r.render(c, image);
  // The texels that showed the impostor (a texel per pixel, a few shared),
  // and only those: nothing was added.
  EXPECT_LE(two.impostorTexelsForgotten, one.pixels.impostor);
  EXPECT_GE(two.impostorTexelsForgotten * 10, one.pixels.impostor * 9);
  EXPECT_EQ(two.pixels.impostor, 0u);
  EXPECT_LT(pixelsOff(image, without), impostorShown / 20) << "the impostor's pixels are gone";
  // The same impostors in a new set: the texels their boxes may hide go,
  // and the frame shows them again as the first did.
  auto again = std::make_shared<ImpostorSet>(*v.set);
  r.setImpostors(again);
  const FrameReport three = r.render(c, image);
  EXPECT_GE(three.impostorTexelsForgotten, one.pixels.impostor);
  EXPECT_EQ(three.pixels.impostor, one.pixels.impostor);
  EXPECT_LT(pixelsOff(image, with), impostorShown / 20);
}

TEST(ImpostorPipeline, SaysWhyWhenTheViewerIsOutsideTheCellOfItsImpostors) {
  const ClientView v;
  const Camera c = towardsTheBlock({0.0f, 2.0f, 20.0f});
  FrameRenderer r(v.held, ClientView::options(RenderMode::Pipeline));
  ImageRgb8 image;
  EXPECT_EQ(r.render(c, image).impostorsWhy, "no impostors held for the viewer's cell");
  r.setImpostors(v.set);
  const FrameReport rep = r.render(c, image);
  EXPECT_FALSE(rep.impostorsRan);
  EXPECT_NE(rep.impostorsWhy.find("not the viewer's"), std::string::npos) << rep.impostorsWhy;
  EXPECT_EQ(rep.pixels.impostor, 0u);
}

}  // namespace
}  // namespace vistream
