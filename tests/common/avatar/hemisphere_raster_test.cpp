#include "common/avatar/hemisphere_raster.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>

namespace vistream {
namespace {

// The oracle: does the ray from the origin along s meet triangle (a, b, c)?
// (Moeller and Trumbore, in double.)
bool rayHitsTriangle(const glm::vec3& s, const glm::vec3& a, const glm::vec3& b,
                     const glm::vec3& c) {
  const glm::dvec3 d(s), A(a), e1 = glm::dvec3(b) - A, e2 = glm::dvec3(c) - A;
  const glm::dvec3 p = glm::cross(d, e2);
  const double det = glm::dot(e1, p);
  if (det == 0.0) return false;
  const glm::dvec3 t = -A;
  const double u = glm::dot(t, p) / det;
  const glm::dvec3 q = glm::cross(t, e1);
  const double v = glm::dot(d, q) / det;
  const double dist = glm::dot(e2, q) / det;
  return u >= 0.0 && v >= 0.0 && u + v <= 1.0 && dist > 0.0;
}

// How close s is to the image's boundary: to one of the planes through the
// origin and an edge (as |s . n| for unit n), or to the horizon (s.z).
double boundaryDistance(const glm::vec3& s, const glm::vec3& a, const glm::vec3& b,
                        const glm::vec3& c) {
  double d = std::abs(double(s.z));
  const glm::dvec3 S(s), P[3] = {glm::dvec3(a), glm::dvec3(b), glm::dvec3(c)};
  for (int k = 0; k < 3; ++k) {
    const glm::dvec3 n = glm::cross(P[k], P[(k + 1) % 3]);
    const double len = glm::length(n);
    if (len > 0.0) d = std::min(d, std::abs(glm::dot(S, n)) / len);
  }
  return d;
}

struct Comparison {
  size_t covered = 0, mismatched = 0;
  double worstDistance = 0.0;  // of a mismatched pixel from the boundary
};

// Rasterizes (a, b, c) alone and compares every disk pixel with the oracle.
Comparison compare(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                   const PlaneMaskTable* table, int side) {
  VisibilityMask mask(side);
  rasterizeBlocker(a, b, c, table, mask);
  Comparison r;
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) {
      if (!maskPixelInDisk(side, x, y)) {
        EXPECT_FALSE(mask.test(x, y)) << "a pixel outside the disk is set";
        continue;
      }
      const glm::vec3 s = maskDirection(side, x, y);
      const bool want = rayHitsTriangle(s, a, b, c);
      r.covered += want;
      if (mask.test(x, y) != want) {
        ++r.mismatched;
        r.worstDistance = std::max(r.worstDistance, boundaryDistance(s, a, b, c));
      }
    }
  return r;
}

// Random blockers around the vertex: small and near, crossing the tangent
// plane, huge, far and thin.
std::vector<std::array<glm::vec3, 3>> randomBlockers() {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> near(-2.0f, 2.0f), up(-0.5f, 2.0f);
  std::vector<std::array<glm::vec3, 3>> out;
  for (int i = 0; i < 300; ++i) {
    const float scale = i % 10 == 0 ? 1e4f : (i % 10 == 1 ? 1e-3f : 1.0f);
    const glm::vec3 centre = i % 10 == 1 ? glm::vec3(0, 0, 0.01f) : glm::vec3(0.0f);
    std::array<glm::vec3, 3> t;
    for (auto& p : t) p = centre + scale * glm::vec3(near(rng), near(rng), up(rng));
    if (i % 10 == 2) t[2] = t[0] + 1e-3f * (t[1] - t[0]) + glm::vec3(0, 0, 1e-3f);  // a sliver
    out.push_back(t);
  }
  return out;
}

TEST(HemisphereRaster, ExactPlanesMatchTheRayOracleExceptOnTheBoundary) {
  size_t covered = 0;
  for (const auto& t : randomBlockers()) {
    const Comparison r = compare(t[0], t[1], t[2], nullptr, 32);
    covered += r.covered;
    EXPECT_LE(r.worstDistance, 1e-4) << r.mismatched << " pixels off";
  }
  EXPECT_GT(covered, 10000u);  // the blockers covered something
}

// A table's plane differs from the true one by at most |q - n| for unit
// normals, so a pixel can only flip within that of an edge plane; on a
// 128-cell cube face that is under sqrt(2) / 128 (half a cell's diagonal).
TEST(HemisphereRaster, ThePlaneTableDiffersOnlyWithinItsQuantizationOfAnEdge) {
  for (const int cube : {32, 128}) {
    const PlaneMaskTable table(32, cube);
    const double bound = std::sqrt(2.0) / cube * 1.02;
    size_t covered = 0, mismatched = 0;
    for (const auto& t : randomBlockers()) {
      const Comparison r = compare(t[0], t[1], t[2], &table, 32);
      covered += r.covered;
      mismatched += r.mismatched;
      EXPECT_LE(r.worstDistance, bound) << "cube " << cube;
    }
    EXPECT_LT(double(mismatched), 0.05 * double(covered)) << "cube " << cube;
  }
}

TEST(HemisphereRaster, TheTableAnswersEveryNormalEvenInfiniteOrNaN) {
  const PlaneMaskTable table(16, 8);
  for (const glm::vec3& n :
       {glm::vec3(INFINITY, 1, 0), glm::vec3(NAN, 0, 1), glm::vec3(0.0f),
        glm::vec3(-INFINITY, -INFINITY, INFINITY), glm::vec3(1e38f, -1e38f, 3)})
    EXPECT_NE(table.above(n).bits, nullptr);
}

// The table stores the positive faces only and complements their mirror
// cells for the negative ones: every normal, on any face, still reads exactly
// the disk pixels on the positive side of its quantized plane.
TEST(HemisphereRaster, EveryNormalReadsThePixelsAboveItsQuantizedPlaneOnAnyFace) {
  const PlaneMaskTable table(32, 16);
  std::mt19937 rng(11);
  std::normal_distribution<float> g;
  int negativeFaces = 0;
  for (int i = 0; i < 3000; ++i) {
    const glm::vec3 n = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    const glm::vec3 a = glm::abs(n);
    const float dominant = a.x >= a.y && a.x >= a.z ? n.x : a.y >= a.z ? n.y : n.z;
    negativeFaces += dominant < 0.0f;
    const PlaneMaskTable::Mask m = table.above(n);
    const glm::vec3 q = table.quantized(n);
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x) {
        const size_t bit = size_t(y) * 32 + size_t(x);
        const bool set = ((m.bits[bit >> 6] ^ m.flip) & table.disk()[bit >> 6]) >> (bit & 63) & 1;
        if (!maskPixelInDisk(32, x, y)) {
          ASSERT_FALSE(set) << "outside the disk at " << x << "," << y;
          continue;
        }
        const float side = glm::dot(maskDirection(32, x, y), q);
        if (std::abs(side) < 1e-5f) continue;  // on the plane: either answer
        ASSERT_EQ(set, side > 0.0f)
            << "normal " << n.x << "," << n.y << "," << n.z << " pixel " << x << "," << y;
      }
  }
  EXPECT_GT(negativeFaces, 1000);  // half the normals read complemented cells
}

