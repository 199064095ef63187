// A strict weak order on integer vectors (x, then y, then z), for ordered
// containers keyed by view-cell indices.
#pragma once

#include <glm/glm.hpp>
#include <tuple>

namespace vistream {

struct IvecLess {
  bool operator()(const glm::ivec3& a, const glm::ivec3& b) const {
    return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z);
  }
};

}  // namespace vistream
