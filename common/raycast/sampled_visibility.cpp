#include "common/raycast/sampled_visibility.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <mutex>
#include <random>

#include "common/core/timer.h"

namespace vistream {

std::vector<glm::vec3> cellViewpoints(const Box3f& cell, size_t points, uint64_t seed) {
  std::vector<glm::vec3> out;
  const glm::vec3 lo = cell.lo, hi = cell.hi, c = cell.center();
  for (int i = 0; i < 8; ++i)
    out.emplace_back((i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z);
  out.emplace_back(lo.x, c.y, c.z);
  out.emplace_back(hi.x, c.y, c.z);
  out.emplace_back(c.x, lo.y, c.z);
  out.emplace_back(c.x, hi.y, c.z);
  out.emplace_back(c.x, c.y, lo.z);
  out.emplace_back(c.x, c.y, hi.z);
  out.push_back(c);
  std::mt19937_64 rng(seed);
  auto u = [&] { return float(double(rng() >> 11) * 0x1.0p-53); };
  while (out.size() < points) out.push_back(lo + (hi - lo) * glm::vec3(u(), u(), u()));
  if (out.size() > points && points >= 1) out.resize(std::max<size_t>(points, 1));
  return out;
}

uint32_t seenTriangle(const RayQuery& rays, const Ray& ray, const Hit& h, std::vector<Hit>& tied) {
  if (!(glm::dot(h.normal, ray.dir) > 0.0f)) return h.triangle;
  const float window = 1e-5f * std::max(h.t, 1e-3f);
  tied.clear();
  // From the ray's start: the query's own tie window (which grows with the
  // triangles' size) may have put a front-facing triangle a little nearer
  // than `h` behind it by index, and such a triangle is seen.
  rays.allHits(Ray{ray.org, ray.dir, ray.tnear, h.t + window}, tied);
  uint32_t best = kNoHit;
  for (const Hit& o : tied)
    if (glm::dot(o.normal, ray.dir) < 0.0f && o.triangle < best) best = o.triangle;
  if (best != kNoHit) return best;
  constexpr float kEdge = 1e-4f;
  const bool onBoundary = h.u <= kEdge || h.v <= kEdge || h.u + h.v >= 1.0f - kEdge;
  return onBoundary ? kNoHit : h.triangle;
}

namespace {

// Points spread over the unit triangle: the centroid, then Halton (2, 3)
// pairs folded into the triangle (a point beyond the diagonal is mirrored).
std::vector<glm::vec2> probeBarycentrics(int count) {
  std::vector<glm::vec2> out;
  if (count <= 0) return out;
  out.emplace_back(1.0f / 3.0f, 1.0f / 3.0f);
  auto radicalInverse = [](uint32_t i, uint32_t base) {
    double f = 1.0, r = 0.0;
    while (i > 0) {
      f /= double(base);
      r += f * double(i % base);
      i /= base;
    }
    return r;
  };
  for (uint32_t i = 1; out.size() < size_t(count); ++i) {
    double u = radicalInverse(i, 2), v = radicalInverse(i, 3);
    if (u + v > 1.0) u = 1.0 - u, v = 1.0 - v;
    // Keep off the edges, where the open-face rule credits nothing.
    const double shrink = 0.98;
    const double cu = 1.0 / 3.0 + (u - 1.0 / 3.0) * shrink;
    const double cv = 1.0 / 3.0 + (v - 1.0 / 3.0) * shrink;
    out.emplace_back(float(cu), float(cv));
  }
  return out;
}

}  // namespace

SampledVisibility sampleVisibleFaces(const RayQuery& rays, const FlatTriangles& triangles,
                                     const Box3f& cell, const SampledVisibilityOptions& options) {
  Stopwatch clock;
  SampledVisibility result;
  const std::vector<glm::vec3> points = cellViewpoints(cell, options.points, options.seed);
  const int res = std::max(1, options.resolution);
  std::vector<uint8_t> seen(triangles.size(), 0);
  std::vector<uint8_t> probed(triangles.size(), 0);  // 1: found by a probe ray only
  // The triangles of the probe faces.
  std::vector<uint32_t> probeTriangles;
  if (!options.probeFaces.empty()) {
    std::vector<uint32_t> wanted = options.probeFaces;
    std::sort(wanted.begin(), wanted.end());
    for (size_t t = 0; t < triangles.size(); ++t)
      if (!triangles.degenerate[t] &&
          std::binary_search(wanted.begin(), wanted.end(), triangles.faceIds[t]))
        probeTriangles.push_back(uint32_t(t));
  }
  const std::vector<glm::vec2> probePoints = probeBarycentrics(options.probeSamples);
  std::mutex merge;  // guards result counters while merging per-viewpoint results

  tbb::parallel_for(size_t(0), points.size(), [&](size_t pi) {
    const glm::vec3 origin = points[pi];
    if (options.skipViewpoint && options.skipViewpoint(origin)) {
      std::lock_guard lock(merge);
      ++result.insideSolid;
      return;
    }
    std::vector<Ray> batch(size_t(res) * size_t(res));
    std::vector<Hit> hits(batch.size());
    std::vector<uint32_t> local;
    std::vector<Hit> tied;
    uint64_t hitCount = 0;
    for (int face = 0; face < 6; ++face) {
      const int axis = face / 2;
      const float sign = (face & 1) ? -1.0f : 1.0f;
      for (int j = 0; j < res; ++j)
        for (int i = 0; i < res; ++i) {
          const float s = (float(i) + 0.5f) / float(res) * 2.0f - 1.0f;
          const float t = (float(j) + 0.5f) / float(res) * 2.0f - 1.0f;
          glm::vec3 d;
          d[axis] = sign;
          d[(axis + 1) % 3] = s;
          d[(axis + 2) % 3] = t;
          batch[size_t(j) * size_t(res) + size_t(i)] =
              Ray{origin, d, 0.0f, std::numeric_limits<float>::infinity()};
        }
      rays.firstHits(batch, hits);
      for (size_t r = 0; r < hits.size(); ++r)
        if (hits[r].valid()) {
          ++hitCount;
          const uint32_t tri = seenTriangle(rays, batch[r], hits[r], tied);
          if (tri != kNoHit) local.push_back(tri);
        }
    }
    // Probe rays: aimed at points of the probe triangles, ending just past them.
    std::vector<uint32_t> fromProbes;
    uint64_t probeRays = 0;
    constexpr size_t kProbeBatch = 16384;
    for (size_t first = 0; first < probeTriangles.size() * probePoints.size();
         first += kProbeBatch) {
      const size_t n = std::min(kProbeBatch, probeTriangles.size() * probePoints.size() - first);
      batch.resize(n);
      hits.resize(n);
      for (size_t k = 0; k < n; ++k) {
        const size_t tri = probeTriangles[(first + k) / probePoints.size()];
        const glm::vec2 b = probePoints[(first + k) % probePoints.size()];
        const glm::vec3 target = triangles.vertex(tri, 0) * (1.0f - b.x - b.y) +
                                 triangles.vertex(tri, 1) * b.x + triangles.vertex(tri, 2) * b.y;
        batch[k] = Ray{origin, target - origin, 0.0f, 1.001f};
      }
      rays.firstHits(std::span<const Ray>(batch.data(), n), std::span<Hit>(hits.data(), n));
      probeRays += n;
      for (size_t r = 0; r < n; ++r)
        if (hits[r].valid()) {
          ++hitCount;
          const uint32_t tri = seenTriangle(rays, batch[r], hits[r], tied);
          if (tri != kNoHit) fromProbes.push_back(tri);
        }
    }
    std::sort(local.begin(), local.end());
    local.erase(std::unique(local.begin(), local.end()), local.end());
    std::lock_guard lock(merge);
    for (uint32_t tri : local) seen[tri] = 1;
    for (uint32_t tri : fromProbes)
      if (!seen[tri]) probed[tri] = 1;
    ++result.viewpoints;
    result.rays += uint64_t(res) * uint64_t(res) * 6 + probeRays;
    result.probeRays += probeRays;
    result.hits += hitCount;
  });

  std::vector<uint32_t> cubeFaces;
  for (size_t t = 0; t < triangles.size(); ++t) {
    if (seen[t]) cubeFaces.push_back(triangles.faceIds[t]);
    if (seen[t] || probed[t]) result.faces.push_back(triangles.faceIds[t]);
  }
  auto sortUnique = [](std::vector<uint32_t>& v) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  };
  sortUnique(cubeFaces);
  sortUnique(result.faces);
  result.probeOnly = result.faces.size() - cubeFaces.size();
  result.timeMs = clock.ms();
  return result;
}

}  // namespace vistream
