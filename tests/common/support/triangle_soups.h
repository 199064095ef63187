// Building blocks for tests and benchmarks of ray queries and spatial
// structures: flat triangle lists from corner triples, and random directions.
#pragma once

#include <array>
#include <random>
#include <vector>

#include "common/scene/scene.h"

namespace vistream::testing {

using Triangle = std::array<glm::vec3, 3>;

// One face per triangle (face ID = index), all in object 0, each flagged
// degenerate as isDegenerateTriangle decides.
inline FlatTriangles makeTriangles(const std::vector<Triangle>& triangles) {
  FlatTriangles flat;
  for (const Triangle& t : triangles) {
    flat.positions.insert(flat.positions.end(), t.begin(), t.end());
    flat.faceIds.push_back(uint32_t(flat.faceIds.size()));
    flat.objectIds.push_back(0);
    flat.degenerate.push_back(isDegenerateTriangle(t[0], t[1], t[2]) ? 1 : 0);
  }
  return flat;
}

// Appends triangle (a, b, c) as the next face of f, in object 0.
inline void addTriangle(FlatTriangles& f, glm::vec3 a, glm::vec3 b, glm::vec3 c) {
  f.faceIds.push_back(uint32_t(f.faceIds.size()));
  f.positions.insert(f.positions.end(), {a, b, c});
  f.objectIds.push_back(0);
  f.degenerate.push_back(isDegenerateTriangle(a, b, c) ? 1 : 0);
}

// The 12 triangles of an axis-aligned box, two per side in the order
// -Z, +Z, -X, +X, +Y, -Y (triangles 2k and 2k + 1 make side k).
inline std::vector<Triangle> boxTriangles(glm::vec3 lo, glm::vec3 hi) {
  const glm::vec3 c[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z},
                          {lo.x, hi.y, lo.z}, {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z},
                          {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
  const int q[6][4] = {{0, 1, 2, 3}, {5, 4, 7, 6}, {4, 0, 3, 7},
                       {1, 5, 6, 2}, {3, 2, 6, 7}, {4, 5, 1, 0}};
  std::vector<Triangle> out;
  for (const auto& f : q) {
    out.push_back({c[f[0]], c[f[1]], c[f[2]]});
    out.push_back({c[f[0]], c[f[2]], c[f[3]]});
  }
  return out;
}

// A uniformly distributed unit direction: a normalised Gaussian vector,
// redrawn while it is too short to normalise safely.
inline glm::vec3 randomDirection(std::mt19937& rng) {
  std::normal_distribution<float> normal(0.0f, 1.0f);
  glm::vec3 d;
  do d = glm::vec3(normal(rng), normal(rng), normal(rng));
  while (glm::length(d) < 1e-3f);
  return glm::normalize(d);
}

}  // namespace vistream::testing
