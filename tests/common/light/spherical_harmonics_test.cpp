#include "common/light/spherical_harmonics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace vistream {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::vector<glm::vec3> randomDirections(size_t n) {
  std::mt19937 rng(5);
  std::normal_distribution<float> g;
  std::vector<glm::vec3> out;
  while (out.size() < n) {
    const glm::vec3 v(g(rng), g(rng), g(rng));
    if (glm::length(v) > 1e-3f) out.push_back(glm::normalize(v));
  }
  return out;
}

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
    const double theta = kPi * (r + 0.5) / rows;
    const double dOmega = (kPi / rows) * (2 * kPi / cols) * std::sin(theta);
    for (int c = 0; c < cols; ++c) {
      const double phi = 2 * kPi * (c + 0.5) / cols;
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
  EXPECT_NEAR(clampedCosineZonal(0) * std::sqrt(4 * kPi), kPi, 1e-9);
  EXPECT_NEAR(clampedCosineZonal(1) * std::sqrt(4 * kPi / 3), 2 * kPi / 3, 1e-9);
  EXPECT_NEAR(clampedCosineZonal(2) * std::sqrt(4 * kPi / 5), kPi / 4, 1e-9);
}

TEST(SphericalHarmonics, FewerOrdersAreThePrefixOfMore) {
  for (const glm::vec3& d : randomDirections(20)) {
    float all[25], some[9];
    shEvaluate(d, 5, all);
    shEvaluate(d, 3, some);
    for (int i = 0; i < 9; ++i) EXPECT_EQ(some[i], all[i]);
  }
}

}  // namespace
}  // namespace vistream
