// Hand-built test scenes made of closed boxes and quads, independent of the
// procedural generators, so tests of spatial code have known answers.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "common/scene/scene.h"

namespace vistream::testing {

// Adds a closed axis-aligned box as one object: 6 quads (12 triangles, two
// per face ID), wound counter-clockwise seen from outside. Face order:
// -x, +x, -y, +y, -z, +z. Returns the first face ID.
inline uint32_t addBox(Scene& scene, const std::string& name, glm::vec3 lo, glm::vec3 hi,
                       bool dynamic = false) {
  Object o;
  o.name = name;
  o.dynamic = dynamic;
  const uint32_t first = scene.faceCount;
  auto quad = [&](glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) {
    const uint32_t base = uint32_t(o.mesh.positions.size());
    o.mesh.positions.insert(o.mesh.positions.end(), {a, b, c, d});
    o.mesh.triangles.emplace_back(base, base + 1, base + 2);
    o.mesh.triangles.emplace_back(base, base + 2, base + 3);
    o.mesh.faceIds.insert(o.mesh.faceIds.end(), {scene.faceCount, scene.faceCount});
    ++scene.faceCount;
  };
  const glm::vec3 l = lo, h = hi;
  quad({l.x, l.y, l.z}, {l.x, l.y, h.z}, {l.x, h.y, h.z}, {l.x, h.y, l.z});  // -x
  quad({h.x, l.y, l.z}, {h.x, h.y, l.z}, {h.x, h.y, h.z}, {h.x, l.y, h.z});  // +x
  quad({l.x, l.y, l.z}, {h.x, l.y, l.z}, {h.x, l.y, h.z}, {l.x, l.y, h.z});  // -y
  quad({l.x, h.y, l.z}, {l.x, h.y, h.z}, {h.x, h.y, h.z}, {h.x, h.y, l.z});  // +y
  quad({l.x, l.y, l.z}, {l.x, h.y, l.z}, {h.x, h.y, l.z}, {h.x, l.y, l.z});  // -z
  quad({l.x, l.y, h.z}, {h.x, l.y, h.z}, {h.x, h.y, h.z}, {l.x, h.y, h.z});  // +z
  scene.objects.push_back(std::move(o));
  return first;
}

// An upward-facing ground quad at y over [x0,x1] x [z0,z1]. Returns its face ID.
inline uint32_t addGround(Scene& scene, float x0, float z0, float x1, float z1, float y = 0.0f) {
  Object o;
  o.name = "ground";
  o.mesh.positions = {{x0, y, z0}, {x0, y, z1}, {x1, y, z1}, {x1, y, z0}};
  o.mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
  o.mesh.faceIds = {scene.faceCount, scene.faceCount};
  scene.objects.push_back(std::move(o));
  return scene.faceCount++;
}

// Adds one object made of planar faces, each a vertex loop fan-triangulated
// from its first vertex (which must see every other vertex); a loop's winding
// gives its normal by the right-hand rule. Returns the first face ID.
using Loop = std::vector<glm::vec3>;
inline uint32_t addFaces(Scene& scene, const std::string& name, const std::vector<Loop>& faces,
                         bool dynamic = false) {
  Object o;
  o.name = name;
  o.dynamic = dynamic;
  const uint32_t first = scene.faceCount;
  for (const Loop& loop : faces) {
    const uint32_t base = uint32_t(o.mesh.positions.size());
    o.mesh.positions.insert(o.mesh.positions.end(), loop.begin(), loop.end());
    for (uint32_t i = 1; i + 1 < loop.size(); ++i) {
      o.mesh.triangles.emplace_back(base, base + i, base + i + 1);
      o.mesh.faceIds.push_back(scene.faceCount);
    }
    ++scene.faceCount;
  }
  scene.objects.push_back(std::move(o));
  return first;
}

// Face IDs of a box added by addBox, by side.
enum BoxSide : uint32_t { kMinusX = 0, kPlusX, kMinusY, kPlusY, kMinusZ, kPlusZ };

// Appends a box standing on y = 0 as an OBJ object (8 vertices, 6 quads);
// `base` is the 1-based index its first vertex gets, advanced by 8.
inline void appendBoxObj(std::string& obj, int& base, const std::string& name, double x0, double z0,
                         double x1, double z1, double h) {
  obj += "o " + name + "\n";
  for (int k = 0; k < 8; ++k)
    obj += "v " + std::to_string((k & 1) ? x1 : x0) + " " + std::to_string((k & 2) ? h : 0.0) +
           " " + std::to_string((k & 4) ? z1 : z0) + "\n";
  for (const auto& f : {std::array{0, 4, 6, 2},
                        {1, 3, 7, 5},
                        {0, 1, 5, 4},
                        {2, 6, 7, 3},
                        {0, 2, 3, 1},
                        {4, 5, 7, 6}})
    obj += "f " + std::to_string(base + f[0]) + " " + std::to_string(base + f[1]) + " " +
           std::to_string(base + f[2]) + " " + std::to_string(base + f[3]) + "\n";
  base += 8;
}

// OBJ text of a ground quad at y = 0 (object "ground", face 0) with boxes
// standing on it, added in order by box() (appendBoxObj).
struct GroundAndBoxesObj {
  GroundAndBoxesObj(double x0, double z0, double x1, double z1) {
    obj = "o ground\n";
    for (const auto& [x, z] : {std::array{x0, z0}, {x0, z1}, {x1, z1}, {x1, z0}})
      obj += "v " + std::to_string(x) + " 0 " + std::to_string(z) + "\n";
    obj += "f 1 2 3 4\n";
  }
  void box(const std::string& name, double x0, double z0, double x1, double z1, double h) {
    appendBoxObj(obj, base, name, x0, z0, x1, z1, h);
  }

  std::string obj;
  int base = 5;  // the OBJ index of the next box's first vertex
};

// An OBJ of 600 m of ground with a row of eight boxes 120-170 m ahead of
// the origin (-Z): street cells round the origin whose far field is the
// row (the impostor tests' scene).
inline std::string farRowObj() {
  GroundAndBoxesObj o(-300, -300, 300, 300);
  for (int k = 0; k < 8; ++k)
    o.box("far" + std::to_string(k), 15 + 5 * k, -170 + 3 * (k % 3), 19 + 5 * k, -120,
          8 + 3 * (k % 4));
  return o.obj;
}

}  // namespace vistream::testing
