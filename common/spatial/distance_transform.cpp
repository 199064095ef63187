#include "common/spatial/distance_transform.h"

#include <algorithm>
#include <utility>

#include "common/core/check.h"

namespace vistream {

std::vector<uint8_t> chessboardDistance(const std::vector<uint8_t>& occupied, int width, int height,
                                        uint8_t cap) {
  VS_CHECK(width >= 0 && height >= 0 && occupied.size() == size_t(width) * size_t(height));
  // Distances beyond the cap are only ever compared and clamped, so an int
  // well above any reachable distance stands for "none yet".
  const int none = 1 << 30;
  std::vector<int> dist(occupied.size());
  for (size_t k = 0; k < occupied.size(); ++k) dist[k] = occupied[k] ? 0 : none;
  auto at = [&](int i, int j) -> int& { return dist[size_t(j) * size_t(width) + size_t(i)]; };
  // Forward pass: the neighbours already visited (left and the row above).
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i)
      for (const auto& [di, dj] : {std::pair{-1, 0}, {-1, -1}, {0, -1}, {1, -1}})
        if (i + di >= 0 && i + di < width && j + dj >= 0)
          at(i, j) = std::min(at(i, j), at(i + di, j + dj) + 1);
  // Backward pass: right and the row below.
  for (int j = height - 1; j >= 0; --j)
    for (int i = width - 1; i >= 0; --i)
      for (const auto& [di, dj] : {std::pair{1, 0}, {1, 1}, {0, 1}, {-1, 1}})
        if (i + di >= 0 && i + di < width && j + dj < height)
          at(i, j) = std::min(at(i, j), at(i + di, j + dj) + 1);
  std::vector<uint8_t> out(dist.size());
  for (size_t k = 0; k < dist.size(); ++k) out[k] = uint8_t(std::min(dist[k], int(cap)));
  return out;
}

}  // namespace vistream
