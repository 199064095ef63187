#include "common/impostor/impostor.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

namespace vistream {

glm::vec2 SamplingPlane::textureCoordinates(const glm::vec3& eye, const glm::vec3& p) const {
  // eye + t (p - eye) on the plane: normal . (x - origin) = 0.
  const glm::vec3 d = p - eye;
  const float denominator = glm::dot(normal, d);
  glm::vec3 x = eye;
  if (std::abs(denominator) > 1e-12f * glm::dot(d, d))
    x = eye + d * (glm::dot(normal, origin - eye) / denominator);
  const glm::vec3 r = x - origin;
  return {glm::dot(r, uAxis) / glm::dot(uAxis, uAxis), glm::dot(r, vAxis) / glm::dot(vAxis, vAxis)};
}

glm::vec3 Impostor::colourAt(size_t k, const glm::vec2& st) const {
  const glm::u8vec3* t = texels.data() + firstTexel[k];
  if (singleColour[k]) return glm::vec3(t[0]);
  // Texel centres at (i + 0.5) / width: bilinear between them, clamped.
  const float x = std::clamp(st.x * float(textureWidth) - 0.5f, 0.0f, float(textureWidth - 1));
  const float y = std::clamp(st.y * float(textureHeight) - 0.5f, 0.0f, float(textureHeight - 1));
  const uint32_t i0 = std::min(uint32_t(x), textureWidth - 1);
  const uint32_t j0 = std::min(uint32_t(y), textureHeight - 1);
  const uint32_t i1 = std::min(i0 + 1, textureWidth - 1), j1 = std::min(j0 + 1, textureHeight - 1);
  const float fx = x - float(i0), fy = y - float(j0);
  auto at = [&](uint32_t i, uint32_t j) { return glm::vec3(t[j * textureWidth + i]); };
  return (at(i0, j0) * (1.0f - fx) + at(i1, j0) * fx) * (1.0f - fy) +
         (at(i0, j1) * (1.0f - fx) + at(i1, j1) * fx) * fy;
}

glm::vec3 Impostor::colourSeenFrom(size_t k, const glm::vec3& eye) const {
  if (singleColour[k]) return glm::vec3(texels[firstTexel[k]]);
  return colourAt(k, plane.textureCoordinates(eye, points[k]));
}

size_t Impostor::bytes() const {
  return points.size() * (12 + 4) + texels.size() * 3;
}

size_t Impostor::bytesUncompressed() const {
  return points.size() * (12 + 4 + size_t(textureTexels()) * 3);
}

std::array<uint32_t, 3> PointGrid::coordinates(const glm::vec3& p) const {
  const glm::vec3 w = p - centre;
  const float z = std::max(glm::dot(w, normal), 1e-30f);
  const glm::vec3 g(glm::dot(w, e1) / z, glm::dot(w, e2) / z, std::log(z));
  std::array<uint32_t, 3> q{};
  for (int a = 0; a < 3; ++a) {
    if (!(step[a] > 0.0f)) continue;
    const float f = std::round((g[a] - lo[a]) / step[a]);
    // NaN (a point at infinity) to 0, like anything below the range.
    q[size_t(a)] = f > 0.0f ? uint32_t(std::min(f, float(steps[size_t(a)]))) : 0u;
  }
  return q;
}

glm::vec3 PointGrid::point(const std::array<uint32_t, 3>& q) const {
  const glm::vec3 g = lo + glm::vec3(float(q[0]), float(q[1]), float(q[2])) * step;
  const float z = std::exp(g.z);
  return centre + z * (normal + g.x * e1 + g.y * e2);
}

namespace {

// v / |v|, computed on v scaled to its largest component; nothing when v is
// zero or not finite.
std::optional<glm::vec3> unitOf(const glm::vec3& v) {
  const float largest = std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)});
  if (!(largest > 0.0f) || !std::isfinite(largest)) return std::nullopt;
  const glm::vec3 scaled = v / largest;
  return scaled / glm::length(scaled);
}

}  // namespace

std::optional<PointGrid> Impostor::pointGrid() const {
  return PointGrid::of(cell, box, plane, angleStep, logDepthStep);
}

