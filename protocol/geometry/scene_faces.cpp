#include "protocol/geometry/scene_faces.h"

#include <algorithm>

namespace vistream::wire {

std::vector<FaceTriangles> sceneFaces(const Scene& scene, const LightingGrid* lighting,
                                      std::vector<Box3f>* boxes) {
  std::vector<FaceTriangles> faces(scene.faceCount);
  if (boxes) boxes->assign(scene.faceCount, Box3f());
  for (uint32_t i = 0; i < scene.faceCount; ++i) faces[i].face = i;
  size_t flat = 0;  // the static triangle's index in the lighting grid
  for (const Object& o : scene.objects) {
    for (size_t t = 0; t < o.mesh.triangles.size(); ++t) {
      const uint32_t id = o.mesh.faceIds[t];
      const size_t lightIndex = o.dynamic ? SIZE_MAX : flat++;
      if (id >= faces.size()) continue;
      FaceTriangles& f = faces[id];
      if (lighting && lightIndex != SIZE_MAX) {
        const uint8_t n = lighting->level[lightIndex];
        f.levels.push_back(n);
        const auto first = lighting->colours.begin() + lighting->first[lightIndex];
        f.colours.insert(f.colours.end(), first, first + LightingGrid::pointsOf(n));
      }
      f.material = uint16_t(
          t < o.mesh.materials.size() ? std::min<uint32_t>(o.mesh.materials[t], 65535) : 0);
      for (int k = 0; k < 3; ++k) {
        const glm::vec3 p = o.mesh.positions[o.mesh.triangles[t][k]];
        f.corners.push_back(p);
        if (boxes) (*boxes)[id].extend(p);
      }
    }
  }
  return faces;
}

}  // namespace vistream::wire
