// Checks on a loaded scene, in file coordinates, shared by the loader tests
// (OBJ, glTF, manifests): each loader must give the same answers for the same
// geometry, so they are checked by the same code.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "common/scene/scene.h"

namespace vistream::testing {

// Expects each coordinate of `actual` within `tolerance` of `expected`.
inline void expectNear(const glm::dvec3& actual, const glm::dvec3& expected, double tolerance) {
  EXPECT_NEAR(actual.x, expected.x, tolerance);
  EXPECT_NEAR(actual.y, expected.y, tolerance);
  EXPECT_NEAR(actual.z, expected.z, tolerance);
}

// The first object named `name`, or nullptr.
inline const Object* findObject(const Scene& scene, const std::string& name) {
  for (const Object& o : scene.objects)
    if (o.name == name) return &o;
  return nullptr;
}

// Expects a texcoord per position, each equal to its position's file x and y
// (to 1e-6): the test files give every vertex uv = xy, so a texcoord that
// moved to another vertex, or was dropped, shows.
inline void expectTexcoordsEqualFileXy(const Scene& scene, const TriangleMesh& mesh) {
  ASSERT_EQ(mesh.texcoords.size(), mesh.positions.size());
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    SCOPED_TRACE("vertex " + std::to_string(v));
    const glm::dvec3 p = scene.toFile(mesh.positions[v]);
    EXPECT_NEAR(mesh.texcoords[v].x, p.x, 1e-6);
    EXPECT_NEAR(mesh.texcoords[v].y, p.y, 1e-6);
  }
}

}  // namespace vistream::testing
