#include "client/farfield/field_grid.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace vistream {

FieldGrid::FieldGrid(const RenderGeometry& g, float cellSize) {
  triangles_ = g.size();
  bounds_ = g.bounds;
  if (g.size() == 0 || bounds_.empty()) return;
  const glm::vec2 ext = glm::max(
      glm::vec2(bounds_.hi.x - bounds_.lo.x, bounds_.hi.z - bounds_.lo.z), glm::vec2(1e-3f));
  const float cell = cellSize > 0.0f && std::isfinite(cellSize)
                         ? cellSize
                         : std::max(4.0f, std::max(ext.x, ext.y) / 64.0f);
  std::vector<Box3f> boxes(g.size());
  for (size_t t = 0; t < g.size(); ++t) boxes[t] = g.triangles.triangleBounds(t);
  grid_ = XzGrid(bounds_, cell, boxes);
  const glm::ivec2 dims = grid_.dims();
  cellY_.assign(size_t(dims.x) * size_t(dims.y),
                glm::vec2(std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest()));
  for (int z = 0; z < dims.y; ++z)
    for (int x = 0; x < dims.x; ++x) {
      glm::vec2& y = cellY_[size_t(z) * size_t(dims.x) + size_t(x)];
      for (uint32_t t : grid_.itemsIn({x, z}))
        y = {std::min(y.x, boxes[t].lo.y), std::max(y.y, boxes[t].hi.y)};
    }
}

namespace {

// Conservative box-outside-frustum test against the four side planes and the near plane.
struct Frustum {
  std::array<glm::vec4, 5> planes;  // inside: dot(plane.xyz, p) + plane.w >= 0
  explicit Frustum(const Camera& c) {
    const glm::mat4 m = c.viewProjection();
    const glm::vec4 r0(m[0][0], m[1][0], m[2][0], m[3][0]), r1(m[0][1], m[1][1], m[2][1], m[3][1]),
        r2(m[0][2], m[1][2], m[2][2], m[3][2]), r3(m[0][3], m[1][3], m[2][3], m[3][3]);
    planes = {r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 + r2};
    for (glm::vec4& p : planes) p /= glm::length(glm::vec3(p));
  }
  bool outside(const glm::vec3& lo, const glm::vec3& hi) const {
    for (const glm::vec4& p : planes) {
      const glm::vec3 far(p.x >= 0 ? hi.x : lo.x, p.y >= 0 ? hi.y : lo.y, p.z >= 0 ? hi.z : lo.z);
      if (glm::dot(glm::vec3(p), far) + p.w < -1e-3f) return true;
    }
    return false;
  }
};

}  // namespace

void FieldGrid::nearField(const Camera& camera, float d, std::vector<uint32_t>& out,
                          std::vector<uint32_t>& stamp, uint32_t& stampValue) const {
  out.clear();
  if (grid_.empty()) return;
  if (stamp.size() != triangles_) {
    stamp.assign(triangles_, 0);
    stampValue = 0;
  }
  if (++stampValue == 0) {
    std::fill(stamp.begin(), stamp.end(), 0);
    stampValue = 1;
  }
  const Frustum frustum(camera);
  const glm::vec2 eye(camera.eye.x, camera.eye.z);
  const glm::ivec2 dims = grid_.dims();
  const glm::vec2 lo = grid_.lo();
  const float cell = grid_.cellSize();
  XzGrid::CellRange range{glm::ivec2(0), dims - 1};
  if (std::isfinite(d)) {
    range = grid_.cellsOverlapping(eye - d, eye + d);
    if (eye.x + d < lo.x || eye.y + d < lo.y || eye.x - d > lo.x + float(dims.x) * cell ||
        eye.y - d > lo.y + float(dims.y) * cell)
      return;
  }
  for (int z = range.lo.y; z <= range.hi.y; ++z)
    for (int x = range.lo.x; x <= range.hi.x; ++x) {
      const std::span<const uint32_t> items = grid_.itemsIn({x, z});
      if (items.empty()) continue;
      const size_t c = size_t(z) * size_t(dims.x) + size_t(x);
      const glm::vec2 clo = grid_.cellLo({x, z}), chi = clo + cell;
      if (std::isfinite(d)) {
        const glm::vec2 q = glm::clamp(eye, clo, chi);
        if (glm::length(q - eye) > d) continue;
      }
      if (frustum.outside({clo.x, cellY_[c].x, clo.y}, {chi.x, cellY_[c].y, chi.y})) continue;
      for (const uint32_t t : items) {
        if (stamp[t] == stampValue) continue;
        stamp[t] = stampValue;
        out.push_back(t);
      }
    }
}

bool FieldGrid::anythingBeyond(const glm::vec3& eye, float d) const {
  if (grid_.empty()) return false;
  const glm::vec2 e(eye.x, eye.z);
  const glm::ivec2 dims = grid_.dims();
  for (int z = 0; z < dims.y; ++z)
    for (int x = 0; x < dims.x; ++x) {
      if (grid_.itemsIn({x, z}).empty()) continue;
      const glm::vec2 clo = grid_.cellLo({x, z}), chi = clo + grid_.cellSize();
      const glm::vec2 far = glm::max(glm::abs(clo - e), glm::abs(chi - e));
      if (glm::length(far) > d) return true;
    }
  return false;
}

}  // namespace vistream
