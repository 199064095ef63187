// An orthonormal frame around a unit normal: t, b, n right-handed (t x b =
// n), built without a branch on the normal's direction (Duff et al., "Building
// an Orthonormal Basis, Revisited", JCGT 2017), so it changes continuously
// with n everywhere but at n = -z exactly.
#pragma once

#include <glm/glm.hpp>

namespace vistream {

struct TangentFrame {
  glm::vec3 t{1, 0, 0}, b{0, 1, 0}, n{0, 0, 1};

  glm::vec3 toLocal(const glm::vec3& v) const {
    return {glm::dot(v, t), glm::dot(v, b), glm::dot(v, n)};
  }
  glm::vec3 toWorld(const glm::vec3& v) const { return t * v.x + b * v.y + n * v.z; }

  static TangentFrame around(const glm::vec3& n) {
    const float s = n.z >= 0.0f ? 1.0f : -1.0f;
    const float a = -1.0f / (s + n.z);
    const float c = n.x * n.y * a;
    TangentFrame f;
    f.t = glm::vec3(1.0f + s * n.x * n.x * a, s * c, -s * n.x);
    f.b = glm::vec3(c, s + n.y * n.y * a, -n.y);
    f.n = n;
    return f;
  }
};

}  // namespace vistream
