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
  // The same items, each once, in no set order, without sorting: an item
  // is visited in the first cell of the range that it was entered in (the
  // larger of its lowest cell and the range's, per axis).
  template <class F>
  void forEachItemNear(glm::vec2 lo, glm::vec2 hi, F&& f) const {
    const CellRange r = cellsOverlapping(lo, hi);
    for (int z = r.lo.y; z <= r.hi.y; ++z)
      for (int x = r.lo.x; x <= r.hi.x; ++x)
        for (uint32_t item : itemsIn({x, z}))
          if (glm::max(itemLo_[item], r.lo) == glm::ivec2(x, z)) f(item);
  }

 private:
  size_t index(glm::ivec2 cell) const { return size_t(cell.y) * size_t(dims_.x) + size_t(cell.x); }

  glm::vec2 lo_{0.0f};
  float cell_ = 1.0f;
  glm::ivec2 dims_{0, 0};
  // CSR: the items of cell c are items_[cellStart_[c] .. cellStart_[c + 1]).
  std::vector<uint32_t> cellStart_{0};
  std::vector<uint32_t> items_;
  std::vector<glm::ivec2> itemLo_;  // by item: the lowest cell it was entered in
};

// An X/Z grid that takes items up and lets them go one at a time (a
// streaming client's triangles), with the lookups of XzGrid.
//
// Cells sit at fixed multiples of cellSize in the frame of the boxes: the
// cell of the plane holding point p is floor(p / cellSize), whatever else was
// entered and in whatever order, so two grids of one cell size holding the
// same items list the same items in the same cells, ascending. The array of
// cells covers every item entered and grows when one lands outside it (with a
// quarter of its size to spare on the side it grows while that stays within
// the limit, so growing costs amortised O(1) a cell); insert() refuses an
// item that would take it beyond `maxCells` cells (a box far away or huge),
// leaving the grid unchanged.
//
// Thread safety: const methods may run concurrently; insert and erase may not
// run with anything else.
class DynamicXzGrid {
 public:
  DynamicXzGrid() = default;
  // cellSize must be positive and finite (VS_CHECK).
  explicit DynamicXzGrid(float cellSize, size_t maxCells = size_t(1) << 20);

  // Enters `item` in every cell `box`'s X/Z rectangle overlaps (an empty box:
  // nowhere, and true). False if the grid would grow beyond maxCells.
  bool insert(uint32_t item, const Box3f& box);
  // Takes `item` out of the cells of `box`, which must be the box it was
  // entered with; an item not there is ignored.
  void erase(uint32_t item, const Box3f& box);

  bool empty() const { return dims_.x == 0; }
  float cellSize() const { return cell_; }
  // The low X/Z corner of array cell (0, 0), and the array's size.
  glm::vec2 lo() const { return glm::vec2(origin_) * cell_; }
  glm::ivec2 dims() const { return dims_; }
  // The cell of the plane (in units of cells) that array cell (0, 0) is.
  glm::ivec2 origin() const { return origin_; }
  // As in XzGrid, over the array's cells.
  glm::ivec2 cellOf(glm::vec2 p) const;
  XzGrid::CellRange cellsOverlapping(glm::vec2 lo, glm::vec2 hi) const;
  glm::vec2 cellLo(glm::ivec2 cell) const { return glm::vec2(origin_ + cell) * cell_; }
  std::span<const uint32_t> itemsIn(glm::ivec2 cell) const;

 private:
  size_t index(glm::ivec2 cell) const { return size_t(cell.y) * size_t(dims_.x) + size_t(cell.x); }
  // The cells of the plane `box` covers; false if beyond +-2^30 cells.
  bool planeCells(const Box3f& box, glm::ivec2& lo, glm::ivec2& hi) const;

  float cell_ = 1.0f;
  size_t maxCells_ = 0;
  glm::ivec2 origin_{0, 0};
  glm::ivec2 dims_{0, 0};
  std::vector<std::vector<uint32_t>> cells_;  // row-major, X fastest; each ascending
};

}  // namespace vistream
