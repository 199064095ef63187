// Tests of the chessboard distance transform
// (common/spatial/distance_transform.h). Oracle: for every cell, the
// smallest max(|di|, |dj|) over every occupied cell, capped.
#include "common/spatial/distance_transform.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <random>
#include <vector>

namespace vistream {
namespace {

std::vector<uint8_t> bruteForce(const std::vector<uint8_t>& occupied, int width, int height,
                                uint8_t cap) {
  std::vector<uint8_t> out(occupied.size(), cap);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      int best = cap;
      for (int q = 0; q < height; ++q)
        for (int p = 0; p < width; ++p)
          if (occupied[size_t(q) * size_t(width) + size_t(p)])
            best = std::min(best, std::max(std::abs(p - i), std::abs(q - j)));
      out[size_t(j) * size_t(width) + size_t(i)] = uint8_t(best);
    }
  return out;
}

std::vector<uint8_t> randomGrid(int width, int height, double density, std::mt19937& rng) {
  std::bernoulli_distribution occupied(density);
  std::vector<uint8_t> grid(size_t(width) * size_t(height));
  for (uint8_t& g : grid) g = occupied(rng) ? 1 : 0;
  return grid;
}

TEST(ChessboardDistance, MatchesBruteForceOnRandomGridsOfEveryShapeAndDensity) {
  std::mt19937 rng(11);
  for (const auto& [w, h] : {std::pair{1, 1}, {1, 37}, {37, 1}, {5, 9}, {40, 23}, {64, 64}})
    for (double density : {0.0, 0.002, 0.02, 0.2, 0.9, 1.0}) {
      const std::vector<uint8_t> grid = randomGrid(w, h, density, rng);
      EXPECT_EQ(chessboardDistance(grid, w, h), bruteForce(grid, w, h, 255))
          << w << "x" << h << " at density " << density;
    }
}

TEST(ChessboardDistance, IsZeroOnOccupiedCellsAndTheCapWhereNothingIsNearer) {
  // One occupied cell in the corner of a 300 x 2 strip: distances climb to
  // the cap of 255 and stay there; a smaller cap clamps sooner.
  const int w = 300, h = 2;
  std::vector<uint8_t> grid(size_t(w) * h, 0);
  grid[0] = 1;
  const std::vector<uint8_t> d = chessboardDistance(grid, w, h);
  EXPECT_EQ(d[0], 0);
  EXPECT_EQ(d[size_t(w)], 1);  // diagonal and straight neighbours alike
  EXPECT_EQ(d[size_t(w) + 1], 1);
  EXPECT_EQ(d[254], 254);
  EXPECT_EQ(d[299], 255);
  EXPECT_EQ(chessboardDistance(grid, w, h, 10)[50], 10);
  EXPECT_EQ(chessboardDistance(grid, w, h, 10), bruteForce(grid, w, h, 10));
  // Nothing occupied: the cap everywhere.
  const std::vector<uint8_t> empty(12, 0);
  EXPECT_EQ(chessboardDistance(empty, 4, 3), std::vector<uint8_t>(12, 255));
}

}  // namespace
}  // namespace vistream
