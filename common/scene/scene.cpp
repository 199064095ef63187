#include "common/scene/scene.h"

#include <algorithm>
#include <cmath>

namespace vistream {

size_t Scene::triangleCount() const {
  size_t n = 0;
  for (const Object& o : objects) n += o.mesh.triangleCount();
  return n;
}

Box3f Scene::bounds() const {
  Box3f b;
  for (const Object& o : objects) b.extend(o.bounds);
  return b;
}

Box3d Scene::fileBounds() const {
  const Box3f b = bounds();
  if (b.empty()) return Box3d{};
  return Box3d(toFile(b.lo), toFile(b.hi));
}

size_t Scene::dynamicObjectCount() const {
  return size_t(
      std::count_if(objects.begin(), objects.end(), [](const Object& o) { return o.dynamic; }));
}

Box3f FlatTriangles::triangleBounds(size_t tri) const {
  Box3f b;
  for (int k = 0; k < 3; ++k) b.extend(vertex(tri, k));
  return b;
}

bool isDegenerateTriangle(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
  if (a == b || b == c || a == c) return true;
  // Zero area relative to the triangle's size: |e1 x e2| against the squared
  // longest edge. 1e-12 is far below float's resolution of a sane triangle
  // (1e-7 relative), so only truly collinear triples are caught.
  const glm::dvec3 e1 = glm::dvec3(b) - glm::dvec3(a);
  const glm::dvec3 e2 = glm::dvec3(c) - glm::dvec3(a);
  const glm::dvec3 e3 = glm::dvec3(c) - glm::dvec3(b);
  const double longest2 = std::max({glm::dot(e1, e1), glm::dot(e2, e2), glm::dot(e3, e3)});
  const double area2 = glm::length(glm::cross(e1, e2));
  return area2 <= 1e-12 * longest2;
}

FlatTriangles flattenMesh(const std::vector<glm::vec3>& positions,
                          const std::vector<glm::uvec3>& triangles) {
  FlatTriangles flat;
  flat.positions.reserve(3 * triangles.size());
  flat.faceIds.reserve(triangles.size());
  flat.objectIds.assign(triangles.size(), 0);
  flat.degenerate.reserve(triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const glm::vec3 a = positions[triangles[t].x], b = positions[triangles[t].y],
                    c = positions[triangles[t].z];
    flat.positions.insert(flat.positions.end(), {a, b, c});
    flat.faceIds.push_back(uint32_t(t));
    flat.degenerate.push_back(isDegenerateTriangle(a, b, c) ? 1 : 0);
  }
  return flat;
}

FlatTriangles flattenScene(const Scene& scene, bool staticOnly) {
  FlatTriangles flat;
  const size_t n = scene.triangleCount();
  flat.positions.reserve(3 * n);
  flat.faceIds.reserve(n);
  flat.objectIds.reserve(n);
  flat.degenerate.reserve(n);
  for (size_t oi = 0; oi < scene.objects.size(); ++oi) {
    const Object& o = scene.objects[oi];
    if (staticOnly && o.dynamic) continue;
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t) {
      const glm::uvec3 tri = o.mesh.triangles[t];
      const glm::vec3 a = o.mesh.positions[tri.x], b = o.mesh.positions[tri.y],
                      c = o.mesh.positions[tri.z];
      flat.positions.push_back(a);
      flat.positions.push_back(b);
      flat.positions.push_back(c);
      flat.faceIds.push_back(o.mesh.faceIds[t]);
      flat.objectIds.push_back(uint32_t(oi));
      flat.degenerate.push_back(
          (tri.x == tri.y || tri.y == tri.z || tri.x == tri.z || isDegenerateTriangle(a, b, c))
              ? 1
              : 0);
    }
  }
  return flat;
}

void finalizeScene(Scene& scene) {
  if (scene.materials.empty()) scene.materials.push_back(Material::unassignedDefault());
  SceneDiagnostics& d = scene.diagnostics;
  d.degenerateTriangles = d.repeatedVertexTriangles = d.zeroAreaTriangles = 0;
  uint32_t maxFace = 0;
  bool any = false;
  for (Object& o : scene.objects) {
    o.bounds = Box3f{};
    for (const glm::vec3& p : o.mesh.positions) o.bounds.extend(p);
    TriangleMesh& m = o.mesh;
    if (m.materials.size() != m.triangles.size()) m.materials.resize(m.triangles.size(), 0);
    for (size_t t = 0; t < m.triangles.size(); ++t) {
      const glm::uvec3 tri = m.triangles[t];
      if (tri.x == tri.y || tri.y == tri.z || tri.x == tri.z) {
        ++d.repeatedVertexTriangles;
        ++d.degenerateTriangles;
      } else if (isDegenerateTriangle(m.positions[tri.x], m.positions[tri.y], m.positions[tri.z])) {
        ++d.zeroAreaTriangles;
        ++d.degenerateTriangles;
      }
      maxFace = std::max(maxFace, m.faceIds[t]);
      any = true;
    }
  }
  scene.faceCount = std::max(scene.faceCount, any ? maxFace + 1 : 0u);
}

}  // namespace vistream
