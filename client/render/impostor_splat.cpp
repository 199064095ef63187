#include "client/render/impostor_splat.h"

#include <cmath>

#include "common/core/check.h"
#include "common/light/lighting.h"

namespace vistream {

void ImpostorSplatter::begin(const Camera& camera) {
  camera_ = camera;
  depth_.assign(size_t(camera.width) * size_t(camera.height), kEmpty);
}

size_t ImpostorSplatter::draw(const Impostor& impostor, ImageRgb8& out) {
  VS_CHECK(out.width == camera_.width && out.height == camera_.height);
  const glm::mat4 rp = camera_.rotationProjection();
  const glm::vec3 forward = camera_.forward();
  const float w = float(camera_.width), h = float(camera_.height);
  // A box wholly outside the view (beyond a side, or behind the near
  // plane) has no point to draw.
  {
    const float mx = 1.0f, my = 1.0f;
    int left = 0, right = 0, below = 0, above = 0, behind = 0;
    for (int k = 0; k < 8; ++k) {
      const glm::vec3 corner{k & 1 ? impostor.box.hi.x : impostor.box.lo.x,
                             k & 2 ? impostor.box.hi.y : impostor.box.lo.y,
                             k & 4 ? impostor.box.hi.z : impostor.box.lo.z};
      const glm::vec3 rel = corner - camera_.eye;
      if (!(glm::dot(rel, forward) > camera_.zNear)) {
        ++behind;
        continue;
      }
      const glm::vec4 clip = rp * glm::vec4(rel, 1.0f);
      left += clip.x < -mx * clip.w;
      right += clip.x > mx * clip.w;
      below += clip.y < -my * clip.w;
      above += clip.y > my * clip.w;
    }
    if (behind == 8 || left == 8 || right == 8 || below == 8 || above == 8) return 0;
  }
  size_t landed = 0;
  for (size_t k = 0; k < impostor.size(); ++k) {
    const glm::vec3 rel = impostor.points[k] - camera_.eye;
    const float z = glm::dot(rel, forward);
    if (!(z > camera_.zNear)) continue;
    const glm::vec4 clip = rp * glm::vec4(rel, 1.0f);
    // A point whose projection is off the screen is clipped whole, as
    // OpenGL clips a point by its centre.
    if (!(std::abs(clip.x) <= clip.w && std::abs(clip.y) <= clip.w)) continue;
    // Window coordinates, row 0 at the top (camera.h).
    const float px = (clip.x / clip.w * 0.5f + 0.5f) * w;
    const float py = (0.5f - clip.y / clip.w * 0.5f) * h;
    // The 2x2 pixels whose centres (x + 0.5, y + 0.5) surround (px, py).
    const int x0 = int(std::floor(px - 0.5f)), y0 = int(std::floor(py - 0.5f));
    ++landed;
    bool coloured = false;
    glm::u8vec3 colour{0, 0, 0};
    for (int y = y0; y <= y0 + 1; ++y)
      for (int x = x0; x <= x0 + 1; ++x) {
        if (x < 0 || y < 0 || x >= camera_.width || y >= camera_.height) continue;
        float& d = depth_[size_t(y) * size_t(camera_.width) + size_t(x)];
        if (!(z < d)) continue;
        d = z;
        if (!coloured) {
          colour = toBytes(impostor.colourSeenFrom(k, camera_.eye));
          coloured = true;
        }
        out.set(x, y, colour);
      }
  }
  return landed;
}

}  // namespace vistream
