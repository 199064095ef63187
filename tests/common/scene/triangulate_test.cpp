// Tests for triangulatePolygon (common/scene/triangulate.h).
//
// Oracles, all computed here independently of the code under test:
// - the shoelace formula for the polygon's signed area;
// - the signed area of every output triangle, measured in the 2D frame the
//   test built the polygon in (so a polygon embedded in any 3D plane is judged
//   by the same ruler);
// - a sampled coverage check: a jittered grid of points, each point strictly
//   inside the polygon (even-odd ray crossing test) must lie in exactly one
//   output triangle, each point outside in none. This catches overlapping or
//   missing triangles that an area sum alone could hide.
#include "common/scene/triangulate.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <random>
#include <set>
#include <vector>

namespace vistream {
namespace {

using Polygon2 = std::vector<glm::dvec2>;

// ---- independent geometry ---------------------------------------------------

double shoelaceArea(const Polygon2& p) {
  double twice = 0.0;
  for (size_t i = 0; i < p.size(); ++i) {
    const glm::dvec2 a = p[i], b = p[(i + 1) % p.size()];
    twice += a.x * b.y - b.x * a.y;
  }
  return 0.5 * twice;
}

double signedTriangleArea(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
  return 0.5 * ((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y));
}

// Even-odd rule with a horizontal ray.
bool insidePolygon(const Polygon2& poly, const glm::dvec2& q) {
  bool inside = false;
  for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const glm::dvec2 a = poly[i], b = poly[j];
    if ((a.y > q.y) != (b.y > q.y)) {
      const double x = a.x + (q.y - a.y) * (b.x - a.x) / (b.y - a.y);
      if (q.x < x) inside = !inside;
    }
  }
  return inside;
}

double distanceToSegment(const glm::dvec2& q, const glm::dvec2& a, const glm::dvec2& b) {
  const glm::dvec2 ab = b - a;
  const double len2 = glm::dot(ab, ab);
  const double t = len2 > 0.0 ? glm::clamp(glm::dot(q - a, ab) / len2, 0.0, 1.0) : 0.0;
  return glm::length(q - (a + t * ab));
}

// 0: outside, 1: strictly inside, -1: too close to an edge to tell.
int classifyInTriangle(const glm::dvec2& q, const glm::dvec2& a, const glm::dvec2& b,
                       const glm::dvec2& c, double eps) {
  const double area = signedTriangleArea(a, b, c);
  if (std::abs(area) < 1e-14) return 0;  // a degenerate triangle covers nothing
  if (distanceToSegment(q, a, b) < eps || distanceToSegment(q, b, c) < eps ||
      distanceToSegment(q, c, a) < eps)
    return -1;
  const double s = area > 0 ? 1.0 : -1.0;
  const bool in = s * signedTriangleArea(a, b, q) > 0 && s * signedTriangleArea(b, c, q) > 0 &&
                  s * signedTriangleArea(c, a, q) > 0;
  return in ? 1 : 0;
}

// ---- embedding 2D polygons in 3D planes -------------------------------------

struct Plane {
  glm::dvec3 origin{0.0};
  glm::dvec3 u{1.0, 0.0, 0.0};
  glm::dvec3 v{0.0, 1.0, 0.0};
};

std::vector<glm::dvec3> embed(const Polygon2& p, const Plane& plane) {
  std::vector<glm::dvec3> out;
  for (const glm::dvec2& q : p) out.push_back(plane.origin + q.x * plane.u + q.y * plane.v);
  return out;
}

std::vector<glm::uvec3> triangulate2d(const Polygon2& p, const Plane& plane = {}) {
  const std::vector<glm::dvec3> poly3 = embed(p, plane);
  std::vector<glm::uvec3> out;
  triangulatePolygon(poly3, out);
  return out;
}

// ---- the full check ---------------------------------------------------------

// Checks that `tris` is a triangulation of `poly`: n-2 triangles, indices in
// range, total signed area equal to the polygon's, every triangle wound like
// the polygon (or degenerate), and sampled points covered exactly once inside
// and never outside.
void expectValidTriangulation(const Polygon2& poly, const std::vector<glm::uvec3>& tris,
                              int samplesPerAxis = 60) {
  const size_t n = poly.size();
  ASSERT_EQ(tris.size(), n - 2) << "an n-gon must give n-2 triangles";
  const double polyArea = shoelaceArea(poly);
  const double sign = polyArea > 0 ? 1.0 : -1.0;
  double sum = 0.0;
  for (size_t t = 0; t < tris.size(); ++t) {
    const glm::uvec3 tri = tris[t];
    ASSERT_LT(tri.x, n);
    ASSERT_LT(tri.y, n);
    ASSERT_LT(tri.z, n);
    const double a = signedTriangleArea(poly[tri.x], poly[tri.y], poly[tri.z]);
    EXPECT_GE(sign * a, -1e-9 * std::abs(polyArea))
        << "triangle " << t << " (" << tri.x << "," << tri.y << "," << tri.z
        << ") is wound against the polygon";
    sum += a;
  }
  EXPECT_NEAR(sum, polyArea, 1e-9 * std::max(1.0, std::abs(polyArea)));

  glm::dvec2 lo(1e300), hi(-1e300);
  for (const glm::dvec2& q : poly) {
    lo = glm::min(lo, q);
    hi = glm::max(hi, q);
  }
  const glm::dvec2 size = hi - lo;
  const double eps = 1e-9 * std::max(size.x, size.y);
  // Irrational offsets keep samples off the rational vertex lattice.
  const double jitterX = std::numbers::sqrt2 / 7.0, jitterY = std::numbers::pi / 11.0;
  int checked = 0;
  for (int iy = 0; iy < samplesPerAxis; ++iy) {
    for (int ix = 0; ix < samplesPerAxis; ++ix) {
      const glm::dvec2 q(lo.x + size.x * (ix + jitterX) / samplesPerAxis,
                         lo.y + size.y * (iy + jitterY) / samplesPerAxis);
      bool nearEdge = false;
      for (size_t i = 0; i < n && !nearEdge; ++i)
        nearEdge = distanceToSegment(q, poly[i], poly[(i + 1) % n]) < eps;
      int covered = 0;
      for (const glm::uvec3& tri : tris) {
        const int c = classifyInTriangle(q, poly[tri.x], poly[tri.y], poly[tri.z], eps);
        if (c < 0) nearEdge = true;
        covered += c > 0 ? 1 : 0;
      }
      if (nearEdge) continue;
      ++checked;
      const int expected = insidePolygon(poly, q) ? 1 : 0;
      ASSERT_EQ(covered, expected)
          << "sample (" << q.x << ", " << q.y << ") is covered " << covered << " times";
    }
  }
  EXPECT_GT(checked, samplesPerAxis * samplesPerAxis / 2) << "too few samples were decidable";
}

// ---- polygons with known areas ------------------------------------------------

Polygon2 regularPolygon(int n, double radius, double phase = 0.3) {
  Polygon2 p;
  for (int i = 0; i < n; ++i) {
    const double a = phase + 2.0 * std::numbers::pi * i / n;
    p.emplace_back(radius * std::cos(a), radius * std::sin(a));
  }
  return p;
}

// Area 3.
Polygon2 lShape() {
  return {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
}

// A 3x3 square with a 1x2 notch cut from the top middle: area 7.
Polygon2 uShape() {
  return {{0, 0}, {3, 0}, {3, 3}, {2, 3}, {2, 1}, {1, 1}, {1, 3}, {0, 3}};
}

Polygon2 star(int points, double outer, double inner) {
  Polygon2 p;
  for (int i = 0; i < 2 * points; ++i) {
    const double a = std::numbers::pi / 2 + std::numbers::pi * i / points;
    const double r = i % 2 == 0 ? outer : inner;
    p.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  return p;
}

// A comb: a base bar of height 1 and `teeth` teeth of width 1 and height
// `height` - 1, with gaps of width 1; 4 * teeth vertices, counter-clockwise.
// Area: (2 * teeth - 1) + teeth * (height - 1).
Polygon2 comb(int teeth, double height) {
  Polygon2 p;
  p.emplace_back(0, 0);
  p.emplace_back(2 * teeth - 1, 0);
  for (int i = teeth - 1; i >= 0; --i) {
    p.emplace_back(2 * i + 1, height);
    p.emplace_back(2 * i, height);
    if (i > 0) {
      p.emplace_back(2 * i, 1);
      p.emplace_back(2 * i - 1, 1);
    }
  }
  return p;
}

Polygon2 reversed(Polygon2 p) {
  std::reverse(p.begin(), p.end());
  return p;
}

// ---- tests -------------------------------------------------------------------

TEST(TriangulatePolygon, AppendsNothingForFewerThanThreeVertices) {
  std::vector<glm::uvec3> out{{7, 8, 9}};
  const std::vector<glm::dvec3> none, one{{0, 0, 0}}, two{{0, 0, 0}, {1, 0, 0}};
  triangulatePolygon(none, out);
  triangulatePolygon(one, out);
  triangulatePolygon(two, out);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0], glm::uvec3(7, 8, 9));
}

TEST(TriangulatePolygon, AppendsAfterWhatIsAlreadyInTheOutput) {
  std::vector<glm::uvec3> out{{7, 8, 9}};
  triangulatePolygon(embed(lShape(), {}), out);
  ASSERT_EQ(out.size(), 1u + 4u);
  EXPECT_EQ(out[0], glm::uvec3(7, 8, 9));
}

TEST(TriangulatePolygon, KeepsATriangleAsIs) {
  const std::vector<glm::uvec3> tris = triangulate2d({{0, 0}, {1, 0}, {0, 1}});
  ASSERT_EQ(tris.size(), 1u);
  EXPECT_EQ(tris[0], glm::uvec3(0, 1, 2));
}

TEST(TriangulatePolygon, SplitsConvexNGonsIntoNMinusTwoTrianglesOfEqualTotalArea) {
  for (int n = 3; n <= 24; ++n) {
    SCOPED_TRACE(n);
    const Polygon2 p = regularPolygon(n, 2.5);
    // Closed form as a second oracle beside the shoelace formula.
    EXPECT_NEAR(shoelaceArea(p), 0.5 * n * 2.5 * 2.5 * std::sin(2 * std::numbers::pi / n), 1e-9);
    expectValidTriangulation(p, triangulate2d(p));
  }
}

TEST(TriangulatePolygon, CoversAConcaveLShapeExactly) {
  const Polygon2 p = lShape();
  EXPECT_DOUBLE_EQ(shoelaceArea(p), 3.0);
  expectValidTriangulation(p, triangulate2d(p));
}

TEST(TriangulatePolygon, CoversAConcaveUShapeExactly) {
  const Polygon2 p = uShape();
  EXPECT_DOUBLE_EQ(shoelaceArea(p), 7.0);
  expectValidTriangulation(p, triangulate2d(p));
}

TEST(TriangulatePolygon, CoversAFivePointedStarExactly) {
  const Polygon2 p = star(5, 2.0, 0.8);
  // Ten triangles (centre, outer, inner): 10 * 0.5 * R * r * sin(36 deg).
  EXPECT_NEAR(shoelaceArea(p), 10 * 0.5 * 2.0 * 0.8 * std::sin(std::numbers::pi / 5), 1e-12);
  expectValidTriangulation(p, triangulate2d(p));
}

TEST(TriangulatePolygon, CoversASpikyTwelvePointedStarExactly) {
  const Polygon2 p = star(12, 5.0, 0.3);
  expectValidTriangulation(p, triangulate2d(p), 120);
}

TEST(TriangulatePolygon, KeepsClockwiseInputClockwise) {
  for (const Polygon2& ccw : {lShape(), uShape(), star(5, 2.0, 0.8), regularPolygon(7, 1.0)}) {
    const Polygon2 cw = reversed(ccw);
    ASSERT_LT(shoelaceArea(cw), 0.0);
    // expectValidTriangulation requires every triangle to share the polygon's
    // (here negative) orientation.
    expectValidTriangulation(cw, triangulate2d(cw));
  }
}

TEST(TriangulatePolygon, ToleratesCollinearVerticesOnEdges) {
  // A 2x2 square with a vertex in the middle of every edge, and a long run of
  // collinear vertices along the bottom of an L.
  const Polygon2 square{{0, 0}, {1, 0}, {2, 0}, {2, 1}, {2, 2}, {1, 2}, {0, 2}, {0, 1}};
  expectValidTriangulation(square, triangulate2d(square));
  const Polygon2 l{{0, 0}, {0.5, 0}, {1, 0}, {1.5, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
  EXPECT_DOUBLE_EQ(shoelaceArea(l), 3.0);
  expectValidTriangulation(l, triangulate2d(l));
}

TEST(TriangulatePolygon, ToleratesRepeatedVertices) {
  const Polygon2 square{{0, 0}, {1, 0}, {1, 0}, {1, 1}, {0, 1}};
  expectValidTriangulation(square, triangulate2d(square));
  const Polygon2 l{{0, 0}, {2, 0}, {2, 1}, {2, 1}, {1, 1}, {1, 2}, {0, 2}, {0, 2}};
  expectValidTriangulation(l, triangulate2d(l));
}

TEST(TriangulatePolygon, CoversAKeyholePolygonWhoseBridgeEdgesCoincide) {
  // A 4x4 square with a 2x2 hole, joined by a zero-width bridge from (0,2) to
  // (1,2): how a wall with a window often arrives as one OBJ face. Area 12.
  const Polygon2 p{{0, 0}, {4, 0}, {4, 4}, {0, 4}, {0, 2}, {1, 2},
                   {1, 3}, {3, 3}, {3, 1}, {1, 1}, {1, 2}, {0, 2}};
  EXPECT_DOUBLE_EQ(shoelaceArea(p), 12.0);
  expectValidTriangulation(p, triangulate2d(p), 80);
}

TEST(TriangulatePolygon, TriangulatesTheSamePolygonInAnyPlane) {
  const double s = std::sqrt(0.5);
  const glm::dvec3 tu = glm::normalize(glm::dvec3(1.0, 2.0, -0.5));
  const glm::dvec3 tv = glm::normalize(glm::cross(glm::dvec3(0.3, -0.1, 1.0), tu));
  const std::vector<std::pair<const char*, Plane>> planes{
      {"XY", {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}},
      {"YX (mirrored)", {{0, 0, 0}, {0, 1, 0}, {1, 0, 0}}},
      {"YZ", {{3, 0, 0}, {0, 1, 0}, {0, 0, 1}}},
      {"ZY (mirrored)", {{-3, 0, 0}, {0, 0, 1}, {0, 1, 0}}},
      {"XZ", {{0, 5, 0}, {1, 0, 0}, {0, 0, 1}}},
      {"ZX (mirrored)", {{0, -5, 0}, {0, 0, 1}, {1, 0, 0}}},
      {"tilted 45 deg about X", {{0, 0, 0}, {1, 0, 0}, {0, s, s}}},
      {"tilted, far from the origin", {{52000.0, 12.0, -31000.0}, tu, tv}},
  };
  for (const auto& [name, plane] : planes) {
    for (const Polygon2& p : {lShape(), uShape(), star(5, 2.0, 0.8), reversed(uShape())}) {
      SCOPED_TRACE(name);
      expectValidTriangulation(p, triangulate2d(p, plane));
    }
  }
}

TEST(TriangulatePolygon, ClipsA200VertexCombQuickly) {
  const Polygon2 p = comb(50, 10.0);
  ASSERT_EQ(p.size(), 200u);
  EXPECT_DOUBLE_EQ(shoelaceArea(p), 99.0 + 50 * 9.0);
  const auto start = std::chrono::steady_clock::now();
  const std::vector<glm::uvec3> tris = triangulate2d(p);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_LT(seconds, 1.0);
  expectValidTriangulation(p, tris, 200);
}

TEST(TriangulatePolygon, TriangulatesRandomStarShapedPolygons) {
  // Vertices at sorted random angles and random radii around a centre: always
  // simple, often very concave.
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> radius(0.2, 3.0), angle(0.0, 2.0 * std::numbers::pi);
  std::uniform_int_distribution<int> count(3, 40);
  for (int k = 0; k < 150; ++k) {
    const int n = count(rng);
    std::vector<double> angles;
    for (int i = 0; i < n; ++i) angles.push_back(angle(rng));
    std::sort(angles.begin(), angles.end());
    Polygon2 p;
    for (double a : angles) {
      const double r = radius(rng);
      p.emplace_back(r * std::cos(a), r * std::sin(a));
    }
    if (k % 2 == 1) p = reversed(p);
    SCOPED_TRACE(k);
    expectValidTriangulation(p, triangulate2d(p), 40);
    if (testing::Test::HasFatalFailure()) return;
  }
}

TEST(TriangulatePolygon, StillGivesNMinusTwoTrianglesForASelfIntersectingBowtie) {
  const Polygon2 bowtie{{0, 0}, {1, 1}, {1, 0}, {0, 1}};
  const std::vector<glm::uvec3> tris = triangulate2d(bowtie);
  ASSERT_EQ(tris.size(), 2u);
  std::set<uint32_t> used;
  for (const glm::uvec3& t : tris) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_LT(t[k], 4u);
      used.insert(t[k]);
    }
  }
  EXPECT_EQ(used.size(), 4u) << "every vertex of the face is covered";
}

TEST(TriangulatePolygon, TerminatesOnFullyDegeneratePolygons) {
  // All on one line, and all on one point: n-2 triangles, indices in range.
  std::vector<glm::dvec3> line, point;
  for (int i = 0; i < 30; ++i) {
    line.emplace_back(i, 2 * i, 0);
    point.emplace_back(1, 1, 1);
  }
  for (const auto& poly : {line, point}) {
    std::vector<glm::uvec3> out;
    triangulatePolygon(poly, out);
    ASSERT_EQ(out.size(), poly.size() - 2);
    for (const glm::uvec3& t : out) EXPECT_LT(glm::max(t.x, glm::max(t.y, t.z)), poly.size());
  }
}

}  // namespace
}  // namespace vistream
