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
  itemLo_.assign(boxes.size(), glm::ivec2(0));
  for (size_t i = 0; i < boxes.size(); ++i) {
    if (boxes[i].empty()) continue;
    const CellRange r = rangeOf(boxes[i]);
    itemLo_[i] = r.lo;
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
  forEachItemNear(lo, hi, [&](uint32_t item) { out.push_back(item); });
  std::sort(out.begin(), out.end());
  return out;
}

DynamicXzGrid::DynamicXzGrid(float cellSize, size_t maxCells)
    : cell_(cellSize), maxCells_(maxCells) {
  VS_CHECK(cellSize > 0.0f && std::isfinite(cellSize));
}

bool DynamicXzGrid::planeCells(const Box3f& box, glm::ivec2& lo, glm::ivec2& hi) const {
  constexpr double kLimit = double(1 << 30);
  const double v[4] = {std::floor(double(box.lo.x) / cell_), std::floor(double(box.lo.z) / cell_),
                       std::floor(double(box.hi.x) / cell_), std::floor(double(box.hi.z) / cell_)};
  for (const double c : v)
    if (!(std::abs(c) < kLimit)) return false;
  lo = {int(v[0]), int(v[1])};
  hi = {int(v[2]), int(v[3])};
  return true;
}

bool DynamicXzGrid::insert(uint32_t item, const Box3f& box) {
  if (box.empty()) return true;
  glm::ivec2 lo, hi;
  if (!planeCells(box, lo, hi)) return false;
  const glm::ivec2 end = origin_ + dims_;
  if (empty() || glm::any(glm::lessThan(lo, origin_)) || glm::any(glm::greaterThanEqual(hi, end))) {
    // Grow: cover the box, with a quarter of the old size to spare on each
    // side that grows.
    glm::ivec2 newLo = empty() ? lo : glm::min(origin_, lo);
    glm::ivec2 newEnd = empty() ? hi + 1 : glm::max(end, hi + 1);
    auto cellsOf = [](glm::ivec2 from, glm::ivec2 to) {
      return double(to.x - from.x) * double(to.y - from.y);
    };
    if (cellsOf(newLo, newEnd) > double(maxCells_)) return false;
    // The spare only where the limit allows it.
    const glm::ivec2 spare = dims_ / 4;
    glm::ivec2 spareLo = newLo, spareEnd = newEnd;
    for (int a = 0; a < 2; ++a) {
      if (!empty() && newLo[a] < origin_[a]) spareLo[a] -= spare[a];
      if (!empty() && newEnd[a] > end[a]) spareEnd[a] += spare[a];
    }
    if (cellsOf(spareLo, spareEnd) <= double(maxCells_)) {
      newLo = spareLo;
      newEnd = spareEnd;
    }
    const glm::ivec2 newDims = newEnd - newLo;
    std::vector<std::vector<uint32_t>> grown(size_t(newDims.x) * size_t(newDims.y));
    for (int z = 0; z < dims_.y; ++z)
      for (int x = 0; x < dims_.x; ++x) {
        const glm::ivec2 to = origin_ + glm::ivec2(x, z) - newLo;
        grown[size_t(to.y) * size_t(newDims.x) + size_t(to.x)] = std::move(cells_[index({x, z})]);
      }
    cells_ = std::move(grown);
    origin_ = newLo;
    dims_ = newDims;
  }
  for (int z = lo.y; z <= hi.y; ++z)
    for (int x = lo.x; x <= hi.x; ++x) {
      std::vector<uint32_t>& items = cells_[index(glm::ivec2(x, z) - origin_)];
      if (items.empty() || items.back() < item)
        items.push_back(item);
      else if (auto at = std::lower_bound(items.begin(), items.end(), item);
               at == items.end() || *at != item)
        items.insert(at, item);
    }
  return true;
}

void DynamicXzGrid::erase(uint32_t item, const Box3f& box) {
  if (box.empty() || empty()) return;
  glm::ivec2 lo, hi;
  if (!planeCells(box, lo, hi)) return;
  lo = glm::max(lo, origin_);
  hi = glm::min(hi, origin_ + dims_ - 1);
  for (int z = lo.y; z <= hi.y; ++z)
    for (int x = lo.x; x <= hi.x; ++x) {
      std::vector<uint32_t>& items = cells_[index(glm::ivec2(x, z) - origin_)];
      if (auto at = std::lower_bound(items.begin(), items.end(), item);
          at != items.end() && *at == item)
        items.erase(at);
    }
}

glm::ivec2 DynamicXzGrid::cellOf(glm::vec2 p) const {
  VS_CHECK(!empty());
  const glm::vec2 v = (p - lo()) / cell_;
  return {clampedIndex(v.x, dims_.x), clampedIndex(v.y, dims_.y)};
}

XzGrid::CellRange DynamicXzGrid::cellsOverlapping(glm::vec2 lo, glm::vec2 hi) const {
  if (empty()) return {};
  return {cellOf(lo), cellOf(hi)};
}

std::span<const uint32_t> DynamicXzGrid::itemsIn(glm::ivec2 cell) const {
  VS_CHECK(cell.x >= 0 && cell.y >= 0 && cell.x < dims_.x && cell.y < dims_.y);
  return cells_[index(cell)];
}

}  // namespace vistream
