// Boxes with chosen face winding, for the winding-independence tests of
// common/world: each face is a separate loop (corners repeated per face, as
// OBJ exports write them), so the solids only know the faces are joined by
// welding equal positions.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "common/raycast/ray_query.h"
#include "common/world/solids.h"
#include "tests/common/support/box_scenes.h"

namespace vistream::testing {

enum class Winding { Outward, Inward, SidesInward };

// The loops of an axis-aligned box, counter-clockwise seen from outside, in
// the order -x, +x, -z, +z, +y (top), -y (bottom).
inline std::vector<Loop> boxLoops(glm::vec3 l, glm::vec3 h) {
  return {{{l.x, l.y, l.z}, {l.x, l.y, h.z}, {l.x, h.y, h.z}, {l.x, h.y, l.z}},
          {{h.x, l.y, l.z}, {h.x, h.y, l.z}, {h.x, h.y, h.z}, {h.x, l.y, h.z}},
          {{l.x, l.y, l.z}, {l.x, h.y, l.z}, {h.x, h.y, l.z}, {h.x, l.y, l.z}},
          {{l.x, l.y, h.z}, {h.x, l.y, h.z}, {h.x, h.y, h.z}, {l.x, h.y, h.z}},
          {{l.x, h.y, l.z}, {l.x, h.y, h.z}, {h.x, h.y, h.z}, {h.x, h.y, l.z}},
          {{l.x, l.y, l.z}, {h.x, l.y, l.z}, {h.x, l.y, h.z}, {l.x, l.y, h.z}}};
}

inline Loop reversed(Loop loop) {
  return Loop(loop.rbegin(), loop.rend());
}

// A box as one object; without `bottom` its -y face is left out (a wall or a
// building standing on the ground, open below). SidesInward flips the four
// side faces only.
inline void addWoundBox(Scene& scene, const std::string& name, glm::vec3 lo, glm::vec3 hi,
                        Winding winding, bool bottom = true) {
  std::vector<Loop> loops = boxLoops(lo, hi);
  if (!bottom) loops.pop_back();
  for (size_t f = 0; f < loops.size(); ++f) {
    const bool side = f < 4;
    if (winding == Winding::Inward || (winding == Winding::SidesInward && side))
      loops[f] = reversed(loops[f]);
  }
  addFaces(scene, name, loops);
}

// A scene with its flattened triangles, an Embree ray query and its solids.
struct SolidsScene {
  Scene scene;
  FlatTriangles triangles;
  std::unique_ptr<RayQuery> rays;
  Solids solids;
  void build(const SolidsOptions& options = {}) {
    finalizeScene(scene);
    triangles = flattenScene(scene);
    rays = makeEmbreeRayQuery(triangles);
    solids = Solids::build(triangles, options);
  }
};

}  // namespace vistream::testing
