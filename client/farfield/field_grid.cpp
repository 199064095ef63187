#include "client/farfield/field_grid.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace vistream {

FieldGrid::FieldGrid(const RenderGeometry& g, float cellSize) {
  triangles_ = g.size();
  bounds_ = g.bounds;
  if (g.size() == 0 || bounds_.empty()) {
    dims_ = {0, 0};
    cellStart_.assign(1, 0);
    return;
  }
  const glm::vec2 lo(bounds_.lo.x, bounds_.lo.z), hi(bounds_.hi.x, bounds_.hi.z);
  const glm::vec2 ext = glm::max(hi - lo, glm::vec2(1e-3f));
  cell_ = cellSize > 0.0f ? cellSize : std::max(4.0f, std::max(ext.x, ext.y) / 64.0f);
  lo_ = lo;
  dims_ = glm::max(glm::ivec2(glm::ceil(ext / cell_)), glm::ivec2(1));
  const size_t cells = size_t(dims_.x) * size_t(dims_.y);
  auto cellRange = [&](const Box3f& box, glm::ivec2& a, glm::ivec2& b) {
    a = glm::clamp(glm::ivec2(glm::floor((glm::vec2(box.lo.x, box.lo.z) - lo_) / cell_)),
                   glm::ivec2(0), dims_ - 1);
    b = glm::clamp(glm::ivec2(glm::floor((glm::vec2(box.hi.x, box.hi.z) - lo_) / cell_)),
                   glm::ivec2(0), dims_ - 1);
  };
  std::vector<uint32_t> count(cells + 1, 0);
  cellY_.assign(cells,
                glm::vec2(std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest()));
  for (size_t t = 0; t < g.size(); ++t) {
    glm::ivec2 a, b;
    const Box3f box = g.triangles.triangleBounds(t);
    cellRange(box, a, b);
    for (int z = a.y; z <= b.y; ++z)
      for (int x = a.x; x <= b.x; ++x) {
        const size_t c = size_t(z) * size_t(dims_.x) + size_t(x);
        ++count[c + 1];
        cellY_[c] = {std::min(cellY_[c].x, box.lo.y), std::max(cellY_[c].y, box.hi.y)};
      }
  }
  cellStart_.assign(cells + 1, 0);
  for (size_t c = 0; c < cells; ++c) cellStart_[c + 1] = cellStart_[c] + count[c + 1];
  items_.resize(cellStart_.back());
  std::vector<uint32_t> fill(cellStart_.begin(), cellStart_.end() - 1);
  for (size_t t = 0; t < g.size(); ++t) {
    glm::ivec2 a, b;
    cellRange(g.triangles.triangleBounds(t), a, b);
    for (int z = a.y; z <= b.y; ++z)
      for (int x = a.x; x <= b.x; ++x)
        items_[fill[size_t(z) * size_t(dims_.x) + size_t(x)]++] = uint32_t(t);
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
  if (dims_.x == 0) return;
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
  glm::ivec2 a(0), b = dims_ - 1;
  if (std::isfinite(d)) {
    a = glm::clamp(glm::ivec2(glm::floor((eye - d - lo_) / cell_)), glm::ivec2(0), dims_ - 1);
    b = glm::clamp(glm::ivec2(glm::floor((eye + d - lo_) / cell_)), glm::ivec2(0), dims_ - 1);
    if (eye.x + d < lo_.x || eye.y + d < lo_.y || eye.x - d > lo_.x + float(dims_.x) * cell_ ||
        eye.y - d > lo_.y + float(dims_.y) * cell_)
      return;
  }
  for (int z = a.y; z <= b.y; ++z)
    for (int x = a.x; x <= b.x; ++x) {
      const size_t c = size_t(z) * size_t(dims_.x) + size_t(x);
      if (cellStart_[c] == cellStart_[c + 1]) continue;
      const glm::vec2 clo = lo_ + glm::vec2(x, z) * cell_, chi = clo + cell_;
      if (std::isfinite(d)) {
        const glm::vec2 q = glm::clamp(eye, clo, chi);
        if (glm::length(q - eye) > d) continue;
      }
      if (frustum.outside({clo.x, cellY_[c].x, clo.y}, {chi.x, cellY_[c].y, chi.y})) continue;
      for (uint32_t i = cellStart_[c]; i < cellStart_[c + 1]; ++i) {
        const uint32_t t = items_[i];
        if (stamp[t] == stampValue) continue;
        stamp[t] = stampValue;
        out.push_back(t);
      }
    }
}

bool FieldGrid::anythingBeyond(const glm::vec3& eye, float d) const {
  if (dims_.x == 0) return false;
  const glm::vec2 e(eye.x, eye.z);
  for (int z = 0; z < dims_.y; ++z)
    for (int x = 0; x < dims_.x; ++x) {
      const size_t c = size_t(z) * size_t(dims_.x) + size_t(x);
      if (cellStart_[c] == cellStart_[c + 1]) continue;
      const glm::vec2 clo = lo_ + glm::vec2(x, z) * cell_, chi = clo + cell_;
      const glm::vec2 far = glm::max(glm::abs(clo - e), glm::abs(chi - e));
      if (glm::length(far) > d) return true;
    }
  return false;
}

}  // namespace vistream
