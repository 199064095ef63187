// Wall lines (server/visibility/wall_occluders.h) against known answers and
// a brute-force oracle: every point (u, y) of a cover the lines report must
// lie in one of the line's triangles, tested point by point in the plane.
#include "server/visibility/wall_occluders.h"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <random>
#include <span>
#include <vector>

namespace vistream {
namespace {

constexpr double kTolerance = 1e-3;

// Vertical quads between X/Z points a and b, heights y0 to y1, each split
// along a diagonal (as a loader fans a quad), collected into one mesh.
struct Walls {
  std::vector<glm::vec3> positions;
  std::vector<glm::uvec3> triangles;
  void quad(glm::vec2 a, glm::vec2 b, float y0, float y1) {
    const uint32_t n = uint32_t(positions.size());
    positions.insert(positions.end(),
                     {{a.x, y0, a.y}, {b.x, y0, b.y}, {b.x, y1, b.y}, {a.x, y1, a.y}});
    triangles.push_back({n, n + 1, n + 2});
    triangles.push_back({n, n + 2, n + 3});
  }
  WallOccluders build() const {
    return WallOccluders(flattenMesh(positions, triangles), kTolerance, 0.25, 0.5 * kTolerance);
  }
};

double tangential(const WallLine& line, glm::vec2 p) {
  return glm::dot(line.t, glm::dvec2(p));
}

TEST(WallOccluders, ADiagonallySplitQuadCoversItsWholeHeightAcrossItsWidth) {
  Walls w;
  w.quad({0.0f, 2.0f}, {6.0f, 2.0f}, 0.0f, 8.0f);
  const WallOccluders walls = w.build();
  ASSERT_EQ(walls.size(), 1u);
  const WallLine& line = walls.line(0);
  EXPECT_NEAR(std::abs(line.n.y), 1.0, 1e-12);
  EXPECT_NEAR(line.c * line.n.y, 2.0, 1e-6);
  const double u0 = tangential(line, {0.3f, 2.0f}), u1 = tangential(line, {5.7f, 2.0f});
  const auto cover = walls.cover(0, std::min(u0, u1), std::max(u0, u1));
  ASSERT_TRUE(cover.has_value());
  EXPECT_NEAR(cover->x, 0.0, 1e-5);
  EXPECT_NEAR(cover->y, 8.0, 1e-5);
  // Past the quad's ends nothing is covered.
  const double out = tangential(line, {6.5f, 2.0f});
  EXPECT_FALSE(walls.cover(0, std::min(u0, out), std::max(u0, out)).has_value());
}

TEST(WallOccluders, JoinsPanelsOnOneLineAcrossHairlinesButNotAcrossGaps) {
  // Three panels along X: the second 0.5 mm after the first (a crack below
  // the tolerance, taken as closed), the third 5 cm after the second.
  Walls w;
  w.quad({0.0f, 0.0f}, {4.0f, 0.0f}, 0.0f, 6.0f);
  w.quad({4.0005f, 0.0f}, {8.0f, 0.0f}, 0.0f, 5.0f);
  w.quad({8.05f, 0.0f}, {12.0f, 0.0f}, 1.0f, 6.0f);
  const WallOccluders walls = w.build();
  ASSERT_EQ(walls.size(), 1u);
  const WallLine& line = walls.line(0);
  auto coverX = [&](float x0, float x1) {
    const double a = tangential(line, {x0, 0.0f}), b = tangential(line, {x1, 0.0f});
    return walls.cover(0, std::min(a, b), std::max(a, b));
  };
  const auto across = coverX(2.0f, 6.0f);
  ASSERT_TRUE(across.has_value());
  EXPECT_NEAR(across->x, 0.0, 1e-5);
  EXPECT_NEAR(across->y, 5.0, 1e-5);  // the lower panel's top
  EXPECT_FALSE(coverX(7.0f, 9.0f).has_value());
  const auto third = coverX(9.0f, 11.0f);
  ASSERT_TRUE(third.has_value());
  EXPECT_NEAR(third->x, 1.0, 1e-5);
}

TEST(WallOccluders, StacksPanelsThatMeetAndLeavesOutTiltedOnes) {
  // A ground-floor panel and an upper one meeting at 3 m; a gable triangle
  // on top; a panel beside, tilted 1 cm off vertical (no wall).
  Walls w;
  w.quad({0.0f, 0.0f}, {0.0f, 5.0f}, 0.0f, 3.0f);
  w.quad({0.0f, 0.0f}, {0.0f, 5.0f}, 3.0f, 7.0f);
  const uint32_t n = uint32_t(w.positions.size());
  w.positions.insert(w.positions.end(),
                     {{0.0f, 7.0f, 0.0f}, {0.0f, 7.0f, 5.0f}, {0.0f, 9.0f, 2.5f}});
  w.triangles.push_back({n, n + 1, n + 2});
  const uint32_t m = uint32_t(w.positions.size());
  w.positions.insert(
      w.positions.end(),
      {{20.0f, 0.0f, 0.0f}, {20.0f, 0.0f, 5.0f}, {20.01f, 4.0f, 5.0f}, {20.01f, 4.0f, 0.0f}});
  w.triangles.push_back({m, m + 1, m + 2});
  w.triangles.push_back({m, m + 2, m + 3});
  const WallOccluders walls = w.build();
  ASSERT_EQ(walls.size(), 1u);
  const WallLine& line = walls.line(0);
  const double a = tangential(line, {0.0f, 2.0f}), b = tangential(line, {0.0f, 3.0f});
  const auto cover = walls.cover(0, std::min(a, b), std::max(a, b));
  ASSERT_TRUE(cover.has_value());
  EXPECT_NEAR(cover->x, 0.0, 1e-5);
  // Under the gable the top rises above 7 m, to 8.6 m at z = 2 and 3; the
  // window's bins (0.25 m) may reach one bin past it, where it is 8.4 m.
  EXPECT_GE(cover->y, 8.4 - 1e-4);
  EXPECT_LE(cover->y, 8.6);
}

// Two panels stacked but 18 mm apart across their plane (a slit a line of
// sight rising through y = 3 passes): no line covers both, although both lie
// within 10 mm of a plane between them; the same panels 2 mm apart (a crack
// read as closed) make one line covering [0, 6]. The horizons give the
// class a quarter of their 1 cm tolerance (proof, step 7).
TEST(WallOccluders, StacksPanelsOnlyWhenTheyAreCloserAcrossTheirPlaneThanTheTolerance) {
  for (const float apart : {0.018f, 0.002f}) {
    Walls w;
    w.quad({0.0f, 0.0f}, {5.0f, 0.0f}, 0.0f, 3.0f);
    w.quad({0.0f, apart}, {5.0f, apart}, 3.0f, 6.0f);
    // A longer panel farther along, midway between their planes: the
    // reference a group is measured against, each panel half the distance
    // from it.
    w.quad({10.0f, 0.5f * apart}, {30.0f, 0.5f * apart}, 0.0f, 6.0f);
    const WallOccluders walls(flattenMesh(w.positions, w.triangles), 0.01 / 4.0, 0.25, 0.01 / 8.0);
    bool spansBoth = false;
    for (size_t k = 0; k < walls.size(); ++k) {
      const WallLine& line = walls.line(k);
      const double a = tangential(line, {1.0f, 0.0f}), b = tangential(line, {4.0f, 0.0f});
      const auto cover = walls.cover(k, std::min(a, b), std::max(a, b));
      spansBoth |= cover && cover->x < 1.0 && cover->y > 5.0;
    }
    EXPECT_EQ(spansBoth, apart < 0.01f) << apart;
  }
}

// The line whose plane holds X/Z points a and b.
size_t lineThrough(const WallOccluders& walls, glm::vec2 a, glm::vec2 b) {
  for (size_t k = 0; k < walls.size(); ++k) {
    const WallLine& l = walls.line(k);
    if (std::abs(glm::dot(l.n, glm::dvec2(a)) - l.c) < 1e-4 &&
        std::abs(glm::dot(l.n, glm::dvec2(b)) - l.c) < 1e-4)
      return k;
  }
  return walls.size();
}

// The joints at the end nearest to X/Z point p of the run of line k that
// holds p.
std::span<const WallJoint> jointsAt(const WallOccluders& walls, size_t k, glm::vec2 p) {
  const double u = glm::dot(walls.line(k).t, glm::dvec2(p));
  const std::optional<uint32_t> r = walls.runOf(k, u);
  if (!r) {
    ADD_FAILURE() << "no run of line " << k << " at (" << p.x << ", " << p.y << ")";
    return {};
  }
  const WallRun& run = walls.run(*r);
  return walls.joints(*r, std::abs(u - run.ua) < std::abs(u - run.ub) ? 0 : 1);
}

// An L of two panels meeting at a corner (x = 6.1, not a whole number of
// bins), a panel ending on the middle of another (a T) on the L's plane
// farther along (one line with a gap), and a panel stopping 5 cm short of
// another's plane: the L's run of that line covers up to its corner, the
// L's run ends are joined to each other at the corner, the T's stem is
// joined to the bar at the bar's middle (the bar's ends to nothing), and
// the short panel to nothing.
TEST(WallOccluders, CoversRunsUpToTheirCornersAndJoinsThoseThatMeet) {
  Walls w;
  w.quad({0.0f, 0.0f}, {6.1f, 0.0f}, 0.0f, 8.0f);    // L, along X
  w.quad({6.1f, 0.0f}, {6.1f, 5.0f}, 0.0f, 6.0f);    // L, along Z
  w.quad({20.0f, 0.0f}, {30.0f, 0.0f}, 0.0f, 5.0f);  // T's bar (z = 0 too, apart)
  w.quad({25.0f, 0.0f}, {25.0f, 7.0f}, 0.0f, 5.0f);  // T's stem
  w.quad({40.0f, 3.0f}, {50.0f, 3.0f}, 0.0f, 5.0f);
  w.quad({45.0f, 3.05f}, {45.0f, 9.0f}, 0.0f, 5.0f);  // 5 cm short of it
  const WallOccluders walls = w.build();
  const size_t alongX = lineThrough(walls, {0.0f, 0.0f}, {6.1f, 0.0f});
  const size_t alongZ = lineThrough(walls, {6.1f, 0.0f}, {6.1f, 5.0f});
  const size_t stem = lineThrough(walls, {25.0f, 1.0f}, {25.0f, 7.0f});
  const size_t shortOne = lineThrough(walls, {45.0f, 4.0f}, {45.0f, 9.0f});
  const size_t far = lineThrough(walls, {40.0f, 3.0f}, {50.0f, 3.0f});
  ASSERT_LT(std::max({alongX, alongZ, stem, shortOne, far}), walls.size());
  // The X line holds the L's and the T's bars (one plane, z = 0): the L's
  // run is covered right up to its corner, not past it.
  const WallLine& lx = walls.line(alongX);
  const double a = tangential(lx, {0.0f, 0.0f}), b = tangential(lx, {6.1f, 0.0f});
  const auto whole = walls.cover(alongX, std::min(a, b), std::max(a, b));
  ASSERT_TRUE(whole.has_value());
  EXPECT_NEAR(whole->y, 8.0, 1e-5);
  const double past = tangential(lx, {6.2f, 0.0f});
  EXPECT_FALSE(walls.cover(alongX, std::min(a, past), std::max(a, past)).has_value());

  const auto cornerOfX = jointsAt(walls, alongX, {6.1f, 0.0f});
  ASSERT_EQ(cornerOfX.size(), 1u);
  EXPECT_EQ(cornerOfX[0].line, alongZ);
  EXPECT_NEAR(cornerOfX[0].u, tangential(walls.line(alongZ), {6.1f, 0.0f}), 1e-5);
  EXPECT_TRUE(jointsAt(walls, alongX, {0.0f, 0.0f}).empty());
  const auto cornerOfZ = jointsAt(walls, alongZ, {6.1f, 0.0f});
  ASSERT_EQ(cornerOfZ.size(), 1u);
  EXPECT_EQ(cornerOfZ[0].line, alongX);
  EXPECT_NEAR(cornerOfZ[0].u, b, 1e-5);
  EXPECT_TRUE(jointsAt(walls, alongZ, {6.1f, 5.0f}).empty());

  const auto stemFoot = jointsAt(walls, stem, {25.0f, 0.0f});
  ASSERT_EQ(stemFoot.size(), 1u);
  EXPECT_EQ(stemFoot[0].line, alongX);
  EXPECT_NEAR(stemFoot[0].u, tangential(lx, {25.0f, 0.0f}), 1e-5);
  EXPECT_TRUE(jointsAt(walls, stem, {25.0f, 7.0f}).empty());
  EXPECT_TRUE(jointsAt(walls, alongX, {20.0f, 0.0f}).empty());
  EXPECT_TRUE(jointsAt(walls, alongX, {30.0f, 0.0f}).empty());

  EXPECT_TRUE(jointsAt(walls, shortOne, {45.0f, 3.05f}).empty());
  EXPECT_TRUE(jointsAt(walls, far, {40.0f, 3.0f}).empty());
  EXPECT_TRUE(jointsAt(walls, far, {50.0f, 3.0f}).empty());
}

// Whether (u, y) lies in a projected triangle of line k (with a hair of
// slack for rounding).
bool inLineTriangles(const WallOccluders& walls, const FlatTriangles& tris, size_t k, double u,
                     double y) {
  const WallLine& line = walls.line(k);
  for (uint32_t t : walls.triangles(k)) {
    glm::dvec2 p[3];
    for (int v = 0; v < 3; ++v) {
      const glm::vec3 q = tris.vertex(t, v);
      p[v] = {glm::dot(line.t, glm::dvec2(q.x, q.z)), q.y};
    }
    double s[3];
    for (int v = 0; v < 3; ++v) {
      const glm::dvec2 a = p[v], b = p[(v + 1) % 3];
      s[v] = (b.x - a.x) * (y - a.y) - (b.y - a.y) * (u - a.x);
    }
    const double eps = 1e-6;
    if ((s[0] >= -eps && s[1] >= -eps && s[2] >= -eps) ||
        (s[0] <= eps && s[1] <= eps && s[2] <= eps))
      return true;
  }
  return false;
}

// Random fences of panels with random heights, random breaks and random
// diagonals, at random angles: every reported cover is covered, point by
// point; and a window inside one panel gets a cover.
TEST(WallOccluders, EveryCoverItReportsIsCoveredPointByPoint) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  size_t covers = 0;
  for (int trial = 0; trial < 20; ++trial) {
    Walls w;
    const float angle = 6.2831853f * unit(rng);
    const glm::vec2 dir(std::cos(angle), std::sin(angle)),
        origin(100.0f * unit(rng), -50.0f * unit(rng));
    float s = 0.0f;
    for (int k = 0; k < 8; ++k) {
      const float len = 1.0f + 5.0f * unit(rng);
      const float y0 = unit(rng) < 0.3f ? unit(rng) : 0.0f, y1 = 3.0f + 6.0f * unit(rng);
      w.quad(origin + s * dir, origin + (s + len) * dir, y0, y1);
      s += len + (unit(rng) < 0.3f ? 0.05f + 0.15f * unit(rng) : 0.0f);
    }
    const FlatTriangles tris = flattenMesh(w.positions, w.triangles);
    const WallOccluders walls(tris, kTolerance, 0.25, 0.5 * kTolerance);
    ASSERT_GE(walls.size(), 1u);
    for (size_t k = 0; k < walls.size(); ++k) {
      const WallLine& line = walls.line(k);
      // Windows may run past the line's last corner (nothing covered there).
      const double span = line.u1 - line.u0 + 1.0;
      for (int q = 0; q < 40; ++q) {
        const double ua = line.u0 + span * double(unit(rng));
        const double ub = ua + 3.0 * double(unit(rng));
        const auto cover = walls.cover(k, ua, ub);
        if (!cover) continue;
        ++covers;
        for (int a = 0; a <= 12; ++a)
          for (int b = 0; b <= 12; ++b) {
            const double u = ua + (ub - ua) * a / 12.0;
            const double y = cover->x + (cover->y - cover->x) * b / 12.0;
            EXPECT_TRUE(inLineTriangles(walls, tris, k, u, y))
                << "trial " << trial << ": (" << u << ", " << y << ") reported covered";
          }
      }
    }
  }
  EXPECT_GT(covers, 100u);
}

}  // namespace
}  // namespace vistream
