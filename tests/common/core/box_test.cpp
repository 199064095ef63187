// Box corners (common/core/box.h): the eight corners of a box are its
// vertices, each once, with bit 0, 1, 2 of the index choosing the high x, y, z.
#include "common/core/box.h"

#include <gtest/gtest.h>

#include <set>
#include <tuple>

namespace vistream {
namespace {

TEST(Box, HasEightDistinctCornersChosenByTheBitsOfTheirIndex) {
  const Box3f b({-1.0f, 2.0f, 10.0f}, {3.0f, 5.0f, 12.5f});
  std::set<std::tuple<float, float, float>> seen;
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 c = b.corner(k);
    EXPECT_EQ(c.x, (k & 1) ? 3.0f : -1.0f) << k;
    EXPECT_EQ(c.y, (k & 2) ? 5.0f : 2.0f) << k;
    EXPECT_EQ(c.z, (k & 4) ? 12.5f : 10.0f) << k;
    EXPECT_TRUE(b.contains(c)) << k;
    seen.insert({c.x, c.y, c.z});
  }
  EXPECT_EQ(seen.size(), 8u);
  EXPECT_EQ(b.corner(0), b.lo);
  EXPECT_EQ(b.corner(7), b.hi);
}

TEST(Box, CornersOfADoubleBoxFarFromTheOriginAreExact) {
  const Box3d b({1e9, -2e9, 0.25}, {1e9 + 0.5, -2e9 + 1.0, 0.75});
  EXPECT_EQ(b.corner(5), glm::dvec3(1e9 + 0.5, -2e9, 0.75));
  EXPECT_EQ(b.corner(2), glm::dvec3(1e9, -2e9 + 1.0, 0.25));
}

}  // namespace
}  // namespace vistream
