// View-cell index vectors: a strict weak order (x, then y, then z), for
// ordered containers keyed by them, and whether one lies in a run of cells.
#pragma once

#include <glm/glm.hpp>
#include <tuple>

namespace vistream {

struct IvecLess {
  bool operator()(const glm::ivec3& a, const glm::ivec3& b) const {
    return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z);
  }
};

// Whether cell c lies in the box of cells lo..hi (inclusive on every axis).
inline bool cellWithin(const glm::ivec3& c, const glm::ivec3& lo, const glm::ivec3& hi) {
  return glm::all(glm::greaterThanEqual(c, lo)) && glm::all(glm::lessThanEqual(c, hi));
}

}  // namespace vistream
