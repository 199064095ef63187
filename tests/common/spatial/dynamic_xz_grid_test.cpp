// DynamicXzGrid against brute force: after any sequence of inserts and
// erases, every cell lists exactly the items held whose X/Z rectangle meets
// the cell's fixed square [i, i + 1) x [j, j + 1) times the cell size, ascending.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>

#include "common/spatial/xz_grid.h"

namespace vistream {
namespace {

// The cells of the plane (fixed multiples of `cell`) a box's rectangle meets.
std::pair<glm::ivec2, glm::ivec2> planeCells(const Box3f& b, float cell) {
  return {
      glm::ivec2(int(std::floor(double(b.lo.x) / cell)), int(std::floor(double(b.lo.z) / cell))),
      glm::ivec2(int(std::floor(double(b.hi.x) / cell)), int(std::floor(double(b.hi.z) / cell)))};
}

void expectSameAsBruteForce(const DynamicXzGrid& grid, const std::map<uint32_t, Box3f>& held) {
  const float cell = grid.cellSize();
  for (int z = 0; z < grid.dims().y; ++z)
    for (int x = 0; x < grid.dims().x; ++x) {
      const glm::ivec2 plane = grid.origin() + glm::ivec2(x, z);
      std::vector<uint32_t> expected;
      for (const auto& [item, box] : held) {
        const auto [lo, hi] = planeCells(box, cell);
        if (plane.x >= lo.x && plane.x <= hi.x && plane.y >= lo.y && plane.y <= hi.y)
          expected.push_back(item);
      }
      const auto items = grid.itemsIn({x, z});
      ASSERT_EQ(std::vector<uint32_t>(items.begin(), items.end()), expected)
          << "cell " << plane.x << "," << plane.y;
    }
  // Every item held lies inside the array.
  for (const auto& [item, box] : held) {
    const auto [lo, hi] = planeCells(box, cell);
    EXPECT_TRUE(glm::all(glm::greaterThanEqual(lo, grid.origin())));
    EXPECT_TRUE(glm::all(glm::lessThan(hi, grid.origin() + grid.dims())));
  }
}

TEST(DynamicXzGrid, ListsWhatBruteForceFindsAfterInsertsAndErasesInAnyOrder) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> pos(-300.0f, 300.0f), size(0.0f, 25.0f);
  DynamicXzGrid grid(7.0f);
  std::map<uint32_t, Box3f> held;
  std::vector<uint32_t> order(400);
  for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);  // items arrive out of order
  for (size_t step = 0; step < order.size(); ++step) {
    const glm::vec3 lo(pos(rng) * float(step + 1) / 400.0f, pos(rng), pos(rng) * 0.3f);
    const Box3f box{lo, lo + glm::vec3(size(rng), size(rng), size(rng))};
    ASSERT_TRUE(grid.insert(order[step], box));
    held[order[step]] = box;
    if (step % 3 == 2) {  // erase one held item
      auto it = held.begin();
      std::advance(it, std::uniform_int_distribution<size_t>(0, held.size() - 1)(rng));
      grid.erase(it->first, it->second);
      held.erase(it);
    }
    if (step % 50 == 49) expectSameAsBruteForce(grid, held);
  }
  expectSameAsBruteForce(grid, held);
}

TEST(DynamicXzGrid, RefusesAnItemThatWouldTakeItPastItsCellLimitAndStaysUnchanged) {
  DynamicXzGrid grid(1.0f, 10'000);
  ASSERT_TRUE(grid.insert(0, Box3f{{0, 0, 0}, {1, 1, 1}}));
  const glm::ivec2 dims = grid.dims();
  EXPECT_FALSE(grid.insert(1, Box3f{{5000, 0, 0}, {5001, 1, 1}}));
  EXPECT_FALSE(grid.insert(2, Box3f{{1e30f, 0, 0}, {1e30f, 1, 1}}));
  EXPECT_EQ(grid.dims(), dims);
  EXPECT_TRUE(grid.insert(3, Box3f{{-20, 0, -20}, {-19, 1, -19}}));
}

TEST(DynamicXzGrid, AnEmptyBoxGoesNowhereAndLookupsClampLikeXzGrid) {
  DynamicXzGrid grid(2.0f);
  EXPECT_TRUE(grid.insert(0, Box3f{}));
  EXPECT_TRUE(grid.empty());
  EXPECT_EQ(grid.cellsOverlapping({0, 0}, {1, 1}).hi.x, -1);
  ASSERT_TRUE(grid.insert(1, Box3f{{3, 0, 3}, {5, 0, 5}}));
  EXPECT_EQ(grid.origin(), glm::ivec2(1, 1));
  EXPECT_EQ(grid.cellOf({-100.0f, 100.0f}), glm::ivec2(0, grid.dims().y - 1));
}

}  // namespace
}  // namespace vistream
