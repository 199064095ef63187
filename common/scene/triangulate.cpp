#include "common/scene/triangulate.h"

#include <cmath>

namespace vistream {
namespace {

// Twice the signed area of triangle (a, b, c) in the projection plane.
double orient2d(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

// Closed point-in-triangle test for a CCW triangle.
bool insideOrOnTriangle(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b,
                        const glm::dvec2& c) {
  return orient2d(a, b, p) >= 0.0 && orient2d(b, c, p) >= 0.0 && orient2d(c, a, p) >= 0.0;
}

}  // namespace

void triangulatePolygon(std::span<const glm::dvec3> polygon, std::vector<glm::uvec3>& out) {
  const size_t n = polygon.size();
  if (n < 3) return;
  if (n == 3) {
    out.emplace_back(0, 1, 2);
    return;
  }

  // Newell normal: robust plane orientation for any simple polygon.
  glm::dvec3 normal(0.0);
  const glm::dvec3 centre = [&] {
    glm::dvec3 c(0.0);
    for (const auto& p : polygon) c += p;
    return c / double(n);
  }();
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec3 a = polygon[i] - centre, b = polygon[(i + 1) % n] - centre;
    normal +=
        glm::dvec3((a.y - b.y) * (a.z + b.z), (a.z - b.z) * (a.x + b.x), (a.x - b.x) * (a.y + b.y));
  }
  // Project onto the plane of the two axes orthogonal to the dominant normal
  // axis, flipping one axis so the polygon is counter-clockwise.
  const glm::dvec3 an = glm::abs(normal);
  const int drop = an.x > an.y ? (an.x > an.z ? 0 : 2) : (an.y > an.z ? 1 : 2);
  const int ax = (drop + 1) % 3, ay = (drop + 2) % 3;
  const double flip = normal[drop] < 0.0 ? -1.0 : 1.0;
  std::vector<glm::dvec2> p2(n);
  for (size_t i = 0; i < n; ++i)
    p2[i] = {polygon[i][ax] - centre[ax], flip * (polygon[i][ay] - centre[ay])};

  std::vector<uint32_t> remaining(n);
  for (size_t i = 0; i < n; ++i) remaining[i] = uint32_t(i);

  // Ear clipping, O(n^2) per polygon: OBJ polygons are small.
  size_t guard = 0;
  size_t i = 0;
  while (remaining.size() > 3 && guard < 2 * remaining.size() + 2) {
    const size_t m = remaining.size();
    const uint32_t ia = remaining[(i + m - 1) % m], ib = remaining[i % m],
                   ic = remaining[(i + 1) % m];
    const glm::dvec2 a = p2[ia], b = p2[ib], c = p2[ic];
    bool ear = orient2d(a, b, c) > 0.0;
    for (size_t k = 0; ear && k < m; ++k) {
      const uint32_t q = remaining[k];
      if (q == ia || q == ib || q == ic) continue;
      // A reflex vertex on or inside the candidate ear blocks it (coincident
      // duplicates of the ear's own corners do not).
      if (p2[q] == a || p2[q] == b || p2[q] == c) continue;
      if (insideOrOnTriangle(p2[q], a, b, c)) ear = false;
    }
    if (ear) {
      out.emplace_back(ia, ib, ic);
      remaining.erase(remaining.begin() + std::ptrdiff_t(i % m));
      guard = 0;
      if (i >= remaining.size()) i = 0;
    } else {
      ++i;
      ++guard;
      if (i >= remaining.size()) i = 0;
    }
  }
  if (remaining.size() == 3) {
    out.emplace_back(remaining[0], remaining[1], remaining[2]);
  } else {
    // Not simple or fully degenerate: no ear left. Fan over what remains, so
    // every face still yields its n-2 triangles (degenerate ones are counted
    // and reported by the loader).
    for (size_t k = 1; k + 1 < remaining.size(); ++k)
      out.emplace_back(remaining[0], remaining[k], remaining[k + 1]);
  }
}

}  // namespace vistream
