#include "client/farfield/horizon.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace vistream {
namespace {

constexpr float kLowest = -std::numeric_limits<float>::infinity();
constexpr int kMaxCells = 2048;

float azimuthOf(const glm::vec3& d) {
  return std::atan2(-d.x, -d.z);
}

float wrapAngle(float a) {
  while (a > std::numbers::pi_v<float>) a -= 2.0f * std::numbers::pi_v<float>;
  while (a < -std::numbers::pi_v<float>) a += 2.0f * std::numbers::pi_v<float>;
  return a;
}

}  // namespace

float HorizonMap::raySlope(const glm::vec3& d) {
  const float h = std::sqrt(d.x * d.x + d.z * d.z);
  if (h <= 0.0f) return d.y > 0.0f ? std::numeric_limits<float>::infinity() : kLowest;
  return d.y / h;
}

HorizonMap::HorizonMap(const RenderGeometry& g, float cellSize, const Box3f& cover) {
  Box3f bounds = g.bounds;
  if (g.size() == 0 || bounds.empty()) return;
  if (!cover.empty()) {
    bounds.extend(cover.lo);
    bounds.extend(cover.hi);
  }
  lo_ = {bounds.lo.x, bounds.lo.z};
  const glm::vec2 ext = glm::max(glm::vec2(bounds.hi.x, bounds.hi.z) - lo_, glm::vec2(1e-3f));
  // At most kMaxCells a side: the levels cost cells x log(cells) of memory.
  cell_ = std::max({cellSize, 0.01f, std::max(ext.x, ext.y) / float(kMaxCells)});
  dims_ = glm::max(glm::ivec2(glm::ceil(ext / cell_)), glm::ivec2(1));
  levels_.assign(1, std::vector<float>(size_t(dims_.x) * size_t(dims_.y), kLowest));
  maxHeight_ = kLowest;
  raiseClamped(g, 0, uint32_t(g.size()));
}

Box3f HorizonMap::extent() const {
  if (levels_.empty()) return {};
  const glm::vec2 hi = lo_ + glm::vec2(dims_) * cell_;
  return Box3f{{lo_.x, maxHeight_, lo_.y}, {hi.x, maxHeight_, hi.y}};
}

bool HorizonMap::raise(const RenderGeometry& g, uint32_t first, uint32_t count) {
  if (levels_.empty()) return count == 0;
  const glm::vec2 hi = lo_ + glm::vec2(dims_) * cell_;
  for (uint32_t t = first; t < first + count; ++t) {
    const Box3f box = g.triangles.triangleBounds(t);
    if (box.empty()) continue;
    // A triangle outside the map would be clamped into the border cells only
    // when the map is built from scratch: refuse, the caller builds a new one.
    if (box.lo.x < lo_.x || box.lo.z < lo_.y || box.hi.x > hi.x || box.hi.z > hi.y) return false;
  }
  raiseClamped(g, first, count);
  return true;
}

void HorizonMap::raiseClamped(const RenderGeometry& g, uint32_t first, uint32_t count) {
  std::vector<float>& base = levels_.front();
  for (uint32_t t = first; t < first + count; ++t) {
    const Box3f box = g.triangles.triangleBounds(t);
    if (box.empty()) continue;
    const glm::ivec2 a =
        glm::clamp(glm::ivec2(glm::floor((glm::vec2(box.lo.x, box.lo.z) - lo_) / cell_)),
                   glm::ivec2(0), dims_ - 1);
    const glm::ivec2 b =
        glm::clamp(glm::ivec2(glm::floor((glm::vec2(box.hi.x, box.hi.z) - lo_) / cell_)),
                   glm::ivec2(0), dims_ - 1);
    for (int z = a.y; z <= b.y; ++z)
      for (int x = a.x; x <= b.x; ++x) {
        float& h = base[size_t(z) * size_t(dims_.x) + size_t(x)];
        h = std::max(h, box.hi.y);
      }
    maxHeight_ = std::max(maxHeight_, box.hi.y);
  }
  buildLevels();
}

