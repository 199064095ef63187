// Occluder fusion within a plane; the proof is in planar_fusion.h.
#include "server/visibility/planar_fusion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>

#include "common/spatial/convex_hull.h"
#include "common/spatial/convex_polygon.h"

namespace vistream {
namespace {

// Keeps the part of the convex polygon where a * p.x + b * p.y <= c; less
// than a triangle is nothing.
void clipHalfPlane(std::vector<glm::dvec2>& poly, std::vector<glm::dvec2>& scratch, double a,
                   double b, double c) {
  clipToHalfSpace(poly, scratch, glm::dvec2(a, b), c);
  if (poly.size() < 3) poly.clear();
}

double twiceArea(const std::vector<glm::dvec2>& poly) {
  double a = 0.0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const glm::dvec2& p = poly[i];
    const glm::dvec2& q = poly[(i + 1) % poly.size()];
    a += p.x * q.y - q.x * p.y;
  }
  return a;
}

// True if the convex polygon is narrower than `width` (twice its area over
// its perimeter: about the width of a thin strip).
bool narrower(const std::vector<glm::dvec2>& poly, double width) {
  double perimeter = 0.0;
  for (size_t i = 0; i < poly.size(); ++i)
    perimeter += glm::length(poly[(i + 1) % poly.size()] - poly[i]);
  return !(perimeter > 0.0) || std::abs(twiceArea(poly)) < width * perimeter;
}

glm::dvec4 boundsOf(const std::vector<glm::dvec2>& poly) {
  glm::dvec4 b(std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
               -std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity());
  for (const glm::dvec2& p : poly) {
    b.x = std::min(b.x, p.x);
    b.y = std::min(b.y, p.y);
    b.z = std::max(b.z, p.x);
    b.w = std::max(b.w, p.y);
  }
  return b;
}

bool overlaps(const glm::dvec4& a, const glm::dvec4& b) {
  return a.x <= b.z && b.x <= a.z && a.y <= b.w && b.y <= a.w;
}

// True if p lies in the counter-clockwise convex polygon grown by `slack`.
bool insidePiece(const std::vector<glm::dvec2>& poly, const glm::dvec2& p, double slack) {
  for (size_t i = 0; i < poly.size(); ++i) {
    const glm::dvec2& a = poly[i];
    const glm::dvec2 e = poly[(i + 1) % poly.size()] - a;
    if (e.x * (p.y - a.y) - e.y * (p.x - a.x) < -slack * glm::length(e)) return false;
  }
  return true;
}

// True if the convex `region` minus the convex `pieces` (counter-clockwise,
// with their bounds) leaves nothing wider than `slack` (planar_fusion.h,
// numerics): the region is cut, piece after piece, into convex parts
// outside each piece's edges; parts narrower than the slack are dropped.
// False as well past 64 parts (give up).
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
      if (!overlaps(boundsOf(piece), bounds[q])) {
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
        clipHalfPlane(part, tmp, -A, -B, -C);  // outside of this edge
        if (!part.empty() && !narrower(part, slack)) next.push_back(part);
        clipHalfPlane(cur, tmp, A, B, C);  // inside, on to the next edge
      }
      if (next.size() > 64) return false;
    }
    left.swap(next);
  }
  return left.empty();
}

// Replaces two pieces by their convex hull where the two cover the hull
// but for strips narrower than `slack` (the seam the shrinking opens
// between abutting solids: coveredBy): a row of wall patches becomes one
// rectangle, so a footprint is tested against a few pieces instead of many.
void mergePieces(std::vector<std::vector<glm::dvec2>>& pieces, std::vector<glm::dvec4>& bounds,
                 double slack) {
  std::vector<glm::dvec2> both;
  for (bool merged = true; merged;) {
    merged = false;
    for (size_t i = 0; i < pieces.size() && !merged; ++i)
      for (size_t j = i + 1; j < pieces.size() && !merged; ++j) {
        const glm::dvec4 gi = bounds[i] + glm::dvec4(-slack, -slack, slack, slack);
        if (!overlaps(gi, bounds[j])) continue;
        both = pieces[i];
        both.insert(both.end(), pieces[j].begin(), pieces[j].end());
        std::vector<glm::dvec2> hull = convexHull2d(both);
        if (hull.size() < 3) continue;
        const std::vector<glm::dvec2> two[2] = {pieces[i], pieces[j]};
        const glm::dvec4 twoBounds[2] = {bounds[i], bounds[j]};
        if (!coveredBy(hull, two, twoBounds, slack)) continue;
        pieces[i] = std::move(hull);
        bounds[i] = boundsOf(pieces[i]);
        pieces.erase(pieces.begin() + std::ptrdiff_t(j));
        bounds.erase(bounds.begin() + std::ptrdiff_t(j));
        merged = true;
      }
  }
}

}  // namespace

