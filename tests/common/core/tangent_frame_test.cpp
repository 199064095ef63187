#include "common/core/tangent_frame.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "tests/common/support/random_directions.h"

namespace vistream {
namespace {

using testing::randomDirections;

TEST(TangentFrame, IsOrthonormalForEveryNormalIncludingThePoles) {
  auto normals = randomDirections(100);
  normals.insert(normals.end(), {{0, 0, 1}, {0, 0, -1}, {1, 0, 0}, {0, -1, 0}});
  for (const glm::vec3& n : normals) {
    const TangentFrame f = TangentFrame::around(n);
    EXPECT_NEAR(glm::length(f.t), 1.0f, 1e-5f);
    EXPECT_NEAR(glm::length(f.b), 1.0f, 1e-5f);
    EXPECT_NEAR(glm::dot(f.t, f.b), 0.0f, 1e-5f);
    EXPECT_NEAR(glm::dot(f.t, n), 0.0f, 1e-5f);
    EXPECT_NEAR(glm::distance(glm::cross(f.t, f.b), n), 0.0f, 1e-5f);  // right-handed
  }
}

TEST(TangentFrame, TurnsVectorsIntoTheFrameAndBack) {
  const TangentFrame f = TangentFrame::around(glm::normalize(glm::vec3(-2, 1, 0.5f)));
  const glm::vec3 v(0.3f, -4.0f, 2.5f);
  EXPECT_NEAR(glm::distance(f.toWorld(f.toLocal(v)), v), 0.0f, 1e-5f);
  EXPECT_NEAR(f.toLocal(f.n).z, 1.0f, 1e-6f);
}

}  // namespace
}  // namespace vistream
