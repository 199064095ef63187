// Unit vectors spread uniformly over the sphere (normalized Gaussian
// triples), reproducible from a seed.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <random>
#include <vector>

namespace vistream::testing {

inline std::vector<glm::vec3> randomDirections(size_t n, uint32_t seed = 5) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g;
  std::vector<glm::vec3> out;
  while (out.size() < n) {
    const glm::vec3 v(g(rng), g(rng), g(rng));
    if (glm::length(v) > 1e-3f) out.push_back(glm::normalize(v));
  }
  return out;
}

}  // namespace vistream::testing
