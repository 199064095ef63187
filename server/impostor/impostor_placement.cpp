#include "server/impostor/impostor_placement.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <glm/gtc/constants.hpp>
#include <limits>

#include "common/core/error.h"

namespace vistream {
namespace {

std::array<glm::vec3, 8> cornersOf(const Box3f& b) {
  std::array<glm::vec3, 8> c;
  for (int k = 0; k < 8; ++k) c[size_t(k)] = b.corner(k);
  return c;
}

std::string boxText(const Box3f& b) {
  return fmt::format("{:.2f},{:.2f},{:.2f},{:.2f},{:.2f},{:.2f}", b.lo.x, b.lo.y, b.lo.z, b.hi.x,
                     b.hi.y, b.hi.z);
}

// The triangle of minimum circumference round `points` whose top edge lies on
// y = top (the points' highest y), apex below: the left side leans out by
// angle a from the vertical, the right side by b. For given angles the sides
// touch the points, so only the two angles are searched (a coarse grid, then
// a finer one round the best).
struct BoundingTriangle {
  glm::vec2 topLeft, topRight, apex;
  float perimeter = std::numeric_limits<float>::infinity();
};

BoundingTriangle triangleFor(const std::vector<glm::vec2>& points, float top, double a, double b) {
  const double ta = std::tan(a), tb = std::tan(b);
  double left = std::numeric_limits<double>::infinity();
  double right = -std::numeric_limits<double>::infinity();
  for (const glm::vec2& p : points) {
    const double below = double(top) - double(p.y);
    left = std::min(left, double(p.x) - below * ta);
    right = std::max(right, double(p.x) + below * tb);
  }
  const double depth = (right - left) / (ta + tb);
  BoundingTriangle t;
  t.topLeft = {float(left), top};
  t.topRight = {float(right), top};
  t.apex = {float(left + depth * ta), float(double(top) - depth)};
  t.perimeter = float((right - left) + depth / std::cos(a) + depth / std::cos(b));
  return t;
}

BoundingTriangle minimumTriangle(const std::vector<glm::vec2>& points, float top) {
  constexpr double kDeg = glm::pi<double>() / 180.0;
  BoundingTriangle best;
  double bestA = 0.0, bestB = 0.0;
  auto search = [&](double a0, double a1, double b0, double b1, double step) {
    for (double a = a0; a <= a1 + 1e-12; a += step)
      for (double b = b0; b <= b1 + 1e-12; b += step) {
        const BoundingTriangle t = triangleFor(points, top, a, b);
        if (t.perimeter < best.perimeter) {
          best = t;
          bestA = a;
          bestB = b;
        }
      }
  };
  search(2 * kDeg, 80 * kDeg, 2 * kDeg, 80 * kDeg, 2 * kDeg);
  const double ca = bestA, cb = bestB;
  search(std::max(1 * kDeg, ca - 2 * kDeg), std::min(85 * kDeg, ca + 2 * kDeg),
         std::max(1 * kDeg, cb - 2 * kDeg), std::min(85 * kDeg, cb + 2 * kDeg), 0.1 * kDeg);
  return best;
}

float circumradius(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
  const double ab = glm::length(glm::dvec3(b - a)), bc = glm::length(glm::dvec3(c - b)),
               ca = glm::length(glm::dvec3(a - c));
  const double twiceArea = glm::length(glm::cross(glm::dvec3(b - a), glm::dvec3(c - a)));
  return twiceArea > 0.0 ? float(ab * bc * ca / (2.0 * twiceArea)) : 0.0f;
}

}  // namespace

ImpostorFrame frameImpostor(const Box3f& cell, const Box3f& box) {
  if (cell.empty() || box.empty())
    throwInputError("impostor: empty {} box", cell.empty() ? "view cell" : "impostor");
  const glm::vec3 toBox = box.center() - cell.center();
  if (!(glm::dot(toBox, toBox) > 0.0f))
    throwInputError("impostor: box {} is centred on the view cell {}", boxText(box), boxText(cell));
  ImpostorFrame f;
  SamplingPlane& plane = f.plane;
  plane.normal = glm::normalize(toBox);
  glm::vec3 u = glm::cross(plane.normal, glm::vec3(0.0f, 1.0f, 0.0f));
  u = glm::dot(u, u) > 1e-6f ? glm::normalize(u) : glm::vec3(1.0f, 0.0f, 0.0f);
  const glm::vec3 v = glm::normalize(glm::cross(u, plane.normal));

  const auto cellCorners = cornersOf(cell), boxCorners = cornersOf(box);
  // Depths along the normal relative to the cell's centre (small numbers
  // even far from the origin).
  const glm::vec3 c0 = cell.center();
  float far = -std::numeric_limits<float>::infinity();
  for (const glm::vec3& c : cellCorners) far = std::max(far, glm::dot(plane.normal, c - c0));
  float nearest = std::numeric_limits<float>::infinity();
  for (const glm::vec3& b : boxCorners) nearest = std::min(nearest, glm::dot(plane.normal, b - c0));
  // A margin of a millimetre a kilometre of scene: the plane must separate.
  const float margin = 1e-6f * std::max(1.0f, glm::length(toBox));
  if (!(nearest > far + margin))
    throwInputError(
        "impostor: box {} reaches the view cell {} (its nearest corner is {:.3f} m beyond the "
        "cell's far side along the direction to it; it must lie wholly beyond)",
        boxText(box), boxText(cell), nearest - far);
  f.nearestDepth = nearest - far;
  f.centre = c0 + plane.normal * far;

  // The shaft's section: where segments from cell corners to box corners
  // cross the plane (cell corners on it are their own crossings).
  for (const glm::vec3& c : cellCorners)
    for (const glm::vec3& b : boxCorners) {
      const float dc = glm::dot(plane.normal, c - c0) - far;  // <= 0
      const float db = glm::dot(plane.normal, b - c0) - far;  // > 0
      const glm::vec3 q = c + (b - c) * (-dc / (db - dc));
      const glm::vec3 r = q - f.centre;
      f.section.emplace_back(glm::dot(r, u), glm::dot(r, v));
    }
  glm::vec2 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
  for (const glm::vec2& p : f.section) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::vec2 size = glm::max(hi - lo, glm::vec2(0.01f));
  plane.origin = f.centre + lo.x * u + lo.y * v;
  plane.uAxis = u * size.x;
  plane.vAxis = v * size.y;

  const BoundingTriangle t = minimumTriangle(f.section, hi.y);
  auto toWorld = [&](const glm::vec2& p) { return f.centre + p.x * u + p.y * v; };
  f.cameras = {toWorld(t.topLeft), toWorld(t.topRight), toWorld(t.apex)};
  f.trianglePerimeter = t.perimeter;
  f.circumradius = circumradius(f.cameras[0], f.cameras[1], f.cameras[2]);
  return f;
}

float ScreenSpec::pixelAngle() const {
  return 2.0f * std::tan(glm::radians(vfovDeg) * 0.5f) / float(height);
}

float ScreenSpec::sampleAngle() const {
  const float c = std::cos(glm::radians(vfovDeg) * 0.5f);
  const float perspective = 1.0f / (c * c);
  return pixelAngle() / (perspective * glm::root_two<float>());
}

float ldiPixelAngle(const ImpostorFrame& frame, const ScreenSpec& screen) {
  const float z = frame.nearestDepth, r = frame.circumradius;
  return screen.sampleAngle() * (z * z) / (r * r + z * z);
}

ImpostorPlacement placeImpostors(const Box3f& cell, const FlatTriangles& triangles,
                                 const std::vector<uint32_t>& pvsTriangles,
                                 const ImpostorPlacementOptions& options) {
  ImpostorPlacement out;
  const uint32_t sectors = std::max(1u, options.sectors), bands = std::max(1u, options.bands);
  std::vector<ImpostorSite> groups(size_t(sectors) * bands);
  const glm::vec3 c = cell.center();
  for (uint32_t t : pvsTriangles) {
    if (triangles.degenerate[t]) continue;
    const Box3f bounds = triangles.triangleBounds(t);
    const float distance = cell.distanceTo(bounds);
    if (!(distance >= options.nearDistance)) {
      ++out.nearTriangles;
      continue;
    }
    ++out.farTriangles;
    const glm::vec3 centroid =
        (triangles.vertex(t, 0) + triangles.vertex(t, 1) + triangles.vertex(t, 2)) / 3.0f;
    const float azimuth = std::atan2(centroid.x - c.x, -(centroid.z - c.z));  // 0 along -Z
    uint32_t sector =
        uint32_t((azimuth + glm::pi<float>()) / glm::two_pi<float>() * float(sectors));
    sector = std::min(sector, sectors - 1);
    uint32_t band = 0;
    for (float edge = 2.0f * options.nearDistance; band + 1 < bands && distance >= edge;
         edge *= 2.0f)
      ++band;
    ImpostorSite& g = groups[size_t(sector) * bands + band];
    g.sector = sector;
    g.band = band;
    g.triangles.push_back(t);
    g.box.extend(bounds);
  }
  for (ImpostorSite& g : groups) {
    if (g.triangles.empty()) continue;
    if (g.triangles.size() < options.minTriangles) {
      ++out.lightGroups;
      continue;
    }
    out.sites.push_back(std::move(g));
  }
  if (out.farTriangles == 0)
    out.why = fmt::format("no impostors: nothing of the PVS lies beyond d = {:.0f} m",
                          options.nearDistance);
  else if (out.sites.empty())
    out.why = fmt::format(
        "no impostors: {} far-field triangles beyond d = {:.0f} m, no sector and band with {} or "
        "more",
        out.farTriangles, options.nearDistance, options.minTriangles);
  else
    out.why = fmt::format(
        "{} impostor sites: {} far-field triangles beyond d = {:.0f} m, {} sector-bands with {} "
        "or more; {} lighter groups stay geometry",
        out.sites.size(), out.farTriangles, options.nearDistance, out.sites.size(),
        options.minTriangles, out.lightGroups);
  return out;
}

}  // namespace vistream
