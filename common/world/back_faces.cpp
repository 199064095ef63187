#include "common/world/back_faces.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <span>

#include "common/core/check.h"
#include "common/spatial/convex_polygon.h"
#include "common/spatial/xz_grid.h"

namespace vistream {
namespace {

using Polygon = std::vector<glm::dvec3>;

// The triangle's frame: unit normal, two in-plane axes, a corner.
struct TriangleFrame {
  glm::dvec3 origin, u, v, n;
  std::array<glm::dvec2, 3> corners{};  // in (u, v)
  glm::dvec2 incentre{};
  double inradius = 0.0;

  glm::dvec2 project(const glm::dvec3& p) const {
    return {glm::dot(p - origin, u), glm::dot(p - origin, v)};
  }
  glm::dvec3 lift(glm::dvec2 q) const { return origin + u * q.x + v * q.y; }
};

TriangleFrame frameOf(const FlatTriangles& tris, size_t t) {
  TriangleFrame f;
  const glm::dvec3 a(tris.vertex(t, 0)), b(tris.vertex(t, 1)), c(tris.vertex(t, 2));
  f.origin = a;
  const glm::dvec3 cr = glm::cross(b - a, c - a);
  const double area2 = glm::length(cr);
  if (!(area2 > 0.0)) return f;
  f.n = cr / area2;
  f.u = glm::normalize(b - a);
  f.v = glm::cross(f.n, f.u);
  f.corners = {glm::dvec2(0.0), f.project(b), f.project(c)};
  const double la = glm::distance(b, c), lb = glm::distance(a, c), lc = glm::distance(a, b);
  const double perimeter = la + lb + lc;
  f.inradius = area2 / perimeter;
  f.incentre = (f.corners[0] * la + f.corners[1] * lb + f.corners[2] * lc) / perimeter;
  return f;
}

// True if some point of triangle `other` lies within `c` of the plane of
// `frame`'s triangle and projects into that triangle shrunk by `c`.
bool comesClose(const TriangleFrame& frame, const FlatTriangles& tris, size_t other, double c,
                Polygon& poly, Polygon& scratch) {
  // In the frame's (u, v, w) coordinates: the slab is |w| <= c, the shrunk
  // triangle each side's inward half-plane moved by c.
  poly.clear();
  for (int k = 0; k < 3; ++k) {
    const glm::dvec3 x = glm::dvec3(tris.vertex(other, k)) - frame.origin;
    poly.emplace_back(glm::dot(x, frame.u), glm::dot(x, frame.v), glm::dot(x, frame.n));
  }
  clipToHalfSpace(poly, scratch, {0.0, 0.0, 1.0}, c);
  clipToHalfSpace(poly, scratch, {0.0, 0.0, -1.0}, c);
  const auto& k = frame.corners;
  for (int e = 0; e < 3 && !poly.empty(); ++e) {
    const glm::dvec2 a = k[size_t(e)], b = k[size_t((e + 1) % 3)],
                     opposite = k[size_t((e + 2) % 3)];
    glm::dvec2 outward = glm::normalize(glm::dvec2(b.y - a.y, a.x - b.x));
    if (glm::dot(outward, opposite - a) > 0.0) outward = -outward;
    clipToHalfSpace(poly, scratch, {outward, 0.0}, glm::dot(outward, a) - c);
  }
  return !poly.empty();
}

}  // namespace

BackFaceSolids backFaceSolids(const FlatTriangles& tris, const Solids& solids, const RayQuery& rays,
                              const BackFaceOptions& options) {
  VS_CHECK(std::isfinite(options.clearance) && options.clearance > 0.0);
  const size_t n = tris.size();
  BackFaceSolids out;
  out.solidOf.assign(n, kNoHit);

  // Orientation proof: the welded components come first in `floor`.
  const auto& components = solids.weldedComponents();
  out.floor.assign(components.size(), -std::numeric_limits<float>::infinity());
  for (size_t t = 0; t < n; ++t) {
    if (tris.degenerate[t]) continue;
    const uint32_t c = solids.weldedComponentOf(uint32_t(t));
    if (c != kNoHit && components[c].kind == SolidClass::ClosedOutward) {
      out.solidOf[t] = c;
      ++out.byOrientation;
    }
  }
  if (!options.parity || solids.enclosureCount() == 0) return out;

  const uint32_t enclosureBase = uint32_t(out.floor.size());
  for (uint32_t e = 0; e < solids.enclosureCount(); ++e)
    out.floor.push_back(solids.enclosureFloor(e));

  // The enclosures' triangles by X/Z cell, for the clearance test.
  std::vector<uint32_t> members;
  std::vector<Box3f> boxes;
  Box3f all;
  for (size_t t = 0; t < n; ++t) {
    if (tris.degenerate[t] || solids.enclosureOf(uint32_t(t)) == kNoHit) continue;
    members.push_back(uint32_t(t));
    boxes.push_back(tris.triangleBounds(t));
    all.extend(boxes.back());
  }
  if (members.empty()) return out;
  const float extent = std::max(all.hi.x - all.lo.x, all.hi.z - all.lo.z);
  const XzGrid grid(all, std::max(extent / 2048.0f, 0.5f), boxes);

  Polygon poly, scratch;
  for (size_t i = 0; i < members.size(); ++i) {
    const uint32_t t = members[i];
    if (out.solidOf[t] != kNoHit) continue;
    const uint32_t e = solids.enclosureOf(t);
    const TriangleFrame frame = frameOf(tris, t);
    const Box3f& tb = boxes[i];
    const float magnitude = std::max(glm::length(tb.lo), glm::length(tb.hi));
    const double c =
        std::max(options.clearance, 8.0 * double(std::nextafter(magnitude, INFINITY) - magnitude));
    if (!(frame.inradius > 2.0 * c)) continue;

    // (a) No other triangle of the enclosure near the shrunk triangle.
    bool clear = true;
    const float grow = float(c);
    const glm::vec3 lo = tb.lo - grow, hi = tb.hi + grow;
    grid.forEachItemNear({lo.x, lo.z}, {hi.x, hi.z}, [&](uint32_t j) {
      const uint32_t other = members[j];
      if (!clear || other == t || solids.enclosureOf(other) != e) return;
      const Box3f& ob = boxes[j];
      if (ob.lo.x > hi.x || ob.hi.x < lo.x || ob.lo.y > hi.y || ob.hi.y < lo.y || ob.lo.z > hi.z ||
          ob.hi.z < lo.z)
        return;
      if (comesClose(frame, tris, other, c, poly, scratch)) clear = false;
    });
    if (!clear) continue;

    // (b) Odd behind, even in front, both above the floor.
    const glm::dvec3 centre = frame.lift(frame.incentre);
    const glm::vec3 behind(centre - frame.n * (0.5 * c)), before(centre + frame.n * (0.5 * c));
    const float floorY = solids.enclosureFloor(e);
    if (!(behind.y > floorY)) continue;
    if (before.y > floorY && solids.enclosureVotes(rays, before, e) != 0) continue;
    if (2 * solids.enclosureVotes(rays, behind, e) <= kSolidTestDirections) continue;
    out.solidOf[t] = enclosureBase + e;
    ++out.byParity;
  }
  return out;
}

}  // namespace vistream