void HorizonMap::buildLevels() {
  levels_.resize(1);
  radius_.assign(1, 0);
  // Dilated levels: r_0 = 0, r_{k+1} = 2 r_k + 1, each the max of the previous
  // level shifted by -(r_k+1), 0, +(r_k+1) on each axis (separably).
  const int maxDim = std::max(dims_.x, dims_.y);
  // The widest level covers the whole grid from any cell within reach of it.
  while (radius_.back() < 2 * maxDim) {
    const int s = radius_.back() + 1;
    const std::vector<float>& prev = levels_.back();
    std::vector<float> tmp(prev.size()), next(prev.size());
    for (int z = 0; z < dims_.y; ++z)
      for (int x = 0; x < dims_.x; ++x) {
        float m = prev[size_t(z) * size_t(dims_.x) + size_t(x)];
        if (x - s >= 0) m = std::max(m, prev[size_t(z) * size_t(dims_.x) + size_t(x - s)]);
        if (x + s < dims_.x) m = std::max(m, prev[size_t(z) * size_t(dims_.x) + size_t(x + s)]);
        tmp[size_t(z) * size_t(dims_.x) + size_t(x)] = m;
      }
    for (int z = 0; z < dims_.y; ++z)
      for (int x = 0; x < dims_.x; ++x) {
        float m = tmp[size_t(z) * size_t(dims_.x) + size_t(x)];
        if (z - s >= 0) m = std::max(m, tmp[size_t(z - s) * size_t(dims_.x) + size_t(x)]);
        if (z + s < dims_.y) m = std::max(m, tmp[size_t(z + s) * size_t(dims_.x) + size_t(x)]);
        next[size_t(z) * size_t(dims_.x) + size_t(x)] = m;
      }
    levels_.push_back(std::move(next));
    radius_.push_back(2 * radius_.back() + 1);
  }
}

float HorizonMap::traceWedge(const glm::vec3& eye, float azimuth, float halfAngle,
                             float nearDistance, size_t& cells) const {
  const glm::vec2 e(eye.x, eye.z);
  const glm::vec2 dir(-std::sin(azimuth), -std::cos(azimuth));
  const float spread = std::tan(std::min(halfAngle, 1.5f));
  const int topLevel = int(levels_.size()) - 1;
  const float reachMax = float(radius_.back() + 1) * cell_;
  // The part of the ray within the grid's bounds grown by the widest reach.
  const glm::vec2 blo = lo_ - reachMax, bhi = lo_ + glm::vec2(dims_) * cell_ + reachMax;
  // Every point of the grown grid projects onto the ray within [t0, t1]: a
  // wedge reaches points beside the ray, so the ray itself is not clipped to
  // the grid but walked over the whole projected extent.
  float t0 = std::numeric_limits<float>::infinity(), t1 = 0.0f;
  for (int k = 0; k < 4; ++k) {
    const glm::vec2 corner((k & 1) ? bhi.x : blo.x, (k & 2) ? bhi.y : blo.y);
    const float t = glm::dot(corner - e, dir);
    t0 = std::min(t0, t);
    t1 = std::max(t1, t);
  }
  t0 = std::max(t0, 0.0f);
  if (t1 <= t0) return kLowest;
  // Amanatides-Woo over (virtual, unbounded) cells.
  const glm::vec2 start = e + dir * t0;
  glm::ivec2 c(glm::floor((start - lo_) / cell_));
  glm::ivec2 step;
  glm::vec2 tMax, tDelta;
  for (int a = 0; a < 2; ++a) {
    step[a] = dir[a] >= 0.0f ? 1 : -1;
    const float boundary = lo_[a] + float(c[a] + (step[a] > 0 ? 1 : 0)) * cell_;
    tMax[a] = std::abs(dir[a]) < 1e-12f ? std::numeric_limits<float>::infinity()
                                        : (boundary - e[a]) / dir[a];
    tDelta[a] = std::abs(dir[a]) < 1e-12f ? std::numeric_limits<float>::infinity()
                                          : cell_ / std::abs(dir[a]);
  }
  const float eyeY = eye.y;
  float best = kLowest;
  float tEnter = t0;
  while (tEnter <= t1) {
    const float tExit = std::min({tMax.x, tMax.y, t1});
    // Whatever is left cannot climb above best: stop.
    const float reachNow = reachMax * 1.4143f;
    const float rise = maxHeight_ - eyeY;
    const float lowerDist = std::max(nearDistance, tEnter - reachNow);
    const float bound = rise >= 0.0f ? (lowerDist > 0.0f ? rise / lowerDist
                                                         : std::numeric_limits<float>::infinity())
                                     : rise / (t1 + reachNow);
    if (bound <= best) break;
    ++cells;
    const float w = tExit * spread;
    int level = 0;
    while (level < topLevel && float(radius_[size_t(level)]) * cell_ < w) ++level;
    const int r = radius_[size_t(level)];
    const glm::ivec2 cc = glm::clamp(c, glm::ivec2(0), dims_ - 1);
    const bool inReach = c.x >= -r && c.y >= -r && c.x < dims_.x + r && c.y < dims_.y + r;
    if (inReach) {
      const float h = height(level, cc.x, cc.y);
      if (h > kLowest) {
        const glm::vec2 dlo = lo_ + glm::vec2(c - r) * cell_,
                        dhi = lo_ + glm::vec2(c + r + 1) * cell_;
        // Above the eye, the nearest point of the (dilated) cell climbs most
        // steeply; below it, the farthest point lies closest to the horizon.
        float slope;
        if (h > eyeY) {
          const float dist = std::max(nearDistance, glm::length(glm::clamp(e, dlo, dhi) - e));
          slope = dist > 0.0f ? (h - eyeY) / dist : std::numeric_limits<float>::infinity();
        } else {
          const glm::vec2 far = glm::max(glm::abs(dlo - e), glm::abs(dhi - e));
          slope = (h - eyeY) / std::max(glm::length(far), 1e-6f);
        }
        best = std::max(best, slope);
      }
    }
    if (tMax.x < tMax.y) {
      tEnter = tMax.x;
      tMax.x += tDelta.x;
      c.x += step.x;
    } else {
      tEnter = tMax.y;
      tMax.y += tDelta.y;
      c.y += step.y;
    }
  }
  return best;
}

