// Building blocks of the procedural scenes: closed boxes and single faces
// appended to a PolygonObject.
//
// Every face is wound counter-clockwise seen from outside (its normal, by the
// right-hand rule, points out of the solid or up from a ground surface). A box
// is always 8 new vertices followed by 6 quads in the order -X, +X, -Y, +Y, -Z,
// +Z of its own frame; the tests rely on "six consecutive faces per box".
//
// Private to common/generate. Degenerate input (a box with a zero or negative
// extent) is a bug in a generator, never user input: VS_CHECK.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <utility>
#include <vector>

#include "common/core/check.h"
#include "common/generate/generate.h"

namespace vistream::generate_detail {

// The facade colours the city generators draw from, in this order.
constexpr int kFacadeMaterials = 5;
inline std::vector<Material> facadeMaterials() {
  const auto material = &Material::diffuseColour;
  return {material("facade_sand", {0.76f, 0.70f, 0.58f}),
          material("facade_brick", {0.62f, 0.36f, 0.28f}),
          material("facade_grey", {0.58f, 0.59f, 0.62f}),
          material("facade_white", {0.85f, 0.84f, 0.80f}),
          material("facade_ochre", {0.80f, 0.62f, 0.35f})};
}

inline PolygonObject makeObject(std::string name, uint32_t material) {
  PolygonObject object;
  object.name = std::move(name);
  object.material = material;
  return object;
}

inline void addQuad(PolygonObject& object, const glm::dvec3& a, const glm::dvec3& b,
                    const glm::dvec3& c, const glm::dvec3& d) {
  const auto base = uint32_t(object.vertices.size());
  object.vertices.insert(object.vertices.end(), {a, b, c, d});
  object.faces.push_back({base, base + 1, base + 2, base + 3});
}

inline void addTriangle(PolygonObject& object, const glm::dvec3& a, const glm::dvec3& b,
                        const glm::dvec3& c) {
  const auto base = uint32_t(object.vertices.size());
  object.vertices.insert(object.vertices.end(), {a, b, c});
  object.faces.push_back({base, base + 1, base + 2});
}

// Six quads over eight corners; corner i has x from bit 0, y from bit 1 and z
// from bit 2 of i (in the box's own frame). The loops are CCW seen from
// outside for any frame with the orientation of x, y, z.
inline void addBoxFaces(PolygonObject& object, const std::array<glm::dvec3, 8>& corners) {
  const auto b = uint32_t(object.vertices.size());
  object.vertices.insert(object.vertices.end(), corners.begin(), corners.end());
  object.faces.push_back({b + 0, b + 4, b + 6, b + 2});  // -X
  object.faces.push_back({b + 1, b + 3, b + 7, b + 5});  // +X
  object.faces.push_back({b + 0, b + 1, b + 5, b + 4});  // -Y
  object.faces.push_back({b + 2, b + 6, b + 7, b + 3});  // +Y
  object.faces.push_back({b + 0, b + 2, b + 3, b + 1});  // -Z
  object.faces.push_back({b + 4, b + 5, b + 7, b + 6});  // +Z
}

// Closed axis-aligned box between two opposite corners (in any order).
inline void addBox(PolygonObject& object, const glm::dvec3& cornerA, const glm::dvec3& cornerB) {
  const glm::dvec3 lo = glm::min(cornerA, cornerB), hi = glm::max(cornerA, cornerB);
  VS_CHECK(hi.x > lo.x && hi.y > lo.y && hi.z > lo.z);
  std::array<glm::dvec3, 8> corners;
  for (int i = 0; i < 8; ++i)
    corners[size_t(i)] = {(i & 1) ? hi.x : lo.x, (i & 2) ? hi.y : lo.y, (i & 4) ? hi.z : lo.z};
  addBoxFaces(object, corners);
}

// Closed box standing upright: footprint centred on (centre.x, centre.z),
// from y = centre.y up by `size.y`, turned by `yaw` radians about +Y.
inline void addUprightBox(PolygonObject& object, const glm::dvec3& baseCentre,
                          const glm::dvec3& size, double yaw) {
  VS_CHECK(size.x > 0.0 && size.y > 0.0 && size.z > 0.0);
  const double c = std::cos(yaw), s = std::sin(yaw);
  std::array<glm::dvec3, 8> corners;
  for (int i = 0; i < 8; ++i) {
    const double lx = ((i & 1) ? 0.5 : -0.5) * size.x;
    const double lz = ((i & 4) ? 0.5 : -0.5) * size.z;
    // Rotation about +Y keeps the frame right-handed, so the loops stay outward.
    corners[size_t(i)] = {baseCentre.x + c * lx + s * lz, baseCentre.y + ((i & 2) ? size.y : 0.0),
                          baseCentre.z - s * lx + c * lz};
  }
  addBoxFaces(object, corners);
}

}  // namespace vistream::generate_detail
