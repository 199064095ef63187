#include "common/spatial/xz_grid.h"

#include <algorithm>
#include <cmath>

#include "common/core/check.h"

namespace vistream {

namespace {

// floor(v) clamped to [0, n - 1] before converting, so a value far outside
// the grid (or NaN) never overflows the int.
int clampedIndex(float v, int n) {
  const float f = std::floor(v);
  if (!(f >= 0.0f)) return 0;
  if (f >= float(n - 1)) return n - 1;
  return int(f);
}

}  // namespace

XzGrid::XzGrid(const Box3f& bounds, float cellSize, std::span<const Box3f> boxes) {
  VS_CHECK(cellSize > 0.0f && std::isfinite(cellSize));
  cell_ = cellSize;
  if (bounds.empty()) return;
  lo_ = {bounds.lo.x, bounds.lo.z};
  const glm::vec2 ext = glm::max(glm::vec2(bounds.hi.x, bounds.hi.z) - lo_, glm::vec2(1e-3f));
  dims_ = glm::max(glm::ivec2(glm::ceil(ext / cell_)), glm::ivec2(1));
  const size_t cells = size_t(dims_.x) * size_t(dims_.y);

  // Two passes over the items: count per cell, then fill; items go in in
  // index order, so each cell's list is ascending.
  auto rangeOf = [&](const Box3f& b) {
    return cellsOverlapping({b.lo.x, b.lo.z}, {b.hi.x, b.hi.z});
  };
  cellStart_.assign(cells + 1, 0);
  for (const Box3f& b : boxes) {
    if (b.empty()) continue;
    const CellRange r = rangeOf(b);
    for (int z = r.lo.y; z <= r.hi.y; ++z)
      for (int x = r.lo.x; x <= r.hi.x; ++x) ++cellStart_[index({x, z}) + 1];
  }
  for (size_t c = 0; c < cells; ++c) cellStart_[c + 1] += cellStart_[c];
  items_.resize(cellStart_.back());
  std::vector<uint32_t> fill(cellStart_.begin(), cellStart_.end() - 1);
  for (size_t i = 0; i < boxes.size(); ++i) {
    if (boxes[i].empty()) continue;
    const CellRange r = rangeOf(boxes[i]);
    for (int z = r.lo.y; z <= r.hi.y; ++z)
      for (int x = r.lo.x; x <= r.hi.x; ++x) items_[fill[index({x, z})]++] = uint32_t(i);
  }
}

glm::ivec2 XzGrid::cellOf(glm::vec2 p) const {
  VS_CHECK(!empty());
  const glm::vec2 v = (p - lo_) / cell_;
  return {clampedIndex(v.x, dims_.x), clampedIndex(v.y, dims_.y)};
}

XzGrid::CellRange XzGrid::cellsOverlapping(glm::vec2 lo, glm::vec2 hi) const {
  if (empty()) return {};
  return {cellOf(lo), cellOf(hi)};
}

std::span<const uint32_t> XzGrid::itemsIn(glm::ivec2 cell) const {
  VS_CHECK(cell.x >= 0 && cell.y >= 0 && cell.x < dims_.x && cell.y < dims_.y);
  const size_t c = index(cell);
  return std::span<const uint32_t>(items_).subspan(cellStart_[c],
                                                   cellStart_[c + 1] - cellStart_[c]);
}

std::vector<uint32_t> XzGrid::itemsNear(glm::vec2 lo, glm::vec2 hi) const {
  std::vector<uint32_t> out;
  const CellRange r = cellsOverlapping(lo, hi);
  for (int z = r.lo.y; z <= r.hi.y; ++z)
    for (int x = r.lo.x; x <= r.hi.x; ++x) {
      const std::span<const uint32_t> items = itemsIn({x, z});
      out.insert(out.end(), items.begin(), items.end());
    }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace vistream