// The four-wide lookups choose exactly the scalar lookup's cell, for every
// kind of normal: random, on cube edges and corners (ties between axes),
// zero, infinite and NaN, in batches of every length (the last partial).
TEST(HemisphereRaster, BatchedLookupsReadTheSameRowsAsOneAtATime) {
  const PlaneMaskTable table(32, 128);
  std::mt19937 rng(5);
  std::normal_distribution<float> g;
  std::vector<glm::vec3> normals;
  for (int i = 0; i < 4000; ++i) normals.emplace_back(g(rng), g(rng), g(rng));
  for (const float a : {1.0f, -1.0f})
    for (const float b : {1.0f, -1.0f, 0.0f})
      for (const float c : {1.0f, -1.0f, 0.0f}) {
        normals.emplace_back(a, b, c);
        normals.emplace_back(b, a, c);
        normals.emplace_back(c, b, a);
      }
  for (const glm::vec3& n :
       {glm::vec3(0.0f), glm::vec3(-0.0f), glm::vec3(INFINITY, 1, 0), glm::vec3(NAN, 0, 1),
        glm::vec3(0, NAN, -1), glm::vec3(-INFINITY, -INFINITY, INFINITY),
        glm::vec3(1e38f, -1e38f, 3), glm::vec3(1e-40f, 0, 0)})
    normals.push_back(n);
  for (const size_t length : {normals.size(), size_t(1), size_t(2), size_t(3), size_t(7)}) {
    std::vector<float> x, y, z;
    for (size_t k = 0; k < length; ++k) {
      x.push_back(normals[k].x);
      y.push_back(normals[k].y);
      z.push_back(normals[k].z);
    }
    std::vector<PlaneMaskTable::Mask> many(length);
    table.aboveMany(x.data(), y.data(), z.data(), length, many.data());
    for (size_t k = 0; k < length; ++k) {
      const PlaneMaskTable::Mask one = table.above(normals[k]);
      ASSERT_EQ(many[k].bits, one.bits) << "normal " << k;
      ASSERT_EQ(many[k].flip, one.flip) << "normal " << k;
    }
  }
  for (const int count : {1, 2, 3, 4})
    for (size_t k = 0; k + 4 <= normals.size(); k += 4) {
      PlaneMaskTable::Mask some[4];
      table.aboveAll(&normals[k], count, some);
      for (int i = 0; i < count; ++i) {
        const PlaneMaskTable::Mask one = table.above(normals[k + size_t(i)]);
        ASSERT_EQ(some[i].bits, one.bits);
        ASSERT_EQ(some[i].flip, one.flip);
      }
    }
}

