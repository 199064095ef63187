// A regular grid of square cells over the X/Z plane that lists items
// (triangles, faces) by index. Used wherever a horizontal neighbourhood is
// looked up: the client's near-field grid (client/farfield/field_grid.h) and
// the server's faces-within-a-radius query (server/stream/stream_world.h).
//
// An item is entered in every cell its box's X/Z rectangle overlaps. Points
// and rectangles outside the grid clamp to the border cells, both when items
// are entered and when cells are looked up, so an item outside the grid is
// still found by a query that reaches past the same border.
//
// Units: metres, in whatever frame the boxes are given (the grid never
// converts). Cells are closed on their low side: cell (i, j) spans
// [lo + (i, j) * cellSize, lo + (i + 1, j + 1) * cellSize).
//
// Thread safety: immutable after construction; const methods may run
// concurrently.
#pragma once

#include <cstddef>
#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <vector>

#include "common/core/box.h"

namespace vistream {

class XzGrid {
 public:
  // Cells in a rectangle of the grid, both corners included.
  struct CellRange {
    glm::ivec2 lo{0, 0};
    glm::ivec2 hi{-1, -1};
  };

  // No cells: every lookup finds nothing.
  XzGrid() = default;
  // Covers the X/Z rectangle of `bounds` with cells of side `cellSize`
  // metres: ceil(extent / cellSize) cells per axis (an extent below 1 mm
  // counts as 1 mm), at least one. boxes[i] is item i's box; items with an
  // empty box are left out. An empty `bounds` gives a grid without cells.
  // cellSize must be positive and finite (VS_CHECK).
  XzGrid(const Box3f& bounds, float cellSize, std::span<const Box3f> boxes);

  bool empty() const { return dims_.x == 0; }
  float cellSize() const { return cell_; }
  // The low X/Z corner of cell (0, 0).
  glm::vec2 lo() const { return lo_; }
  // Cells along X and along Z; (0, 0) when empty.
  glm::ivec2 dims() const { return dims_; }

  // The cell holding X/Z point p, clamped to the grid (NaN maps to 0).
  // Must not be called on an empty grid.
  glm::ivec2 cellOf(glm::vec2 p) const;
  // The cells the closed rectangle [lo, hi] overlaps, clamped to the grid;
  // an empty range when the grid is empty.
  CellRange cellsOverlapping(glm::vec2 lo, glm::vec2 hi) const;
  // The low corner of a cell; it spans [cellLo, cellLo + cellSize].
  glm::vec2 cellLo(glm::ivec2 cell) const { return lo_ + glm::vec2(cell) * cell_; }
  // The items entered in a cell, ascending. `cell` must lie in the grid.
  std::span<const uint32_t> itemsIn(glm::ivec2 cell) const;
  // Every item entered in a cell that [lo, hi] overlaps, each once,
  // ascending: a superset of the items whose X/Z rectangle meets [lo, hi].
  std::vector<uint32_t> itemsNear(glm::vec2 lo, glm::vec2 hi) const;

 private:
  size_t index(glm::ivec2 cell) const { return size_t(cell.y) * size_t(dims_.x) + size_t(cell.x); }

  glm::vec2 lo_{0.0f};
  float cell_ = 1.0f;
  glm::ivec2 dims_{0, 0};
  // CSR: the items of cell c are items_[cellStart_[c] .. cellStart_[c + 1]).
  std::vector<uint32_t> cellStart_{0};
  std::vector<uint32_t> items_;
};

}  // namespace vistream
