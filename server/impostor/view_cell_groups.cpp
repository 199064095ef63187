#include "server/impostor/view_cell_groups.h"

#include <algorithm>

#include "common/core/error.h"

namespace vistream {

Box3f viewCellBox(const ViewCellGrid& grid, const glm::ivec3& lo, const glm::ivec3& hi) {
  return Box3f(grid.cellBox(lo).lo, grid.cellBox(hi).hi);
}

std::vector<ViewCellGroup> mergeViewCells(const ViewCellGrid& grid,
                                          const std::vector<uint32_t>& cells, uint32_t maxCells) {
  if (maxCells == 0) throwInputError("a view cell must merge at least 1 cell, got 0");
  const size_t count = grid.cellCount();
  std::vector<uint32_t> sorted = cells;
  std::sort(sorted.begin(), sorted.end());
  sorted.erase(std::unique(sorted.begin(), sorted.end()), sorted.end());
  std::vector<uint8_t> given(count, 0);
  for (uint32_t c : sorted) {
    if (c >= count)
      throwInputError("cell {} lies outside the grid of {} cells, cannot merge it", c, count);
    given[c] = 1;
  }
  auto isGiven = [&](glm::ivec3 c) { return grid.contains(c) && given[grid.linearIndex(c)]; };
  // The length of the line of given cells through c along axis a.
  auto lineLength = [&](glm::ivec3 c, int a) {
    int n = 1;
    for (glm::ivec3 p = c; p[a] -= 1, isGiven(p);) ++n;
    for (glm::ivec3 p = c; p[a] += 1, isGiven(p);) ++n;
    return n;
  };
  // Per given cell: its street's axis (0: X, 2: Z).
  std::vector<uint8_t> axis(count, 0);
  for (uint32_t c : sorted) {
    const glm::ivec3 p = grid.cellAt(c);
    axis[c] = lineLength(p, 2) > lineLength(p, 0) ? 2 : 0;
  }
  std::vector<uint8_t> taken(count, 0);
  auto free = [&](glm::ivec3 p, int a) {
    if (!isGiven(p)) return false;
    const size_t i = grid.linearIndex(p);
    return !taken[i] && axis[i] == a;
  };
  std::vector<ViewCellGroup> groups;
  // Ascending linear index visits each line of one axis from its low end
  // (x varies fastest, then y, then z), so the first untaken cell met is
  // where the line's remaining stretch starts.
  for (uint32_t c : sorted) {
    if (taken[c]) continue;
    const int a = axis[c];
    const glm::ivec3 start = grid.cellAt(c);
    int stretch = 1;
    for (glm::ivec3 p = start; p[a] += 1, free(p, a);) ++stretch;
    const int pieces = (stretch + int(maxCells) - 1) / int(maxCells);
    const int length = (stretch + pieces - 1) / pieces;
    ViewCellGroup g;
    g.lo = g.hi = start;
    for (int k = 0; k < length; ++k) {
      glm::ivec3 p = start;
      p[a] += k;
      const uint32_t i = uint32_t(grid.linearIndex(p));
      taken[i] = 1;
      g.members.push_back(i);
      g.hi = p;
    }
    groups.push_back(std::move(g));
  }
  return groups;
}

}  // namespace vistream
