#include "server/impostor/impostor_bake.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <glm/gtc/constants.hpp>
#include <limits>
#include <unordered_set>

#include "common/core/check.h"
#include "common/core/error.h"
#include "common/core/random.h"
#include "common/core/timer.h"
#include "protocol/impostor/impostor_codec.h"

namespace vistream {
namespace {

// How near another camera's sample must lie, in that camera's sample
// spacings, for a point to be dropped in its favour (point removal): half a
// grid step's diagonal and a margin for the grid's bending on a surface
// seen in perspective.
constexpr float kCoverReach = 0.75f;
// Thinning a camera's own samples on a surface: it thins where its spacing
// times kThinFactor (sqrt 2 and a margin for the spacing's change across a
// surface seen in perspective) is still sufficient, and a neighbour in the
// LDI counts when it lies within kThinReach of its spacing (a step, and the
// same margin).
constexpr float kThinFactor = 1.4142136f * 1.05f;
constexpr float kThinReach = 1.25f;

// One LDI hit: a candidate point.
struct Sample {
  glm::vec3 position;
  uint32_t triangle;  // into ImpostorScene::triangles
  float u, v;         // barycentrics on it
  uint8_t camera;
};

// The part [t0, t1] of the ray org + t dir inside `box`; empty if t0 > t1.
std::pair<float, float> clipToBox(const glm::vec3& org, const glm::vec3& dir, const Box3f& box) {
  float t0 = 0.0f, t1 = std::numeric_limits<float>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (dir[a] == 0.0f) {
      if (org[a] < box.lo[a] || org[a] > box.hi[a]) return {1.0f, 0.0f};
      continue;
    }
    const float inv = 1.0f / dir[a];
    float near = (box.lo[a] - org[a]) * inv, far = (box.hi[a] - org[a]) * inv;
    if (near > far) std::swap(near, far);
    t0 = std::max(t0, near);
    t1 = std::min(t1, far);
  }
  return {t0, t1};
}

glm::vec3 unitNormal(const FlatTriangles& t, uint32_t k) {
  const glm::vec3 a = t.vertex(k, 0);
  const glm::vec3 n = glm::cross(t.vertex(k, 1) - a, t.vertex(k, 2) - a);
  const float len = glm::length(n);
  return len > 0.0f ? n / len : glm::vec3(0.0f, 1.0f, 0.0f);
}

// An LDI camera: at `eye`, looking along the plane's normal, its image
// window [x0, x0 + width * pixel] x [y0, y0 + height * pixel] in tangent
// units along the plane's (u, v) axes.
struct LdiCamera {
  glm::vec3 eye;
  float x0 = 0, y0 = 0, pixel = 0;
  uint32_t width = 0, height = 0;
};

LdiCamera ldiCamera(const glm::vec3& eye, const ImpostorFrame& frame, const Box3f& box,
                    float pixel) {
  const glm::vec3 n = frame.plane.normal, u = glm::normalize(frame.plane.uAxis),
                  v = glm::normalize(frame.plane.vAxis);
  glm::vec2 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
  for (int k = 0; k < 8; ++k) {
    const glm::vec3 w = box.corner(k) - eye;
    const float z = glm::dot(w, n);  // > 0: the box lies beyond the plane
    const glm::vec2 xy(glm::dot(w, u) / z, glm::dot(w, v) / z);
    lo = glm::min(lo, xy);
    hi = glm::max(hi, xy);
  }
  LdiCamera c;
  c.eye = eye;
  c.pixel = pixel;
  // Half a pixel of margin round the window, so the box's rim is sampled.
  c.x0 = lo.x - 0.5f * pixel;
  c.y0 = lo.y - 0.5f * pixel;
  c.width = uint32_t(std::ceil((hi.x - lo.x) / pixel)) + 1;
  c.height = uint32_t(std::ceil((hi.y - lo.y) / pixel)) + 1;
  return c;
}

// Camera j's sample spacing on the surface with unit normal `normal` at p.
float sampleSpacing(const LdiCamera& c, const glm::vec3& axis, const glm::vec3& p,
                    const glm::vec3& normal) {
  const glm::vec3 w = p - c.eye;
  const float length = glm::length(w);
  const float z = glm::dot(w, axis);
  const float slant = std::abs(glm::dot(normal, w)) / std::max(length, 1e-20f);
  return c.pixel * z / std::max(slant, 1e-4f);
}

// The point of segment (a, b) nearest to c, as the parameter along it.
float nearestOnSegment(const glm::vec2& a, const glm::vec2& b, const glm::vec2& c) {
  const glm::vec2 d = b - a;
  const float len2 = glm::dot(d, d);
  return len2 > 0.0f ? std::clamp(glm::dot(c - a, d) / len2, 0.0f, 1.0f) : 0.0f;
}

// Adds, for every triangle of `own` and every LDI pixel of camera `c` that
// the triangle's projection comes within half a pixel diagonal of but whose
// centre ray met nothing (`empty`), one point: the point of the triangle's
// edges whose projection lies nearest the pixel's centre (perspective-correct
// along the edge). The pixel is then no longer empty. Such pixels lie on the
// triangle's projected edges (a pixel whose centre the projection holds saw
// the triangle), so the edges are walked, half a pixel at a time, looking at
// each visited pixel and its eight neighbours.
uint64_t addThinSamples(const LdiCamera& c, const glm::vec3& axis, const glm::vec3& uDir,
                        const glm::vec3& vDir, const FlatTriangles& own,
                        const std::vector<uint32_t>& sceneIndex, const Box3f& box, uint8_t camera,
                        std::vector<uint8_t>& empty, std::vector<Sample>& samples) {
  uint64_t added = 0;
  const float reach2 = 0.5f + 1e-4f;  // (half the pixel diagonal)^2, in pixels
  for (size_t t = 0; t < own.size(); ++t) {
    if (own.degenerate[t]) continue;
    std::array<glm::vec3, 3> p;
    std::array<glm::vec2, 3> q;  // in LDI pixels
    std::array<float, 3> z;
    bool behind = false;
    for (int k = 0; k < 3; ++k) {
      p[size_t(k)] = own.vertex(t, k);
      const glm::vec3 w = p[size_t(k)] - c.eye;
      z[size_t(k)] = glm::dot(w, axis);
      if (!(z[size_t(k)] > 0.0f)) behind = true;
      q[size_t(k)] = {(glm::dot(w, uDir) / z[size_t(k)] - c.x0) / c.pixel,
                      (glm::dot(w, vDir) / z[size_t(k)] - c.y0) / c.pixel};
    }
    if (behind) continue;
    auto tryPixel = [&](int64_t x, int64_t y) {
      if (x < 0 || y < 0 || x >= int64_t(c.width) || y >= int64_t(c.height)) return;
      uint8_t& e = empty[size_t(y) * c.width + size_t(x)];
      if (!e) return;
      const glm::vec2 centre(float(x) + 0.5f, float(y) + 0.5f);
      float best = std::numeric_limits<float>::infinity();
      glm::vec3 point(0.0f);
      for (int k = 0; k < 3; ++k) {
        const size_t a = size_t(k), b = size_t((k + 1) % 3);
        const float s = nearestOnSegment(q[a], q[b], centre);
        const glm::vec2 at = q[a] + s * (q[b] - q[a]);
        const float d2 = glm::dot(at - centre, at - centre);
        if (d2 < best) {
          best = d2;
          // Projected parameter s is 3D parameter s z_a / (s z_a + (1 - s) z_b).
          const float denominator = s * z[a] + (1.0f - s) * z[b];
          const float s3 = denominator > 0.0f ? s * z[a] / denominator : s;
          point = p[a] + s3 * (p[b] - p[a]);
        }
      }
      if (!(best <= reach2) || !box.contains(point)) return;
      e = 0;
      // Barycentrics of the point (for a fallback colour).
      const glm::vec3 e1 = p[1] - p[0], e2 = p[2] - p[0], r = point - p[0];
      const float d11 = glm::dot(e1, e1), d12 = glm::dot(e1, e2), d22 = glm::dot(e2, e2);
      const float r1 = glm::dot(r, e1), r2 = glm::dot(r, e2);
      const float det = d11 * d22 - d12 * d12;
      const float u = det > 0.0f ? (d22 * r1 - d12 * r2) / det : 0.0f;
      const float v = det > 0.0f ? (d11 * r2 - d12 * r1) / det : 0.0f;
      samples.push_back({point, sceneIndex[t], u, v, camera});
      ++added;
    };
    for (int k = 0; k < 3; ++k) {
      const glm::vec2 a = q[size_t(k)], b = q[size_t((k + 1) % 3)];
      const float length = glm::length(b - a);
      if (!(length < 1e7f)) continue;
      const int steps = int(std::ceil(length * 2.0f)) + 1;
      for (int i = 0; i <= steps; ++i) {
        const glm::vec2 at = a + (b - a) * (float(i) / float(steps));
        const int64_t x = int64_t(std::floor(at.x)), y = int64_t(std::floor(at.y));
        if (x < -1 || y < -1 || x > int64_t(c.width) || y > int64_t(c.height)) continue;
        for (int64_t dy = -1; dy <= 1; ++dy)
          for (int64_t dx = -1; dx <= 1; ++dx) tryPixel(x + dx, y + dy);
      }
    }
  }
  return added;
}

}  // namespace

