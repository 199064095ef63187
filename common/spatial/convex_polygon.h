// Convex polygons as vertex lists: clipping to a half-space (Sutherland and
// Hodgman), in any dimension glm has (2D polygons in a plane's frame, 3D
// polygons in space).
#pragma once

#include <glm/glm.hpp>
#include <vector>

namespace vistream {

// Keeps the part of the convex `poly` where dot(n, x) <= d. Closed
// half-spaces: a polygon touching the boundary keeps the touching points,
// so what is left may have fewer than three vertices. `scratch` is reused
// (its contents are lost).
template <glm::length_t N>
void clipToHalfSpace(std::vector<glm::vec<N, double>>& poly,
                     std::vector<glm::vec<N, double>>& scratch, const glm::vec<N, double>& n,
                     double d) {
  scratch.clear();
  for (size_t i = 0; i < poly.size(); ++i) {
    const glm::vec<N, double> a = poly[i], b = poly[(i + 1) % poly.size()];
    const double da = glm::dot(n, a) - d, db = glm::dot(n, b) - d;
    if (da <= 0.0) scratch.push_back(a);
    if ((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0))
      scratch.push_back(a + (b - a) * (da / (da - db)));
  }
  poly.swap(scratch);
}

}  // namespace vistream