std::vector<float> HorizonMap::trace(const Camera& camera, float nearDistance, int subsample,
                                     HorizonStats* stats) const {
  std::vector<float> slopes(size_t(camera.width), kLowest);
  if (dims_.x == 0) return slopes;
  const int k = std::max(1, subsample);
  const int groups = (camera.width + k - 1) / k;
  std::vector<size_t> cellCount(size_t(groups), 0);
  tbb::parallel_for(0, groups, [&](int gi) {
    const int x0 = gi * k, x1 = std::min(camera.width, x0 + k);  // columns [x0, x1)
    const glm::vec3 centreDir =
        camera.rayDirection(0.5f * float(x0 + x1), 0.5f * float(camera.height));
    const float centre = azimuthOf(centreDir);
    float lo = 0.0f, hi = 0.0f;
    for (float px : {float(x0), float(x1)})
      for (float py : {0.0f, float(camera.height)}) {
        const float a = wrapAngle(azimuthOf(camera.rayDirection(px, py)) - centre);
        lo = std::min(lo, a);
        hi = std::max(hi, a);
      }
    const float mid = centre + 0.5f * (lo + hi);
    const float half = 0.5f * (hi - lo) + 1e-5f;
    // A column that fans over more than about 140 degrees of azimuth (the
    // camera looks close to the zenith or nadir) cannot be traced as one
    // wedge: nothing in it is called sky.
    const float s = half > 1.2f
                        ? std::numeric_limits<float>::infinity()
                        : traceWedge(camera.eye, mid, half, nearDistance, cellCount[size_t(gi)]);
    for (int x = x0; x < x1; ++x) slopes[size_t(x)] = s;
  });
  if (stats) {
    stats->columnsTraced = size_t(groups);
    stats->cellsVisited = 0;
    for (size_t c : cellCount) stats->cellsVisited += c;
  }
  return slopes;
}

}  // namespace vistream
