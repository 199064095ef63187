// Distance transforms over 2D grids.
#pragma once

#include <cstdint>
#include <vector>

namespace vistream {

// For each cell of a width x height grid (row-major, `occupied[j * width +
// i]` non-zero where the cell is occupied), the chessboard (L-infinity)
// distance in cells to the nearest occupied cell, capped at `cap`: 0 on an
// occupied cell, `cap` where no occupied cell is nearer (an empty grid is
// `cap` everywhere). Exact: two raster passes of the 3 x 3 mask, O(cells).
// Requires occupied.size() == width * height.
std::vector<uint8_t> chessboardDistance(const std::vector<uint8_t>& occupied, int width, int height,
                                        uint8_t cap = 255);

}  // namespace vistream
