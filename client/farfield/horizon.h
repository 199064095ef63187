// Horizon tracing (thesis section 4.5).
//
// A 2D height field over X/Z holds the highest point of the geometry in each
// cell. For every pixel column, a 2D ray through the height field finds the
// steepest slope (height above the eye over horizontal distance) of the far
// field under the column; a pixel whose view ray climbs more steeply than that
// cannot hit far-field geometry and is sky. The result is conservative:
//  - the trace covers the whole wedge of azimuths the column spans (with a
//    pitched camera a column is not a vertical plane, so the wedge includes
//    the azimuths of its top and bottom pixels), using max-dilated copies of
//    the height field as wide as the wedge at each distance;
//  - a cell's height above the eye counts at the shortest horizontal
//    distance from the eye to the (dilated) cell, and a height below the eye
//    at the longest (farther ground lies closer to the horizon);
//  - the caller asks only about pixels no near-field polygon reaches at all,
//    which can see only far-field geometry, and that lies farther than d
//    horizontally (FieldGrid): no height counts nearer than d.
// Subsampling while moving (the thesis's graceful degradation) traces every
// k-th column with a wedge k columns wide, which fills the columns between
// with the maximum of their neighbourhood and stays conservative.
//
// Thread safety: trace() is const and may run concurrently.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "client/render/camera.h"
#include "client/render/render_geometry.h"

namespace vistream {

struct HorizonStats {
  size_t columnsTraced = 0;
  size_t cellsVisited = 0;
};

class HorizonMap {
 public:
  HorizonMap() = default;
  // cellSize in metres (the resolution knob of the thesis: coarser is faster
  // but overestimates the horizon). The map covers the X/Z rectangle of the
  // geometry's bounds and of `cover` (room for geometry still to come).
  HorizonMap(const RenderGeometry& geometry, float cellSize, const Box3f& cover = {});

  // Raises the height field by triangles [first, first + count) of
  // `geometry` (added since the map was built). False, leaving the map as it
  // was, if one lies outside the map's rectangle: build a new map then.
  // Removed triangles may stay in the map: a height field that is too high
  // only makes fewer pixels sky, which the ray caster then finds (the same
  // colour), so the map stays conservative.
  bool raise(const RenderGeometry& geometry, uint32_t first, uint32_t count);
  // The X/Z rectangle the map covers (Y: the highest point), empty without geometry.
  Box3f extent() const;

  float cellSize() const { return cell_; }
  glm::ivec2 dims() const { return dims_; }

  // Per pixel column, the steepest far-field slope (-infinity if the column
  // sees no far-field geometry). `subsample` >= 1 traces every k-th column.
  std::vector<float> trace(const Camera& camera, float nearDistance, int subsample,
                           HorizonStats* stats = nullptr) const;

  // The slope of the view ray through a pixel centre: dy / |d_xz| (infinity straight up).
  static float raySlope(const glm::vec3& dir);

 private:
  float height(int level, int x, int z) const {
    return levels_[size_t(level)][size_t(z) * size_t(dims_.x) + size_t(x)];
  }
  // Raises level 0 by the triangles (clamped into the border cells) and rebuilds the levels.
  void raiseClamped(const RenderGeometry& geometry, uint32_t first, uint32_t count);
  void buildLevels();  // levels 1.. from level 0
  float traceWedge(const glm::vec3& eye, float azimuth, float halfAngle, float nearDistance,
                   size_t& cells) const;

  glm::vec2 lo_{0.0f};
  float cell_ = 1.0f;
  glm::ivec2 dims_{0, 0};
  float maxHeight_ = 0.0f;
  std::vector<std::vector<float>>
      levels_;  // level k: max over a (2r_k+1)^2 neighbourhood, r_k = 2^k - 1
  std::vector<int> radius_;
};

}  // namespace vistream
