// Triangulation of simple planar polygons, convex or concave.
//
// Ear clipping in the polygon's best-fit plane (Newell normal). Collinear and
// repeated vertices are tolerated; a polygon that is not simple (self
// intersecting) still yields n-2 triangles covering its vertices, falling back
// to a fan when no ear can be found. Never fails, never loops forever.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <span>
#include <vector>

namespace vistream {

// Appends n-2 index triples (indices into `polygon`, in the polygon's winding)
// to `out` for an n-gon; nothing for n < 3.
void triangulatePolygon(std::span<const glm::dvec3> polygon, std::vector<glm::uvec3>& out);

}  // namespace vistream
