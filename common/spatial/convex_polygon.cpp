// Convex polygons in the plane; the contracts are in convex_polygon.h.
#include "common/spatial/convex_polygon.h"

#include <cmath>
#include <limits>

namespace vistream {
namespace {

// True if the convex polygon is narrower than `width` (twice its area over
// its perimeter: about the width of a thin strip).
bool narrower(const std::vector<glm::dvec2>& poly, double width) {
  double perimeter = 0.0;
  for (size_t i = 0; i < poly.size(); ++i)
    perimeter += glm::length(poly[(i + 1) % poly.size()] - poly[i]);
  return !(perimeter > 0.0) || std::abs(twiceArea(poly)) < width * perimeter;
}

}  // namespace

void clipToHalfPlane(std::vector<glm::dvec2>& poly, std::vector<glm::dvec2>& scratch, double a,
                     double b, double c) {
  clipToHalfSpace(poly, scratch, glm::dvec2(a, b), c);
  if (poly.size() < 3) poly.clear();
}

double twiceArea(std::span<const glm::dvec2> poly) {
  double a = 0.0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const glm::dvec2& p = poly[i];
    const glm::dvec2& q = poly[(i + 1) % poly.size()];
    a += p.x * q.y - q.x * p.y;
  }
  return a;
}

glm::dvec4 polygonBounds(std::span<const glm::dvec2> poly) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  glm::dvec4 b(kInf, kInf, -kInf, -kInf);
  for (const glm::dvec2& p : poly) {
    b.x = std::min(b.x, p.x);
    b.y = std::min(b.y, p.y);
    b.z = std::max(b.z, p.x);
    b.w = std::max(b.w, p.y);
  }
  return b;
}

bool coveredBy(const std::vector<glm::dvec2>& region,
               std::span<const std::vector<glm::dvec2>> pieces, std::span<const glm::dvec4> bounds,
               double slack) {
  thread_local std::vector<std::vector<glm::dvec2>> left, next;
  thread_local std::vector<glm::dvec2> cur, part, tmp;
  left.assign(1, region);
  for (size_t q = 0; q < pieces.size() && !left.empty(); ++q) {
    const std::vector<glm::dvec2>& Q = pieces[q];
    next.clear();
    for (const std::vector<glm::dvec2>& piece : left) {
      if (!rectsOverlap(polygonBounds(piece), bounds[q])) {
        next.push_back(piece);
        continue;
      }
      cur = piece;
      for (size_t k = 0; k < Q.size() && !cur.empty(); ++k) {
        const glm::dvec2& a = Q[k];
        const glm::dvec2& b = Q[(k + 1) % Q.size()];
        // Inside Q is left of a -> b: (b - a) x (p - a) >= 0, i.e.
        // A p.x + B p.y <= C with (A, B) = (dy, -dx).
        const double A = b.y - a.y, B = a.x - b.x, C = A * a.x + B * a.y;
        part = cur;
        clipToHalfPlane(part, tmp, -A, -B, -C);  // outside of this edge
        if (!part.empty() && !narrower(part, slack)) next.push_back(part);
        clipToHalfPlane(cur, tmp, A, B, C);  // inside, on to the next edge
      }
      if (next.size() > 64) return false;
    }
    left.swap(next);
  }
  return left.empty();
}

}  // namespace vistream
