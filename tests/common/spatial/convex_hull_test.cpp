#include "common/spatial/convex_hull.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace vistream {
namespace {

// Brute-force oracle: a hull is right when it is strictly convex and
// counter-clockwise, every input point lies on its inner side of every edge,
// and every hull vertex is an input point.
void expectHullOf(const std::vector<glm::dvec2>& pts, const std::vector<glm::dvec2>& hull) {
  ASSERT_GE(hull.size(), 3u);
  for (size_t i = 0; i < hull.size(); ++i) {
    const glm::dvec2 a = hull[i], b = hull[(i + 1) % hull.size()], c = hull[(i + 2) % hull.size()];
    EXPECT_GT(cross2(a, b, c), 0.0) << "corner " << i << " is not a strict left turn";
    for (const glm::dvec2& p : pts) EXPECT_GE(cross2(a, b, p), 0.0) << "a point lies outside";
    EXPECT_NE(std::find(pts.begin(), pts.end(), a), pts.end()) << "hull vertex not an input";
  }
}

TEST(ConvexHull2d, RandomCloudsAgreeWithTheBruteForceOracle) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  for (int trial = 0; trial < 50; ++trial) {
    SCOPED_TRACE(trial);
    std::vector<glm::dvec2> pts(3 + size_t(trial) * 7);
    for (auto& p : pts) p = {u(rng), u(rng)};
    expectHullOf(pts, convexHull2d(pts));
  }
}

TEST(ConvexHull2d, DropsCollinearAndRepeatedPoints) {
  // A square with points along its edges and a repeated corner.
  const std::vector<glm::dvec2> pts{{0, 0}, {1, 0}, {2, 0}, {2, 1}, {2, 2}, {1, 2},
                                    {0, 2}, {0, 1}, {1, 1}, {0, 0}, {2, 2}};
  const auto hull = convexHull2d(pts);
  EXPECT_EQ(hull.size(), 4u);
  expectHullOf(pts, hull);
}

TEST(ConvexHull2d, FewerThanThreeDistinctPointsComeBackDeduplicated) {
  EXPECT_TRUE(convexHull2d({}).empty());
  EXPECT_EQ(convexHull2d({{1, 1}, {1, 1}}).size(), 1u);
  EXPECT_EQ(convexHull2d({{0, 0}, {3, 1}, {0, 0}}).size(), 2u);
}

TEST(ConvexHull2d, StaysConvexFarFromTheOrigin) {
  const glm::dvec2 o(1e6, -2e6);
  std::vector<glm::dvec2> pts;
  for (int i = 0; i < 12; ++i) {
    const double a = i * 0.5235987755982988;  // 30 degrees
    pts.push_back(o + 5.0 * glm::dvec2(std::cos(a), std::sin(a)));
    pts.push_back(o + 2.0 * glm::dvec2(std::cos(a), std::sin(a)));
  }
  const auto hull = convexHull2d(pts);
  EXPECT_EQ(hull.size(), 12u);
  expectHullOf(pts, hull);
}

}  // namespace
}  // namespace vistream