// A batch draws, bit for bit, what the blockers draw one at a time, and
// takes or refuses the same blockers.
TEST(HemisphereRaster, ABatchOfBlockersDrawsExactlyWhatTheyDrawOneByOne) {
  const PlaneMaskTable table(32, 128);
  std::vector<std::array<glm::vec3, 3>> blockers = randomBlockers();
  blockers.push_back({glm::vec3(1, 0, 1), glm::vec3(0, 1, 1), glm::vec3(-1, -1, -2)});  // edge-on
  blockers.push_back({glm::vec3(1, 0, -1), glm::vec3(0, 1, -1), glm::vec3(1, 1, -2)});  // below
  BlockerBatch batch;
  for (size_t first = 0; first < blockers.size(); first += 37) {
    VisibilityMask one(32), many(32);
    batch.clear();
    size_t refused = 0;
    for (size_t k = first; k < std::min(blockers.size(), first + 37); ++k) {
      const auto& t = blockers[k];
      const bool drawn = rasterizeBlocker(t[0], t[1], t[2], &table, one);
      ASSERT_EQ(batch.add(t[0], t[1], t[2]), drawn) << "blocker " << k;
      refused += !drawn;
    }
    batch.draw(table, many);
    EXPECT_EQ(batch.size() + refused, std::min(blockers.size(), first + 37) - first);
    ASSERT_GT(one.count(), 0u);
    for (int w = 0; w < one.words(); ++w) ASSERT_EQ(many.data()[w], one.data()[w]) << "word " << w;
  }
}

TEST(HemisphereRaster, TheTablesQuantizedNormalIsWithinHalfACellDiagonal) {
  const PlaneMaskTable table(32, 64);
  std::mt19937 rng(3);
  std::normal_distribution<float> g;
  for (int i = 0; i < 10000; ++i) {
    const glm::vec3 n = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
    ASSERT_LE(glm::distance(table.quantized(n), n), std::sqrt(2.0f) / 64.0f * 1.02f);
  }
}

TEST(HemisphereRaster, ATriangleEdgeOnToTheVertexDrawsNothing) {
  const PlaneMaskTable table(32, 64);
  VisibilityMask mask(32);
  // Its plane holds the vertex: c = -(a + b).
  EXPECT_FALSE(rasterizeBlocker({1, 0, 1}, {0, 1, 1}, {-1, -1, -2}, &table, mask));
  // The vertex lies on the edge from a to b.
  EXPECT_FALSE(rasterizeBlocker({-1, -1, -1}, {1, 1, 1}, {0, 1, 3}, &table, mask));
  // The vertex is one of its corners (a triangle of the vertex's own ring).
  EXPECT_FALSE(rasterizeBlocker({0, 0, 0}, {1, 0, 0.5f}, {0, 1, 0.5f}, &table, mask));
  // Collinear corners.
  EXPECT_FALSE(rasterizeBlocker({1, 0, 1}, {2, 0, 2}, {3, 0, 3}, &table, mask));
  EXPECT_EQ(mask.count(), 0u);
}

TEST(HemisphereRaster, ATriangleAtOrBelowTheTangentPlaneDrawsNothing) {
  const PlaneMaskTable table(32, 64);
  VisibilityMask mask(32);
  EXPECT_FALSE(rasterizeBlocker({-1, -1, -1}, {1, -1, -1}, {0, 1, -0.5f}, &table, mask));
  EXPECT_FALSE(rasterizeBlocker({-1, -1, 0}, {1, -1, -1}, {0, 1, 0}, &table, mask));
  EXPECT_EQ(mask.count(), 0u);
}

// A ceiling over everything (two huge triangles at z = 1) covers the whole
// hemisphere: every disk pixel but a few along the horizon and the seam.
TEST(HemisphereRaster, TwoTrianglesOfAnEndlessCeilingCoverTheWholeDisk) {
  const PlaneMaskTable table(32, 128);
  VisibilityMask mask(32);
  const float f = 1e5f;
  EXPECT_TRUE(rasterizeBlocker({-f, -f, 1}, {f, -f, 1}, {f, f, 1}, &table, mask));
  EXPECT_TRUE(rasterizeBlocker({-f, -f, 1}, {f, f, 1}, {-f, f, 1}, &table, mask));
  size_t disk = 0;
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) disk += maskPixelInDisk(32, x, y);
  EXPECT_GE(double(mask.count()), 0.97 * double(disk));
  EXPECT_LE(mask.count(), disk);
}

// A wall crossing the tangent plane: only its upper part is drawn, and the
// result is the oracle's but for the boundary (the clipped edge included).
TEST(HemisphereRaster, ABlockerCrossingTheTangentPlaneIsClippedToItsUpperPart) {
  const glm::vec3 a{2, -3, -1}, b{2, 3, -1}, c{2, 0, 3};
  const Comparison exact = compare(a, b, c, nullptr, 32);
  EXPECT_GT(exact.covered, 20u);
  EXPECT_LE(exact.worstDistance, 1e-4);
}

TEST(VisibilityMask, SetsTestsCountsAndClearsBits) {
  VisibilityMask m(16);
  EXPECT_EQ(m.words(), 4);
  m.set(0, 0);
  m.set(15, 15);
  m.set(3, 7);
  EXPECT_TRUE(m.test(3, 7));
  EXPECT_FALSE(m.test(7, 3));
  EXPECT_EQ(m.count(), 3u);
  m.clear();
  EXPECT_EQ(m.count(), 0u);
}

}  // namespace
}  // namespace vistream