ScreenCoverage screenCoverage(const std::vector<glm::vec3>& points, const glm::vec3& eye,
                              const glm::vec3& target, const ScreenSpec& screen) {
  ScreenCoverage out;
  if (points.empty()) return out;
  const glm::vec3 forward = glm::normalize(target - eye);
  glm::vec3 right = glm::cross(forward, glm::vec3(0.0f, 1.0f, 0.0f));
  right = glm::dot(right, right) > 1e-6f ? glm::normalize(right) : glm::vec3(1.0f, 0.0f, 0.0f);
  const glm::vec3 up = glm::cross(right, forward);
  const float pixel = screen.pixelAngle();
  std::vector<uint64_t> keys;
  keys.reserve(points.size());
  int64_t x0 = std::numeric_limits<int64_t>::max(), x1 = std::numeric_limits<int64_t>::min();
  int64_t y0 = x0, y1 = x1;
  for (const glm::vec3& p : points) {
    const glm::vec3 w = p - eye;
    const float z = glm::dot(w, forward);
    if (!(z > 0.0f)) continue;
    const int64_t x = int64_t(std::floor(glm::dot(w, right) / z / pixel));
    const int64_t y = int64_t(std::floor(glm::dot(w, up) / z / pixel));
    x0 = std::min(x0, x);
    x1 = std::max(x1, x);
    y0 = std::min(y0, y);
    y1 = std::max(y1, y);
    keys.push_back((uint64_t(uint32_t(int32_t(x))) << 32) | uint32_t(int32_t(y)));
  }
  if (keys.empty()) return out;
  std::sort(keys.begin(), keys.end());
  out.pixels = uint64_t(std::unique(keys.begin(), keys.end()) - keys.begin());
  out.boxPixels = uint64_t(x1 - x0 + 1) * uint64_t(y1 - y0 + 1);
  return out;
}

