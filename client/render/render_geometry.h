// The triangles a client holds, with the one colour each is drawn in.
//
// Shading is prelit and flat, as in the thesis's implementation (section
// 4.6): each triangle gets one 8-bit colour, its material's diffuse colour
// times (ambient + diffuse * |n . L|) for a fixed sun direction, computed
// once here. The OpenGL near field, the software rasterizer and the ray
// caster all read these bytes, so a far-field pixel and a near-field pixel of
// the same triangle are identical and the border does not show.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <vector>

#include "common/core/box.h"
#include "common/light/lighting.h"
#include "common/scene/scene.h"

namespace vistream {

// The prelit colour of a triangle with the given corners and diffuse colour.
glm::u8vec3 shadeTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                          const glm::vec3& diffuse);

struct RenderGeometry {
  FlatTriangles triangles;           // local frame
  std::vector<glm::u8vec3> colours;  // per triangle
  glm::u8vec3 sky{140, 180, 230};    // background for pixels that see nothing
  // An assumed ground plane (static_world.h) at this local height: pixels
  // that see nothing below the horizon show `ground` instead of the sky.
  std::optional<float> groundY;
  glm::u8vec3 ground{118, 112, 100};
  // The background a ray from `eye` along `dir` meets when it hits no triangle.
  glm::u8vec3 background(const glm::vec3& eye, const glm::vec3& dir) const {
    return groundY && dir.y < 0.0f && eye.y > *groundY ? ground : sky;
  }
  Box3f bounds;

  size_t size() const { return triangles.size(); }
};

// Every triangle of the scene's static objects, coloured from its materials.
RenderGeometry renderGeometryFromScene(const Scene& scene);
// Recomputes bounds and colours after `triangles` changed; `diffuse` gives a
// triangle's diffuse colour.
template <class DiffuseOf>
void recolour(RenderGeometry& g, DiffuseOf&& diffuse) {
  g.colours.resize(g.triangles.size());
  g.bounds = Box3f{};
  for (size_t t = 0; t < g.triangles.size(); ++t) {
    const glm::vec3 a = g.triangles.vertex(t, 0), b = g.triangles.vertex(t, 1),
                    c = g.triangles.vertex(t, 2);
    g.colours[t] = shadeTriangle(a, b, c, diffuse(t));
    g.bounds.extend(a);
    g.bounds.extend(b);
    g.bounds.extend(c);
  }
}

}  // namespace vistream
