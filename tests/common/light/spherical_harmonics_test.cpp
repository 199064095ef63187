#include "common/light/spherical_harmonics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "tests/common/support/random_directions.h"

namespace vistream {
namespace {

using testing::randomDirections;

// Closed forms from the literature (Sloan, "Stupid spherical harmonics tricks").
TEST(SphericalHarmonics, MatchesTheClosedFormsOfOrdersZeroToFour) {
  for (const glm::vec3& d : randomDirections(200)) {
    float y[25];
    shEvaluate(d, 5, y);
    const double x = d.x, yy = d.y, z = d.z;
    const double want[][2] = {
        {0, 0.282095},
        {1, 0.488603 * yy},
        {2, 0.488603 * z},
        {3, 0.488603 * x},
        {4, 1.092548 * x * yy},
        {5, 1.092548 * yy * z},
        {6, 0.315392 * (3 * z * z - 1)},
        {7, 1.092548 * x * z},
        {8, 0.546274 * (x * x - yy * yy)},
        {9, 0.590044 * yy * (3 * x * x - yy * yy)},
        {12, 0.373176 * z * (5 * z * z - 3)},
        {15, 0.590044 * x * (x * x - 3 * yy * yy)},
        {20, 0.105786 * (35 * z * z * z * z - 30 * z * z + 3)},
        {24, 0.625836 * (x * x * x * x - 6 * x * x * yy * yy + yy * yy * yy * yy)},
    };
    for (const auto& [index, value] : want) EXPECT_NEAR(y[int(index)], value, 2e-5) << index;
  }
}

// Midpoint quadrature over the sphere: integral of Y_i Y_j is delta_ij, and
// the clamped cosine projects onto the m = 0 terms only, with
// clampedCosineZonal's values.
TEST(SphericalHarmonics, AreOrthonormalAndProjectTheClampedCosineAsStated) {
  const int rows = 400, cols = 800;
  std::vector<double> gram(25 * 25, 0.0), cosine(25, 0.0);
  for (int r = 0; r < rows; ++r) {
    const double theta = std::numbers::pi * (r + 0.5) / rows;
    const double dOmega =
        (std::numbers::pi / rows) * (2 * std::numbers::pi / cols) * std::sin(theta);
    for (int c = 0; c < cols; ++c) {
      const double phi = 2 * std::numbers::pi * (c + 0.5) / cols;
      const glm::vec3 d(float(std::sin(theta) * std::cos(phi)),
                        float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)));
      float y[25];
      shEvaluate(d, 5, y);
      for (int i = 0; i < 25; ++i) {
        for (int j = 0; j < 25; ++j) gram[size_t(i * 25 + j)] += double(y[i]) * y[j] * dOmega;
        cosine[size_t(i)] += double(y[i]) * std::max(0.0, double(d.z)) * dOmega;
      }
    }
  }
  for (int i = 0; i < 25; ++i)
    for (int j = 0; j < 25; ++j)
      EXPECT_NEAR(gram[size_t(i * 25 + j)], i == j ? 1.0 : 0.0, 2e-3) << i << "," << j;
  for (int l = 0; l <= 4; ++l)
    for (int m = -l; m <= l; ++m)
      EXPECT_NEAR(cosine[size_t(l * (l + 1) + m)], m == 0 ? clampedCosineZonal(l) : 0.0, 2e-3)
          << "l " << l << " m " << m;
  // Ramamoorthi and Hanrahan's weights pi, 2 pi / 3, pi / 4.
  EXPECT_NEAR(clampedCosineZonal(0) * std::sqrt(4 * std::numbers::pi), std::numbers::pi, 1e-9);
  EXPECT_NEAR(clampedCosineZonal(1) * std::sqrt(4 * std::numbers::pi / 3), 2 * std::numbers::pi / 3,
              1e-9);
  EXPECT_NEAR(clampedCosineZonal(2) * std::sqrt(4 * std::numbers::pi / 5), std::numbers::pi / 4,
              1e-9);
}

TEST(SphericalHarmonics, FewerOrdersAreThePrefixOfMore) {
  for (const glm::vec3& d : randomDirections(20)) {
    float all[25], some[9];
    shEvaluate(d, 5, all);
    shEvaluate(d, 3, some);
    for (int i = 0; i < 9; ++i) EXPECT_EQ(some[i], all[i]);
  }
}

glm::mat3 randomRotation(std::mt19937& rng) {
  std::normal_distribution<float> g;
  const glm::vec3 a = glm::normalize(glm::vec3(g(rng), g(rng), g(rng)));
  glm::vec3 b = glm::vec3(g(rng), g(rng), g(rng));
  b = glm::normalize(b - a * glm::dot(a, b));
  return glm::mat3(a, b, glm::cross(a, b));  // columns: a right-handed frame
}

// Y(r s) = D Y(s): the rotated basis, evaluated directly, is the rotation
// matrix applied to the basis at s, for every band and random rotations.
TEST(ShRotation, TurnsTheBasisAsTurningItsArgumentDoes) {
  std::mt19937 rng(21);
  const auto dirs = randomDirections(20);
  for (int trial = 0; trial < 20; ++trial) {
    const glm::mat3 r = randomRotation(rng);
    const ShRotation d(r, 5);
    for (const glm::vec3& s : dirs) {
      float ys[25], yrs[25], turned[25];
      shEvaluate(s, 5, ys);
      shEvaluate(r * s, 5, yrs);
      d.apply(ys, turned);
      for (int i = 0; i < 25; ++i) ASSERT_NEAR(turned[i], yrs[i], 2e-4) << "term " << i;
    }
  }
}

TEST(ShRotation, TheIdentityLeavesCoefficientsAloneAndBandsAreOrthogonal) {
  const ShRotation id(glm::mat3(1.0f), 5);
  float c[25], out[25];
  for (int i = 0; i < 25; ++i) c[i] = float(i) - 7.5f;
  id.apply(c, out);
  for (int i = 0; i < 25; ++i) EXPECT_NEAR(out[i], c[i], 1e-6f);
  std::mt19937 rng(4);
  const ShRotation d(randomRotation(rng), 5);
  for (int l = 0; l <= 4; ++l)
    for (int a = -l; a <= l; ++a)
      for (int b = -l; b <= l; ++b) {
        double dot = 0.0;
        for (int k = -l; k <= l; ++k) dot += double(d.at(l, a, k)) * d.at(l, b, k);
        EXPECT_NEAR(dot, a == b ? 1.0 : 0.0, 1e-5) << l << " " << a << " " << b;
      }
}

}  // namespace
}  // namespace vistream