Impostor bakeImpostor(const ImpostorScene& scene, const Box3f& cell, const Box3f& box,
                      const std::vector<uint32_t>& triangles, const ImpostorOptions& options,
                      ImpostorStats* statsOut) {
  std::optional<Impostor> imp =
      bakeImpostorWithin(scene, cell, box, triangles, options, 0, statsOut);
  VS_CHECK(imp.has_value());
  return std::move(*imp);
}

std::optional<Impostor> bakeImpostorWithin(const ImpostorScene& scene, const Box3f& cell,
                                           const Box3f& box, const std::vector<uint32_t>& triangles,
                                           const ImpostorOptions& options, uint64_t maxBytes,
                                           ImpostorStats* statsOut) {
  if (!(options.resolutionFactor > 0.0f))
    throwInputError("impostor: the resolution factor must be positive");
  if (!(options.pixelFilterSigma >= 0.0f) || !std::isfinite(options.pixelFilterSigma))
    throwInputError("impostor: the pixel filter's sigma must be a non-negative number, got {}",
                    options.pixelFilterSigma);
  if (options.textureWidth == 0 || options.textureHeight == 0 || options.textureWidth > 64 ||
      options.textureHeight > 64)
    throwInputError("impostor: texture size {}x{} (each side 1 to 64)", options.textureWidth,
                    options.textureHeight);
  if (!(options.positionError >= 0.0f) || !std::isfinite(options.positionError))
    throwInputError("impostor: the position error must be a non-negative number of pixels, got {}",
                    options.positionError);
  if (!Impostor::isColourStep(options.colourStep))
    throwInputError("impostor: colour step {} (1, 2, 4, 8 or 16)", options.colourStep);
  Stopwatch total;
  ImpostorStats stats;
  const ImpostorFrame frame = frameImpostor(cell, box);
  if (!PointGrid::of(cell, box, frame.plane, 0.0f, 0.0f))
    throwInputError(
        "impostor: the box reaches more than {:.0f} degrees off the sampling plane's normal seen "
        "from the cell's centre (too wide for its points' grid)",
        glm::degrees(std::atan(PointGrid::kMaxTangent)));
  const glm::vec3 axis = frame.plane.normal;
  const glm::vec3 uDir = glm::normalize(frame.plane.uAxis),
                  vDir = glm::normalize(frame.plane.vAxis);
  const float pixel = ldiPixelAngle(frame, options.screen) / options.resolutionFactor;
  stats.ldiPixelAngle = pixel;
  std::array<LdiCamera, 3> cameras;
  uint64_t ldiPixels = 0;
  for (size_t k = 0; k < 3; ++k) {
    cameras[k] = ldiCamera(frame.cameras[k], frame, box, pixel);
    stats.ldiWidth[k] = cameras[k].width;
    stats.ldiHeight[k] = cameras[k].height;
    ldiPixels += uint64_t(cameras[k].width) * cameras[k].height;
  }
  if (ldiPixels > options.maxLdiPixels)
    throwInputError(
        "impostor: box {:.0f}x{:.0f}x{:.0f} m at {:.1f} m needs {} LDI pixels (limit {}); lower "
        "the resolution factor or use a smaller box",
        box.extent().x, box.extent().y, box.extent().z, frame.nearestDepth, ldiPixels,
        options.maxLdiPixels);

  // The impostor's own triangles, for the LDI rays and the points' z-buffer.
  FlatTriangles own;
  own.positions.reserve(triangles.size() * 3);
  for (uint32_t t : triangles) {
    for (int k = 0; k < 3; ++k) own.positions.push_back(scene.triangles.vertex(t, k));
    own.faceIds.push_back(scene.triangles.faceIds[t]);
    own.objectIds.push_back(scene.triangles.objectIds[t]);
    own.degenerate.push_back(scene.triangles.degenerate[t]);
  }
  const std::unique_ptr<RayQuery> ownRays = makeEmbreeRayQuery(own);

  // Geometric sampling: three LDIs, every layer inside the box.
  Stopwatch watch;
  std::vector<Sample> samples;
  for (uint8_t k = 0; k < 3; ++k) {
    const LdiCamera& c = cameras[k];
    std::vector<std::vector<Sample>> rows(c.height);
    std::vector<uint8_t> empty(size_t(c.width) * c.height, 1);  // centre ray met nothing
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, c.height), [&](const auto& range) {
      std::vector<Hit> hits;
      for (uint32_t y = range.begin(); y != range.end(); ++y) {
        std::vector<Sample>& row = rows[y];
        const float ty = c.y0 + (float(y) + 0.5f) * c.pixel;
        for (uint32_t x = 0; x < c.width; ++x) {
          const float tx = c.x0 + (float(x) + 0.5f) * c.pixel;
          const glm::vec3 dir = axis + tx * uDir + ty * vDir;
          const auto [t0, t1] = clipToBox(c.eye, dir, box);
          if (t0 > t1) continue;
          hits.clear();
          ownRays->allHits(Ray{c.eye, dir, t0, t1}, hits);
          float lastT = -1.0f;
          uint32_t layers = 0;
          for (const Hit& h : hits) {
            // A ray through an edge hits both triangles at one depth: one point.
            if (h.t - lastT <= 1e-6f * h.t) continue;
            lastT = h.t;
            row.push_back({c.eye + dir * h.t, triangles[h.triangle], h.u, h.v, k});
            if (++layers == options.maxLayers) break;
          }
          if (layers) empty[size_t(y) * c.width + x] = 0;
        }
      }
    });
    // Thin geometry: a triangle that overlaps an LDI pixel whose centre ray
    // met nothing (a pole narrower than a pixel against the sky) gets one
    // point there, so no viewer sees it without a point near it.
    for (auto& row : rows) samples.insert(samples.end(), row.begin(), row.end());
    stats.thinSamples +=
        addThinSamples(c, axis, uDir, vDir, own, triangles, box, k, empty, samples);
  }
  stats.samples = samples.size();
  stats.sampleSeconds = watch.ms() / 1000.0;

  // Hidden points: kept when some viewpoint in the cell sees them.
  watch.reset();
  auto visibleFrom = [&](const glm::vec3& eye, const glm::vec3& p) {
    const glm::vec3 w = p - eye;
    const float distance = glm::length(w);
    const float slack = std::max(1e-4f, 0.01f / std::max(distance, 1e-3f));
    return !ownRays->occluded(Ray{eye, w, 0.0f, 1.0f - slack});
  };
  if (options.cullHidden && options.visibilityViews > 0) {
    const uint32_t views = options.visibilityViews;
    const uint32_t grid = std::max(1u, uint32_t(std::cbrt(double(views)) + 1e-9));
    std::vector<uint8_t> keep(samples.size(), 0);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size(), 256), [&](const auto& range) {
      for (size_t i = range.begin(); i != range.end(); ++i) {
        SplitMix rng(mixBits(options.seed ^ 0x5eedf00dULL ^ mixBits(i)));
        for (uint32_t v = 0; v < views && !keep[i]; ++v) {
          // First a jittered grid over the cell, then random viewpoints.
          glm::vec3 f;
          if (v < grid * grid * grid) {
            const glm::uvec3 cellOfGrid(v % grid, (v / grid) % grid, v / (grid * grid));
            f = (glm::vec3(cellOfGrid) +
                 glm::vec3(float(rng.uniform()), float(rng.uniform()), float(rng.uniform()))) /
                float(grid);
          } else {
            f = glm::vec3(float(rng.uniform()), float(rng.uniform()), float(rng.uniform()));
          }
          if (visibleFrom(cell.lo + f * cell.extent(), samples[i].position)) keep[i] = 1;
        }
      }
    });
    size_t kept = 0;
    for (size_t i = 0; i < samples.size(); ++i)
      if (keep[i]) samples[kept++] = samples[i];
    stats.hidden = samples.size() - kept;
    samples.resize(kept);
  }
  stats.hiddenSeconds = watch.ms() / 1000.0;

  // Point removal: drop a point that another camera samples better and
  // sufficiently, and has a sample beside.
  watch.reset();
  if (options.removePoints) {
    // The spacing the LDIs were sized for: the resolution factor scales it.
    const float sampleAngle = options.screen.sampleAngle() / options.resolutionFactor;
    // Each camera's samples by LDI pixel (CSR), to find a camera's samples
    // near a point.
    std::array<std::vector<uint32_t>, 3> first, index;
    auto pixelOf = [&](size_t cam, const glm::vec3& p) {
      const LdiCamera& c = cameras[cam];
      const glm::vec3 w = p - c.eye;
      const float z = glm::dot(w, axis);
      return glm::vec2((glm::dot(w, uDir) / z - c.x0) / c.pixel,
                       (glm::dot(w, vDir) / z - c.y0) / c.pixel);
    };
    auto linearPixel = [&](size_t cam, int64_t x, int64_t y) -> int64_t {
      const LdiCamera& c = cameras[cam];
      if (x < 0 || y < 0 || x >= int64_t(c.width) || y >= int64_t(c.height)) return -1;
      return y * int64_t(c.width) + x;
    };
    for (size_t cam = 0; cam < 3; ++cam) {
      first[cam].assign(size_t(cameras[cam].width) * cameras[cam].height + 1, 0);
      std::vector<int64_t> at(samples.size(), -1);
      for (size_t i = 0; i < samples.size(); ++i) {
        if (samples[i].camera != cam) continue;
        const glm::vec2 q = pixelOf(cam, samples[i].position);
        at[i] = linearPixel(cam, int64_t(std::floor(q.x)), int64_t(std::floor(q.y)));
        if (at[i] >= 0) ++first[cam][size_t(at[i]) + 1];
      }
      for (size_t k = 1; k < first[cam].size(); ++k) first[cam][k] += first[cam][k - 1];
      index[cam].resize(first[cam].back());
      std::vector<uint32_t> next(first[cam].begin(), first[cam].end() - 1);
      for (size_t i = 0; i < samples.size(); ++i)
        if (at[i] >= 0) index[cam][next[size_t(at[i])]++] = uint32_t(i);
    }
    // Whether camera `cam`'s LDI pixel (x, y) holds a sample within `reach`
    // of p on a surface facing like `normal`. `among` (when given) limits
    // the samples to those it marks non-zero.
    auto sampleInPixel = [&](size_t cam, int64_t x, int64_t y, const glm::vec3& p,
                             const glm::vec3& normal, float reach,
                             const std::vector<uint8_t>* among) {
      const int64_t at = linearPixel(cam, x, y);
      if (at < 0) return false;
      for (uint32_t k = first[cam][size_t(at)]; k < first[cam][size_t(at) + 1]; ++k) {
        const uint32_t o = index[cam][k];
        if (among && !(*among)[o]) continue;
        if (glm::distance(samples[o].position, p) <= reach &&
            glm::dot(unitNormal(scene.triangles, samples[o].triangle), normal) >= 0.9f)
          return true;
      }
      return false;
    };
    // The same in the 3x3 LDI pixels round p's projection.
    auto nearbySample = [&](size_t cam, const glm::vec3& p, const glm::vec3& normal, float reach,
                            const std::vector<uint8_t>* among) {
      const glm::vec2 q = pixelOf(cam, p);
      const int64_t x = int64_t(std::floor(q.x)), y = int64_t(std::floor(q.y));
      for (int64_t dy = -1; dy <= 1; ++dy)
        for (int64_t dx = -1; dx <= 1; ++dx)
          if (sampleInPixel(cam, x + dx, y + dy, p, normal, reach, among)) return true;
      return false;
    };
    // Per sample (the values of `keep` below): dropped, kept, or kept though
    // a camera samples its surface better (that camera has no sample beside
    // it).
    constexpr uint8_t kDropped = 0, kKept = 1, kKeptUnsampled = 2;
    // What becomes of sample i: dropped when another camera samples its
    // surface sufficiently and better and has a sample (among `among`)
    // covering it.
    // The largest sample spacing on the surface at p (unit normal `normal`)
    // that every viewer sees within sampleAngle: sampleAngle over the
    // largest foreshortened angle per metre of spacing any viewer sees,
    // |n . w_v| / |p - v|, over the cell's corners and centre.
    auto enoughSpacing = [&](const glm::vec3& p, const glm::vec3& normal) {
      float worst = 0.0f;
      for (int c = 0; c < 9; ++c) {
        const glm::vec3 v = c == 8 ? cell.center() : cell.corner(c);
        const glm::vec3 w = p - v;
        const float d2 = glm::dot(w, w);
        worst = std::max(worst, std::abs(glm::dot(normal, w)) / std::max(d2, 1e-12f));
      }
      return worst > 0.0f ? sampleAngle / worst : 1e30f;
    };
    auto removal = [&](size_t i, const std::vector<uint8_t>* among) -> uint8_t {
      const Sample& s = samples[i];
      const glm::vec3 normal = unitNormal(scene.triangles, s.triangle);
      // Spacing s_j is sufficient when s_j <= enough.
      const float enough = enoughSpacing(s.position, normal);
      std::array<float, 3> spacing;
      for (size_t j = 0; j < 3; ++j)
        spacing[j] = sampleSpacing(cameras[j], axis, s.position, normal);
      uint8_t fate = kKept;
      for (size_t j = 0; j < 3; ++j) {
        if (j == s.camera || !(spacing[j] <= enough)) continue;
        if (!(spacing[j] < spacing[s.camera] || (spacing[j] == spacing[s.camera] && j < s.camera)))
          continue;
        fate = kKeptUnsampled;
        // Camera j must have a point of this surface covering p (after the
        // hidden ones are gone). Its samples of a surface lie on a grid of
        // steps at most spacing[j], so where it sampled, one lies within
        // half the grid's diagonal (0.71 spacing[j]) of p. Where it did not,
        // its nearest sample is a step or more away: at an occluding edge its
        // samples there lie on the hidden side, and where its rays stopped at
        // maxLayers (a facade behind rows of buildings, seen along a street)
        // it has none. p is then the only point there.
        if (nearbySample(j, s.position, normal, kCoverReach * spacing[j], among)) return kDropped;
      }
      return fate;
    };
    // First every sample against all others; then each dropped one again
    // against those that stay, since the sample it was dropped for may have
    // gone too (for a third camera's, farther away). Keeping a sample there
    // only adds points, so one more pass settles it.
    std::vector<uint8_t> keep(samples.size(), kKept);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size()), [&](const auto& range) {
      for (size_t i = range.begin(); i != range.end(); ++i) keep[i] = removal(i, nullptr);
    });
    std::vector<uint8_t> settled = keep;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size()), [&](const auto& range) {
      for (size_t i = range.begin(); i != range.end(); ++i)
        if (keep[i] == kDropped && removal(i, &keep) != kDropped) settled[i] = kKeptUnsampled;
    });
    keep.swap(settled);
    // Thinning: where a sample's own camera samples its surface at least
    // sqrt(2) times finer than sufficient, that camera's samples on the
    // even squares of its LDI's checkerboard are enough there: they form a
    // lattice of spacing sqrt(2) s_j, within the bound removal keeps, whose
    // holes (the odd squares) lie within s_j of four of them, as a square
    // lattice of that spacing would. A sample on an odd square goes when
    // each of its four edge neighbours holds a kept sample of its surface
    // (those lie on even squares, which thinning never drops), so nothing
    // is thinned at a surface's edge or beside an occluder.
    if (options.thinOversampled) {
      std::vector<uint8_t> thin(samples.size(), 0);
      tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size()), [&](const auto& range) {
        for (size_t i = range.begin(); i != range.end(); ++i) {
          if (keep[i] == kDropped) continue;
          const Sample& s = samples[i];
          const glm::vec2 q = pixelOf(s.camera, s.position);
          const int64_t x = int64_t(std::floor(q.x)), y = int64_t(std::floor(q.y));
          if (((x + y) & 1) == 0) continue;
          const glm::vec3 normal = unitNormal(scene.triangles, s.triangle);
          const float ownSpacing = sampleSpacing(cameras[s.camera], axis, s.position, normal);
          if (!(ownSpacing * kThinFactor <= enoughSpacing(s.position, normal))) continue;
          // keep marks dropped samples 0 (kDropped).
          const float reach = kThinReach * ownSpacing;
          thin[i] = sampleInPixel(s.camera, x + 1, y, s.position, normal, reach, &keep) &&
                    sampleInPixel(s.camera, x - 1, y, s.position, normal, reach, &keep) &&
                    sampleInPixel(s.camera, x, y + 1, s.position, normal, reach, &keep) &&
                    sampleInPixel(s.camera, x, y - 1, s.position, normal, reach, &keep);
        }
      });
      for (size_t i = 0; i < samples.size(); ++i)
        if (thin[i]) {
          keep[i] = kDropped;
          ++stats.thinned;
        }
    }
    size_t kept = 0;
    for (size_t i = 0; i < samples.size(); ++i) {
      stats.keptUnsampled += keep[i] == kKeptUnsampled;
      if (keep[i]) samples[kept++] = samples[i];
    }
    stats.removed = samples.size() - kept;
    samples.resize(kept);
  }
  stats.removeSeconds = watch.ms() / 1000.0;

  // The precision kept (PointGrid): half the error budget to each of angle
  // and parallax at the box's nearest depth (every viewer is at least that
  // far), against the screen's smallest pixel angle (at its border, the
  // perspective factor smaller than at its centre); r is the cell's half
  // diagonal, the farthest a viewer stands from its centre.
  Impostor imp;
  imp.cell = cell;
  imp.box = box;
  imp.plane = frame.plane;
  imp.cameras = frame.cameras;
  imp.textureWidth = options.textureWidth;
  imp.textureHeight = options.textureHeight;
  const float smallestPixel = options.screen.sampleAngle() * glm::root_two<float>();
  imp.angleStep = options.positionError * smallestPixel;
  imp.logDepthStep = options.positionError * smallestPixel * frame.nearestDepth /
                     (0.5f * glm::length(cell.extent()));
  imp.colourStep = options.colourStep;

  // A byte budget: the points' positions are known now, and their encoding
  // does not depend on the colours, so if the positions alone exceed it the
  // impostor would too, and the appearance (most of the bake) is not worked
  // out for nothing.
  if (maxBytes > 0) {
    Impostor positions = imp;
    const glm::u8vec3 black(0);
    for (const Sample& sample : samples) positions.appendPoint(sample.position, &black, true);
    positions.quantize();
    wire::ImpostorSections sections;
    wire::encodeImpostor(positions, &sections);
    if (sections.bytes[0] > maxBytes) {
      stats.points = positions.size();
      stats.positionBytes = sections.bytes[0];
      stats.seconds = total.ms() / 1000.0;
      if (statsOut) *statsOut = stats;
      return std::nullopt;
    }
  }

  // Appearance: Monte Carlo integration of the plenoptic image function.
  watch.reset();
  const uint32_t tw = options.textureWidth, th = options.textureHeight, texelCount = tw * th;
  const float screenPixel = options.screen.pixelAngle();
  std::vector<glm::u8vec3> colours(samples.size() * texelCount);
  std::vector<uint8_t> single(samples.size(), 0);
  std::atomic<uint64_t> appearanceRays{0}, visibilityRays{0}, unseen{0};
  const float threshold2 = options.varianceThreshold * options.varianceThreshold;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, samples.size(), 64), [&](const auto& range) {
    uint64_t pifRays = 0, occlusionRays = 0, unseenHere = 0;
    std::vector<glm::vec3> mean(texelCount);
    std::vector<uint32_t> seen(texelCount);
    for (size_t i = range.begin(); i != range.end(); ++i) {
      const Sample& s = samples[i];
      SplitMix rng(mixBits(options.seed ^ mixBits(i)));
      for (uint32_t texel = 0; texel < texelCount; ++texel) {
        const float cs = (float(texel % tw) + 0.5f) / float(tw);
        const float ct = (float(texel / tw) + 0.5f) / float(th);
        glm::dvec3 sum(0.0), sum2(0.0);
        uint32_t n = 0;
        for (uint32_t tries = 0; tries < options.maxRays; ++tries) {
          // A viewpoint by the texel's filter, on the rectangle.
          float ss = cs + float(rng.normal()) * 0.5f / float(tw);
          float st = ct + float(rng.normal()) * 0.5f / float(th);
          ss = std::clamp(ss, 0.0f, 1.0f);
          st = std::clamp(st, 0.0f, 1.0f);
          const glm::vec3 eye = frame.plane.at(ss, st);
          // Visible in the points' z-buffer: nothing of the impostor between.
          ++occlusionRays;
          if (!visibleFrom(eye, s.position)) continue;
          const glm::vec3 w = s.position - eye;
          const float distance = glm::length(w);
          // A random orientation puts the point anywhere in its pixel; the
          // monitor's filter (a box, widened by a Gaussian of
          // pixelFilterSigma) picks the ray about that pixel's centre.
          const glm::vec3 forward = w / distance;
          glm::vec3 a = glm::cross(forward, glm::vec3(0.0f, 1.0f, 0.0f));
          a = glm::dot(a, a) > 1e-8f ? glm::normalize(a) : glm::vec3(1.0f, 0.0f, 0.0f);
          const glm::vec3 b = glm::cross(a, forward);
          const double sigma = double(options.pixelFilterSigma);
          const float ox = float(rng.uniform() - 0.5 + sigma * rng.normal());
          const float oy = float(rng.uniform() - 0.5 + sigma * rng.normal());
          const glm::vec3 dir = forward + (ox * a + oy * b) * screenPixel;
          ++pifRays;
          glm::vec3 colour;
          const auto [t0, t1] = clipToBox(eye, dir, box);
          const Hit hit = t0 <= t1 ? scene.rays.firstHit(Ray{eye, dir, t0}) : Hit{};
          if (hit.valid())
            colour = scene.backdrop.haze.apply(scene.lighting.colourAt(hit.triangle, hit.u, hit.v),
                                               hit.t * glm::length(dir));
          else
            colour = glm::vec3(scene.backdrop.along(eye, dir, scene.groundY));
          sum += glm::dvec3(colour);
          sum2 += glm::dvec3(colour) * glm::dvec3(colour);
          ++n;
          if (n >= options.minRays) {
            // Standard error of the mean, worst channel.
            const glm::dvec3 m = sum / double(n);
            const glm::dvec3 var = glm::max(glm::dvec3(0.0), sum2 / double(n) - m * m);
            const double worst = std::max({var.x, var.y, var.z}) / double(n);
            if (worst <= double(threshold2)) break;
          }
        }
        seen[texel] = n;
        mean[texel] = n ? glm::vec3(sum / double(n)) : glm::vec3(0.0f);
      }
      // Texels that never saw the point: the mean of those that did, or the
      // surface's own colour.
      glm::vec3 fill(0.0f);
      uint32_t filled = 0;
      for (uint32_t texel = 0; texel < texelCount; ++texel)
        if (seen[texel]) {
          fill += mean[texel];
          ++filled;
        }
      if (filled)
        fill /= float(filled);
      else {
        ++unseenHere;
        fill = scene.backdrop.haze.apply(scene.lighting.colourAt(s.triangle, s.u, s.v),
                                         glm::length(s.position - frame.centre));
      }
      glm::u8vec3* out = colours.data() + i * texelCount;
      glm::vec3 lo(255.0f), hi(0.0f), all(0.0f);
      for (uint32_t texel = 0; texel < texelCount; ++texel) {
        const glm::vec3 c = seen[texel] ? mean[texel] : fill;
        out[texel] = toBytes(c);
        lo = glm::min(lo, c);
        hi = glm::max(hi, c);
        all += c;
      }
      all /= float(texelCount);
      const glm::vec3 spread = glm::max(hi - all, all - lo);
      if (std::max({spread.x, spread.y, spread.z}) <= options.singleColourTolerance) {
        single[i] = 1;
        out[0] = toBytes(all);
      }
    }
    appearanceRays += pifRays;
    visibilityRays += occlusionRays;
    unseen += unseenHere;
  });
  stats.appearanceSeconds = watch.ms() / 1000.0;
  stats.appearanceRays = appearanceRays;
  stats.visibilityRays = visibilityRays;
  stats.unseenPoints = unseen;

  imp.points.reserve(samples.size());
  for (size_t i = 0; i < samples.size(); ++i) {
    imp.appendPoint(samples[i].position, colours.data() + i * texelCount, single[i] != 0);
    stats.singleColour += single[i];
  }
  imp.quantize();
  stats.points = imp.size();
  const ScreenCoverage coverage =
      screenCoverage(imp.points, cell.center(), box.center(), options.screen);
  stats.screenPixels = coverage.boxPixels;
  stats.coveredPixels = coverage.pixels;
  stats.pointsPerPixel =
      coverage.boxPixels ? double(stats.points) / double(coverage.boxPixels) : 0.0;
  stats.pointsPerCoveredPixel =
      coverage.pixels ? double(stats.points) / double(coverage.pixels) : 0.0;
  wire::ImpostorSections sections;
  stats.bytes = wire::encodeImpostor(imp, &sections).size();
  stats.positionBytes = sections.bytes[0];
  stats.colourBytes = sections.bytes[1] + sections.bytes[2];
  stats.textureBytes = sections.bytes[3];
  stats.memoryBytes = imp.bytes();
  stats.bytesUncompressed = imp.bytesUncompressed();
  stats.seconds = total.ms() / 1000.0;
  if (statsOut) *statsOut = stats;
  return imp;
}

}  // namespace vistream
