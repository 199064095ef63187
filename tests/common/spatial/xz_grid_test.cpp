// Tests of the X/Z grid (common/spatial/xz_grid.h). Oracle: brute force over
// every item and every cell, with cell membership decided by comparing
// coordinates with the cell edges (no division, no floor). Coordinates lie on
// a 1/64 m lattice and cells are powers of two, so every computation is exact
// and items often start or end exactly on a cell edge.
#include "common/spatial/xz_grid.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace vistream {
namespace {

constexpr float kLattice = 1.0f / 64.0f;

// Random boxes over [-40, 140] in X and Z (the grid below covers [0, 100]),
// snapped to the lattice: points, flat boxes, boxes ending on cell edges
// (multiples of 4 m) and boxes partly or wholly outside the grid.
std::vector<Box3f> latticeBoxes(size_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> pos(-40 * 64, 140 * 64), size(0, 20 * 64), kind(0, 4);
  std::vector<Box3f> boxes;
  for (size_t i = 0; i < count; ++i) {
    glm::vec3 lo(float(pos(rng)) * kLattice, float(pos(rng)) * kLattice,
                 float(pos(rng)) * kLattice);
    glm::vec3 hi = lo + glm::vec3(float(size(rng)), float(size(rng)), float(size(rng))) * kLattice;
    switch (kind(rng)) {
      case 0:
        hi = lo;
        break;  // a point
      case 1:
        lo.x = std::round(lo.x / 4.0f) * 4.0f;
        break;  // starts on an edge
      case 2:
        hi.z = std::max(lo.z, std::round(hi.z / 4.0f) * 4.0f);
        break;  // ends on one
      default:
        break;
    }
    boxes.emplace_back(lo, hi);
  }
  return boxes;
}

// The cell along one axis that holds coordinate v: the last cell whose low
// edge is at or below v, found by walking the edges; values below the grid
// land in cell 0, values above it in the last cell.
int cellByWalking(float v, float lo, float cell, int n) {
  int i = 0;
  while (i + 1 < n && lo + float(i + 1) * cell <= v) ++i;
  return i;
}

struct Span {
  int lo, hi;
};

Span cellsByWalking(float a, float b, float lo, float cell, int n) {
  return {cellByWalking(a, lo, cell, n), cellByWalking(b, lo, cell, n)};
}

// Bounds [0, 100] x [0, 100] in X/Z (Y does not matter) with 4 m cells: 25 x 25.
const Box3f kBounds(glm::vec3(0.0f, -5.0f, 0.0f), glm::vec3(100.0f, 5.0f, 100.0f));
constexpr float kCell = 4.0f;

TEST(XzGrid, CoversTheBoundsWithCeilExtentOverCellSizeCellsPerAxis) {
  const std::vector<Box3f> none;
  EXPECT_EQ(XzGrid(kBounds, kCell, none).dims(), glm::ivec2(25, 25));
  const Box3f b(glm::vec3(-3.0f, 0.0f, 2.0f), glm::vec3(7.0f, 1.0f, 3.0f));  // 10 m x 1 m
  EXPECT_EQ(XzGrid(b, 4.0f, none).dims(), glm::ivec2(3, 1));
  EXPECT_EQ(XzGrid(b, 4.0f, none).lo(), glm::vec2(-3.0f, 2.0f));
  const Box3f flat(glm::vec3(5.0f), glm::vec3(5.0f));  // a single point
  EXPECT_EQ(XzGrid(flat, 4.0f, none).dims(), glm::ivec2(1, 1));
}

TEST(XzGrid, ListsEveryItemInExactlyTheCellsItsRectangleReaches) {
  const std::vector<Box3f> boxes = latticeBoxes(600, 7);
  const XzGrid grid(kBounds, kCell, boxes);
  ASSERT_EQ(grid.dims(), glm::ivec2(25, 25));
  size_t entries = 0;
  for (int z = 0; z < 25; ++z)
    for (int x = 0; x < 25; ++x) {
      std::vector<uint32_t> expected;
      for (uint32_t i = 0; i < boxes.size(); ++i) {
        const Span sx = cellsByWalking(boxes[i].lo.x, boxes[i].hi.x, 0.0f, kCell, 25);
        const Span sz = cellsByWalking(boxes[i].lo.z, boxes[i].hi.z, 0.0f, kCell, 25);
        if (sx.lo <= x && x <= sx.hi && sz.lo <= z && z <= sz.hi) expected.push_back(i);
      }
      const auto items = grid.itemsIn({x, z});
      EXPECT_EQ(std::vector<uint32_t>(items.begin(), items.end()), expected)
          << "cell " << x << ", " << z;
      entries += expected.size();
    }
  EXPECT_GT(entries, boxes.size());  // the sample has items in several cells
}

TEST(XzGrid, ItemsNearFindsEveryItemWhoseRectangleMeetsTheQueryAndOnlyThoseOfItsCells) {
  const std::vector<Box3f> boxes = latticeBoxes(400, 11);
  const XzGrid grid(kBounds, kCell, boxes);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> pos(-60 * 64, 160 * 64), size(0, 30 * 64);
  for (int q = 0; q < 300; ++q) {
    const glm::vec2 lo(float(pos(rng)) * kLattice, float(pos(rng)) * kLattice);
    const glm::vec2 hi = lo + glm::vec2(float(size(rng)), float(size(rng))) * kLattice;
    const std::vector<uint32_t> near = grid.itemsNear(lo, hi);
    ASSERT_TRUE(std::is_sorted(near.begin(), near.end()));
    // forEachItemNear visits the same items, each once.
    std::vector<uint32_t> visited;
    grid.forEachItemNear(lo, hi, [&](uint32_t i) { visited.push_back(i); });
    std::sort(visited.begin(), visited.end());
    ASSERT_EQ(visited, near);
    ASSERT_EQ(std::adjacent_find(near.begin(), near.end()), near.end()) << "duplicates";
    const Span qx = cellsByWalking(lo.x, hi.x, 0.0f, kCell, 25);
    const Span qz = cellsByWalking(lo.y, hi.y, 0.0f, kCell, 25);
    for (uint32_t i = 0; i < boxes.size(); ++i) {
      const Box3f& b = boxes[i];
      const bool listed = std::binary_search(near.begin(), near.end(), i);
      // Conservative: a rectangle that meets the query is always found.
      if (b.lo.x <= hi.x && lo.x <= b.hi.x && b.lo.z <= hi.y && lo.y <= b.hi.z) {
        EXPECT_TRUE(listed) << "query " << q << " misses item " << i;
      }
      // Exact over cells: found if and only if its cells meet the query's cells.
      const Span sx = cellsByWalking(b.lo.x, b.hi.x, 0.0f, kCell, 25);
      const Span sz = cellsByWalking(b.lo.z, b.hi.z, 0.0f, kCell, 25);
      const bool cellsMeet = sx.lo <= qx.hi && qx.lo <= sx.hi && sz.lo <= qz.hi && qz.lo <= sz.hi;
      EXPECT_EQ(listed, cellsMeet) << "query " << q << ", item " << i;
    }
  }
}

TEST(XzGrid, ItemsFarOutsideTheGridClampToItsBorderAndAreFoundFromThere) {
  const float big = 1e30f;
  const std::vector<Box3f> boxes = {
      Box3f(glm::vec3(big, 0.0f, big), glm::vec3(big, 1.0f, big)),        // far beyond the corner
      Box3f(glm::vec3(-big, 0.0f, 50.0f), glm::vec3(-big, 1.0f, 50.0f)),  // far left, mid Z
  };
  const XzGrid grid(kBounds, kCell, boxes);
  EXPECT_EQ(grid.cellOf({big, big}), glm::ivec2(24, 24));
  EXPECT_EQ(grid.cellOf({-big, 50.0f}), glm::ivec2(0, 12));
  EXPECT_EQ(grid.itemsNear({big, big}, {big, big}), std::vector<uint32_t>{0});
  EXPECT_EQ(grid.itemsNear({-big, -big}, {big, big}), (std::vector<uint32_t>{0, 1}));
  EXPECT_EQ(grid.itemsNear({40.0f, 40.0f}, {60.0f, 60.0f}), std::vector<uint32_t>{});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(grid.cellOf({nan, nan}), glm::ivec2(0, 0));
}

TEST(XzGrid, AGridWithoutCellsFindsNothingAndEmptyBoxesAreLeftOut) {
  const std::vector<Box3f> boxes = {Box3f(), Box3f(glm::vec3(1.0f), glm::vec3(2.0f)), Box3f()};
  EXPECT_TRUE(XzGrid().empty());
  EXPECT_TRUE(XzGrid().itemsNear({-1e9f, -1e9f}, {1e9f, 1e9f}).empty());
  const XzGrid noBounds(Box3f(), kCell, boxes);
  EXPECT_TRUE(noBounds.empty());
  EXPECT_TRUE(noBounds.itemsNear({-1e9f, -1e9f}, {1e9f, 1e9f}).empty());
  const XzGrid grid(kBounds, kCell, boxes);
  EXPECT_EQ(grid.itemsNear({-1e9f, -1e9f}, {1e9f, 1e9f}), std::vector<uint32_t>{1});
}

}  // namespace
}  // namespace vistream
