// The regular grid that splits a client's geometry into near field and far
// field (thesis section 4.3.1: "find objects in the near field using a
// regular grid").
//
// The grid (a DynamicXzGrid, common/spatial/xz_grid.h) covers the geometry in
// X and Z with square cells at fixed multiples of the cell size; a triangle is
// entered in every cell its X/Z bounding rectangle overlaps. Triangles can be
// added and removed (a streaming client's geometry): the grid then lists the
// same triangles in the same order as one built from scratch with the same
// cell size over the triangles held. The near field of a viewer is every triangle
// entered in a cell that comes within d of the viewer horizontally, so every
// triangle NOT in the near field lies entirely farther than d from the viewer
// horizontally.
//
// Thread safety: const methods may run concurrently; nearField() uses a
// caller-owned scratch buffer. add() and remove() may not run with anything else.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <vector>

#include "client/render/camera.h"
#include "client/render/render_geometry.h"
#include "common/spatial/xz_grid.h"

namespace vistream {

class FieldGrid {
 public:
  FieldGrid() = default;
  // cellSize in metres; 0 picks one from the geometry (about 64 x 64 cells, at least 4 m).
  FieldGrid(const RenderGeometry& geometry, float cellSize = 0.0f);

  // Enters triangles [first, first + count) of `geometry` (the geometry this
  // grid was built over, grown since). False if the grid would grow beyond
  // its cell limit (geometry very far away); the grid is then unusable and
  // must be built again (with larger cells).
  bool add(const RenderGeometry& geometry, uint32_t first, uint32_t count);
  // Takes triangles out (their corners must be those they were added with).
  void remove(const RenderGeometry& geometry, std::span<const uint32_t> triangles);

  float cellSize() const { return grid_.cellSize(); }
  glm::ivec2 dims() const { return grid_.dims(); }

  // Triangles of the near field of `camera` within horizontal distance d,
  // each once, in cell order, skipping cells wholly outside the view
  // frustum. With d = infinity: every triangle in the frustum (full rendering).
  void nearField(const Camera& camera, float d, std::vector<uint32_t>& out,
                 std::vector<uint32_t>& stamp, uint32_t& stampValue) const;
  // False only if all geometry lies within horizontal distance d of the
  // viewer. Conservative: measured to the far corners of the grid cells that
  // hold geometry, so it may say true when the geometry itself ends within d.
  bool anythingBeyond(const glm::vec3& eye, float d) const;

 private:
  // min and max Y of the triangles in a cell of grid_ (empty: +max, lowest)
  glm::vec2& cellY(glm::ivec2 cell) {
    return cellY_[size_t(cell.y) * size_t(grid_.dims().x) + size_t(cell.x)];
  }
  // Follows grid_ after it grew: cellY_ gets its new layout.
  void followGrowth(glm::ivec2 oldOrigin, glm::ivec2 oldDims);

  DynamicXzGrid grid_;            // triangles by X/Z cell
  std::vector<glm::vec2> cellY_;  // per cell (row-major, X fastest): min and max Y of its triangles
  size_t triangles_ = 0;
};

}  // namespace vistream
