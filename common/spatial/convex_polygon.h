// Convex polygons as vertex lists: clipping to a half-space (Sutherland and
// Hodgman), in any dimension glm has (2D polygons in a plane's frame, 3D
// polygons in space); and, in the plane, whether convex pieces cover a
// convex region (the exact subtraction that occluder fusion within a plane
// and the caps of enclosures rest on).
#pragma once

#include <glm/glm.hpp>
#include <span>
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

// 2D: keeps the part of the convex polygon where a * p.x + b * p.y <= c;
// less than a triangle is nothing (the polygon is cleared).
void clipToHalfPlane(std::vector<glm::dvec2>& poly, std::vector<glm::dvec2>& scratch, double a,
                     double b, double c);

// Twice the signed area (positive counter-clockwise).
double twiceArea(std::span<const glm::dvec2> poly);

// Bounds as (min x, min y, max x, max y); empty polygons give an inverted box.
glm::dvec4 polygonBounds(std::span<const glm::dvec2> poly);

// Closed rectangles (polygonBounds) overlap.
inline bool rectsOverlap(const glm::dvec4& a, const glm::dvec4& b) {
  return a.x <= b.z && b.x <= a.z && a.y <= b.w && b.y <= a.w;
}

// True if the convex `region` minus the convex `pieces` (counter-clockwise,
// with their polygonBounds) leaves nothing wider than `slack`: the region is
// cut, piece after piece, into convex parts outside each piece's edges, and
// parts narrower than the slack (twice their area over their perimeter) are
// dropped. So a seam narrower than the slack between two pieces counts as
// covered, a wider one does not. False as well past 64 parts (gives up,
// which is the conservative answer for every caller).
bool coveredBy(const std::vector<glm::dvec2>& region,
               std::span<const std::vector<glm::dvec2>> pieces, std::span<const glm::dvec4> bounds,
               double slack);

}  // namespace vistream
