#include "client/render/render_geometry.h"

#include <cmath>

namespace vistream {

glm::u8vec3 shadeTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                          const glm::vec3& diffuse) {
  const glm::vec3 n = glm::cross(b - a, c - a);
  const float len = glm::length(n);
  const float lambert = len > 0.0f ? std::abs(glm::dot(n / len, defaultSunDirection())) : 0.0f;
  return encodeColour(diffuse * (0.3f + 0.7f * lambert));
}

RenderGeometry renderGeometryFromScene(const Scene& scene) {
  RenderGeometry g;
  g.triangles = flattenScene(scene, /*staticOnly=*/true);
  // Material of each flattened triangle, in the same order flattenScene emits them.
  std::vector<uint32_t> material;
  material.reserve(g.triangles.size());
  for (const Object& o : scene.objects) {
    if (o.dynamic) continue;
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t)
      material.push_back(t < o.mesh.materials.size() ? o.mesh.materials[t] : 0u);
  }
  const glm::vec3 sky = scene.environment.skyColor;
  g.sky = encodeColour(sky);
  recolour(g, [&](size_t t) {
    const uint32_t m = t < material.size() ? material[t] : 0u;
    return m < scene.materials.size() ? scene.materials[m].diffuse : glm::vec3(0.8f);
  });
  return g;
}

}  // namespace vistream
