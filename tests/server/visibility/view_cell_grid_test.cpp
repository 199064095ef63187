#include "server/visibility/view_cell_grid.h"

#include <gtest/gtest.h>

namespace vistream {
namespace {

TEST(ViewCellGrid, CoversTheRegionWithWholeCells) {
  const ViewCellGrid grid(Box3f({0, 0, 0}, {10, 3, 4.5f}), {2, 3, 2});
  EXPECT_EQ(grid.dims(), glm::ivec3(5, 1, 3));
  EXPECT_EQ(grid.cellCount(), 15u);
  const Box3f last = grid.cellBox({4, 0, 2});
  EXPECT_FLOAT_EQ(last.hi.x, 10.0f);
  EXPECT_FLOAT_EQ(last.hi.z, 6.0f);  // the last cell reaches past the region
}

TEST(ViewCellGrid, FindsTheCellHoldingAPointAndItsBoxContainsThePoint) {
  const ViewCellGrid grid(Box3f({-5, 0, -5}, {5, 2, 5}), {1, 2, 1});
  for (float x = -4.9f; x < 5.0f; x += 0.37f)
    for (float z = -4.9f; z < 5.0f; z += 0.53f) {
      const glm::vec3 p(x, 1.0f, z);
      const auto c = grid.cellOf(p);
      ASSERT_TRUE(c.has_value());
      EXPECT_TRUE(grid.cellBox(*c).contains(p));
      EXPECT_EQ(grid.cellAt(grid.linearIndex(*c)), *c);
    }
}

TEST(ViewCellGrid, PointsOnTheOuterBoundaryBelongToTheEdgeCellAndOutsidePointsToNone) {
  const ViewCellGrid grid(Box3f({0, 0, 0}, {4, 1, 4}), {1, 1, 1});
  EXPECT_EQ(grid.cellOf({4, 1, 4}), glm::ivec3(3, 0, 3));
  EXPECT_EQ(grid.cellOf({0, 0, 0}), glm::ivec3(0, 0, 0));
  EXPECT_FALSE(grid.cellOf({-0.001f, 0.5f, 0.5f}).has_value());
  EXPECT_FALSE(grid.cellOf({0.5f, std::nanf(""), 0.5f}).has_value());
}

}  // namespace
}  // namespace vistream
