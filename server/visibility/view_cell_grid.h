// A regular grid of view cells (Cohen-Or and Zadicario 1998: the
// epsilon-neighbourhoods of the walkthrough).
//
// Cell (i, j, k) is the closed box [lo + (i,j,k)*size, lo + (i+1,j+1,k+1)*size]
// in the scene's local frame. Neighbouring cells share their faces; a point
// on a shared face belongs to the cell of lower index when asked with
// cellOf(), but a PVS computed for a closed cell is valid on all of its
// boundary, so either answer is safe.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>

#include "common/core/box.h"

namespace vistream {

class ViewCellGrid {
 public:
  ViewCellGrid() = default;
  // Covers `region` with cells of `cellSize` (all components > 0); the last
  // cell along an axis may reach past the region.
  ViewCellGrid(const Box3f& region, const glm::vec3& cellSize);

  glm::ivec3 dims() const { return dims_; }
  size_t cellCount() const { return size_t(dims_.x) * size_t(dims_.y) * size_t(dims_.z); }
  glm::vec3 cellSize() const { return size_; }
  glm::vec3 origin() const { return lo_; }

  bool contains(const glm::ivec3& c) const {
    return c.x >= 0 && c.y >= 0 && c.z >= 0 && c.x < dims_.x && c.y < dims_.y && c.z < dims_.z;
  }
  Box3f cellBox(const glm::ivec3& c) const;
  // The cell holding a point, or nothing outside the grid.
  std::optional<glm::ivec3> cellOf(const glm::vec3& p) const;
  size_t linearIndex(const glm::ivec3& c) const {
    return (size_t(c.z) * size_t(dims_.y) + size_t(c.y)) * size_t(dims_.x) + size_t(c.x);
  }
  glm::ivec3 cellAt(size_t linear) const;

 private:
  glm::vec3 lo_{0.0f};
  glm::vec3 size_{1.0f};
  glm::ivec3 dims_{0};
};

}  // namespace vistream
