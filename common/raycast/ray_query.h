// Ray queries against a fixed set of triangles (the scene's FlatTriangles).
//
// One interface, several back ends: EmbreeRayQuery (production, robust
// watertight mode), BruteForceRayQuery (the oracle: tests every triangle with
// a watertight test) and KdTreeRayQuery (the project's own kD-tree). All three
// answer in the local frame of the scene and report triangle indices into the
// FlatTriangles they were built from; FlatTriangles::faceIds maps them to
// face IDs.
//
// Semantics shared by every back end:
//  - A ray is org + t*dir for t in [tnear, tfar] (closed interval). dir need
//    not be normalised; t is in units of |dir|.
//  - Triangles are two-sided. Degenerate triangles are never hit.
//  - Hits on an edge or vertex count (closed triangles), so a ray through an
//    edge shared by two triangles reports both in allHits and at least one
//    of them in firstHit: nothing slips through a seam.
//  - firstHit ties (equal t) resolve to the smaller triangle index.
//
// Thread safety: all queries are const and may run concurrently from any
// number of threads once the object is constructed.
#pragma once

#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "common/scene/scene.h"

namespace vistream {

struct Ray {
  glm::vec3 org{0.0f};
  glm::vec3 dir{0.0f, 0.0f, -1.0f};
  float tnear = 0.0f;
  float tfar = std::numeric_limits<float>::infinity();
};

// A ray the intersection tests can answer: finite origin and direction, a
// non-zero direction and a non-empty interval (NaN bounds make it empty).
// Every back end treats any other ray as missing everything.
inline bool isTraceable(const Ray& ray) {
  const auto finite = [](const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
  };
  return finite(ray.org) && finite(ray.dir) && ray.dir != glm::vec3(0.0f) && ray.tnear <= ray.tfar;
}

inline constexpr uint32_t kNoHit = 0xffffffffu;

struct Hit {
  uint32_t triangle = kNoHit;  // index into FlatTriangles, kNoHit on a miss
  float t = std::numeric_limits<float>::infinity();
  float u = 0.0f, v = 0.0f;  // barycentrics of vertices 1 and 2
  glm::vec3 normal{0.0f};    // geometric normal (unnormalised), (v1-v0) x (v2-v0)

  bool valid() const { return triangle != kNoHit; }
};

class RayQuery {
 public:
  virtual ~RayQuery() = default;

  // The nearest hit in [tnear, tfar], or an invalid Hit.
  virtual Hit firstHit(const Ray& ray) const = 0;
  // True if anything is hit in [tnear, tfar].
  virtual bool occluded(const Ray& ray) const = 0;
  // Every triangle hit in [tnear, tfar], each once, sorted by t then triangle.
  virtual void allHits(const Ray& ray, std::vector<Hit>& hits) const = 0;

  // Batched forms: hits.size() == rays.size(). Back ends that have packet or
  // stream paths override these; the defaults loop over single rays.
  virtual void firstHits(std::span<const Ray> rays, std::span<Hit> hits) const;
  virtual void occludedMany(std::span<const Ray> rays, std::span<uint8_t> occluded) const;

  virtual const char* name() const = 0;
};

// Back ends. Each keeps a reference to `triangles`, which must outlive it.
std::unique_ptr<RayQuery> makeEmbreeRayQuery(const FlatTriangles& triangles);
std::unique_ptr<RayQuery> makeBruteForceRayQuery(const FlatTriangles& triangles);
std::unique_ptr<RayQuery> makeKdTreeRayQuery(const FlatTriangles& triangles);

}  // namespace vistream
