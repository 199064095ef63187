#include "server/visibility/view_cell_grid.h"

#include <cmath>

#include "common/core/check.h"

namespace vistream {

ViewCellGrid::ViewCellGrid(const Box3f& region, const glm::vec3& cellSize)
    : lo_(region.lo), size_(cellSize) {
  VS_CHECK(cellSize.x > 0.0f && cellSize.y > 0.0f && cellSize.z > 0.0f);
  VS_CHECK(!region.empty());
  const glm::vec3 ext = region.extent();
  for (int a = 0; a < 3; ++a) dims_[a] = std::max(1, int(std::ceil(ext[a] / size_[a])));
}

Box3f ViewCellGrid::cellBox(const glm::ivec3& c) const {
  const glm::vec3 lo = lo_ + glm::vec3(c) * size_;
  return Box3f(lo, lo + size_);
}

std::optional<glm::ivec3> ViewCellGrid::cellOf(const glm::vec3& p) const {
  glm::ivec3 c;
  for (int a = 0; a < 3; ++a) {
    const float f = (p[a] - lo_[a]) / size_[a];
    if (!(f >= 0.0f) || f > float(dims_[a])) return std::nullopt;
    c[a] = std::min(dims_[a] - 1, int(std::floor(f)));
  }
  return c;
}

glm::ivec3 ViewCellGrid::cellAt(size_t linear) const {
  VS_CHECK_LT(linear, cellCount());
  const size_t x = linear % size_t(dims_.x);
  const size_t y = (linear / size_t(dims_.x)) % size_t(dims_.y);
  const size_t z = linear / (size_t(dims_.x) * size_t(dims_.y));
  return {int(x), int(y), int(z)};
}

}  // namespace vistream
