// The convex hull of points in the plane (Andrew's monotone chain).
#pragma once

#include <algorithm>
#include <glm/glm.hpp>
#include <vector>

namespace vistream {

// Twice the signed area of triangle (a, b, c): positive when counter-clockwise.
inline double cross2(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

// The hull's vertices counter-clockwise, without collinear or repeated
// points. Fewer than three distinct points come back sorted and deduplicated
// (a point or a segment); so do collinear inputs' extreme points.
inline std::vector<glm::dvec2> convexHull2d(std::vector<glm::dvec2> pts) {
  std::sort(pts.begin(), pts.end(), [](const glm::dvec2& a, const glm::dvec2& b) {
    return a.x < b.x || (a.x == b.x && a.y < b.y);
  });
  pts.erase(std::unique(pts.begin(), pts.end()), pts.end());
  if (pts.size() < 3) return pts;
  std::vector<glm::dvec2> hull(2 * pts.size());
  size_t k = 0;
  for (size_t i = 0; i < pts.size(); ++i) {  // lower chain
    while (k >= 2 && cross2(hull[k - 2], hull[k - 1], pts[i]) <= 0.0) --k;
    hull[k++] = pts[i];
  }
  for (size_t i = pts.size() - 1, t = k + 1; i-- > 0;) {  // upper chain
    while (k >= t && cross2(hull[k - 2], hull[k - 1], pts[i]) <= 0.0) --k;
    hull[k++] = pts[i];
  }
  hull.resize(k - 1);
  return hull;
}

}  // namespace vistream
