#include "client/render/render_geometry.h"

#include <cmath>

#include "common/light/lighting_cache.h"

namespace vistream {

glm::u8vec3 shadeTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c,
                          const glm::vec3& diffuse) {
  const glm::vec3 n = glm::cross(b - a, c - a);
  const float len = glm::length(n);
  const float lambert = len > 0.0f ? std::abs(glm::dot(n / len, defaultSunDirection())) : 0.0f;
  return encodeColour(diffuse * (0.3f + 0.7f * lambert));
}

glm::u8vec3 RenderGeometry::background(const glm::vec3& eye, const glm::vec3& dir) const {
  if (!groundY || !(dir.y < 0.0f) || !(eye.y > *groundY)) return sky;
  const float distance = (eye.y - *groundY) / -dir.y * glm::length(dir);
  return toBytes(haze.apply(glm::vec3(ground), distance));
}

EyeTriangle EyeTriangle::of(const FlatTriangles& triangles, size_t t, const glm::vec3& eye) {
  const glm::vec3 a = triangles.vertex(t, 0);
  const glm::vec3 e1 = triangles.vertex(t, 1) - a, e2 = triangles.vertex(t, 2) - a;
  const glm::vec3 s = eye - a;
  EyeTriangle e;
  e.normal = glm::cross(e2, e1);
  e.toU = glm::cross(e2, s);
  e.toV = glm::cross(s, e1);
  e.along = glm::dot(e2, e.toV);
  e.centreDistance = glm::length(a + (e1 + e2) / 3.0f - eye);
  return e;
}

glm::u8vec3 RenderGeometry::colourAlong(size_t t, const EyeTriangle& seen,
                                        const glm::vec3& dir) const {
  const float det = glm::dot(dir, seen.normal);
  if (!(std::abs(det) > 0.0f))  // seen edge-on: the centre, at its distance
    return colourAt(t, 1.0f / 3.0f, 1.0f / 3.0f, seen.centreDistance);
  const float inv = 1.0f / det;
  const float u = glm::dot(dir, seen.toU) * inv, v = glm::dot(dir, seen.toV) * inv;
  return colourAt(t, u, v, std::abs(seen.along * inv) * glm::length(dir));
}

void setBackdrop(RenderGeometry& g, const Backdrop& backdrop) {
  g.sky = backdrop.sky;
  g.ground = backdrop.ground;
  g.haze = backdrop.haze;
}

RenderGeometry renderGeometryFromScene(const Scene& scene, const LightingOptions& options,
                                       const std::filesystem::path& lightingCache) {
  RenderGeometry g;
  g.triangles = flattenScene(scene, /*staticOnly=*/true);
  SceneLighting lit = lightScene(scene, g.triangles, options, lightingCache);
  setBackdrop(g, lit.backdrop);
  g.lighting = std::move(lit.load.grid);
  for (size_t t = 0; t < g.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) g.bounds.extend(g.triangles.vertex(t, k));
  return g;
}

}  // namespace vistream