PlanarFusion::PlanarFusion(const OccluderSet& occluders) {
  // Every face plane of every solid occluder, by normal then offset.
  struct Entry {
    glm::dvec3 n;
    double d;
    uint32_t occluder;
  };
  std::vector<Entry> entries;
  double magnitude = 0.0;
  for (size_t i = 0; i < occluders.occluders.size(); ++i) {
    const ConvexOccluder& o = occluders.occluders[i];
    if (o.kind != ConvexOccluder::Kind::Solid) continue;
    magnitude =
        std::max({magnitude, double(glm::length(o.bounds.lo)), double(glm::length(o.bounds.hi))});
    for (const glm::dvec4& p : o.planes) entries.push_back({glm::dvec3(p), p.w, uint32_t(i)});
  }
  const double tolerance = 1e-6 * (1.0 + magnitude);
  // A slab depth far above rounding, far below any wall's thickness.
  const double e = std::max(1e-3, 1e-6 * (1.0 + magnitude));
  auto key = [](const glm::dvec3& n) {
    return glm::dvec3(std::round(n.x * 1e9), std::round(n.y * 1e9), std::round(n.z * 1e9));
  };
  std::sort(entries.begin(), entries.end(), [&](const Entry& a, const Entry& b) {
    const glm::dvec3 ka = key(a.n), kb = key(b.n);
    if (ka.x != kb.x) return ka.x < kb.x;
    if (ka.y != kb.y) return ka.y < kb.y;
    if (ka.z != kb.z) return ka.z < kb.z;
    return a.d < b.d;
  });
  std::vector<glm::dvec2> poly, tmp;
  for (size_t i = 0; i < entries.size();) {
    // One plane: the same normal, offsets chained within the tolerance.
    size_t j = i + 1;
    while (j < entries.size() && key(entries[j].n) == key(entries[i].n) &&
           entries[j].d - entries[j - 1].d <= tolerance)
      ++j;
    if (j - i < 2) {  // one face alone fuses nothing
      i = j;
      continue;
    }
    Plane pl;
    pl.n = glm::normalize(entries[i].n);
    const glm::dvec3 axis = std::abs(pl.n.x) < 0.6 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    pl.u = glm::normalize(glm::cross(pl.n, axis));
    pl.v = glm::cross(pl.n, pl.u);
    pl.top = entries[i].d - e;  // the smallest offset comes first
    pl.bottom = pl.top - e;
    double planeMagnitude = 0.0;
    for (size_t k = i; k < j; ++k) {
      const ConvexOccluder& o = occluders.occluders[entries[k].occluder];
      // Q: the points (a, b) at height top whose segment down to bottom
      // lies in the region, from a square around the occluder's bounds.
      const glm::dvec3 lo(o.bounds.lo), hi(o.bounds.hi);
      const double r = glm::length(hi - lo) + 1.0;
      const glm::dvec3 c = 0.5 * (lo + hi);
      const double cu = glm::dot(c, pl.u), cv = glm::dot(c, pl.v);
      poly = {{cu - r, cv - r}, {cu + r, cv - r}, {cu + r, cv + r}, {cu - r, cv + r}};
      for (const glm::dvec4& h : o.planes) {
        const glm::dvec3 hn(h);
        const double a = glm::dot(hn, pl.u), b = glm::dot(hn, pl.v), w = glm::dot(hn, pl.n);
        // hn . (a u + b v + t n) < h.w at t = top and t = bottom.
        const double limit = h.w - std::max(w * pl.top, w * pl.bottom);
        if (std::abs(a) < 1e-12 && std::abs(b) < 1e-12) {
          if (!(0.0 < limit)) poly.clear();
        } else {
          clipHalfPlane(poly, tmp, a, b, limit);
        }
        if (poly.empty()) break;
      }
      if (poly.size() < 3 || !(twiceArea(poly) > 0.0)) continue;
      pl.pieceBounds.push_back(boundsOf(poly));
      for (const glm::dvec2& q : poly) {
        const glm::dvec3 x = q.x * pl.u + q.y * pl.v + pl.top * pl.n;
        pl.bounds.extend(glm::vec3(x));
        planeMagnitude = std::max(planeMagnitude, glm::length(x));
      }
      pl.pieces.push_back(poly);
    }
    if (pl.pieces.size() >= 2) {
      pl.margin = occluderMargin(planeMagnitude);
      mergePieces(pl.pieces, pl.pieceBounds, 4.0 * pl.margin);
      pl.unionBounds = pl.pieceBounds[0];
      for (const glm::dvec4& b : pl.pieceBounds)
        pl.unionBounds =
            glm::dvec4(std::min(pl.unionBounds.x, b.x), std::min(pl.unionBounds.y, b.y),
                       std::max(pl.unionBounds.z, b.z), std::max(pl.unionBounds.w, b.w));
      // Grown by the float rounding of the bounds.
      pl.bounds.lo -= glm::vec3(float(1e-5 * (1.0 + planeMagnitude)));
      pl.bounds.hi += glm::vec3(float(1e-5 * (1.0 + planeMagnitude)));
      planes_.push_back(std::move(pl));
    }
    i = j;
  }
}

