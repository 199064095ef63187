#include "client/farfield/field_grid.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "common/core/check.h"

namespace vistream {

namespace {
constexpr glm::vec2 kNoY(std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest());
}  // namespace

FieldGrid::FieldGrid(const RenderGeometry& g, float cellSize) {
  const Box3f bounds = g.bounds;
  const glm::vec2 ext =
      bounds.empty() ? glm::vec2(0.0f)
                     : glm::max(glm::vec2(bounds.hi.x - bounds.lo.x, bounds.hi.z - bounds.lo.z),
                                glm::vec2(1e-3f));
  const float cell = cellSize > 0.0f && std::isfinite(cellSize)
                         ? cellSize
                         : std::max(4.0f, std::max(ext.x, ext.y) / 64.0f);
  // Cells for the whole extent (64 x 64 at the automatic size), so a
  // scene's grid never hits the limit a streamed one may.
  const size_t cells = size_t(std::ceil(ext.x / cell) + 2) * size_t(std::ceil(ext.y / cell) + 2);
  grid_ = DynamicXzGrid(cell, std::max(cells, size_t(1) << 20));
  VS_CHECK(add(g, 0, uint32_t(g.size())));
}

void FieldGrid::followGrowth(glm::ivec2 oldOrigin, glm::ivec2 oldDims) {
  const glm::ivec2 dims = grid_.dims();
  std::vector<glm::vec2> y(size_t(dims.x) * size_t(dims.y), kNoY);
  for (int z = 0; z < oldDims.y; ++z)
    for (int x = 0; x < oldDims.x; ++x) {
      const glm::ivec2 to = oldOrigin + glm::ivec2(x, z) - grid_.origin();
      y[size_t(to.y) * size_t(dims.x) + size_t(to.x)] =
          cellY_[size_t(z) * size_t(oldDims.x) + size_t(x)];
    }
  cellY_ = std::move(y);
}

bool FieldGrid::add(const RenderGeometry& g, uint32_t first, uint32_t count) {
  VS_CHECK_LE(size_t(first) + count, g.size());
  triangles_ = g.size();
  for (uint32_t t = first; t < first + count; ++t) {
    const Box3f box = g.triangles.triangleBounds(t);
    const glm::ivec2 origin = grid_.origin(), dims = grid_.dims();
    if (!grid_.insert(t, box)) return false;
    if (grid_.origin() != origin || grid_.dims() != dims) followGrowth(origin, dims);
    if (box.empty()) continue;
    const XzGrid::CellRange r = grid_.cellsOverlapping({box.lo.x, box.lo.z}, {box.hi.x, box.hi.z});
    for (int z = r.lo.y; z <= r.hi.y; ++z)
      for (int x = r.lo.x; x <= r.hi.x; ++x) {
        glm::vec2& y = cellY({x, z});
        y = {std::min(y.x, box.lo.y), std::max(y.y, box.hi.y)};
      }
  }
  return true;
}

void FieldGrid::remove(const RenderGeometry& g, std::span<const uint32_t> triangles) {
  std::vector<glm::ivec2> touched;
  for (const uint32_t t : triangles) {
    const Box3f box = g.triangles.triangleBounds(t);
    grid_.erase(t, box);
    if (box.empty() || grid_.empty()) continue;
    const XzGrid::CellRange r = grid_.cellsOverlapping({box.lo.x, box.lo.z}, {box.hi.x, box.hi.z});
    for (int z = r.lo.y; z <= r.hi.y; ++z)
      for (int x = r.lo.x; x <= r.hi.x; ++x) touched.push_back({x, z});
  }
  std::sort(touched.begin(), touched.end(),
            [](glm::ivec2 a, glm::ivec2 b) { return a.y != b.y ? a.y < b.y : a.x < b.x; });
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  // The Y range of a cell shrinks only with its triangles: recompute it there.
  for (const glm::ivec2 c : touched) {
    glm::vec2& y = cellY(c);
    y = kNoY;
    for (const uint32_t t : grid_.itemsIn(c)) {
      const Box3f box = g.triangles.triangleBounds(t);
      y = {std::min(y.x, box.lo.y), std::max(y.y, box.hi.y)};
    }
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
