// The regular grid that splits a client's geometry into near field and far
// field (thesis section 4.3.1: "find objects in the near field using a
// regular grid").
//
// The grid (an XzGrid, common/spatial/xz_grid.h) covers the geometry's bounds
// in X and Z with square cells; a triangle is entered in every cell its X/Z
// bounding rectangle overlaps. The near field of a viewer is every triangle
// entered in a cell that comes within d of the viewer horizontally, so every
// triangle NOT in the near field lies entirely farther than d from the viewer
// horizontally.
//
// Thread safety: const methods may run concurrently; nearField() uses a
// caller-owned scratch buffer.
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
  XzGrid grid_;                   // triangles by X/Z cell
  std::vector<glm::vec2> cellY_;  // per cell (row-major, X fastest): min and max Y of its triangles
  size_t triangles_ = 0;
  Box3f bounds_;
};

}  // namespace vistream