PlanarFusion::CellPlanes PlanarFusion::planesFor(const Box3f& cell) const {
  CellPlanes out;
  const glm::dvec3 centre(cell.center()), half(0.5 * (glm::dvec3(cell.hi) - glm::dvec3(cell.lo)));
  for (size_t i = 0; i < planes_.size(); ++i) {
    const Plane& p = planes_[i];
    // The lowest height of a cell point along n, above the slab's top.
    const double lowest = glm::dot(p.n, centre) - glm::dot(glm::abs(p.n), half);
    if (lowest > p.top + p.margin) out.planes.push_back(uint32_t(i));
  }
  return out;
}

bool PlanarFusion::hidden(const Box3f& cell, const CellPlanes& cellPlanes,
                          std::span<const glm::dvec3> vertices) const {
  if (vertices.empty()) return false;
  Box3f shaft = cell;
  for (const glm::dvec3& p : vertices) shaft.extend(glm::vec3(p));
  glm::dvec3 corners[8];
  for (int k = 0; k < 8; ++k)
    corners[k] = glm::dvec3((k & 1) ? cell.hi.x : cell.lo.x, (k & 2) ? cell.hi.y : cell.lo.y,
                            (k & 4) ? cell.hi.z : cell.lo.z);
  thread_local std::vector<glm::dvec2> points;
  for (uint32_t index : cellPlanes.planes) {
    const Plane& pl = planes_[index];
    if (!pl.bounds.overlaps(shaft)) continue;
    bool behind = true;
    for (const glm::dvec3& p : vertices) behind &= glm::dot(pl.n, p) < pl.bottom - pl.margin;
    if (!behind) continue;
    // The footprint F (planar_fusion.h): its points, each tested as it
    // comes. Every point of F lies in some piece, or F is not covered
    // (most planes fail on the first points); if all lie in one (convex)
    // piece, so does F.
    const double slack = 4.0 * pl.margin;
    points.clear();
    size_t home = 0;
    bool inOne = true, inAll = true;
    auto take = [&](const glm::dvec3& x) {
      const glm::dvec2 q(glm::dot(x, pl.u), glm::dot(x, pl.v));
      points.push_back(q);
      if (insidePiece(pl.pieces[home], q, slack)) return true;
      inOne = false;
      for (size_t k = 0; k < pl.pieces.size(); ++k)
        if (insidePiece(pl.pieces[k], q, slack)) {
          home = k;
          return true;
        }
      return false;
    };
    // The line from the cell's centre to the face's first vertex first.
    {
      const glm::dvec3 c(cell.center()), p = vertices[0];
      const double hc = glm::dot(pl.n, c), hp = glm::dot(pl.n, p);
      inAll = take(c + (p - c) * ((hc - pl.top) / (hc - hp)));
      points.clear();
      inOne = true;  // `home` holds the centre line's piece
    }
    for (size_t ci = 0; ci < 8 && inAll; ++ci) {
      const glm::dvec3& c = corners[ci];
      const double hc = glm::dot(pl.n, c);
      for (size_t vi = 0; vi < vertices.size() && inAll; ++vi) {
        const glm::dvec3& p = vertices[vi];
        const double hp = glm::dot(pl.n, p);
        inAll = take(c + (p - c) * ((hc - pl.top) / (hc - hp))) &&
                take(c + (p - c) * ((hc - pl.bottom) / (hc - hp)));
      }
    }
    if (!inAll) continue;
    if (inOne) return true;
    std::vector<glm::dvec2> footprint = convexHull2d(points);
    if (footprint.size() < 3) continue;
    // F minus each Q_i (planar_fusion.h, numerics).
    if (coveredBy(footprint, pl.pieces, pl.pieceBounds, slack)) return true;
  }
  return false;
}

}  // namespace vistream