std::optional<PointGrid> PointGrid::of(const Box3f& cell, const Box3f& box,
                                       const SamplingPlane& plane, float angleStep,
                                       float logDepthStep) {
  PointGrid grid;
  grid.centre = cell.center();
  // The frame must be orthonormal to float precision, or a point's
  // coordinates would not give back the point: each axis is scaled to its
  // largest component before it is normalised, so that tiny (subnormal)
  // axes do not lose their length to underflow.
  // The frame is built in double: an axis that leans towards the normal
  // loses most of its bits to the subtraction below, and in float the
  // frame's error grows by the inverse of the sine between them.
  const std::optional<glm::vec3> n = unitOf(plane.normal);
  const std::optional<glm::vec3> uScaled = unitOf(plane.uAxis);
  if (!n || !uScaled) return std::nullopt;
  const glm::dvec3 nd = glm::normalize(glm::dvec3(*n));
  const glm::dvec3 ud = glm::dvec3(*uScaled) - glm::dot(glm::dvec3(*uScaled), nd) * nd;
  const double un = glm::length(ud);  // 0 to 1: the sine between the axis and the normal
  if (!(un > 1e-6)) return std::nullopt;
  const glm::dvec3 e1 = ud / un;
  grid.normal = glm::vec3(nd);
  grid.e1 = glm::vec3(e1);
  grid.e2 = glm::vec3(glm::cross(nd, e1));
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  for (int corner = 0; corner < 8; ++corner) {
    const glm::vec3 p((corner & 1) ? box.hi.x : box.lo.x, (corner & 2) ? box.hi.y : box.lo.y,
                      (corner & 4) ? box.hi.z : box.lo.z);
    const glm::vec3 w = p - grid.centre;
    const float z = glm::dot(w, grid.normal);
    // In front by more than float noise at the box's scale, and by a
    // millimetre at least (no impostor stands closer to its cell).
    if (!(z > 1e-4f * glm::length(w)) || !(z > 1e-3f)) return std::nullopt;
    const glm::vec3 g(glm::dot(w, grid.e1) / z, glm::dot(w, grid.e2) / z, std::log(z));
    lo = glm::min(lo, g);
    hi = glm::max(hi, g);
  }
  const auto finite = [](const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  };
  if (!finite(lo) || !finite(hi)) return std::nullopt;
  // Beyond about 83 degrees off the normal, the angles lose the precision
  // the grid promises (a float's error grows with the tangent's square).
  if (std::max({-lo.x, hi.x, -lo.y, hi.y}) > PointGrid::kMaxTangent) return std::nullopt;
  grid.lo = lo;
  const std::array<float, 3> wanted = {angleStep, angleStep, logDepthStep};
  const float finest = 1.0f / float((1u << PointGrid::kMaxBits) - 1);
  for (int a = 0; a < 3; ++a) {
    const float range = hi[a] - lo[a];
    if (!std::isfinite(range)) return std::nullopt;
    if (!(range > 0.0f)) continue;  // flat: one coordinate
    const float s =
        wanted[size_t(a)] > 0.0f ? std::max(wanted[size_t(a)], range * finest) : range / 65535.0f;
    const float count = std::ceil(range / s);
    if (!(s > 0.0f) || !std::isfinite(count)) return std::nullopt;  // steps below float's reach
    grid.step[a] = s;
    grid.steps[size_t(a)] = uint32_t(std::min(count, float((1u << PointGrid::kMaxBits) - 1)));
  }
  // Half a step of each coordinate at the farthest depth, along the longest
  // ray, with a margin for rounding.
  const float farthest = std::exp(hi.z);
  const float longest =
      std::sqrt(1.0f + std::max(lo.x * lo.x, hi.x * hi.x) + std::max(lo.y * lo.y, hi.y * hi.y));
  grid.slack = 1.01f * (farthest * (std::exp(0.5f * grid.step.z) - 1.0f) * longest +
                        farthest * 0.5f * (grid.step.x + grid.step.y)) +
               1e-5f * glm::length(box.extent()) +
               1e-6f * (glm::length(grid.centre) + glm::length(box.hi - grid.centre));
  if (!std::isfinite(grid.slack)) return std::nullopt;
  return grid;
}

uint8_t Impostor::levelIndex(uint8_t v, uint32_t step) {
  return step <= 1 ? v : uint8_t((uint32_t(v) + step / 2) / step);
}

uint8_t Impostor::levelOf(uint32_t index, uint32_t step) {
  return uint8_t(std::min<uint32_t>(255, index * std::max(step, 1u)));
}

uint8_t Impostor::snapLevel(uint8_t v, uint32_t step) {
  return levelOf(levelIndex(v, step), step);
}

void Impostor::quantize() {
  if (const std::optional<PointGrid> grid = pointGrid())
    for (glm::vec3& p : points) p = grid->point(grid->coordinates(p));
  if (colourStep > 1)
    for (size_t k = 0; k < points.size(); ++k) {
      if (singleColour[k]) continue;
      glm::u8vec3* t = texels.data() + firstTexel[k];
      for (uint32_t i = 0; i < textureTexels(); ++i)
        for (int c = 0; c < 3; ++c) t[i][c] = snapLevel(t[i][c], colourStep);
    }
  boundBlocks();
}

void Impostor::boundBlocks() {
  blockBounds.assign(blockCount(), Box3f{});
  for (size_t k = 0; k < points.size(); ++k) blockBounds[k / kBlockPoints].extend(points[k]);
}

void Impostor::appendPoint(const glm::vec3& p, const glm::u8vec3* colours, bool single) {
  points.push_back(p);
  firstTexel.push_back(uint32_t(texels.size()));
  singleColour.push_back(single ? 1 : 0);
  texels.insert(texels.end(), colours, colours + (single ? 1 : textureTexels()));
}

}  // namespace vistream
